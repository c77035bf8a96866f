"""The MRCLAM report (``docs/mrclam/``) from the replay family's results: the template of
``swarmloc report`` for ``family = "replay"``.

From the rows of ``swarmloc experiment mrclam6`` (one per run and robot) it writes, as the
evaluation always has: ``results.csv`` (every configuration, seed and robot, scores to 4
decimals), ``results.md`` (position and heading RMSE per robot, one line per configuration; for
an algorithm run over several seeds the mean over them) and ``trajectories_<config>.png`` for each
configuration's first seed (estimated paths solid, Vicon dotted). The trajectories are not in the
results: the first seed of each configuration is replayed again (deterministic: the same run),
with the spec's settings (``--spec``, default the shipped spec named like the experiment) and
``--set`` (e.g. ``dataset=PATH``).
"""

from __future__ import annotations

import csv
import math
from pathlib import Path

import numpy as np

from swarmloc.config import ConfigError
from swarmloc.deploy.lab.replay.mrclam import (
    LOCALIZED_M,
    REPORT_ALGORITHMS,
    ReplayConfig,
    format_table,
    plot_name,
)

#: The columns of the report's ``results.csv``.
RESULT_COLUMNS = ("dataset", "algorithm", "cooperative", "calibration", "start", "kidnap_s",
                  "seed", "dt_s", "robot", "position_rmse_m", "heading_rmse_rad", "final_error_m",
                  "scored_ticks", "localized_s", "rmse_localized_m", "recovery_s",
                  "position_nees_mean", "position_nees_in_95", "position_cov_trace_m2",
                  "heading_nees_mean", "heading_nees_in_95", "landmark_nis_mean",
                  "landmark_nis_in_95", "teammate_nis_mean", "teammate_nis_in_95", "ape_rmse_m",
                  "rpe_rmse_m", "cpu_s")
#: Consistency and trajectory columns (issue 46): absent from results files written before them.
_CONSISTENCY = ("position_nees_mean", "position_nees_in_95", "position_cov_trace_m2",
                "heading_nees_mean", "heading_nees_in_95", "landmark_nis_mean",
                "landmark_nis_in_95", "teammate_nis_mean", "teammate_nis_in_95", "ape_rmse_m",
                "rpe_rmse_m")
_INT = frozenset({"seed", "replication", "robot", "scored_ticks"})
_FLOAT = frozenset({"dt_s", "position_rmse_m", "heading_rmse_rad", "final_error_m", "cpu_s",
                    "wall_s", "kidnap_s", "localized_s", "rmse_localized_m", "recovery_s",
                    *_CONSISTENCY})
_ROUNDED = frozenset({"position_rmse_m", "heading_rmse_rad", "final_error_m", "localized_s",
                      "rmse_localized_m", "recovery_s", *_CONSISTENCY})
#: Rows of results files written before these columns existed: the Vicon fit, known start.
_DEFAULTS = {"calibration": "vicon", "start": "known", "kidnap_s": None}
#: Issue 19's bar for a global localization: under LOCALIZED_M within this long of the start.
LOCALIZE_WITHIN_S = 60.0
_CALIBRATION_ORDER = {"self": 0, "self-own": 1, "none": 2, "vicon": 3}


def load_replay_results(paths) -> list[dict]:
    """The rows of replay results files, typed (a file without the replay columns is a
    ConfigError naming it)."""
    rows = []
    for path in paths:
        with Path(path).open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            missing = sorted({"experiment", "setting", "robot", "position_rmse_m", "algorithm",
                              "cooperative"} - set(reader.fieldnames or ()))
            if missing:
                raise ConfigError(f"{path}: not a replay results file (no {', '.join(missing)})")
            for line, raw in enumerate(reader, start=2):
                row = dict(_DEFAULTS)
                try:
                    for k, v in raw.items():
                        if v == "" or v is None:
                            row[k] = row.get(k)
                        elif k in _INT:
                            row[k] = int(v)
                        elif k in _FLOAT:
                            row[k] = float(v)
                        elif k == "cooperative":
                            row[k] = v == "True"
                        else:
                            row[k] = v
                except ValueError as exc:
                    raise ConfigError(f"{path}:{line}: {exc}") from None
                rows.append(row)
    return rows


#: A configuration of the report: (algorithm, cooperative, calibration, start, kidnap_s).
def _key(row: dict) -> tuple:
    return (row["algorithm"], row["cooperative"], row["calibration"], row["start"],
            row["kidnap_s"])


def _config_order(key):
    algorithm, cooperative, calibration, start, kidnap_s = key
    index = REPORT_ALGORITHMS.index(algorithm) if algorithm in REPORT_ALGORITHMS else 99
    return (start != "known", kidnap_s is not None, _CALIBRATION_ORDER.get(calibration, 9),
            index, algorithm, cooperative)


def _label(key) -> str:
    algorithm, cooperative, calibration, start, kidnap_s = key
    return ReplayConfig(algorithm=algorithm, cooperative=cooperative, calibration=calibration,
                        start=start, kidnap_s=kidnap_s).label


def _num(value) -> float:
    return math.nan if value is None else float(value)


def _fmt(value, spec: str = "{:.3f}") -> str:
    return "-" if value is None or not math.isfinite(value) else spec.format(value)


def _global_tables(groups: dict, robot_ids: list[int]) -> list[str]:
    """Unknown start: per configuration and robot, the seeds localized within
    LOCALIZE_WITHIN_S (the rest are failures), the median time and the mean RMSE after; then
    every seed."""
    head = "| configuration | " + " | ".join(f"R{r}" for r in robot_ids) + " | all robots |"
    sep = "|---|" + "---:|" * (len(robot_ids) + 1)
    summary, per_seed = [head, sep], []
    for key, by_seed in groups.items():
        seeds = sorted(by_seed)
        cells, all_ok = [], 0
        for rid in robot_ids:
            times = np.array([by_seed[s][rid]["localized_s"] for s in seeds], dtype=float)
            after = np.array([by_seed[s][rid]["rmse_localized_m"] for s in seeds], dtype=float)
            ok = np.isfinite(times) & (times <= LOCALIZE_WITHIN_S)
            cells.append(f"{int(ok.sum())}/{len(seeds)}, {_fmt(np.median(times[ok]) if ok.any() else None, '{:.0f}')} s, "
                         f"{_fmt(float(np.mean(after[ok])) if ok.any() else None)} m")
        for s in seeds:
            t = [by_seed[s][rid]["localized_s"] for rid in robot_ids]
            all_ok += all(math.isfinite(v) and v <= LOCALIZE_WITHIN_S for v in t)
            per_seed.append(f"| {_label(key)} | {s} | " + " | ".join(
                f"{_fmt(by_seed[s][rid]['localized_s'], '{:.1f}')} / "
                f"{_fmt(by_seed[s][rid]['rmse_localized_m'])}" for rid in robot_ids) + " |")
        summary.append(f"| {_label(key)} | " + " | ".join(cells) + f" | {all_ok}/{len(seeds)} |")
    seed_head = ["| configuration | seed | " + " | ".join(f"R{r}" for r in robot_ids) + " |",
                 "|---|---:|" + "---:|" * len(robot_ids)]
    return [("Unknown start (uniform over the landmark field, every heading). Per robot: seeds "
            f"under {LOCALIZED_M} m within {LOCALIZE_WITHIN_S:.0f} s and staying there to the "
            "end (the others are failures), the median time to get there, the mean position "
            "RMSE from then on; last column: seeds in which every robot made it."), "",
            *summary, "", "Every seed: time until localized [s] / RMSE after [m] ('-': never).",
            "", *seed_head, *per_seed, ""]


def _kidnap_table(groups: dict) -> list[str]:
    lines = ["| configuration | robot | kidnap at [s] | seed | recovered after [s] | RMSE after [m] |",
             "|---|---:|---:|---:|---:|---:|"]
    for key, by_seed in groups.items():
        for s in sorted(by_seed):
            for rid, r in sorted(by_seed[s].items()):
                if r.get("kidnapped"):
                    lines.append(f"| {_label(key)} | {rid} | {key[4]:.0f} | {s} | "
                                 f"{_fmt(r['recovery_s'], '{:.1f}')} | "
                                 f"{_fmt(r['rmse_localized_m'])} |")
    return [("Kidnap: at the given time the robot's odometry says it jumped 2 m and turned 90 "
            "degrees (its estimate is teleported; the robot did not move). Recovered: under "
            f"{LOCALIZED_M} m again and staying there ('-': never)."), "", *lines, ""]


def bound_table(dataset) -> list[str]:
    """What the data allows from an unknown start
    (:mod:`swarmloc.deploy.lab.replay.feasibility`): per robot, its first landmark reading and
    the time its readings bound its position std under 0.1 m, alone and cooperative, and the
    share of robots any algorithm could localize within :data:`LOCALIZE_WITHIN_S`."""
    from swarmloc.deploy.lab.replay.feasibility import first_reading_times, fix_times, success_cap

    ids = list(dataset.robot_ids)
    rows = [("first reading (hard bound), alone", first_reading_times(dataset)),
            ("first reading (hard bound), cooperative", first_reading_times(dataset, True)),
            ("position std < 0.1 m (5 s window), alone", fix_times(dataset, 5.0, 0.1)),
            ("position std < 0.1 m (5 s window), cooperative", fix_times(dataset, 5.0, 0.1, True)),
            ("position std < 0.1 m (30 s window), alone", fix_times(dataset, 30.0, 0.1))]
    lines = ["| bound [s from the start] | " + " | ".join(f"R{r}" for r in ids)
             + f" | robots within {LOCALIZE_WITHIN_S:.0f} s |",
             "|---|" + "---:|" * (len(ids) + 1)]
    for label, times in rows:
        lines.append(f"| {label} | " + " | ".join(_fmt(times[r], '{:.1f}') for r in ids)
                     + f" | {success_cap(times, LOCALIZE_WITHIN_S):.0%} |")
    return [("What the data allows from an unknown start, whatever the algorithm "
             "(`deploy/lab/replay/feasibility.py`): the Cramér-Rao bound of the position from "
             "the Fisher information of the readings in a window (camera noise 0.02 m + 4 % of "
             "the range, 0.015 rad; Jacobians at the Vicon poses: an analysis of the data, not "
             "an input of any localizer); cooperative, a teammate counts once its own bound has "
             "passed. '-': never."), "", *lines, ""]


def write_report(rows: list[dict], out_dir: str | Path, replay_first=None,
                 datasets_by_name: dict | None = None) -> Path:
    """``results.csv``, ``results.md`` and (with ``replay_first(key, seed)`` giving ``(result,
    dataset)``) the trajectory plots in ``out_dir``; returns ``results.md``. Plots: every
    self-calibrated tracking configuration and every global-localization and kidnap one (the
    reference calibrations only have table rows). With ``datasets_by_name`` (the data sets
    themselves) the global-localization section opens with :func:`bound_table`."""
    from swarmloc.deploy.lab.replay.mrclam import plot_consistency, plot_trajectories

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    configs = sorted({_key(r) for r in rows}, key=_config_order)
    robot_ids = sorted({r["robot"] for r in rows})
    ordered, tracking, global_groups, kidnap_groups = [], [], {}, {}
    for key in configs:
        mine = sorted((r for r in rows if _key(r) == key), key=lambda r: (r["seed"], r["robot"]))
        settings = sorted({r.get("setting") for r in mine} - {None})
        if len({(r["seed"], r["robot"]) for r in mine}) < len(mine):
            # This template tells configurations apart by algorithm, cooperation, calibration,
            # start and kidnap; rows that differ otherwise (a parameter, CoLo-AT's setting)
            # would overwrite each other.
            raise ConfigError(f"settings {', '.join(map(str, settings))} share the configuration "
                              f"{_label(key)!r} and a seed: this report cannot tell them apart; "
                              "use `swarmloc report ... --family generic`")
        ordered += mine
        seeds = sorted({r["seed"] for r in mine})
        by_seed = {s: {r["robot"]: r for r in mine if r["seed"] == s} for s in seeds}
        if key[4] is not None:
            for s in seeds:  # the kidnapped robot: the setting's, else the one that recovered
                robots = by_seed[s]
                rid = mine[0].get("kidnap_robot")
                if rid not in robots:
                    rid = next((r for r, row in robots.items() if row["recovery_s"] is not None
                                and math.isfinite(row["recovery_s"])), min(robots))
                robots[rid] = {**robots[rid], "kidnapped": True}
            kidnap_groups[key] = by_seed
        elif key[3] != "known":
            global_groups[key] = by_seed
        else:
            mean_scores = {rid: {k: float(np.mean([_num(by_seed[s][rid].get(k)) for s in seeds]))
                                 for k in ("position_rmse_m", "heading_rmse_rad", *_CONSISTENCY)}
                           for rid in robot_ids}
            label = _label(key) + (f" ({len(seeds)} seeds)" if len(seeds) > 1 else "")
            if key[2] == "vicon":
                label += " [reference: Vicon in the loop]"
            tracking.append((label, mean_scores))
        if replay_first is not None and (key[2] == "self" or key[3] != "known"
                                         or key[4] is not None):
            result, dataset = replay_first(key, seeds[0])
            plot_trajectories(result, dataset, out / f"trajectories_{plot_name(_label(key))}.png")
            plot_consistency(result, out / f"consistency_{plot_name(_label(key))}.png")
    with (out / "results.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(RESULT_COLUMNS))
        writer.writeheader()
        for r in ordered:
            writer.writerow({k: (round(r[k], 4) if k in _ROUNDED and r.get(k) is not None
                                 else r.get(k)) for k in RESULT_COLUMNS})
    datasets = sorted({r["dataset"] for r in rows})
    dt_s = sorted({r["dt_s"] for r in rows})
    seed = min(r["seed"] for r in rows)
    text = [(f"Dataset {', '.join(datasets)}, tick {', '.join(map(str, dt_s))} s, seeds from "
             f"{seed}."), ""]
    if tracking:
        text += [("Known start (the first Vicon pose; no other ground truth in the loop but in "
                 "the rows marked reference). Calibration of the camera's range bias: self "
                 "(estimated while localizing, the default), none-cal (none), vicon-cal (fitted "
                 "against Vicon on the first 120 s of the run scored)."), "",
                 "Position RMSE [m]", "", format_table(tracking, robot_ids), "",
                 "Heading RMSE [rad]", "", format_table(tracking, robot_ids, "heading_rmse_rad"),
                 ""]
        consistent = [(label, sc) for label, sc in tracking
                      if any(math.isfinite(v["position_nees_mean"]) for v in sc.values())]
        if consistent:
            text += [("Consistency (the localizers that give a covariance): position NEES, mean "
                      "over the scored ticks (2 for a consistent filter, more: overconfident), and "
                      "the share of ticks inside the chi-square 95 % band (0.95 if consistent)."),
                     "", "Position NEES mean", "",
                     format_table(consistent, robot_ids, "position_nees_mean", "{:.1f}"), "",
                     "Share of ticks with the position NEES inside the 95 % band", "",
                     format_table(consistent, robot_ids, "position_nees_in_95", "{:.2f}"), ""]
            heading = [(label, sc) for label, sc in consistent
                       if any(math.isfinite(v["heading_nees_mean"]) for v in sc.values())]
            if heading:
                text += [("Heading NEES (one degree of freedom: 1 for a consistent filter), mean "
                          "over the scored ticks, and the share inside the chi-square 95 % band "
                          "(0.95 if consistent); the localizers that estimate the heading."), "",
                         "Heading NEES mean", "",
                         format_table(heading, robot_ids, "heading_nees_mean", "{:.1f}"), "",
                         "Share of ticks with the heading NEES inside the 95 % band", "",
                         format_table(heading, robot_ids, "heading_nees_in_95", "{:.2f}"), ""]
        for kind in ("landmark", "teammate"):
            tallied = [(label, sc) for label, sc in tracking
                       if any(math.isfinite(v[f"{kind}_nis_mean"]) for v in sc.values())]
            if tallied:
                text += [(f"NIS of the {kind} updates (2 degrees of freedom: 2 if the filter's "
                          "innovations are as large as it expects), mean over the updates, and the "
                          "share inside the chi-square 95 % band; the localizers that tally it "
                          "(CoLo's estimators, the EKFs, the hybrid while its EKF tracks)."), "",
                         f"{kind.capitalize()} NIS mean", "",
                         format_table(tallied, robot_ids, f"{kind}_nis_mean", "{:.2f}"), ""]
        if any(math.isfinite(v["ape_rmse_m"]) for _, sc in tracking for v in sc.values()):
            text += [("evo's absolute and relative trajectory errors (translation, RMSE, no "
                      "alignment: the estimates are in the landmarks' frame; RPE over 1 m of "
                      "travel)."), "", "APE RMSE [m]", "",
                     format_table(tracking, robot_ids, "ape_rmse_m"), "", "RPE RMSE [m] per 1 m", "",
                     format_table(tracking, robot_ids, "rpe_rmse_m"), ""]
    if global_groups:
        for name in datasets:
            if datasets_by_name and name in datasets_by_name:
                text += bound_table(datasets_by_name[name])
        text += _global_tables(global_groups, robot_ids)
    if kidnap_groups:
        text += _kidnap_table(kidnap_groups)
    page = out / "results.md"
    page.write_text("\n".join(text))
    return page


def write_from_args(paths: list[Path], args) -> Path:
    """The replay template of ``swarmloc report``: the tables from the rows, the plots by
    replaying each configuration's first seed with the spec's settings."""
    from swarmloc.deploy.lab.experiment import load_spec, settings, with_overrides
    from swarmloc.deploy.lab.replay.experiment import _dataset, load_replay_scenario
    from swarmloc.deploy.lab.replay.mrclam import run_replay

    rows = load_replay_results(paths)
    if not rows:
        raise ConfigError(f"{', '.join(map(str, paths))}: no rows to report")
    experiments = sorted({r["experiment"] for r in rows})
    if len(experiments) > 1 and not args.spec:
        raise ConfigError(f"rows of experiments {', '.join(experiments)}: give --spec")
    spec = with_overrides(load_spec(args.spec or experiments[0]),
                          fixed=list(getattr(args, "set", None) or []))
    by_id = {s.id: s for s in settings(spec)}
    for r in rows:  # which robot a kidnap setting kidnaps (not a column of the results)
        if r.get("kidnap_s") is not None and r["setting"] in by_id:
            setting = by_id[r["setting"]]
            scenario = load_replay_scenario(setting.scenario, list(setting.overrides))
            r["kidnap_robot"] = scenario.config().kidnap_robot
    first_setting = {}
    for r in sorted(rows, key=lambda r: r["seed"]):
        first_setting.setdefault(_key(r), r["setting"])

    loaded = {}

    def replay_first(key, seed):
        setting = by_id.get(first_setting[key])
        if setting is None:
            raise ConfigError(f"setting {first_setting[key]!r} is not in "
                              f"spec {spec.name!r}: give the spec the rows come from (--spec)")
        scenario = load_replay_scenario(setting.scenario, [*setting.overrides, f"seed={seed}"])
        dataset = _dataset(str(Path(scenario.dataset).resolve()))
        loaded[dataset.name] = dataset
        return run_replay(dataset, scenario.config()), dataset

    out = Path(args.out) if args.out else Path("docs/mrclam")
    return write_report(rows, out, replay_first, loaded)


def _template():
    from swarmloc.deploy.lab.report import ReportTemplate

    return ReportTemplate("replay", frozenset({"experiment", "robot", "position_rmse_m",
                                               "heading_rmse_rad"}), write_from_args)


#: This family's template of ``swarmloc report`` (named by its ``Family.report``, ``swarmloc.families``).
TEMPLATE = _template()

__all__ = ["RESULT_COLUMNS", "TEMPLATE", "load_replay_results", "write_from_args", "write_report"]
