"""Evaluation on MRCLAM data: run one configuration on one data set in-process, score it.

``run_replay(dataset, config)`` builds one localizer per robot
(:func:`swarmloc.agents.replay.localizers.build_localizer`), drives them with the replay world
(:class:`swarmloc.world.replay.replay.ReplayWorld`) in lockstep, and returns every estimate with the
ground truth at the same instants. :func:`score` gives per robot the position RMSE
``sqrt(mean |p_est - p_true|^2)`` and heading RMSE ``sqrt(mean wrap(theta_est - theta_true)^2)``
over the ticks where ground truth exists (Dataset 6's robot 1 has none after +771.9 s; Vicon
gaps longer than 0.5 s are skipped). :func:`plot_trajectories` draws estimated vs true paths.

No ground truth in the loop but, with ``start="known"``, the initial pose: each camera's range
bias is estimated while localizing (``calibration="self"``, the default); ``calibration="vicon"``
fits it against Vicon (:func:`fit_camera`, a reference), ``"none"`` leaves it. ``start="unknown"``
starts the population localizers from a uniform belief; ``kidnap_s`` teleports a robot's
estimate. :func:`score` also times how long a robot takes to be localized (under
:data:`LOCALIZED_M` to stay) and to recover from the kidnap.

``swarmloc mrclam PATH`` runs one configuration and prints the table. Every algorithm alone and
cooperative, the report of ``docs/mrclam/``, is the experiment spec ``mrclam6`` (the replay
family of the experiment engine, ``deploy/lab/replay/experiment.py``; its report template
``deploy/lab/replay/report.py``): ``swarmloc experiment mrclam6`` then ``swarmloc report
results/mrclam6.csv --out docs/mrclam``.

Each robot's generator is ``numpy.random.default_rng([seed, 7, robot_id])``: the same seed gives
the same estimates, whichever order the robots are stepped in.

The data set is cited as: K. Y. K. Leung, Y. Halpern, T. D. Barfoot, H. H. T. Liu, "The UTIAS
multi-robot cooperative localization and mapping dataset", IJRR 30(8):969-974, 2011.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from swarmloc.agents.replay.localizers import (
    ALGORITHMS,
)

# The replay's configuration, world, localizers, in-process run and scores live in
# world/replay/evaluation.py, below deploy/ (issue 48: the replay world-server and agents built
# from this module); re-exported here.
from swarmloc.world.replay.evaluation import (  # noqa: F401 -- re-exported
    CALIBRATIONS,
    CHI2_2DOF_95,
    GLOBAL_ALGORITHMS,
    HEADINGS,
    KIDNAP_JUMP,
    LOCALIZED_M,
    MRCLAM_STREAM,
    REPORT_ALGORITHMS,
    STARTS,
    ReplayConfig,
    ReplayResult,
    _reading_errors,
    consistency,
    fit_camera,
    localized_from,
    parse_links,
    position_nees,
    replay_localizer,
    replay_world,
    rmse_at_truth_stamps,
    robot_rng,
    run_replay,
    score,
    trajectory_errors,
    write_tum,
)
from swarmloc.world.replay.mrclam import MrclamDataset, load_dataset
from swarmloc.world.replay.replay import DEFAULT_DT_S


def plot_name(label: str) -> str:
    """A configuration's label as a file name part."""
    return label.replace("+", "_").replace(" ", "_")


def _save(fig, path: Path) -> Path:
    """Write a report figure to ``path`` (its folder made) and free it."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path)
    plt.close(fig)
    return path


def plot_consistency(result: ReplayResult, path: Path, title: str | None = None) -> Path | None:
    """Each robot's position NEES (with the chi-square 95 % bound; a 5 s running median, the
    ticks are strongly correlated) and the trace of its position covariance over time, as CoLo-AT
    plots the trace (issue 46). None (nothing drawn) for a localizer without a covariance."""
    if result.covariance_xy is None or not np.isfinite(result.covariance_xy).any():
        return None
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    from scipy.ndimage import median_filter

    nees = position_nees(result)
    t = result.times_s - result.times_s[0]
    window = max(1, round(5.0 / max(float(np.median(np.diff(result.times_s))), 1e-9)))
    fig, (top, bottom) = plt.subplots(2, 1, figsize=(7.5, 6.0), dpi=110, sharex=True)
    for i, rid in enumerate(result.robot_ids):
        n = nees[:, i]
        ok = np.isfinite(n)
        if ok.sum() > window:
            top.semilogy(t[ok], median_filter(n[ok], size=window, mode="nearest"), lw=0.8,
                         label=f"robot {rid}")
        trace = np.trace(result.covariance_xy[:, i], axis1=-2, axis2=-1)
        good = np.isfinite(trace)
        bottom.semilogy(t[good], trace[good], lw=0.8, label=f"robot {rid}")
    top.axhline(CHI2_2DOF_95, color="k", ls="--", lw=0.8, label="95 % bound (2 dof)")
    top.set_ylabel("position NEES (5 s median)")
    top.legend(fontsize=7, ncol=3)
    bottom.set_ylabel("trace of P_xy [m^2]")
    bottom.set_xlabel("time [s]")
    top.set_title(title or f"{result.config.label}: consistency over time", fontsize=9)
    return _save(fig, path)


def plot_trajectories(result: ReplayResult, dataset: MrclamDataset, path: Path,
                      title: str | None = None) -> Path:
    """Estimated (solid) vs true (dotted) paths of every robot, landmarks as black squares."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6.5, 8.0), dpi=110)
    colours = plt.rcParams["axes.prop_cycle"].by_key()["color"]
    for i, rid in enumerate(result.robot_ids):
        c = colours[i % len(colours)]
        ax.plot(result.truth[:, i, 0], result.truth[:, i, 1], ":", color=c, lw=0.9)
        ax.plot(result.estimates[:, i, 0], result.estimates[:, i, 1], "-", color=c, lw=0.7,
                label=f"robot {rid}")
    ax.plot(dataset.landmarks.xy_m[:, 0], dataset.landmarks.xy_m[:, 1], "ks", ms=4,
            label="landmarks")
    ax.set_aspect("equal")
    ax.set_xlabel("x [m]")
    ax.set_ylabel("y [m]")
    ax.set_title(title or f"{dataset.name}: {result.config.label} (solid) vs Vicon (dotted)",
                 fontsize=9)
    ax.legend(fontsize=7, loc="upper right")
    return _save(fig, path)


def format_table(rows: Sequence[tuple[str, dict[int, dict[str, float]]]],
                 robot_ids: Sequence[int], metric: str = "position_rmse_m",
                 unit_format: str = "{:.3f}") -> str:
    """A markdown table: one row per configuration, one column per robot, then the mean."""
    head = "| configuration | " + " | ".join(f"R{r}" for r in robot_ids) + " | mean |"
    sep = "|---|" + "---:|" * (len(robot_ids) + 1)
    lines = [head, sep]
    for label, scores in rows:
        values = [scores[r][metric] for r in robot_ids]
        lines.append(f"| {label} | " + " | ".join(unit_format.format(v) for v in values)
                     + f" | {unit_format.format(float(np.mean(values)))} |")
    return "\n".join(lines)


def print_scores(result: ReplayResult, scores: dict[int, dict[str, float]], name: str) -> None:
    print(f"{name}: {result.config.label}, seed {result.config.seed}, dt {result.config.dt_s} s, "
          f"{len(result.times_s)} ticks, CPU {result.cpu_s:.1f} s")
    print(f"{'robot':>6} {'pos RMSE [m]':>13} {'heading RMSE [rad]':>19} {'final err [m]':>14} "
          f"{'localized [s]':>14} {'RMSE after [m]':>15} {'recovery [s]':>13}")
    for rid, s in scores.items():
        print(f"{rid:>6} {s['position_rmse_m']:13.3f} {s['heading_rmse_rad']:19.3f} "
              f"{s['final_error_m']:14.3f} {s['localized_s']:14.1f} {s['rmse_localized_m']:15.3f} "
              f"{s['recovery_s']:13.1f}")
    pos = [s["position_rmse_m"] for s in scores.values()]
    head = [s["heading_rmse_rad"] for s in scores.values()]
    print(f"{'mean':>6} {np.mean(pos):13.3f} {np.mean(head):19.3f}")
    nees = {rid: (c["position_nees_mean"], c["position_nees_in_95"]) for rid, c in consistency(result).items()}
    if any(np.isfinite(v[0]) for v in nees.values()):
        print("consistency, position NEES mean (2 if consistent) / share within chi2 95 % (0.95): "
              + ", ".join(f"{rid} {m:.1f} / {f:.2f}" for rid, (m, f) in nees.items()))
    for kind in ("landmark", "teammate"):
        if result.nis and any(s.get(f"{kind}_nis_count") for s in result.nis.values()):
            print(f"NIS of the {kind} updates, mean (2 if consistent) / share within chi2 95 % "
                  "(0.95): " + ", ".join(
                      f"{rid} {s[f'{kind}_nis_mean']:.1f} / {s[f'{kind}_nis_in_95']:.2f}"
                      for rid, s in result.nis.items()))


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------


def add_arguments(p) -> None:
    """The options of ``swarmloc mrclam`` (used by ``deploy/cli.py``)."""
    p.add_argument("path", help="an MRCLAM data set folder (e.g. ../shared/data/mrclam/MRCLAM_Dataset6)")
    # No argparse choices: a plugin's localizer registers after the parser is built (the
    # names are checked by ReplayConfig, against the registry as plugins left it).
    p.add_argument("--algorithm", default="ekf", metavar="NAME",
                   help=f"localizer: {', '.join(sorted(ALGORITHMS))} or a plugin's (default ekf)")
    p.add_argument("--cooperative", action="store_true", help="robots share estimates and readings")
    p.add_argument("--seed", type=int, default=0, help="run seed (default 0)")
    p.add_argument("--dt-s", type=float, default=DEFAULT_DT_S, help="tick length (default 0.02 s)")
    p.add_argument("--duration-s", type=float, default=None, help="replay only this long")
    p.add_argument("--calibration", default="self",
                   help="camera range bias: self (estimated while localizing, no ground truth; "
                        "cooperative, a camera not yet calibrated starts from a teammate's "
                        "calibration; the default), self-own (the same, each robot from its own "
                        "readings only), vicon (fitted against the ground truth: a reference), "
                        "none")
    p.add_argument("--calibration-s", type=float, default=120.0,
                   help="with --calibration vicon: fit on the first SECONDS of readings "
                        "(default 120)")
    p.add_argument("--start", default="known",
                   help="known (the first Vicon pose; default) or unknown (uniform over the "
                        "landmark field, every heading: pf, cfsga, ssga and hybrid only)")
    p.add_argument("--kidnap-s", type=float, default=None,
                   help="teleport a robot's estimate this many seconds after the start")
    p.add_argument("--kidnap-robot", type=int, default=None,
                   help="the robot kidnapped (data set id; default the first)")
    p.add_argument("--heading", default="estimate",
                   help="estimate (default) or truth: the ground truth's heading given to CoLo's "
                        "estimators (CoLo-AT's setting)")
    p.add_argument("--landmark-robots", default=None, metavar="IDS",
                   help="only these robots get landmark readings, e.g. 1,2,3 (default: all)")
    p.add_argument("--links", default=None, metavar="LINKS",
                   help="who hears whom, RECEIVER:SENDER[,SENDER] items, e.g. '1:2 2:3' "
                        "(default: everyone hears everyone)")
    p.add_argument("--initial-std", default=None, metavar="X,Y,THETA",
                   help="std of the known start (default 0.05,0.05,0.05; CoLo-AT: 0.2,0.2,0)")
    p.add_argument("--param", action="append", default=[], metavar="KEY=VALUE",
                   help="algorithm parameter, value as JSON (repeatable), e.g. --param fusion=\"sgikf\"")
    p.add_argument("--out", default=None,
                   help="folder for the trajectory plot and scores.json")
    p.add_argument("--all", action="store_true",
                   help="retired: every configuration is the spec mrclam6 (`swarmloc experiment "
                        "mrclam6`, then `swarmloc report results/mrclam6.csv --out docs/mrclam`)")


def _parse_params(items: Sequence[str]) -> dict:
    """``--param KEY=VALUE`` values, read as every ``KEY=VALUE`` is (TOML, else a plain string:
    ``swarmloc.config.parse_assignment``)."""
    from swarmloc.config import parse_assignment

    return dict(parse_assignment(item, "--param") for item in items)


def main(args) -> int:
    """``swarmloc mrclam``: returns 0, or 2 with a message for a bad folder or option."""
    if args.calibration not in CALIBRATIONS:
        raise ValueError(f"--calibration: unknown value {args.calibration!r} (known: "
                         f"{', '.join(CALIBRATIONS)})")
    if args.start not in STARTS:
        raise ValueError(f"--start: unknown value {args.start!r} (known: {', '.join(STARTS)})")
    if not args.calibration_s >= 0:
        raise ValueError(f"--calibration-s must be >= 0, got {args.calibration_s}")
    extra = {}
    if args.landmark_robots is not None:
        try:
            extra["landmark_robots"] = tuple(int(v) for v in args.landmark_robots.split(",") if v)
        except ValueError:
            raise ValueError(f"--landmark-robots: expected robot ids like 1,2,3, got "
                             f"{args.landmark_robots!r}") from None
    if args.initial_std is not None:
        try:
            extra["initial_std"] = tuple(float(v) for v in args.initial_std.split(","))
        except ValueError:
            raise ValueError(f"--initial-std: expected X,Y,THETA, got {args.initial_std!r}") from None
    config = ReplayConfig(algorithm=args.algorithm, cooperative=args.cooperative, seed=args.seed,
                          dt_s=args.dt_s, params=_parse_params(args.param),
                          duration_s=args.duration_s, calibration=args.calibration,
                          calibration_s=args.calibration_s or None, start=args.start,
                          kidnap_s=args.kidnap_s, kidnap_robot=args.kidnap_robot,
                          heading=args.heading, links=args.links, **extra)
    dataset = load_dataset(args.path)
    try:
        result = run_replay(dataset, config)
    except TypeError as exc:  # a --param of the wrong type: a usage error like a bad value
        raise ValueError(str(exc)) from None
    scores = score(result)
    print_scores(result, scores, dataset.name)
    stamps = rmse_at_truth_stamps(result, dataset)
    print("position RMSE at every ground-truth stamp (CoLo-AT's metric): "
          + ", ".join(f"{rid} {v:.3f}" for rid, v in stamps.items())
          + f", mean {np.mean(list(stamps.values())):.3f}")
    if args.out:
        out = Path(args.out)
        plot = plot_trajectories(result, dataset, out / f"trajectories_{plot_name(config.label)}.png")
        (out / "scores.json").write_text(json.dumps(
            {"dataset": dataset.name, "config": config.label, "seed": config.seed,
             "dt_s": config.dt_s, "calibration": config.calibration,
             "calibration_s": config.calibration_s, "start": config.start,
             "kidnap_s": config.kidnap_s,
             "params": dict(config.params),
             "robots": {str(k): v for k, v in scores.items()}}, indent=2))
        tum = write_tum(result, out)
        errors = trajectory_errors(result)
        print(f"plot: {plot}; TUM trajectories: {out}/estimate_R*.tum, groundtruth_R*.tum "
              f"({len(tum)} files)")
        print("evo APE / RPE (translation, per metre travelled) RMSE [m]: "
              + ", ".join(f"{rid} {e['ape_rmse_m']:.3f} / {e['rpe_rmse_m']:.3f}"
                          for rid, e in errors.items()))
    return 0
