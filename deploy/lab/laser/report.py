"""The laser report: seeds 002 and 003's tables and figures from our runs, next to the papers'.

Seeds ``002_fe2ac635ba0eab3e.txt`` (§6, table 3, fig. 9) and ``003_5278cbbbf8cc61de.txt`` (§V,
figs. 3-4, robustness) in ``/work/shared/seeds/``.

:func:`write_report` reads the results files of the laser experiments
(``deploy/lab/laser/experiment.py``: one row per run, with every robot's error at every step) and
writes, into one folder:

- ``README.md``: for each experiment, our table next to the paper's numbers, the figure, the
  difference in words and its likely reason (``reasons.toml`` in the folder, by claim id,
  written by whoever analysed the runs; "not analysed yet" otherwise), then CPU figures and the
  command that regenerates it all;
- PNG figures in the style of the papers: 002 table 3 as box plots of the per-trial error with
  the paper's range, 002 fig. 9 (error over time), 003 fig. 3 (kidnap, error over time averaged
  over runs), 003 fig. 4 (collaborative vs autonomous, per robot), and the failure rates of the
  robustness runs with 95 % Wilson intervals;
- ``results.csv``: the runs' summary rows (all columns but the per-step series) and
  ``curves.csv``: the error-over-time curves drawn (mean and median over runs, per step).

Measures (see ``deploy/lab/laser/runner.py``): a run's *final error* is the mean position error over
its last ``final_window_steps`` steps (averaged over robots); 002 table 3's minimum, maximum and
mean are taken over trials of that (:func:`table3_indexes`); the table also gives another reading,
the same indexes over the last quarter of the error curve averaged over trials (fig. 9's curve,
:func:`curve_tail_indexes`). 003 fig. 4's "iterations until all robots settle around
15 cm" is read on the curves averaged over runs (as the paper's figure is): the first step from
which every robot's mean curve stays below 15 cm; per-run settling steps are given too.

Figures are drawn on :class:`matplotlib.figure.Figure` objects rendered by Agg: no pyplot, no
display, no global matplotlib state.
"""

from __future__ import annotations

import csv
import math
import textwrap
import tomllib
from collections import defaultdict
from collections.abc import Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.deploy.lab.laser.runner import ALGORITHMS, decode_series_mm

#: Columns read as numbers (the rest stay text); empty cells become None.
_INT_COLUMNS = frozenset({"robots", "steps", "seed", "replication", "settle_step",
                          "settled_robots", "localized", "kidnap_step", "settled_before_kidnap",
                          "recovered", "recover_steps", "first_contact_step", "bumps",
                          "cooperative"})
_FLOAT_COLUMNS = frozenset({"final_error_m", "final_error_max_m", "final_error_sym_m",
                            "final_heading_error_rad", "mean_error_m", "cpu_s", "wall_s"})
SERIES_COLUMN = "position_error_mm"
SETTLE_ERROR_M = 0.15
DEFAULT_REASON = "not analysed yet"
_COLOURS = {"cfsga": "tab:green", "ssga": "tab:red", "amcl": "tab:blue", "simple_ga": "tab:orange",
            "amcl-player": "tab:purple"}
_ROBOT_COLOURS = ("tab:red", "tab:green", "tab:blue", "tab:orange", "tab:purple")


def _parse(column: str, text: str):
    if text == "":
        return None
    if column in _INT_COLUMNS:
        return int(float(text))
    if column in _FLOAT_COLUMNS:
        return float(text)
    return text


def load_laser_results(paths: Sequence[str | Path]) -> list[dict]:
    """The rows of laser results files, typed; ``position_error_mm`` stays text (decode it with
    :func:`series_of`). A file that is not a laser results file is a ValueError naming it."""
    rows: list[dict] = []
    for path in paths:
        path = Path(path)
        with path.open(newline="", encoding="utf-8") as handle:
            reader = csv.DictReader(handle)
            missing = {"experiment", "algorithm", "final_error_m", SERIES_COLUMN} - set(
                reader.fieldnames or ())
            if missing:
                raise ValueError(f"{path}: not a laser results file (no {', '.join(sorted(missing))})")
            for line_no, raw in enumerate(reader, start=2):
                try:
                    rows.append({k: _parse(k, v or "") for k, v in raw.items()})
                except ValueError as exc:
                    raise ValueError(f"{path}:{line_no}: {exc}") from None
    return rows


def series_of(row: dict) -> np.ndarray:
    """A run's position errors ``(T, N)`` in metres."""
    return decode_series_mm(row[SERIES_COLUMN])


# -- statistics -------------------------------------------------------------------------------


def wilson_interval(successes: int, n: int, z: float = 1.96) -> tuple[float, float]:
    """95 % Wilson score interval of a proportion (``(nan, nan)`` when ``n == 0``)."""
    if n == 0:
        return (math.nan, math.nan)
    p = successes / n
    denom = 1.0 + z * z / n
    centre = (p + z * z / (2 * n)) / denom
    half = z * math.sqrt(p * (1 - p) / n + z * z / (4 * n * n)) / denom
    return (max(0.0, centre - half), min(1.0, centre + half))


def settle_index(curve: np.ndarray, threshold: float = SETTLE_ERROR_M) -> int | None:
    """First index from which ``curve`` stays below ``threshold`` to its end (None: never)."""
    bad = np.flatnonzero(~(np.asarray(curve) < threshold))
    first = int(bad[-1]) + 1 if bad.size else 0
    return first if first < len(curve) else None


def _stack(rows: Sequence[dict]) -> np.ndarray:
    """Runs' series ``(R, T, N)`` (runs of one setting share T and N)."""
    return np.stack([series_of(r) for r in rows])


def _label(algorithm: str) -> str:
    try:
        return ALGORITHMS.get(algorithm).label
    except ValueError:
        return algorithm


def _fmt(x, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "–"
    return f"{x:.{digits}f}"


def _pct(x: float) -> str:
    return "–" if not math.isfinite(x) else f"{100 * x:.0f} %"


# -- figures ----------------------------------------------------------------------------------


def _figure(width: float, height: float, ncols: int = 1, nrows: int = 1):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(width, height), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, axes


def _save(fig, path: Path) -> None:
    from matplotlib.backends.backend_agg import FigureCanvasAgg

    FigureCanvasAgg(fig)
    fig.savefig(path, dpi=110)


@dataclass
class Section:
    """One experiment's part of the page."""

    title: str
    lines: list[str]
    figures: list[str]
    curves: list[tuple[str, str, np.ndarray, np.ndarray, int]]  # label, robot, mean, median, n


# -- 002 table 3 ------------------------------------------------------------------------------

def _final_window(scenarios: Sequence[str]) -> str:
    """The scenarios' ``metrics.final_window_steps`` (text; '?' if a scenario does not load)."""
    from swarmloc.config import ConfigError
    from swarmloc.deploy.lab.laser.runner import load_laser_scenario

    windows = set()
    for name in scenarios:
        try:
            windows.add(load_laser_scenario(name).metrics.final_window_steps)
        except (ConfigError, ValueError):
            windows.add("?")
    return "/".join(str(w) for w in sorted(windows, key=str))


#: 002 table 3: (max, min, mean) final error in metres, by (algorithm, population).
PAPER_TABLE3 = {
    ("ssga", "50"): (0.054, 0.012, 0.023), ("simple_ga", "50"): (0.133, 0.027, 0.053),
    ("amcl", "50"): (0.205, 0.148, 0.178), ("ssga", "100"): (0.021, 0.010, 0.014),
    ("simple_ga", "100"): (0.056, 0.009, 0.021), ("amcl", "100"): (0.157, 0.107, 0.133),
}
_TABLE3_ORDER = ("ssga", "simple_ga", "amcl")
#: 002's names of table 3's rows.
_PAPER_NAMES = {"ssga": "MR-SSGA", "simple_ga": "simple GA", "amcl": "PF"}


#: Steps over which the alternative reading of table 3 takes its indexes from the error curve
#: averaged over trials (fig. 9), as a fraction of the run: its last quarter.
CURVE_TAIL_FRACTION = 0.25


def table3_indexes(final_errors_m: Sequence[float]) -> tuple[float, float, float]:
    """002 table 3's indexes as we read them: (min, max, mean) over trials of each trial's final
    team error (``final_error_m``: position error averaged over the robots and the last
    ``final_window_steps`` steps)."""
    err = np.asarray(final_errors_m, dtype=float)
    if err.size == 0:
        return (math.nan, math.nan, math.nan)
    return (float(err.min()), float(err.max()), float(err.mean()))


def curve_tail_indexes(runs_m: np.ndarray, fraction: float = CURVE_TAIL_FRACTION
                       ) -> tuple[float, float, float]:
    """The alternative reading: ``runs_m`` ``(R, T)`` errors (mean over robots) averaged over the
    R trials into one curve (fig. 9), then (min, max, mean) of that curve over its last
    ``fraction`` of steps."""
    curve = np.asarray(runs_m, dtype=float).mean(axis=0)
    tail = curve[-max(1, round(fraction * curve.shape[0])):]
    return (float(tail.min()), float(tail.max()), float(tail.mean()))


def _table3(rows: list[dict], out: Path, reasons: dict) -> Section:
    from swarmloc.deploy.lab.laser.runner import map_rotations
    from swarmloc.world.laser.maps import build_map

    groups: dict[tuple[str, str], list[dict]] = defaultdict(list)
    algorithm_of: dict[str, str] = {}
    for variant, variant_rows in _variants(rows).items():  # an algorithm or a named group
        for r in variant_rows:
            groups[(variant, str(r["population"]))].append(r)
            algorithm_of[variant] = r["algorithm"]

    def paper_key(key):  # the paper's row of a group: its algorithm's, for the groups it ran
        algorithm = algorithm_of[key[0]]
        return (algorithm, key[1]) if key[0] in (algorithm, "pf") else None

    def group_label(group):
        algorithm = algorithm_of[group]
        return _label(algorithm) if group in (algorithm, "pf") else f"{_label(algorithm)} ({group})"

    keys = sorted(groups, key=lambda k: (int(k[1].split("-")[0]),
                                         _TABLE3_ORDER.index(algorithm_of[k[0]])
                                         if algorithm_of[k[0]] in _TABLE3_ORDER else 9, k[0]))
    maps = sorted({str(r["map"]) for r in rows})
    scenarios = sorted({str(r["scenario"]) for r in rows})
    symmetric = any(map_rotations(build_map(m)) for m in maps)
    steps = max(int(r["steps"]) for r in rows)
    tail = max(1, round(CURVE_TAIL_FRACTION * steps))
    window = _final_window(scenarios)
    bound = _table3_bound(scenarios)
    lines = [
        (f"Three robots start in three rooms of the floor `{'`, `'.join(maps)}` (world/laser/maps.py) "
         f"and walk scripted paths into its corridor "
         f"({', '.join(f'`deploy/scenarios/laser/{s}.toml`' for s in scenarios)}); parameters "
         "of table 2 of 002, population 50 or 100, the trials of each row in its n column "
         "(002: 100). PF = the modern AMCL "
         "(`agents/laser/amcl.py`) with a fixed population (min = max particles), "
         "collaborative (002's PF is collaborative; Player's AMCL is not)."),
        "",
        ("**What the indexes are over.** 002 §6 takes \"minimum, maximum and average error\" "
         "over \"100 trials for each configuration\" and fig. 9 shows the error falling once "
         "the robots meet, so we read table 3 as statistics over trials of each trial's error "
         "after convergence: a trial's *final error* is the position error averaged over the "
         f"three robots and the last {window} of {steps} steps (after the third robot has "
         "joined); min / max / mean are over the trials. The last column is another reading, "
         f"the min / max / mean over the last {tail} steps of the error curve averaged over "
         "trials (fig. 9's curve)."
         + (" 'Up to the symmetry': the error to the nearest of the true pose and its images "
            "under the rotations that map this floor onto itself (no sensor can tell them "
            "apart)." if symmetric else "")),
        "",
        ("| population | algorithm | n | min (m) | max (m) | mean (m) | median (m) | paper min / "
         "max / mean (m) | trials < 0.5 m | their mean (m) | every robot < 0.5 m | their "
         "mean (m) | single-scan bound per robot (m) | "
         + ("trials < 0.5 m up to the symmetry | " if symmetric else "")
         + "first sighting (step) | fig. 9 curve, last steps: min / max / mean (m) | CPU per "
         "run, mean (s) |"),
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|" + ("---|" if symmetric else ""),
    ]
    for key in keys:
        g = groups[key]
        err = np.array([r["final_error_m"] for r in g])
        worst = np.array([r["final_error_max_m"] for r in g])
        every = err[worst < 0.5]
        lo, hi, mean = table3_indexes(err)
        paper = PAPER_TABLE3.get(paper_key(key))
        paper_text = f"{paper[1]} / {paper[0]} / {paper[2]}" if paper else "–"
        contact = [r["first_contact_step"] for r in g if r["first_contact_step"] is not None]
        good = err[err < 0.5]
        c_lo, c_hi, c_mean = curve_tail_indexes(_stack(g).mean(axis=2))
        sym_text = ""
        if symmetric:
            sym = np.array([r["final_error_sym_m"] for r in g])
            sym_text = f"{_pct(float(np.mean(sym < 0.5)))} | "
        lines.append(
            f"| {key[1]} | {group_label(key[0])} | {len(g)} | {_fmt(lo)} | {_fmt(hi)} | "
            f"{_fmt(mean)} | {_fmt(float(np.median(err)))} | {paper_text} | "
            f"{_pct(float(np.mean(err < 0.5)))} | {_fmt(float(good.mean())) if good.size else '–'} | "
            f"{_pct(every.size / len(g))} | {_fmt(float(every.mean())) if every.size else '–'} | "
            f"{_bound_text(bound)} | "
            f"{sym_text}{int(np.median(contact)) if contact else '–'} | "
            f"{_fmt(c_lo)} / {_fmt(c_hi)} / {_fmt(c_mean)} | "
            f"{np.mean([r['cpu_s'] for r in g]):.2f} |")
    lines += ["", ("**Every robot, and the bound.** 'Trials < 0.5 m' keeps trials whose *team "
              "mean* is under 0.5 m, so one robot of such a trial can be a metre off; 'every "
              "robot < 0.5 m' keeps those whose worst robot is (`final_error_max_m`), and its mean "
              "is the figure to compare with 002's. 'Single-scan bound': the Cramér-Rao bound on "
              "the position (pose unknown) of one scan of this laser (8 beams, 0.1 m noise, "
              "`world/laser/laser.py` `single_scan_crb`), per robot, RMS over its true poses in the "
              f"final window of seeds {_BOUND_SEEDS[0]}-{_BOUND_SEEDS[-1]} (dashed in the box "
              "plot): what an estimator of one scan cannot beat on average ('≥ 1': a robot that "
              "stands where one scan cannot fix its position, such as along a corridor whose ends "
              "are out of the laser's range); a GA's best individual carries, on top of it, "
              "the population's resolution (how finely 50-100 individuals sample the fitness "
              "peak). Rows '(…-refine)' run the refinement option (`agents/laser/refine.py`, "
              "not in 002, off by default), which climbs eq. 1-2 from the best individuals."),
              "", ("**Units.** Table 3 of 002 prints no units. We read its entries as metres (a "
              "1.4 cm mean). Read as squared metres (mean squared errors), their square roots "
              "would be " + ", ".join(
                  f"{_PAPER_NAMES.get(a, a)} {pop}: {math.sqrt(v[2]):.3f} m"
                  for (a, pop), v in PAPER_TABLE3.items())
              + " (square roots of the means); a reading stated here, not adopted."),
              "", f"**Difference and likely reason.** {reasons.get('table3', DEFAULT_REASON)}"]

    fig, axes = _figure(9.0, 4.2)
    ax = axes[0][0]
    data = [np.maximum([r["final_error_m"] for r in groups[k]], 1e-3) for k in keys]
    positions = np.arange(len(keys))
    ax.boxplot(data, positions=positions, widths=0.55, flierprops={"marker": "o", "markersize": 3})
    for x, key in zip(positions, keys):
        paper = PAPER_TABLE3.get(paper_key(key))
        if paper:
            ax.plot([x + 0.35] * 2, [paper[1], paper[0]], color="black", lw=2)
            ax.plot(x + 0.35, paper[2], marker="D", color="black", ms=5,
                    label="paper: min-max, mean" if x == 0 else None)
    ax.set_yscale("log")
    ax.set_xticks(positions, [f"{group_label(k[0])}\n{k[1]}".replace(" (", "\n(") for k in keys],
                  fontsize=7)
    for b in (bound or []):
        if b < 1.0:
            ax.axhline(b, color="tab:purple", ls="--", lw=0.8)
    ax.axhline(0.5, color="grey", ls=":", lw=1)
    ax.set_ylabel("final position error per trial (m)")
    ax.set_title("002 table 3: per-trial error, ours (boxes) vs paper (black)")
    if any(PAPER_TABLE3.get(paper_key(k)) for k in keys):
        ax.legend(loc="upper left", fontsize=8)
    _save(fig, out / "table3_errors.png")

    curves = []
    fig, axes = _figure(12.0, 4.2, ncols=2)
    for key in keys:
        runs = _stack(groups[key]).mean(axis=2)  # mean over robots: (R, T)
        mean, median = runs.mean(axis=0), np.median(runs, axis=0)
        curves.append((f"table3/{key[0]}/{key[1]}", "mean over robots", mean, median, runs.shape[0]))
        refined = paper_key(key) is None
        for ax, curve in zip(axes[0], (mean, median)):
            ax.plot(curve, color=_COLOURS.get(algorithm_of[key[0]], "black"),
                    ls=(":" if refined else "-") if key[1] == "100" else "--",
                    lw=0.8 if refined else 1.2, label=f"{group_label(key[0])} {key[1]}")
    for ax, what in zip(axes[0], ("mean", "median")):
        for step in (100, 250):  # 002 §6: first meeting at about 100, third robot about 250
            ax.axvline(step, color="grey", ls=":", lw=1)
        ax.set_yscale("log")
        ax.set_xlabel("iteration (dotted: 002's meetings, about 100 and 250)")
        ax.set_ylabel(f"position error, mean over robots, {what} over trials (m)")
    axes[0][0].set_title("002 fig. 9 (our runs), mean over trials; solid 100, dashed 50")
    axes[0][1].set_title("median over trials")
    axes[0][0].legend(fontsize=8, ncol=3)
    _save(fig, out / "table3_error_over_time.png")
    figures = ["table3_errors.png", "table3_error_over_time.png"]
    if _draw_floor(scenarios, out / "table3_floor.png"):
        figures.insert(0, "table3_floor.png")
    return Section("002 table 3: MR-SSGA vs simple GA vs particle filter", lines, figures, curves)


#: Seeds of the world whose true poses the single-scan bound of table 3 is taken at.
_BOUND_SEEDS = (1, 2, 3, 4, 5)


def _table3_bound(scenarios: Sequence[str]) -> list[float] | None:
    """Per robot, the RMS over final-window steps and :data:`_BOUND_SEEDS` of
    :func:`single_scan_crb` at the true poses of the first scenario, run without localizers (the
    paths are scripted). None if the scenario does not load."""
    import dataclasses

    from swarmloc.config import ConfigError
    from swarmloc.deploy.lab.laser.runner import load_laser_scenario
    from swarmloc.world.laser.laser import single_scan_crb
    from swarmloc.world.laser.maps import build_map
    from swarmloc.world.laser.world import WORLD_STREAM, LaserWorld

    try:
        scenario = load_laser_scenario(scenarios[0])
    except (ConfigError, ValueError, IndexError):
        return None
    config, window = scenario.world, scenario.metrics.final_window_steps
    world_map = build_map(config.map)
    beams = np.arange(config.laser.n_beams) * (2.0 * math.pi / config.laser.n_beams)
    squares: list[np.ndarray] = []
    for seed in _BOUND_SEEDS:
        seeded = dataclasses.replace(config, seed=seed)
        world = LaserWorld(seeded, np.random.default_rng([seed, WORLD_STREAM]))
        poses = []
        while not world.done:
            if world.step_index >= config.steps - window:
                poses.append(world.true_poses.copy())
            world.observe()
            world.step([None] * config.robots)
        stacked = np.stack(poses)  # (W, N, 3)
        bound = single_scan_crb(world_map, stacked.reshape(-1, 3), beams,
                                config.laser.max_range_m, config.laser.noise_std_m)
        squares.append(bound.reshape(stacked.shape[:2]) ** 2)
    return [float(v) for v in np.sqrt(np.concatenate(squares).mean(axis=0))]


def _bound_text(bounds: list[float] | None) -> str:
    """Per robot: the bound in metres, or '>= 1 m' where one scan cannot fix the position."""
    if not bounds:
        return "–"
    return " / ".join(_fmt(b) if b < 1.0 else "≥ 1" for b in bounds)


#: The robots' colours in 002 fig. 8/9 (red and yellow meet first, the third joins later).
_PAPER_ROBOT_COLOURS = ("tab:red", "gold", "tab:blue")


def _draw_floor(scenarios: Sequence[str], path: Path, title: str = "002 fig. 8 (ours)",
                colours: Sequence[str] = ()) -> bool:
    """002 fig. 8 for our runs: the floor of the first scenario, its walls and each robot's
    scripted path (start dot, then the waypoints in order). False if it does not load."""
    from swarmloc.config import ConfigError
    from swarmloc.deploy.lab.laser.runner import load_laser_scenario

    try:
        world = load_laser_scenario(scenarios[0]).world
    except (ConfigError, ValueError, IndexError):
        return False
    segments = world.segment_map().segments_m
    fig, axes = _figure(7.0, 4.4)
    ax = axes[0][0]
    for x1, y1, x2, y2 in segments:
        ax.plot([x1, x2], [y1, y2], color="black", lw=1.5)
    for r, robot_path in enumerate(world.paths):
        if robot_path.start is None:
            continue
        points = np.array([robot_path.start[:2], *robot_path.waypoints])
        palette = tuple(colours) or _PAPER_ROBOT_COLOURS
        colour = palette[r % len(palette)]
        ax.plot(points[:, 0], points[:, 1], color=colour, lw=1.2, label=f"robot {r}")
        ax.plot(*points[0], marker="o", color=colour, ms=7)
    ax.set_aspect("equal")
    ax.set_xlabel("x (m)")
    ax.set_ylabel("y (m)")
    ax.set_title(f"{title}: floor `{world.map}`, paths (dots: starts)")
    ax.legend(fontsize=8, loc="upper left")
    _save(fig, path)
    return True


# -- 003 fig. 3 -------------------------------------------------------------------------------


def _variants(rows: list[dict]) -> dict[str, list[dict]]:
    """Rows by variant: the algorithm, or the spec group's name when a group named otherwise
    runs a single algorithm (a variant of it, such as "amcl-no-recovery")."""
    algorithms: dict[str, set[str]] = defaultdict(set)
    for r in rows:
        algorithms[r["group"]].add(r["algorithm"])
    out: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        group = r["group"]
        named = group == r["algorithm"] or len(algorithms[group]) > 1
        out[r["algorithm"] if named else group].append(r)
    return out


def _variant_label(variant: str, rows: list[dict]) -> str:
    algorithm = rows[0]["algorithm"]
    return _label(algorithm) if variant == algorithm else f"{_label(algorithm)} ({variant})"


def _kidnap(rows: list[dict], out: Path, reasons: dict) -> Section:
    groups = _variants(rows)
    order = [a for a in ("cfsga", "ssga", "amcl") if a in groups] + sorted(
        set(groups) - {"cfsga", "ssga", "amcl"})
    kidnap_step = next((r["kidnap_step"] for r in rows if r["kidnap_step"] is not None), None)
    lines = [
        ("One robot in the office floor (`office`, 20 x 12 m) goes from S (south-west room) "
        "through the corridor to K (north-middle room), waits there, is kidnapped at step "
        f"{kidnap_step} to R (south-east room) and goes on to G (north-east room) "
        "(`laser-kidnap-office.toml`); table I of 003. CFS-GA and SSGA with 300 individuals, "
        "both AMCLs adapting between 1000 and 10000 particles (Player AMCL: the filter 003 ran; "
        "modern AMCL: the ROS-amcl-like one). 'Recovered': final error below 0.5 m; "
        "'recovery time': steps from the kidnap until the error stays below 15 cm."),
        "",
        "| algorithm | n | error at step 150, mean (m) | settled < 15 cm before the kidnap | recovered after the kidnap | recovery time, median (steps) | final error, mean / median (m) |",
        "|---|---|---|---|---|---|---|",
    ]
    curves = []
    fig, axes = _figure(11.0, 4.2, ncols=2)
    for variant in order:
        g = groups[variant]
        algorithm, label = g[0]["algorithm"], _variant_label(variant, g)
        runs = _stack(g)[:, :, 0]
        mean, median = runs.mean(axis=0), np.median(runs, axis=0)
        curves.append((f"kidnap/{variant}", "0", mean, median, runs.shape[0]))
        pre = np.mean([bool(r["settled_before_kidnap"]) for r in g])
        recovered = sum(bool(r["recovered"]) for r in g)
        lo, hi = wilson_interval(recovered, len(g))
        times = [r["recover_steps"] for r in g if r["recover_steps"] is not None]
        final = np.array([r["final_error_m"] for r in g])
        at = min(150, runs.shape[1] - 1)
        lines.append(
            f"| {label} | {len(g)} | {_fmt(float(runs[:, at].mean()))} | {_pct(pre)} | "
            f"{_pct(recovered / len(g))} (95 % CI {_pct(lo)}-{_pct(hi)}) | "
            f"{int(np.median(times)) if times else '–'} | {_fmt(final.mean())} / "
            f"{_fmt(float(np.median(final)))} |")
        for ax in axes[0]:
            ax.plot(mean, color=_COLOURS.get(algorithm, "black"), lw=1.2, label=label,
                    ls="-" if variant == algorithm else "--")
    for ax in axes[0]:
        if kidnap_step is not None:
            ax.axvline(kidnap_step, color="grey", ls=":", lw=1)
        ax.axhline(SETTLE_ERROR_M, color="grey", ls="--", lw=0.8)
        ax.set_xlabel("iteration")
        ax.set_yscale("log")
    axes[0][0].set_ylabel("position error, mean over runs (m)")
    axes[0][0].set_title("003 fig. 3 (our runs): kidnapped robot")
    axes[0][0].legend(fontsize=8)
    if kidnap_step is not None:
        axes[0][1].set_xlim(kidnap_step - 10, min(kidnap_step + 150, len(mean)))
    axes[0][1].set_title("after the kidnap (the paper's box b)")
    _save(fig, out / "fig3_kidnap.png")
    lines += ["", ("Paper (003 §V, fig. 3): the three perform alike until the kidnap, AMCL "
              "converging first, CFS-GA a little later and SSGA later still; after the kidnap "
              "CFS-GA always recovers, AMCL often fails to, and SSGA also fails (it needs a kidnap "
              "detector that may miss the event)."), "",
              f"**Difference and likely reason.** {reasons.get('fig3', DEFAULT_REASON)}"]
    return Section("003 fig. 3: the kidnapped robot, CFS-GA vs SSGA vs AMCL", lines,
                   ["fig3_kidnap.png"], curves)


# -- 003 fig. 4 -------------------------------------------------------------------------------

#: 003 fig. 4 is run on this scenario; other scenarios of the laser-collab spec are our variants.
_COLLAB_PAPER_SCENARIO = "laser-collab-three-corridors"

_COLLAB_INTRO = {
    _COLLAB_PAPER_SCENARIO: (
        "As 003 writes it: \"robots have been purposely placed in the middle of three different "
        "corridors where laser data are temporarily partially useless\" (issue 43). Floor "
        "`three_corridors` (24 x 14 m, world/laser/maps.py): two halls joined by three alike 2 m "
        "corridors, invariant under a half turn but for one 3 x 2.5 m bay off the middle "
        "corridor. Green starts in front of the bay, paces past it and walks into the east "
        "hall; red and blue start in the middle of the south and north corridors, walk west to "
        "the west hall and back east the length of their corridors into the east hall, where "
        "the three meet (about steps 250-300), then walk west along the middle corridor past "
        "the bay (about steps 380-420), which is where, alone, they can first localize; 500 "
        "steps ""(`laser-collab-three-corridors.toml`). CFS-GA with 300 individuals, table I of 003 "
        "(communication range 4 m, line of sight); the same seeds for both modes. Read as the "
        "paper reads its figure: the error averaged over the trials, and the iteration from "
        "which every robot's averaged curve stays under 15 cm; the per-run settling iterations "
        "(the earlier report's figure) beside it."),
    "laser-collab-three-rooms": (
        "**The earlier setup (one corridor), kept for comparison.** Three robots start 3.5-4 m "
        "apart in the one corridor of the three-rooms floor (`three_rooms_corridor`), in radio "
        "range from the start, and walk into the three rooms (`laser-collab-three-rooms.toml`)."),
    "laser-collab-three-rooms-long-corridor": (
        "**Long-corridor variant (ours, not in 003).** The one-corridor floor, robots and "
        "parameters, but each robot first walks the corridor back and forth for about "
        "250 steps (22-24 m; some teammate within 4 m and in sight in about 230 of the first 250 "
        "steps, against about 55 above) and only then enters its room, where it stops about 35 "
        "steps later; 500 steps instead of 400 (`laser-collab-three-rooms-long-corridor.toml`). "
        "The same seeds for both modes."),
}


def _collab_paired(coop: list[dict], auto: list[dict]) -> str:
    """Per-seed comparison of the settling iterations of the two modes (same seed, same paths
    and noise)."""
    by_seed = {r["seed"]: r["settle_step"] for r in auto}
    pairs = [(r["settle_step"], by_seed[r["seed"]]) for r in coop
             if r["seed"] in by_seed and r["settle_step"] is not None
             and by_seed[r["seed"]] is not None]
    if not pairs:
        return "Paired by seed: no seed where both modes settle."
    gain = np.array([a - c for c, a in pairs])  # > 0: collaboration settles sooner
    median = _fmt(float(np.median(gain)), 0)
    return (f"Paired by seed: of the {len(pairs)} seeds where both modes settle, collaboration "
            f"settles sooner in {int((gain > 0).sum())} and later in {int((gain < 0).sum())}, "
            f"by {median} iteration{'' if median in ('1', '-1') else 's'} at the median "
            "(autonomous minus collaborative).")


def _collab_block(rows: list[dict], paper: bool, label: str, figure: Path, title: str
                  ) -> tuple[list[str], list]:
    """One scenario's table and figure: collaborative against autonomous."""
    groups: dict[int, list[dict]] = defaultdict(list)
    for r in rows:
        groups[int(r["cooperative"])].append(r)
    lines = [
        "| CFS-GA | n | all robots' mean curves under 15 cm from (iteration) | median curves | paper | runs where all robots settle | settling iteration per run, median (IQR) | final error, mean (m) |",
        "|---|---|---|---|---|---|---|---|",
    ]
    curves = []
    fig, axes = _figure(11.0, 4.2, ncols=2)
    for col, coop in enumerate((1, 0)):
        g = groups.get(coop, [])
        name = "collaborative" if coop else "autonomous"
        ax = axes[0][col]
        if not g:
            ax.set_visible(False)
            continue
        runs = _stack(g)  # (R, T, N)
        mean, median = runs.mean(axis=0), np.median(runs, axis=0)
        settle = [settle_index(mean[:, k]) for k in range(mean.shape[1])]
        all_settle = None if any(s is None for s in settle) else max(settle)
        settle_median = [settle_index(median[:, k]) for k in range(median.shape[1])]
        median_settle = None if any(s is None for s in settle_median) else max(settle_median)
        for k in range(mean.shape[1]):
            curves.append((f"{label}/{name}", str(k), mean[:, k], median[:, k], runs.shape[0]))
            colour = _ROBOT_COLOURS[k % len(_ROBOT_COLOURS)]
            ax.plot(mean[:, k], color=colour, lw=1.2, label=f"robot {k}, mean")
            ax.plot(median[:, k], color=colour, lw=0.8, ls="--",
                    label=f"robot {k}, median" if coop else None)
        ax.axhline(SETTLE_ERROR_M, color="grey", ls="--", lw=0.8)
        if all_settle is not None:
            ax.axvline(all_settle, color="black", ls=":", lw=1)
        ax.set_yscale("log")
        ax.set_xlabel("iteration")
        ax.set_title(f"({'a' if coop else 'b'}) {name} localization")
        per_run = np.array([r["settle_step"] for r in g if r["settle_step"] is not None])
        iqr = (f"{int(np.median(per_run))} ({int(np.percentile(per_run, 25))}-"
               f"{int(np.percentile(per_run, 75))})") if per_run.size else "–"
        final = np.array([r["final_error_m"] for r in g])
        cited = ("about 100" if coop else "almost 300") if paper else "–"
        lines.append(
            f"| {name} | {len(g)} | {all_settle if all_settle is not None else 'never (within the run)'} | "
            f"{median_settle if median_settle is not None else 'never'} | "
            f"{cited} | {_pct(per_run.size / len(g))} | {iqr} | "
            f"{_fmt(final.mean())} |")
    if groups.get(1) and groups.get(0):
        lines += ["", _collab_paired(groups[1], groups[0])]
    axes[0][0].set_ylabel("position error, mean over runs (m)")
    axes[0][0].legend(fontsize=7, ncol=2)
    fig.suptitle(title)
    _save(fig, figure)
    return lines, curves


def _collab(rows: list[dict], out: Path, reasons: dict) -> Section:
    by_scenario: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        by_scenario[str(r["scenario"])].append(r)
    order = sorted(by_scenario, key=lambda s: (s != _COLLAB_PAPER_SCENARIO, s))
    lines: list[str] = []
    curves: list = []
    figures: list[str] = []
    for scenario in order:
        g = by_scenario[scenario]
        paper = scenario == _COLLAB_PAPER_SCENARIO
        figure = "fig4_collab.png" if paper else f"fig4_{scenario}.png"
        title = ("003 fig. 4 (our runs): collaborative vs autonomous CFS-GA "
                 "(solid: mean over runs, dashed: median)" if paper else
                 f"{scenario} (our variant): collaborative vs autonomous CFS-GA "
                 "(solid: mean over runs, dashed: median)")
        label = "collab" if paper else str(g[0]["group"])
        if paper and _draw_floor([scenario], out / "fig4_floor.png", "003 fig. 4 (ours)",
                                 _ROBOT_COLOURS):
            figures.append("fig4_floor.png")
        intro = _COLLAB_INTRO.get(scenario, f"Scenario `{scenario}.toml` (our variant, not in 003).")
        block, block_curves = _collab_block(g, paper, label, out / figure, title)
        lines += ([""] if lines else []) + [intro, "", *block]
        curves += block_curves
        figures.append(figure)
    lines += ["", f"**Difference and likely reason.** {reasons.get('fig4', DEFAULT_REASON)}"]
    return Section("003 fig. 4: collaborative vs autonomous CFS-GA", lines, figures, curves)


# -- 003 robustness ---------------------------------------------------------------------------

_MAP_SHORT = {"office": "office", "three_rooms_corridor": "3 rooms", "symmetric_rooms": "sym. rooms"}

#: 003 §V: failure rates with random start and goal points.
#: The paper's AMCL is Player's (amcl-player); the modern filter (amcl) has no paper figure.
PAPER_FAILURE = {"cfsga": 0.0, "amcl-player": 0.35, "ssga": 0.15}
#: Rows first, in this order; other variants after them.
_ROBUSTNESS_ORDER = ("cfsga", "ssga", "amcl-player", "amcl")


def _robustness(rows: list[dict], out: Path, reasons: dict) -> Section:
    by_algo = _variants(rows)  # an algorithm, or a named variant of one (amcl-no-recovery)
    maps = sorted({r["map"] for r in rows})
    order = [a for a in _ROBUSTNESS_ORDER if a in by_algo] + sorted(
        set(by_algo) - set(_ROBUSTNESS_ORDER))
    lines = [
        ("One robot, random start and random goals one after another (driver `random_goals`), "
        f"400 steps, in {' and '.join(f'`{m}`' for m in maps)} "
        "(`laser-robust-*.toml`); autonomous, from a uniform initial population; table I of 003. "
        "A run fails when its final error (last 20 steps) is above 0.5 m."),
        "",
        "| algorithm | population | " + " | ".join(f"failures, {m}" for m in maps)
        + " | failures, all (95 % CI) | paper | final error of successes, median (m) |",
        "|---|---|" + "---|" * len(maps) + "---|---|---|",
    ]
    fig, axes = _figure(max(8.0, 1.5 * len(order)), 4.6)
    ax = axes[0][0]
    width = 0.8 / (len(maps) + 1)
    for i, variant in enumerate(order):
        g = by_algo[variant]
        algorithm, label = g[0]["algorithm"], _variant_label(variant, g)
        cells = []
        for j, m in enumerate([*maps, None]):
            sub = [r for r in g if m is None or r["map"] == m]
            fails = sum(not r["localized"] for r in sub)
            rate = fails / len(sub) if sub else math.nan
            lo, hi = wilson_interval(fails, len(sub))
            cells.append((rate, lo, hi, len(sub)))
            x = i + (j - len(maps) / 2) * width
            ax.bar(x, rate, width * 0.9, color=_COLOURS.get(algorithm, "grey"),
                   alpha=0.45 if m is not None else 0.9, edgecolor="black", lw=0.5)
            ax.errorbar(x, rate, yerr=[[rate - lo], [hi - rate]], color="black", capsize=2, lw=0.8)
        paper = PAPER_FAILURE.get(algorithm) if variant == algorithm else None
        if paper is not None:
            ax.plot(i + 0.45, paper, marker="D", color="black", ms=6,
                    label="paper" if i == 0 else None)
        success = [r["final_error_m"] for r in g if r["localized"]]
        populations = sorted({str(r["population"]) for r in g})
        lines.append(
            f"| {label} | {', '.join(populations)} | "
            + " | ".join(f"{_pct(c[0])} (n = {c[3]})" for c in cells[:-1])
            + f" | {_pct(cells[-1][0])} ({_pct(cells[-1][1])}-{_pct(cells[-1][2])}), n = {cells[-1][3]} | "
            f"{_pct(paper) if paper is not None else '–'} | "
            f"{_fmt(float(np.median(success))) if success else '–'} |")
    ticks, labels = [], []
    for i in range(len(order)):
        for j, m in enumerate([*maps, None]):
            ticks.append(i + (j - len(maps) / 2) * width)
            labels.append("all" if m is None else _MAP_SHORT.get(m, m))
    ax.set_xticks(ticks, labels, fontsize=7)
    for i, variant in enumerate(order):
        ax.text(i, -0.12, textwrap.fill(_variant_label(variant, by_algo[variant]), 16,
                                        break_on_hyphens=True),
                ha="center", va="top", fontsize=8,
                transform=ax.get_xaxis_transform())
    ax.set_ylabel("fraction of runs that fail to localize")
    ax.set_title("003 §V robustness (our runs): per map (light) and all (dark), 95 % CI")
    ax.legend(fontsize=8)
    _save(fig, out / "robustness.png")
    lines += ["", ("Paper (003 §V, 500 runs with random start and goal points in both "
              "environments): CFS-GA with 300 individuals always localizes; AMCL fails about 35 % "
              "(10000 to 1000 particles); SSGA about 15 % (300 individuals)."), "",
              ("**Two AMCLs.** 'Player AMCL' (`agents/laser/amcl_player.py`) is the filter 003 "
               "ran, read from Player's `amcl` driver: per-beam product of "
               "`0.1 + 0.9 exp(-z^2 / 2 (0.1 m)^2)` on 6 of the 18 beams, Player's odometric "
               "drift model and update threshold (0.2 m, 30 deg), KLD with pf_err 0.01 and "
               "pf_z 3, and no injection (Player's pf.c has none); its two other readings are "
               "rows of their own: '(amcl-player-low-variance)', the resampler of Player's pf.c "
               "from April 2008 on, and '(amcl-player-fixed-injection)', 003's text (\"simply "
               "adds a number of randomly placed samples at every time instant\": 100 uniform "
               "samples after every update). 'Modern AMCL' (`agents/laser/amcl.py`) is the "
               "stronger, ROS-amcl-like baseline (likelihood field of 0.5 m, adaptive injection "
               "of Augmented_MCL); the paper's 35 % is not its figure. Groups differ in their "
               "number of runs (n in each cell); the intervals are 95 % Wilson intervals."), "",
              f"**Difference and likely reason.** {reasons.get('robustness', DEFAULT_REASON)}"]
    return Section("003 §V: robustness over random starts and goals", lines, ["robustness.png"], [])


# -- the page ---------------------------------------------------------------------------------

_SECTIONS = (("laser-table3", _table3), ("laser-kidnap", _kidnap), ("laser-collab", _collab),
             ("laser-robustness", _robustness))


def _load_reasons(out: Path) -> dict[str, str]:
    path = out / "reasons.toml"
    if not path.exists():
        return {}
    with path.open("rb") as handle:
        data = tomllib.load(handle)
    return {str(k): " ".join(str(v).split()) for k, v in data.items()}


def _cpu_lines(rows: list[dict]) -> list[str]:
    # One line per run shape too: an experiment's scenarios may differ in robots or steps.
    # Variants of an algorithm (a spec group named otherwise, e.g. a refinement option) apart.
    groups: dict[tuple[str, str, str, int, int], list[dict]] = defaultdict(list)
    for experiment in sorted({r["experiment"] for r in rows}):
        for variant, variant_rows in _variants([r for r in rows
                                                if r["experiment"] == experiment]).items():
            for r in variant_rows:
                groups[(experiment, variant, str(r["population"]), int(r["robots"]),
                        int(r["steps"]))].append(r)
    lines = ["| experiment | algorithm | population | runs | robots x steps | CPU per run, mean (s) | CPU per robot-step (ms) |",
             "|---|---|---|---|---|---|---|"]
    for (exp, variant, pop, robots, steps), g in sorted(groups.items()):
        cpu = np.array([r["cpu_s"] for r in g])
        lines.append(f"| {exp} | {_variant_label(variant, g)} | {pop} | {len(g)} | "
                     f"{robots} x {steps} | "
                     f"{cpu.mean():.2f} | {1000 * cpu.mean() / (robots * steps):.2f} |")
    total = sum(r["cpu_s"] for r in rows)
    lines += ["", (f"Total CPU of these runs: {total / 60:.1f} min ({total / 120:.1f} min of wall "
              f"time on 2 free cores).")]
    planned, estimate = _full_run_estimate(rows)
    if planned:
        lines += ["", (f"The full specs plan {planned} runs; at the CPU per run measured here "
                       f"they take about {estimate / 60:.0f} CPU-minutes ({estimate / 120:.0f} "
                       f"min of wall time on 2 free cores).")]
    return lines


def _full_run_estimate(rows: list[dict]) -> tuple[int, float]:
    """(runs, CPU seconds) of the shipped specs of these rows' experiments, run in full, at the
    mean CPU per run of each setting measured in ``rows``."""
    from swarmloc.config import ConfigError
    from swarmloc.deploy.lab.experiment import load_spec, plan

    cpu: dict[tuple[str, str], list[float]] = defaultdict(list)
    for r in rows:
        cpu[(r["experiment"], r["setting"])].append(r["cpu_s"])
    planned, seconds = 0, 0.0
    for experiment in sorted({r["experiment"] for r in rows}):
        try:
            jobs = plan(load_spec(experiment))
        except (ConfigError, ValueError):
            continue  # not a shipped spec
        planned += len(jobs)
        for job in jobs:
            measured = cpu.get((experiment, job.setting))
            seconds += float(np.mean(measured)) if measured else 0.0
    return planned, seconds


def write_report(paths: Sequence[str | Path], out_dir: str | Path, *, command: str = "") -> Path:
    """Write the report of the laser results files ``paths`` into ``out_dir``; return the page."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    rows = load_laser_results(paths)
    reasons = _load_reasons(out)
    by_experiment: dict[str, list[dict]] = defaultdict(list)
    for r in rows:
        by_experiment[r["experiment"]].append(r)
    sections = [build(by_experiment[name], out, reasons)
                for name, build in _SECTIONS if by_experiment.get(name)]
    missing = [name for name, _ in _SECTIONS if not by_experiment.get(name)]

    with (out / "results.csv").open("w", newline="", encoding="utf-8") as handle:
        fields: list[str] = []  # every file's columns, in order of first appearance
        for r in rows:
            fields += [k for k in r if k != SERIES_COLUMN and k not in fields]
        writer = csv.DictWriter(handle, fieldnames=fields, lineterminator="\n")
        writer.writeheader()
        for r in rows:
            writer.writerow({k: "" if r.get(k) is None else r[k] for k in fields})
    with (out / "curves.csv").open("w", newline="", encoding="utf-8") as handle:
        writer = csv.writer(handle, lineterminator="\n")
        writer.writerow(["curve", "robot", "step", "mean_error_m", "median_error_m", "runs"])
        for section in sections:
            for label, robot, mean, median, n in section.curves:
                for step, (a, b) in enumerate(zip(mean, median)):
                    writer.writerow([label, robot, step, f"{a:.4f}", f"{b:.4f}", n])

    runs = len(rows)
    seeds = sorted({r["seed"] for r in rows})
    page = [
        "# Map-based laser localization: seeds 002 and 003, reproduced",
        "",
        ("Generated by `deploy/lab/laser/report.py` from the laser experiments "
        "(`deploy/experiments/laser-*.toml`, issue 4). Our runs stand next to the papers' "
        "numbers: MR-SSGA (002, `agents/laser/ssga.py`), the simple GA (`agents/laser/simple_ga.py`), CFS-GA "
        "(003, `agents/laser/cfsga.py`), Player's AMCL as 003 ran it (`agents/laser/amcl_player.py`, "
        "'Player AMCL') and the stronger modern, ROS-amcl-like particle filter "
        "(`agents/laser/amcl.py`, 'modern AMCL'), in the "
        "laser world of `world/laser/world.py` (maps of `world/laser/maps.py`: reconstructions, the "
        "papers' drawings are not in their text). Everything here comes from "
        f"{runs} runs (seeds {seeds[0] if seeds else '–'}..{seeds[-1] if seeds else '–'}); "
        "`results.csv` has one row per run, `curves.csv` the curves drawn."),
        "",
    ]
    if missing:
        page += [f"Not in these results (not run yet): {', '.join(missing)}.", ""]
    for section in sections:
        page += [f"## {section.title}", "", *section.lines, ""]
        page += [f"![{name}]({name})" for name in section.figures]
        page.append("")
    page += ["## CPU", "", *_cpu_lines(rows), "", "## Regenerate", "",
             "These results:", "", "```", command or full_command(), "```", "",
             "The full experiments (every spec's own number of replications):", "", "```",
             full_command(), "```", "",
             ("The results files are resumable: the same command skips the runs already done; "
             "`--replications N` runs the first N seeds of every setting (a preview the full run "
             "resumes from). `swarmloc report` alone redraws this page from the results."), ""]
    path = out / "README.md"
    path.write_text("\n".join(page), encoding="utf-8")
    return path


def full_command(specs: Sequence[str] = (), replications: int | None = None,
                 out: str = "docs/laser") -> str:
    """The commands that run the laser specs (default: the report's four) and write this page."""
    from swarmloc.deploy.lab.laser.experiment import REPORT_SPECS

    specs = list(specs) or list(REPORT_SPECS)
    extra = f" --replications {replications}" if replications else ""
    lines = [f"swarmloc experiment {name}{extra} --out results/{name}.csv" for name in specs]
    lines.append("swarmloc report " + " ".join(f"results/{name}.csv" for name in specs)
                 + f" --out {out}")
    return "\n".join(lines)


def _fewer(experiment: str, replications: int) -> str:
    """`` --replications N`` if the rows have fewer than the shipped spec's (or it is none)."""
    from swarmloc.config import ConfigError
    from swarmloc.deploy.lab.experiment import load_spec

    try:
        full = load_spec(experiment).replications
    except ConfigError:
        full = None
    return "" if full == replications else f" --replications {replications}"


def write_from_args(paths: list[Path], args) -> Path:
    """The laser template of ``swarmloc report`` (ConfigError for a file that is not laser
    results)."""
    from swarmloc.config import ConfigError

    out = Path(args.out) if args.out else Path("docs/laser")
    command = args.regen_command
    if not command:
        try:
            rows = load_laser_results(paths)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        reps: dict[str, int] = {}
        for r in rows:
            reps[r["experiment"]] = max(reps.get(r["experiment"], 0), r["replication"] + 1)
        command = "\n".join([*(f"swarmloc experiment {n}{_fewer(n, k)} --out "
                                f"results/{n}.csv" for n, k in reps.items()),
                             "swarmloc report " + " ".join(map(str, paths)) + f" --out {out}"])
    try:
        return write_report(paths, out, command=command)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None


def _template():
    from swarmloc.deploy.lab.report import ReportTemplate

    return ReportTemplate("laser", frozenset({"experiment", "algorithm", "final_error_m",
                                              SERIES_COLUMN}), write_from_args)


#: This family's template of ``swarmloc report`` (named by its ``Family.report``, ``swarmloc.families``).
TEMPLATE = _template()

__all__ = [
    "PAPER_FAILURE",
    "PAPER_TABLE3",
    "TEMPLATE",
    "curve_tail_indexes",
    "full_command",
    "load_laser_results",
    "series_of",
    "settle_index",
    "table3_indexes",
    "wilson_interval",
    "write_from_args",
    "write_report",
]
