"""The e-puck foraging family's hooks for the experiment engine (seeds 000-001).

``swarmloc experiment SPEC`` with ``family = "foraging"`` (the default; ``"epuck"`` too) runs the foraging scenarios
(``deploy/scenarios/ES*.toml``, ``SO-*.toml``) with the batch engine
(:func:`swarmloc.deploy.lab.epuck.batch.run_batch`). This module is the family's entry in
the ``experiment`` of the family's entry in :data:`swarmloc.families.FAMILIES`:

- :func:`settings`: every setting's scenario built and validated before anything runs (a group's
  ``duration_s`` becomes ``world.duration_s``);
- :func:`run_job`: one replication with the batch engine;
- :func:`columns` and :func:`row`: the setting (experiment, group, setting, scenario, strategy,
  beta, robots, duration_s, seed, replication, one column per grid key), the metrics of seed 000
  §6 (recruitment_time_s, empty if not reached; robots_found_both; round_trips_total;
  on_path_fraction_mean; lost_total), the retrieval diagnostic of issue 42 (departures, the
  number of times a robot set out for an area, and departure_error_m_median, the median error
  of the estimate it set out with: ``batch.DepartureErrors``), wall_s and config_hash;
- :func:`prepare`: the kernels compiled once in the engine's process before the pool starts.

The report template is :mod:`swarmloc.deploy.lab.epuck.report`.
"""

from __future__ import annotations

import hashlib
import json
import time

import numpy as np

from swarmloc.config import ConfigError
from swarmloc.deploy.lab.experiment import (
    ExperimentSpec,
    Job,
    Setting,
    override_text,
    setting_grid,
)
from swarmloc.deploy.scenario import Scenario, load_scenario

#: Columns of the results file before the grid keys and after them.
LEAD_COLUMNS = ("experiment", "group", "setting", "scenario", "strategy", "beta", "robots",
                "duration_s", "seed", "replication")
METRIC_COLUMNS = ("recruitment_time_s", "robots_found_both", "round_trips_total",
                  "on_path_fraction_mean", "lost_total", "departures", "departure_error_m_median",
                  "wall_s", "config_hash")
#: The replication's seed is this scenario key.
SEED_KEY = "world.seed"


def config_hash(scenario: Scenario) -> str:
    """Hash of the scenario without its seed."""
    data = scenario.to_dict()
    data["world"].pop("seed", None)
    blob = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
    return hashlib.sha256(blob).hexdigest()[:12]


def columns(spec: ExperimentSpec) -> list[str]:
    return [*LEAD_COLUMNS, *spec.grid_keys(), *METRIC_COLUMNS]


def settings(spec: ExperimentSpec) -> list[Setting]:
    """Every setting of an e-puck spec, each scenario built once; an error names group and
    setting."""
    out = []
    for g in spec.group:
        for scenario_name, sid, grid, overrides in setting_grid(g):
            if g.duration_s is not None:
                overrides.append(f"world.duration_s={override_text(float(g.duration_s))}")
            try:
                scenario = load_scenario(scenario_name, overrides)
            except ConfigError as exc:
                raise ConfigError(f"experiment '{spec.name}', group '{g.name}', "
                                  f"setting '{sid}': {exc}") from None
            out.append(Setting(sid, g.name, scenario_name, tuple(overrides), grid,
                               config_hash(scenario), scenario.world.robots,
                               scenario.world.duration_s, scenario.agent.strategy))
    return out


def prepare(log) -> None:
    """Compile the kernels once here, not in every worker at once (``deploy/warm.py``)."""
    from swarmloc.deploy.warm import ensure_compiled

    ensure_compiled(log)


def run_job(job: Job) -> dict:
    """Run one replication with the batch engine; a flat dict of what the row needs."""
    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.warm import ensure_compiled

    # On a cluster worker's host nobody compiled yet: one process compiles, the others of the
    # host wait on its lock (a stamp check of a few ms once warm).
    ensure_compiled()
    t0 = time.perf_counter()
    scenario = load_scenario(job.scenario, list(job.overrides))
    result = run_batch(scenario)
    m = result.metrics
    return {
        "strategy": scenario.agent.strategy,
        "beta": scenario.agent.beta,
        "robots": scenario.world.robots,
        "duration_s": scenario.world.duration_s,
        "recruitment_time_s": m["recruitment_time_s"],
        "robots_found_both": m["robots_found_both"],
        "round_trips_total": m["round_trips_total"],
        "on_path_fraction_mean": m["on_path_fraction_mean"],
        "lost_total": int(result.lost_count.sum()),
        "departures": int(result.departure_error_m.size),
        "departure_error_m_median": (round(float(np.median(result.departure_error_m)), 4)
                                     if result.departure_error_m.size else None),
        "wall_s": round(time.perf_counter() - t0, 3),
    }


def row(spec: ExperimentSpec, job: Job, out: dict) -> list:
    grid = dict(job.grid)
    return [spec.name, job.group, job.setting, job.scenario, out["strategy"], out["beta"],
            out["robots"], out["duration_s"], job.seed, job.replication,
            *(grid.get(k) for k in spec.grid_keys()),
            out["recruitment_time_s"], out["robots_found_both"], out["round_trips_total"],
            out["on_path_fraction_mean"], out["lost_total"], out["departures"],
            out["departure_error_m_median"], out["wall_s"], job.config_hash]


__all__ = ["LEAD_COLUMNS", "METRIC_COLUMNS", "SEED_KEY", "columns", "config_hash", "prepare",
           "row", "run_job", "settings"]
