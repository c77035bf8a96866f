"""MRCLAM replays through the experiment engine: the replay family's hooks.

A spec with ``family = "replay"`` (shipped: ``deploy/experiments/mrclam6.toml``, the report of
``docs/mrclam/``) names replay scenarios (``deploy/scenarios/replay/``, flat tables of
:class:`~swarmloc.world.replay.service.ReplayScenario`: ``dataset``, ``algorithm``,
``cooperative``, ``calibration``, ``start``, ``kidnap_s``, ``dt_s``, ``duration_s``,
``calibration_s``, ``params``) and a grid of their
keys (``algorithm = ["pf", "cfsga"]``); replication ``r`` runs with ``seed = spec seed + r`` (the
localizers' generators ``[seed, 7, robot]``). One job replays the whole data set through one
localizer per robot (:func:`~swarmloc.deploy.lab.replay.mrclam.run_replay`) and scores each robot
against the Vicon ground truth (:func:`~swarmloc.deploy.lab.replay.mrclam.score`); its rows
(:func:`rows`, one per robot, written in one call) are the setting (experiment, group, setting,
scenario, dataset, algorithm, cooperative, dt_s, seed, replication, one column per grid key), the
robot and its scores (with the time until localized, the RMSE after and a kidnap's recovery
time; the position NEES's mean and share inside the chi-square 95 % band and the mean trace of
the position covariance, the heading NEES's mean and share (one degree of freedom), the NIS of
the landmark and teammate updates (mean, share inside the band), each NaN for localizers without
a covariance or a NIS tally, and evo's APE and RPE (translation, RMSE); issue 46), cpu_s (the
replay loop), wall_s and config_hash.

The data set is not part of the repository: ``dataset`` is a folder (relative to the working
directory), ``../shared/data/mrclam/MRCLAM_Dataset6`` in the shipped scenario and spec; elsewhere
``swarmloc experiment mrclam6 --set dataset=PATH``. A missing folder stops the plan with a message
naming it. The config hash leaves the folder's path out (only its name): a results file made
from another working directory resumes.
"""

from __future__ import annotations

import functools
import hashlib
import json
import time
from pathlib import Path

from swarmloc.config import ConfigError
from swarmloc.deploy.lab.experiment import ExperimentSpec, Job, Setting, setting_grid

#: The replication's seed is this scenario key.
SEED_KEY = "seed"
LEAD_COLUMNS = ("experiment", "group", "setting", "scenario", "dataset", "algorithm",
                "cooperative", "calibration", "start", "kidnap_s", "dt_s", "seed", "replication")
METRIC_COLUMNS = ("robot", "position_rmse_m", "heading_rmse_rad", "final_error_m",
                  "scored_ticks", "localized_s", "rmse_localized_m", "recovery_s",
                  "position_nees_mean", "position_nees_in_95", "position_cov_trace_m2",
                  "heading_nees_mean", "heading_nees_in_95", "landmark_nis_mean",
                  "landmark_nis_in_95", "teammate_nis_mean", "teammate_nis_in_95", "ape_rmse_m",
                  "rpe_rmse_m", "cpu_s", "wall_s", "config_hash")
#: NIS columns of localizers that tally none (NaN: not measured, not zero).
_NO_NIS = {f"{kind}_nis_{stat}": float("nan") for kind in ("landmark", "teammate")
           for stat in ("mean", "in_95")}
#: What a job reports of its configuration (the lead columns it fills).
_CONFIG_COLUMNS = ("dataset", "algorithm", "cooperative", "calibration", "start", "kidnap_s",
                   "dt_s")
#: Relative CPU per tick of each localizer (the plan's progress weights; measured on Dataset 6).
_COST = {"dr": 1, "ekf": 2, "pf": 6, "cfsga": 6, "ssga": 5, "hybrid": 4, "ls-cen": 6,
         "ls-bda": 6, "ls-ci": 2, "gs-ci": 6, "gs-sci": 6}


def load_replay_scenario(name_or_path: str, overrides: list[str] = ()):
    """A replay scenario (shipped name or file) with ``key=value`` overrides."""
    from swarmloc.deploy.scenario import load_any

    loaded = load_any(name_or_path, overrides=list(overrides))
    if loaded.family != "replay":
        raise ConfigError(f"scenario '{name_or_path}' is a {loaded.family} scenario, not a "
                          f"replay scenario (deploy/scenarios/replay/)")
    return loaded.scenario


def config_hash(scenario) -> str:
    """Hash of the scenario without its seed and with the data set folder's name only."""
    data = scenario.to_dict()
    data.pop("seed", None)
    data["dataset"] = Path(str(data["dataset"])).name
    blob = json.dumps(data, sort_keys=True, separators=(",", ":"), default=str).encode()
    return hashlib.sha256(blob).hexdigest()[:12]


def _grid_keys(spec: ExperimentSpec) -> list[str]:
    """The grid keys with a column of their own (``algorithm``, ``cooperative`` and ``dt_s``
    have theirs among the lead columns)."""
    return [k for k in spec.grid_keys() if k not in LEAD_COLUMNS]


def columns(spec: ExperimentSpec) -> list[str]:
    return [*LEAD_COLUMNS, *_grid_keys(spec), *METRIC_COLUMNS]


def settings(spec: ExperimentSpec) -> list[Setting]:
    """Every setting of a replay spec, validated; a missing data set folder is an error naming
    the folder (and how to give another)."""
    out, folders = [], []
    for g in spec.group:
        for scenario_name, sid, grid, overrides in setting_grid(g):
            where = f"experiment '{spec.name}', group '{g.name}', setting '{sid}'"
            if g.duration_s is not None:
                overrides.append(f"duration_s={json.dumps(float(g.duration_s))}")
            try:
                scenario = load_replay_scenario(scenario_name, overrides)
            except (ConfigError, ValueError, TypeError) as exc:
                raise ConfigError(f"{where}: {exc}") from None
            folders.append((where, scenario.dataset))
            ticks = round((scenario.duration_s or 900.0) / scenario.dt_s)
            out.append(Setting(sid, g.name, scenario_name, tuple(overrides), grid,
                               config_hash(scenario), 5, scenario.duration_s or 900.0,
                               scenario.config().label,
                               cost=5 * ticks * _COST.get(scenario.algorithm, 4)))
    # Folders last: a wrong value anywhere in the spec is named first, data set or not.
    for where, dataset in folders:
        folder = Path(dataset)
        if not folder.is_dir():
            raise ConfigError(
                f"{where}: the MRCLAM data set folder {dataset!r} does not exist "
                f"(looked for {folder.resolve()}); give its path with `--set dataset=PATH` "
                f"or the group's `dataset` (see ../shared/data/mrclam/SOURCE.md)")
    return out


@functools.lru_cache(maxsize=2)
def _dataset(folder: str):
    from swarmloc.world.replay.mrclam import load_dataset

    return load_dataset(folder)


def run_job(job: Job) -> dict:
    """One replay of a setting, scored per robot."""
    from swarmloc.deploy.lab.replay.mrclam import consistency, run_replay, score, trajectory_errors

    t0 = time.perf_counter()
    scenario = load_replay_scenario(job.scenario, list(job.overrides))
    dataset = _dataset(str(Path(scenario.dataset).resolve()))
    config = scenario.config()
    result = run_replay(dataset, config)
    consistent, trajectories = consistency(result), trajectory_errors(result)
    return {"dataset": dataset.name, "algorithm": config.algorithm,
            "cooperative": config.cooperative, "calibration": config.calibration,
            "start": config.start, "kidnap_s": config.kidnap_s, "dt_s": config.dt_s,
            "scores": {int(rid): {**sc, **consistent[rid], **_NO_NIS,
                                  **{k: v for k, v in result.nis.get(rid, {}).items() if k in _NO_NIS},
                                  **trajectories[rid]}
                       for rid, sc in score(result).items()},
            "cpu_s": round(result.cpu_s, 1), "wall_s": round(time.perf_counter() - t0, 3)}


def rows(spec: ExperimentSpec, job: Job, out: dict) -> list[list]:
    """One row per robot, in :func:`columns` order (scores unrounded: the report rounds)."""
    grid = dict(job.grid)
    lead = {"experiment": spec.name, "group": job.group, "setting": job.setting,
            "scenario": job.scenario, "seed": job.seed, "replication": job.replication,
            **{k: out[k] for k in _CONFIG_COLUMNS}}
    lines = []
    for rid, sc in out["scores"].items():
        values = {"robot": rid, **sc,
                  "cpu_s": out["cpu_s"], "wall_s": out["wall_s"], "config_hash": job.config_hash}
        lines.append([*(lead[c] for c in LEAD_COLUMNS), *(grid.get(k) for k in _grid_keys(spec)),
                      *(values[c] for c in METRIC_COLUMNS)])
    return lines


def row(spec: ExperimentSpec, job: Job, out: dict) -> list:
    """The first robot's row (the engine writes :func:`rows`, every robot's)."""
    return rows(spec, job, out)[0]


__all__ = ["LEAD_COLUMNS", "METRIC_COLUMNS", "SEED_KEY", "columns", "config_hash",
           "load_replay_scenario", "row", "rows", "run_job", "settings"]
