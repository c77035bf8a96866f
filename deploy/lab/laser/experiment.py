"""Laser experiments: the papers' tables and figures (seeds 002 and 003) as seeded replications.

Seeds ``002_fe2ac635ba0eab3e.txt`` §6 table 3 and ``003_5278cbbbf8cc61de.txt`` §V figs. 3-4 and the
robustness runs (``/work/shared/seeds/``).

Specs are ordinary experiment specs (``deploy/experiments/laser-*.toml``) with
``family = "laser"``: groups of laser scenarios (``deploy/scenarios/laser/``) times a grid of
``section.key`` values, each setting run ``replications`` times with seeds ``seed + r``. The
machinery of ``swarmloc experiment`` runs them (spec checks, plan, spawned pool, one CSV row per
finished job, resume, progress); this module supplies what is laser-specific, through the
hooks of :data:`swarmloc.families.FAMILIES` (its entry's ``experiment``):

- :func:`settings`: every setting's scenario built and validated before anything runs (a group's
  ``duration_s`` becomes ``world.steps``);
- :func:`run_job`: one replication with :func:`~swarmloc.deploy.lab.laser.runner.run_laser`;
- :func:`columns` and :func:`row`: the tidy results file. Columns: the setting (experiment,
  group, setting, scenario, map, algorithm, population, cooperative, robots, steps, seed,
  replication, one column per grid key), the run summary (``laser_batch`` module docstring),
  cpu_s, wall_s, config_hash, and ``position_error_mm``: every robot's error at every step
  (:func:`~swarmloc.deploy.lab.laser.runner.encode_series_mm`), from which the report draws the
  papers' error-over-time figures.

The shipped specs: ``laser-table3`` (002 table 3), ``laser-kidnap`` (003 fig. 3),
``laser-collab`` (003 fig. 4) and ``laser-robustness`` (003 §V, 500 runs). ``swarmloc experiment
laser-kidnap`` runs one (``--replications N``: a preview that the full run later resumes from);
``swarmloc report results/laser-*.csv --out docs/laser`` writes the report from their results
files (the template of ``deploy/lab/laser/report.py``).
"""

from __future__ import annotations

import time

from swarmloc.config import ConfigError
from swarmloc.deploy.lab.experiment import ExperimentSpec, Job, Setting, setting_grid
from swarmloc.deploy.lab.laser.runner import encode_series_mm, load_laser_scenario, run_laser

#: The setting's description, before the grid keys.
LEAD_COLUMNS = ("experiment", "group", "setting", "scenario", "map", "algorithm", "population",
                "cooperative", "robots", "steps", "seed", "replication")
#: The run's figures, after the grid keys (``position_error_mm`` last: it is long).
METRIC_COLUMNS = ("final_error_m", "final_error_max_m", "final_error_sym_m",
                  "final_heading_error_rad", "mean_error_m", "settle_step", "settled_robots",
                  "localized", "kidnap_step", "settled_before_kidnap", "recovered",
                  "recover_steps", "first_contact_step", "bumps", "cpu_s", "wall_s",
                  "config_hash", "position_error_mm")
#: The replication's seed is this scenario key.
SEED_KEY = "world.seed"
#: The experiments of the report, in its order.
REPORT_SPECS = ("laser-table3", "laser-kidnap", "laser-collab", "laser-robustness")


def columns(spec: ExperimentSpec) -> list[str]:
    """The header of a laser results file."""
    return [*LEAD_COLUMNS, *spec.grid_keys(), *METRIC_COLUMNS]


def settings(spec: ExperimentSpec) -> list[Setting]:
    """Every setting of a laser spec, each scenario loaded and validated once; an error names
    the group and the setting."""
    out = []
    for g in spec.group:
        for scenario_name, sid, grid, overrides in setting_grid(g):
            where = f"experiment '{spec.name}', group '{g.name}', setting '{sid}'"
            try:
                scenario = load_laser_scenario(scenario_name, overrides)
                if g.duration_s is not None:
                    steps = max(1, round(g.duration_s / scenario.world.dt_s))
                    overrides.append(f"world.steps={steps}")
                    scenario = load_laser_scenario(scenario_name, overrides)
            except (ConfigError, ValueError) as exc:
                raise ConfigError(f"{where}: {exc}") from None
            w = scenario.world
            out.append(Setting(
                sid, g.name, scenario_name, tuple(overrides), grid, scenario.config_hash(),
                w.robots, w.steps * w.dt_s, scenario.algorithm.name, cost=w.robots * w.steps))
    return out


def run_job(job: Job) -> dict:
    """One replication of a laser setting; a flat dict of what the row needs."""
    t0, c0 = time.perf_counter(), time.process_time()
    scenario = load_laser_scenario(job.scenario, list(job.overrides))
    result = run_laser(scenario)
    algo = scenario.algorithm
    return {
        "map": scenario.world.map,
        "algorithm": algo.name,
        "population": algo.entry.population_text(algo.resolved_params()),
        "cooperative": algo.cooperative,
        "robots": scenario.world.robots,
        "steps": scenario.world.steps,
        **result.summary,
        "cpu_s": round(time.process_time() - c0, 3),
        "wall_s": round(time.perf_counter() - t0, 3),
        "position_error_mm": encode_series_mm(result.position_error_m),
    }


def _cell(value):
    if isinstance(value, bool):
        return int(value)
    if isinstance(value, float):
        return round(value, 6)
    return value


def row(spec: ExperimentSpec, job: Job, out: dict) -> list:
    """One results row, in :func:`columns` order (None written as an empty cell)."""
    grid = dict(job.grid)
    lead = {"experiment": spec.name, "group": job.group, "setting": job.setting,
            "scenario": job.scenario, "seed": job.seed, "replication": job.replication,
            "config_hash": job.config_hash}
    values = {**out, **lead}
    return [*(_cell(values[c]) for c in LEAD_COLUMNS), *(grid.get(k) for k in spec.grid_keys()),
            *(_cell(values[c]) for c in METRIC_COLUMNS)]


__all__ = ["LEAD_COLUMNS", "METRIC_COLUMNS", "REPORT_SPECS", "SEED_KEY", "columns", "row",
           "run_job", "settings"]
