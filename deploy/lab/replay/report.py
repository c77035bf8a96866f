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
from pathlib import Path

import numpy as np

from swarmloc.config import ConfigError
from swarmloc.deploy.lab.replay.mrclam import REPORT_ALGORITHMS, format_table

#: The columns of the report's ``results.csv``.
RESULT_COLUMNS = ("dataset", "algorithm", "cooperative", "seed", "dt_s", "robot",
                  "position_rmse_m", "heading_rmse_rad", "final_error_m", "scored_ticks", "cpu_s")
_INT = frozenset({"seed", "replication", "robot", "scored_ticks"})
_FLOAT = frozenset({"dt_s", "position_rmse_m", "heading_rmse_rad", "final_error_m", "cpu_s",
                    "wall_s"})


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
                row = {}
                try:
                    for k, v in raw.items():
                        if v == "":
                            row[k] = None
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


def _config_order(key):
    algorithm, cooperative = key
    index = REPORT_ALGORITHMS.index(algorithm) if algorithm in REPORT_ALGORITHMS else 99
    return (index, algorithm, cooperative)


def _label(algorithm: str, cooperative: bool) -> str:
    return f"{algorithm}{'+coop' if cooperative else ''}"


def write_report(rows: list[dict], out_dir: str | Path, replay_first=None) -> Path:
    """``results.csv``, ``results.md`` and (with ``replay_first(algorithm, cooperative, seed)``
    giving ``(result, dataset)``) the trajectory plots in ``out_dir``; returns ``results.md``."""
    from swarmloc.deploy.lab.replay.mrclam import plot_trajectories

    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    configs = sorted({(r["algorithm"], r["cooperative"]) for r in rows}, key=_config_order)
    robot_ids = sorted({r["robot"] for r in rows})
    ordered, table_rows = [], []
    for algorithm, cooperative in configs:
        mine = sorted((r for r in rows if (r["algorithm"], r["cooperative"]) == (algorithm,
                                                                                  cooperative)),
                      key=lambda r: (r["seed"], r["robot"]))
        ordered += mine
        seeds = sorted({r["seed"] for r in mine})
        by_seed = {s: {r["robot"]: r for r in mine if r["seed"] == s} for s in seeds}
        mean_scores = {rid: {k: float(np.mean([by_seed[s][rid][k] for s in seeds]))
                             for k in ("position_rmse_m", "heading_rmse_rad")}
                       for rid in robot_ids}
        label = _label(algorithm, cooperative) + (f" ({len(seeds)} seeds)" if len(seeds) > 1
                                                  else "")
        table_rows.append((label, mean_scores))
        if replay_first is not None:
            result, dataset = replay_first(algorithm, cooperative, seeds[0])
            name = _label(algorithm, cooperative).replace("+", "_")
            plot_trajectories(result, dataset, out / f"trajectories_{name}.png")
    with (out / "results.csv").open("w", newline="") as fh:
        writer = csv.DictWriter(fh, fieldnames=list(RESULT_COLUMNS))
        writer.writeheader()
        for r in ordered:
            writer.writerow({k: (round(r[k], 4) if k in ("position_rmse_m", "heading_rmse_rad",
                                                        "final_error_m") else r[k])
                             for k in RESULT_COLUMNS})
    datasets = sorted({r["dataset"] for r in rows})
    dt_s = sorted({r["dt_s"] for r in rows})
    seed = min(r["seed"] for r in rows)
    text = [(f"Dataset {', '.join(datasets)}, tick {', '.join(map(str, dt_s))} s, seeds from "
             f"{seed}."), "",
            "Position RMSE [m]", "", format_table(table_rows, robot_ids), "",
            "Heading RMSE [rad]", "",
            format_table(table_rows, robot_ids, "heading_rmse_rad"), ""]
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
    first_setting = {}
    for r in sorted(rows, key=lambda r: r["seed"]):
        first_setting.setdefault((r["algorithm"], r["cooperative"]), r["setting"])

    def replay_first(algorithm, cooperative, seed):
        setting = by_id.get(first_setting[(algorithm, cooperative)])
        if setting is None:
            raise ConfigError(f"setting {first_setting[(algorithm, cooperative)]!r} is not in "
                              f"spec {spec.name!r}: give the spec the rows come from (--spec)")
        scenario = load_replay_scenario(setting.scenario, [*setting.overrides, f"seed={seed}"])
        dataset = _dataset(str(Path(scenario.dataset).resolve()))
        return run_replay(dataset, scenario.config()), dataset

    out = Path(args.out) if args.out else Path("docs/mrclam")
    return write_report(rows, out, replay_first)


def _template():
    from swarmloc.deploy.lab.report import ReportTemplate

    return ReportTemplate("replay", frozenset({"experiment", "robot", "position_rmse_m",
                                               "heading_rmse_rad"}), write_from_args)


#: This family's template of ``swarmloc report`` (:data:`swarmloc.deploy.lab.report.TEMPLATES`).
TEMPLATE = _template()

__all__ = ["RESULT_COLUMNS", "TEMPLATE", "load_replay_results", "write_from_args", "write_report"]
