"""Report: box plots and a markdown page from experiment results, next to the papers' numbers.

``swarmloc report RESULTS.csv`` reads the tidy results of ``swarmloc experiment`` (one row per
setting and replication) and writes, into one folder, PNG figures in the style of seed 000
figures 13-16 and seed 001 figures 6-8, and a markdown page with:

- a comparison table: each published claim (:data:`paper_figures`, with the section and figure it
  comes from), our measured value (medians over replications, ratios of medians), the difference
  in words, and a "likely reason" filled in by whoever analyses it (``reasons``);
- the figures, and which could not be drawn from these rows and why (a smoke or partial run still
  gives a page);
- a per-setting table: n, median and interquartile range of round trips, recruitment time and
  the fraction of robots on the path;
- the command and seeds that regenerate it.

Box plots follow the papers' caption (seed 000 fig. 13): a box from the first to the third
quartile, a bar at the median, whiskers to the farthest point within 1.5 interquartile ranges,
outliers as circles. Quartiles are numpy's linear interpolation, the same as matplotlib's.

A replication in which some robot never visited both areas has no recruitment time; it is counted
at the run's duration, a lower bound, and the page says so ("≥").

A box is a *variant*: a strategy, its β (Fermi strategies), and any grid value that differs from
the default (``world.odometry.slip_fraction = 0`` reads "no odometry error"). Values a group fixes
in its spec's ``set`` table are not columns of the results; they are read back from the shipped
spec named like the experiment (or ``--spec``). Two groups whose rows still look alike are kept
apart by labelling their boxes with the group. Fermi strategies appear at their best β (most
median round trips) except in the β sweep.

Figures are drawn on :class:`matplotlib.figure.Figure` objects rendered by Agg: no pyplot, no
display, no global matplotlib state.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import re
import shlex
import sys
from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.config import ConfigError

# -- the results file -------------------------------------------------------------------------

#: Columns every results file has (``swarmloc experiment`` writes them), besides one column per
#: grid key with a dotted name ("agent.beta", "world.odometry.slip_fraction", ...).
REQUIRED_COLUMNS: tuple[str, ...] = (
    "experiment", "group", "setting", "scenario", "strategy", "beta", "robots", "duration_s",
    "seed", "replication", "recruitment_time_s", "robots_found_both", "round_trips_total",
    "on_path_fraction_mean", "lost_total", "wall_s",
)
_STRING_COLUMNS = frozenset({"experiment", "group", "setting", "scenario", "strategy"})
_INT_COLUMNS = frozenset({"robots", "seed", "replication", "robots_found_both",
                          "round_trips_total", "lost_total"})
_FLOAT_COLUMNS = frozenset({"beta", "duration_s", "recruitment_time_s", "on_path_fraction_mean",
                            "wall_s"})
#: Grid keys that already have a column of their own (or are the x axis of a sweep): never part
#: of a variant's label.
_MAPPED_GRID_KEYS = frozenset({"agent.strategy", "agent.beta", "world.robots", "world.seed",
                               "world.duration_s", "scenario"})
_SLIP_KEY = "world.odometry.slip_fraction"
#: Pseudo grid key naming a row's group, added to a variant only when two groups would otherwise
#: give the same box (their difference is not in the rows).
_GROUP_EXTRA = "group"


def _parse_int(text: str) -> int:
    try:
        return int(text)
    except ValueError:
        value = float(text)
        if not value.is_integer():
            raise ValueError(f"not an integer: {text!r}") from None
        return int(value)


def _parse_float(text: str) -> float | None:
    value = float(text)
    return None if math.isnan(value) else value


def _parse_auto(text: str):
    for parse in (int, float):
        try:
            return parse(text)
        except ValueError:
            pass
    if text.lower() in ("true", "false"):
        return text.lower() == "true"
    return text


def _parse_cell(column: str, text: str):
    text = text.strip()
    if text == "":
        return None
    if column in _STRING_COLUMNS:
        return text
    if column in _INT_COLUMNS:
        return _parse_int(text)
    if column in _FLOAT_COLUMNS:
        return _parse_float(text)
    return _parse_auto(text)


def load_results(path: str | Path) -> list[dict]:
    """The rows of a results CSV, typed: numbers parsed, empty cells ``None``.

    Raises ``ValueError`` naming the missing columns if the file is not a results CSV (or naming
    the line and column of a cell that does not parse), ``OSError`` if it cannot be read.
    """
    path = Path(path)
    try:
        with path.open(newline="", encoding="utf-8-sig") as f:
            reader = csv.DictReader(f)
            header = [h.strip() for h in (reader.fieldnames or [])]
            missing = [c for c in REQUIRED_COLUMNS if c not in header]
            if missing:
                raise ValueError(
                    f"{path}: not a results CSV: missing column(s) {', '.join(missing)}"
                    + (f" (found: {', '.join(header[:8])}{' ...' if len(header) > 8 else ''})"
                       if header else " (the file is empty)"))
            reader.fieldnames = header
            rows = []
            for raw in reader:
                line = reader.line_num
                if None in raw:
                    raise ValueError(f"{path}, line {line}: more fields than the header has")
                row = {}
                for column, text in raw.items():
                    if text is None:
                        raise ValueError(f"{path}, line {line}: fewer fields than the header has "
                                         f"(no '{column}')")
                    try:
                        row[column] = _parse_cell(column, text)
                    except ValueError:
                        raise ValueError(f"{path}, line {line}, column '{column}': cannot read "
                                         f"{text!r} as a number") from None
                rows.append(row)
    except UnicodeDecodeError:
        raise ValueError(f"{path}: not a results CSV: not UTF-8 text") from None
    except csv.Error as exc:
        raise ValueError(f"{path}: not a results CSV: {exc}") from None
    return rows


# -- the papers' numbers ----------------------------------------------------------------------


@dataclass(frozen=True)
class PaperFigure:
    """One published number or finding, with where it comes from."""

    paper: str  # seed id: "000" (social odometry, journal) or "001" (imitation dynamics)
    section: str
    figure: str
    claim: str
    value: str  # as the paper states it
    number: float | tuple[float, float] | None = None  # for the arithmetic, when there is one


#: The papers' published results the report compares against, by claim id. Comparison rows add
#: a qualifier to the id ("000/retrieval-ratio-ES1/SSGIKF"); a reason given for the bare id
#: applies to all its rows.
paper_figures: dict[str, PaperFigure] = {
    "000/retrieval-ratio-ES1": PaperFigure(
        "000", "§6.1.2", "fig. 14a", "round trips of the SGIKFs vs NC in ES1", "about 2.5x", 2.5),
    "000/recruitment-speedup-ES1": PaperFigure(
        "000", "§6.1.1", "fig. 13a",
        "recruitment time, NC / communication strategies, ES1", "about 4x faster", 4.0),
    "000/recruitment-speedup-ES2": PaperFigure(
        "000", "§6.1.1", "fig. 13b",
        "recruitment time, NC / communication strategies, ES2", "about 4x faster", 4.0),
    "000/recruitment-NC-ES3": PaperFigure(
        "000", "§6.1.1", "fig. 13c", "NC robots that never find both areas in ES3 (7200 s)",
        "not all NC robots find the path"),
    "000/retrieval-SGIKF-ES2": PaperFigure(
        "000", "§6.1.2", "fig. 14b", "round trips of the SGIKFs in ES2", "1400 (average)", 1400.0),
    "000/retrieval-SGIKF-ES3": PaperFigure(
        "000", "§6.1.2", "fig. 14c", "round trips of the SGIKFs in ES3", "2000 (average)", 2000.0),
    "000/retrieval-NC-ES2": PaperFigure(
        "000", "§6.1.2", "fig. 14b", "round trips of NC in ES2", "at most 50", 50.0),
    "000/retrieval-NC-ES3": PaperFigure(
        "000", "§6.1.2", "fig. 14c", "round trips of NC in ES3", "at most 50", 50.0),
    "000/on-path-communication": PaperFigure(
        "000", "§6.1.3", "fig. 16", "robots on the path in steady state, communication strategies",
        "50-70 %", (0.5, 0.7)),
    "000/on-path-NC": PaperFigure(
        "000", "§6.1.3", "fig. 16", "robots on the path in steady state, NC", "at most 20 %", 0.2),
    "000/best-beta-ES1": PaperFigure(
        "000", "§6.1.2", "fig. 15a", "β of the SGIFFs with the most round trips, ES1",
        "1e-2", 1e-2),
    "000/best-beta-ES2": PaperFigure(
        "000", "§6.1.2", "fig. 15b", "β of the SGIFFs with the most round trips, ES2",
        "1e-2", 1e-2),
    "000/best-beta-ES3": PaperFigure(
        "000", "§6.1.2", "fig. 15c", "β of the SGIFFs with the most round trips, ES3",
        "1e-3", 1e-3),
    "000/best-beta-vs-SGIKF": PaperFigure(
        "000", "§6.1.2", "fig. 15",
        "SGIFF at the best β vs the SGIKF; every other β below the SGIKF",
        "best β better, other β worse"),
    "000/single-vs-double": PaperFigure(
        "000", "§6.1.2", "fig. 14, 15", "round trips, single vs double filter",
        "single better than double"),
    "000/simulation-ES1-SGIKF": PaperFigure(
        "000", "§6.2 (text)", "fig. 18 discussion", "round trips of the SGIKFs in simulated ES1",
        "about 150", 150.0),
    "000/simulation-ES1-SGIFF": PaperFigure(
        "000", "§6.2 (text)", "fig. 18 discussion",
        "round trips of the SGIFFs (β = 1e-2) in simulated ES1", "about 170", 170.0),
    "001/recruitment-reduction-30": PaperFigure(
        "001", "§5", "fig. 6",
        "time for 30 robots to locate both areas, imitation vs no imitation (4 x 4 m)",
        "40 % shorter", 0.40),
    "001/local-beats-global": PaperFigure(
        "001", "§5", "fig. 7", "round trips, local imitation (best β) vs global imitation",
        "local better (statistically)"),
    "001/no-odometry-ceiling": PaperFigure(
        "001", "§5", "fig. 7, 8", "round trips without odometry error vs every other variant",
        "the highest (the ceiling)"),
    "001/imitation-doubles": PaperFigure(
        "001", "§5", "fig. 8 (text)", "round trips, local imitation (best β) / no imitation",
        "about 2x", 2.0),
    "001/covariance-vs-best-beta": PaperFigure(
        "001", "§5", "fig. 7", "round trips, covariance knowledge (SSIKF) vs best-β imitation",
        "not statistically different"),
}

#: Panel of each shipped setup in the papers' figures.
_PAPER_PANEL = {
    "ES1": ("000", "a"), "ES2": ("000", "b"), "ES3": ("000", "c"),
    "SO-3.0x3.0": ("001", "a"), "SO-3.5x3.5": ("001", "b"), "SO-4.0x4.0": ("001", "c"),
    "SO-4.5x4.5": ("001", "d"),
}
_PAPER_SCENARIOS = {"000": ("ES1", "ES2", "ES3"),
                    "001": ("SO-3.0x3.0", "SO-3.5x3.5", "SO-4.0x4.0", "SO-4.5x4.5")}
_STRATEGY_ORDER = ("NC", "SSGIKF", "DSGIKF", "SSIKF", "DSIKF", "SSGIFF", "DSGIFF", "GLOBAL")
#: The communication strategies of seed 000 §6.1 (its claims about "the communication strategies"
#: pool these; SSIKF/DSIKF, seed 001's covariance knowledge, are shown but not pooled).
_PAPER_000_COMMUNICATION = frozenset({"SSGIKF", "DSGIKF", "SSGIFF", "DSGIFF"})
DEFAULT_REASON = "not analysed yet"


# -- small statistics -------------------------------------------------------------------------


@dataclass(frozen=True)
class Summary:
    """Median and quartiles of one metric over replications.

    ``censored`` counts replications without a value that are counted at the run's duration
    (recruitment not reached); ``lower_bound`` says the median itself is such a bound.
    """

    n: int
    median: float | None
    q1: float | None
    q3: float | None
    censored: int = 0
    lower_bound: bool = False
    values: tuple[float, ...] = ()


def summarize(rows: Sequence[dict], metric: str) -> Summary:
    """Median and interquartile range of ``metric`` over ``rows`` (None values left out, except a
    missing recruitment time, counted at the run's duration as a lower bound)."""
    values: list[float] = []
    censored = 0
    for row in rows:
        value = row.get(metric)
        if value is None:
            if metric == "recruitment_time_s" and row.get("duration_s") is not None:
                values.append(float(row["duration_s"]))
                censored += 1
            continue
        values.append(float(value))
    if not values:
        return Summary(0, None, None, None)
    q1, median, q3 = (float(v) for v in np.percentile(values, [25, 50, 75]))
    return Summary(len(values), median, q1, q3, censored, 2 * censored >= len(values) > 0,
                   tuple(values))


def _fmt(x: float | None, digits: int = 3) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "–"
    if float(x).is_integer():
        return str(int(x))
    if abs(x) >= 100:
        return f"{x:.0f}"
    return f"{x:.{digits}g}"


def _fmt_beta(beta: float | None) -> str:
    if beta is None:
        return "–"
    if beta >= 1 and float(beta).is_integer():
        return str(int(beta))
    mantissa, exponent = f"{beta:.0e}".split("e")
    if float(f"{mantissa}e{exponent}") != beta:
        return f"{beta:g}"
    return f"{mantissa}e{int(exponent)}"


def _fmt_summary(s: Summary, scale: float = 1.0, digits: int = 3) -> str:
    if s.median is None:
        return "–"
    bound = "≥ " if s.lower_bound else ""
    text = (f"{bound}{_fmt(s.median * scale, digits)} "
            f"[{_fmt(s.q1 * scale, digits)}-{_fmt(s.q3 * scale, digits)}]")
    if s.censored:
        text += f" ({s.censored} not reached)"
    return text


def _ratio(a: float | None, b: float | None) -> float | None:
    if a is None or b is None or b == 0:
        return None
    return a / b


def _relative_words(ours: float, paper: float, fmt=_fmt, unit: str = "") -> str:
    """"ours 1.7x vs paper 2.5x: 32 % lower"."""
    head = f"ours {fmt(ours)}{unit} vs paper {fmt(paper)}{unit}"
    if paper == 0:
        return head
    d = (ours - paper) / abs(paper)
    pct = round(abs(d) * 100)
    return f"{head}: " + ("the same" if pct == 0 else f"{pct} % {'higher' if d > 0 else 'lower'}")


def _fmt_ratio(r: float) -> str:
    return f"{r:.2f}x"


def _mann_whitney_p(a: Sequence[float], b: Sequence[float]) -> float | None:
    if len(a) < 2 or len(b) < 2:
        return None
    try:
        from scipy.stats import mannwhitneyu

        p = float(mannwhitneyu(a, b, alternative="two-sided").pvalue)
    except (ValueError, ImportError):
        return None
    return None if math.isnan(p) else p


def _fmt_p(p: float | None) -> str:
    if p is None:
        return "p not computed (fewer than 2 replications)"
    return f"Mann-Whitney p = {p:.2g}"


def _ranges(values: Iterable[int]) -> str:
    """1, 2, 3, 5 -> "1-3, 5"."""
    vs = sorted(set(values))
    parts: list[str] = []
    start = prev = None
    for v in vs:
        if start is None:
            start = prev = v
        elif v == prev + 1:
            prev = v
        else:
            parts.append(str(start) if start == prev else f"{start}-{prev}")
            start = prev = v
    if start is not None:
        parts.append(str(start) if start == prev else f"{start}-{prev}")
    return ", ".join(parts)


def describe_seeds(rows: Sequence[dict]) -> str:
    """The run seeds of the rows in words, e.g. "every setting (93) uses run seeds 1-30 (30
    replications)"."""
    seeds: dict[tuple, set] = defaultdict(set)
    for row in rows:
        if row.get("seed") is not None:
            seeds[(row.get("experiment"), row.get("group"), row.get("setting"))].add(row["seed"])
    if not seeds:
        return "no seeds recorded in the results"
    distinct = {frozenset(s) for s in seeds.values()}
    if len(distinct) == 1:
        only = next(iter(distinct))
        return (f"every setting ({len(seeds)}) uses run seeds {_ranges(only)} "
                f"({len(only)} replication{'s' if len(only) != 1 else ''})")
    every = set().union(*seeds.values())
    return f"run seeds {_ranges(every)} over {len(seeds)} settings (not the same in every setting)"


# -- variants: what a box stands for ----------------------------------------------------------


def _is_fermi(strategy: str | None) -> bool:
    from swarmloc.agents.epuck.social_odometry import STRATEGIES

    known = STRATEGIES.get(strategy or "")
    return known.gain == "fermi" if known is not None else bool(strategy) and "FF" in strategy


def _strategy_rank(strategy: str) -> tuple:
    if strategy in _STRATEGY_ORDER:
        return (_STRATEGY_ORDER.index(strategy), strategy)
    return (len(_STRATEGY_ORDER), strategy)


@dataclass(frozen=True)
class Variant:
    """What one box stands for: a strategy, its β (Fermi strategies only), and any other grid
    value that differs from the default (e.g. no odometry error)."""

    strategy: str
    beta: float | None = None
    extras: tuple[tuple[str, object], ...] = ()

    @property
    def base(self) -> Variant:
        return Variant(self.strategy, None, self.extras)

    @property
    def communicates(self) -> bool:
        return self.strategy != "NC"

    @property
    def special(self) -> bool:
        return bool(self.extras)

    def extras_label(self) -> str:
        parts = []
        for key, value in self.extras:
            if key == _SLIP_KEY and value == 0:
                parts.append("no odometry error")
            elif key == _GROUP_EXTRA:
                parts.append(f"[{value}]")
            else:
                shown = _fmt(value) if isinstance(value, float) else value
                parts.append(f"{key.rsplit('.', 1)[-1]}={shown}")
        return ", ".join(parts)

    def label(self, sep: str = " ") -> str:
        parts = [self.strategy]
        if self.beta is not None:
            parts.append(f"β={_fmt_beta(self.beta)}")
        if self.extras:
            parts.append(self.extras_label())
        return sep.join(parts)

    def sort_key(self) -> tuple:
        return (bool(self.extras), _strategy_rank(self.strategy), repr(self.extras),
                -1.0 if self.beta is None else self.beta)


class _Table:
    """The rows with what the figures and claims need: each row's variant, which rows belong to a
    sweep over the number of robots, and the best β of each Fermi variant."""

    def __init__(self, rows: Sequence[dict],
                 fixed: dict[tuple[str, str], dict[str, object]] | None = None):
        # Values a group fixes (its spec's ``set``) are not columns of the results; put them back
        # so that, e.g., "no odometry error" (slip_fraction = 0) is told apart from local imitation.
        fixed = fixed or {}
        self.rows = []
        for row in rows:
            extra = fixed.get((str(row.get("experiment")), str(row.get("group"))), {})
            if any(row.get(k) is None for k in extra):
                row = dict(row)
                for key, value in extra.items():
                    if row.get(key) is None:
                        row[key] = value
            self.rows.append(row)
        self._extra_columns = self._find_extra_columns()
        self._labelled_groups: set[tuple] = set()
        self._variants = {id(row): self._variant(row) for row in self.rows}
        # A (experiment, group, scenario) whose rows have several robot counts is a robots sweep
        # (seed 001 fig. 6b, 8); the other rows compare settings at one swarm size.
        robots: dict[tuple, set] = defaultdict(set)
        for row in self.rows:
            robots[self._group_key(row)].add(row.get("robots"))
        self.sweep_groups = {k for k, v in robots.items() if len(v) >= 2}
        self.comparison = [r for r in self.rows if self._group_key(r) not in self.sweep_groups]
        self.sweep = [r for r in self.rows if self._group_key(r) in self.sweep_groups]
        self._label_colliding_groups()
        self.best_beta = self._find_best_beta()

    def _label_colliding_groups(self) -> None:
        """Two groups of one scenario whose rows look alike (same strategy, β and grid values)
        differ by something the rows do not say: label their variants with the group."""
        for rows in (self.comparison, self.sweep):
            owners: dict[tuple, set] = defaultdict(set)
            for row in rows:
                key = (row.get("experiment"), row.get("scenario"), row.get("robots")
                       if rows is self.sweep else None, self.variant(row))
                owners[key].add(row.get("group"))
            for (experiment, scenario, _, _), groups in owners.items():
                if len(groups) > 1:
                    self._labelled_groups |= {(experiment, g, scenario) for g in groups}
        if self._labelled_groups:
            self._variants = {id(row): self._variant(row) for row in self.rows}

    @staticmethod
    def _group_key(row: dict) -> tuple:
        return (row.get("experiment"), row.get("group"), row.get("scenario"))

    def _find_extra_columns(self) -> dict[str, object]:
        """Grid columns (besides strategy, β, robots) whose value varies, with their default:
        None if some rows leave the column empty, else the most common value."""
        extras: dict[str, object] = {}
        columns = {c for row in self.rows for c in row if "." in c and c not in _MAPPED_GRID_KEYS}
        for column in sorted(columns):
            values = [row.get(column) for row in self.rows]
            if len(set(map(repr, values))) < 2:
                continue
            if any(v is None for v in values):
                extras[column] = None
            else:
                extras[column] = Counter(map(repr, values)).most_common(1)[0][0]
        return extras

    def variant(self, row: dict) -> Variant:
        cached = self._variants.get(id(row))
        return cached if cached is not None else self._variant(row)

    def _variant(self, row: dict) -> Variant:
        strategy = row.get("strategy") or "?"
        extras = []
        for column, default in self._extra_columns.items():
            value = row.get(column)
            if value is None or (default is not None and repr(value) == default):
                continue
            extras.append((column, value))
        if self._group_key(row) in self._labelled_groups:
            extras.append((_GROUP_EXTRA, str(row.get("group"))))
        beta = row.get("beta") if _is_fermi(strategy) else None
        return Variant(strategy, beta, tuple(extras))

    def _find_best_beta(self) -> dict[tuple, float]:
        by: dict[tuple, dict[float, list]] = defaultdict(lambda: defaultdict(list))
        for row in self.comparison:
            v = self.variant(row)
            if v.beta is not None:
                by[(row.get("scenario"), v.base)][v.beta].append(row)
        best = {}
        for key, per_beta in by.items():
            medians = {b: summarize(rs, "round_trips_total").median for b, rs in per_beta.items()}
            medians = {b: m for b, m in medians.items() if m is not None}
            if medians:
                best[key] = max(sorted(medians), key=lambda b: medians[b])
        return best

    def betas(self, scenario: str, base: Variant) -> list[float]:
        return sorted({self.variant(r).beta for r in self.comparison
                       if r.get("scenario") == scenario and self.variant(r).base == base
                       and self.variant(r).beta is not None})

    def select(self, scenario: str, variant: Variant | str, rows: Sequence[dict] | None = None,
               best: bool = True) -> list[dict]:
        """Comparison rows of ``scenario`` and ``variant`` (a strategy name means the default
        variant); a Fermi variant without β means its best β."""
        if isinstance(variant, str):
            variant = Variant(variant)
        if best and variant.beta is None and _is_fermi(variant.strategy):
            beta = self.best_beta.get((scenario, variant.base))
            if beta is None:
                return []
            variant = Variant(variant.strategy, beta, variant.extras)
        pool = self.comparison if rows is None else rows
        return [r for r in pool if r.get("scenario") == scenario and self.variant(r) == variant]

    def strategy_variants(self, rows: Sequence[dict]) -> list[Variant]:
        """The variants of a strategy figure: each one once, Fermi variants at their best β."""
        found = set()
        for row in rows:
            v = self.variant(row)
            if v.beta is not None:
                best = self.best_beta.get((row.get("scenario"), v.base))
                if best is None or v.beta != best:
                    continue
            found.add(v)
        return sorted(found, key=Variant.sort_key)


def fixed_values_from_spec(spec: str | Path) -> dict[tuple[str, str], dict[str, object]]:
    """What each group of an experiment spec fixes (its ``set`` table), keyed by (experiment,
    group): values the results file has no column for. ``spec``: a shipped spec's name or a
    ``.toml`` path. Raises ConfigError if it cannot be loaded."""
    from swarmloc.deploy.lab.experiment import load_spec

    loaded = load_spec(spec)
    return {(loaded.name, g.name): dict(g.set) for g in loaded.groups}


def _fixed_values_of_shipped_specs(rows: Sequence[dict]) -> dict[tuple[str, str], dict]:
    """:func:`fixed_values_from_spec` for every experiment of the rows that is a shipped spec."""
    try:
        from swarmloc.deploy.lab.experiment import shipped_specs

        shipped = set(shipped_specs())
    except (ImportError, OSError):
        return {}
    fixed: dict[tuple[str, str], dict] = {}
    for name in sorted({str(r.get("experiment")) for r in rows} & shipped):
        try:
            fixed.update(fixed_values_from_spec(name))
        except (ConfigError, OSError):
            continue
    return fixed


def _scenarios(rows: Iterable[dict]) -> list[str]:
    names = {r.get("scenario") for r in rows if r.get("scenario")}
    order = [s for ss in _PAPER_SCENARIOS.values() for s in ss]
    return sorted(names, key=lambda s: (order.index(s) if s in order else len(order), s))


def _mode(values: Iterable) -> object:
    counted = Counter(v for v in values if v is not None)
    return counted.most_common(1)[0][0] if counted else None


# -- comparison with the papers ---------------------------------------------------------------


@dataclass(frozen=True)
class Comparison:
    """One line of the comparison table."""

    id: str
    paper: str
    section: str
    figure: str
    claim: str
    paper_value: str
    ours: str
    difference: str
    reason: str
    measured: bool = True


def unknown_claim_ids(ids: Iterable[str]) -> list[str]:
    """The ids that are neither a claim of :data:`paper_figures` nor one followed by /qualifier."""
    return sorted(k for k in ids
                  if not any(k == base or k.startswith(base + "/") for base in paper_figures))


def _reason_for(claim_id: str, reasons: dict[str, str]) -> str:
    key = claim_id
    while key:
        if key in reasons:
            return reasons[key]
        if "/" not in key.split("/", 1)[-1]:
            break
        key = key.rsplit("/", 1)[0]
    return DEFAULT_REASON


def compare_with_papers(rows: Sequence[dict], reasons: dict[str, str] | None = None,
                        fixed: dict[tuple[str, str], dict[str, object]] | None = None
                        ) -> list[Comparison]:
    """For each claim of :data:`paper_figures` the rows can speak to, our measured value next to
    the paper's. Claims of a paper none of whose setups is in the rows are left out; claims whose
    setup is there but whose variants are not say "not measured" and what is missing. ``fixed``
    as in :func:`build_report`."""
    table = rows if isinstance(rows, _Table) else _Table(
        rows, _fixed_values_of_shipped_specs(rows) if fixed is None else fixed)
    return _Claims(table, reasons or {}).all()


class _Claims:
    def __init__(self, table: _Table, reasons: dict[str, str]):
        self.t = table
        self.reasons = reasons
        self.out: list[Comparison] = []
        self.present = set(_scenarios(table.rows))

    def add(self, base_id: str, qualifier: str, ours: str, difference: str,
            measured: bool = True) -> None:
        fig = paper_figures[base_id]
        claim_id = f"{base_id}/{qualifier}" if qualifier else base_id
        self.out.append(Comparison(
            claim_id, fig.paper, fig.section, fig.figure,
            fig.claim + (f" ({qualifier})" if qualifier else ""), fig.value, ours, difference,
            _reason_for(claim_id, self.reasons), measured))

    def missing(self, base_id: str, qualifier: str, what: str) -> None:
        self.add(base_id, qualifier, "not measured", f"no rows for {what}", measured=False)

    def rt(self, rows) -> Summary:
        return summarize(rows, "round_trips_total")

    def all(self) -> list[Comparison]:
        if self.present & set(_PAPER_SCENARIOS["000"]):
            self.claims_000()
        if self.present & set(_PAPER_SCENARIOS["001"]):
            self.claims_001()
        return self.out

    # seed 000 -----------------------------------------------------------------------------

    def claims_000(self) -> None:
        t = self.t
        # §6.1.2, fig. 14a: SGIKFs vs NC in ES1.
        nc = self.rt(t.select("ES1", "NC"))
        for s in ("SSGIKF", "DSGIKF"):
            sg = self.rt(t.select("ES1", s))
            r = _ratio(sg.median, nc.median)
            if sg.median is None or nc.median is None:
                self.missing("000/retrieval-ratio-ES1", s, f"ES1 {s} and NC")
            elif r is None:
                self.add("000/retrieval-ratio-ES1", s, f"NC median is 0 round trips ({s} "
                         f"{_fmt(sg.median)})", "ratio undefined: NC never completes a round trip")
            else:
                self.add("000/retrieval-ratio-ES1", s,
                         f"{_fmt_ratio(r)} ({s} {_fmt(sg.median)} / NC {_fmt(nc.median)} "
                         "round trips)", _relative_words(r, 2.5, _fmt_ratio_short, "x"))
        # §6.1.1, fig. 13: recruitment speed-up with communication in ES1, ES2.
        for scen in ("ES1", "ES2"):
            self.recruitment_speedup(scen)
        # ES3: not all NC robots find the path.
        ncs = t.select("ES3", "NC")
        if not ncs:
            self.missing("000/recruitment-NC-ES3", "", "ES3 NC")
        else:
            s = summarize(ncs, "recruitment_time_s")
            found = summarize(ncs, "robots_found_both")
            robots = _mode(r.get("robots") for r in ncs)
            ours = (f"recruitment not reached in {s.censored}/{s.n} replications; median "
                    f"{_fmt(found.median)} of {robots} robots found both areas")
            if s.censored == s.n:
                diff = "agrees: in every replication some NC robots never found both areas"
            elif 2 * s.censored > s.n:
                diff = (f"mostly agrees: in {s.n - s.censored}/{s.n} replications every NC robot "
                        "found both areas")
            elif s.censored:
                diff = (f"mostly differs: only in {s.censored}/{s.n} replications some NC robots "
                        "never found both areas")
            else:
                diff = (f"differs: every NC robot found both areas in every replication (median "
                        f"{_fmt(s.median)} s)")
            self.add("000/recruitment-NC-ES3", "", ours, diff)
        # §6.1.2: SGIKF round trips in ES2/ES3 and NC at most 50.
        for scen in ("ES2", "ES3"):
            cid = f"000/retrieval-SGIKF-{scen}"
            for s in ("SSGIKF", "DSGIKF"):
                sg = self.rt(t.select(scen, s))
                if sg.median is None:
                    self.missing(cid, s, f"{scen} {s}")
                    continue
                self.add(cid, s, f"median {_fmt(sg.median)} (mean {_fmt(np.mean(sg.values))})",
                         _relative_words(sg.median, paper_figures[cid].number))
            cid = f"000/retrieval-NC-{scen}"
            nc = self.rt(t.select(scen, "NC"))
            if nc.median is None:
                self.missing(cid, "", f"{scen} NC")
                continue
            top = max(nc.values)
            ours = f"max {_fmt(top)}, median {_fmt(nc.median)}"
            if top <= 50:
                diff = f"agrees: every replication at most 50 (max {_fmt(top)})"
            else:
                diff = (f"ours max {_fmt(top)} vs paper at most 50: {round(100 * (top - 50) / 50)} "
                        f"% above; {sum(v > 50 for v in nc.values)}/{nc.n} replications above 50")
            self.add(cid, "", ours, diff)
        # §6.1.3, fig. 16: robots on the path.
        for scen in ("ES1", "ES2", "ES3"):
            self.on_path(scen)
        # §6.1.2, fig. 15: best β; best β vs SGIKF; single vs double.
        for scen in ("ES1", "ES2", "ES3"):
            self.best_beta(scen)
        for scen in ("ES1", "ES2", "ES3"):
            self.single_vs_double(scen)
        # §6.2 text: simulated ES1 round trips.
        for s in ("SSGIKF", "DSGIKF", "SSGIFF", "DSGIFF"):
            cid = f"000/simulation-ES1-{s[1:]}"
            rows = t.select("ES1", s)
            sg = self.rt(rows)
            if sg.median is None:
                self.missing(cid, s, f"ES1 {s}")
                continue
            beta = f" at β={_fmt_beta(rows[0].get('beta'))}" if _is_fermi(s) else ""
            self.add(cid, s, f"median {_fmt(sg.median)}{beta}",
                     _relative_words(sg.median, paper_figures[cid].number))

    def recruitment_speedup(self, scen: str) -> None:
        t = self.t
        cid = f"000/recruitment-speedup-{scen}"
        nc = summarize(t.select(scen, "NC"), "recruitment_time_s")
        comm_variants = [v for v in t.strategy_variants(
            [r for r in t.comparison if r.get("scenario") == scen])
            if v.strategy in _PAPER_000_COMMUNICATION and not v.special]
        if nc.median is None or not comm_variants:
            self.missing(cid, "", f"{scen} NC and a communication strategy")
            return
        pooled: list[dict] = []
        per = []
        for v in comm_variants:
            rows = t.select(scen, v)
            pooled += rows
            s = summarize(rows, "recruitment_time_s")
            if s.median:
                per.append((v.label(), nc.median / s.median))
        comm = summarize(pooled, "recruitment_time_s")
        if not comm.median:
            self.missing(cid, "", f"{scen} recruitment times")
            return
        if comm.lower_bound:
            self.add(cid, "", f"communication: recruitment not completed in {comm.censored}/"
                     f"{comm.n} replications (median ≥ {_fmt(comm.median)} s)",
                     "undefined: with communication most runs never completed recruitment")
            return
        speedup = nc.median / comm.median
        bound = "≥ " if nc.lower_bound else ""
        spread = ", ".join(f"{name} {r:.1f}x" for name, r in per)
        ours = (f"{bound}{speedup:.2f}x (NC {'≥ ' if nc.lower_bound else ''}{_fmt(nc.median)} s / "
                f"communication {_fmt(comm.median)} s; {spread})")
        diff = _relative_words(speedup, 4.0, _fmt_ratio_short, "x")
        if bound:
            diff += " (ours is a bound: some replications never completed recruitment)"
        self.add(cid, "", ours, diff)

    def on_path(self, scen: str) -> None:
        t = self.t
        variants = t.strategy_variants([r for r in t.comparison if r.get("scenario") == scen])
        comm = [(v, summarize(t.select(scen, v), "on_path_fraction_mean")) for v in variants
                if v.strategy in _PAPER_000_COMMUNICATION and not v.special]
        comm = [(v, s) for v, s in comm if s.median is not None]
        if not comm:
            self.missing("000/on-path-communication", scen, f"{scen} communication strategies")
        else:
            meds = [100 * s.median for _, s in comm]
            lo, hi = min(meds), max(meds)
            ours = f"{lo:.0f}-{hi:.0f} % (" + ", ".join(
                f"{v.label()} {100 * s.median:.0f} %" for v, s in comm) + ")"
            self.add("000/on-path-communication", scen, ours, _range_words(lo, hi, 50, 70))
        nc = summarize(t.select(scen, "NC"), "on_path_fraction_mean")
        if nc.median is None:
            self.missing("000/on-path-NC", scen, f"{scen} NC")
        else:
            m = 100 * nc.median
            diff = ("agrees: at most 20 %" if m <= 20
                    else f"ours {m:.0f} % vs paper at most 20 %: {m - 20:.0f} points above")
            self.add("000/on-path-NC", scen, f"{m:.0f} %", diff)

    def best_beta(self, scen: str) -> None:
        t = self.t
        cid = f"000/best-beta-{scen}"
        paper_beta = paper_figures[cid].number
        for s, kf in (("SSGIFF", "SSGIKF"), ("DSGIFF", "DSGIKF")):
            betas = t.betas(scen, Variant(s))
            if len(betas) < 2:
                self.missing(cid, s, f"{scen} {s} at two or more β")
                continue
            meds = {b: self.rt(t.select(scen, Variant(s, b))).median for b in betas}
            best = t.best_beta.get((scen, Variant(s)))
            if best is None:
                self.missing(cid, s, f"{scen} {s} round trips")
                continue
            runner_up = max((b for b in betas if b != best), key=lambda b: meds[b] or 0)
            tie = " (a tie)" if meds[runner_up] == meds[best] else ""
            ours = (f"β = {_fmt_beta(best)}{tie} (median {_fmt(meds[best])}; next β = "
                    f"{_fmt_beta(runner_up)}: {_fmt(meds[runner_up])})")
            if best != paper_beta and meds.get(paper_beta) is not None:
                ours += f"; the paper's β = {_fmt_beta(paper_beta)}: {_fmt(meds[paper_beta])}"
            exponent = math.log10(best / paper_beta) if best > 0 else None
            if best == paper_beta:
                diff = "the same"
            elif exponent is not None and abs(exponent - round(exponent)) < 1e-9:
                decades = round(exponent)
                diff = (f"ours {_fmt_beta(best)} vs paper {_fmt_beta(paper_beta)}: {abs(decades)} "
                        f"decade{'s' if abs(decades) > 1 else ''} "
                        f"{'higher' if decades > 0 else 'lower'}")
            else:
                diff = (f"ours {_fmt_beta(best)} vs paper {_fmt_beta(paper_beta)}: "
                        f"{_fmt_ratio_short(best / paper_beta)}x")
            self.add(cid, s, ours, diff)
            # Best β above the SGIKF, every other β below it.
            ref = self.rt(t.select(scen, kf))
            if ref.median is None:
                self.missing("000/best-beta-vs-SGIKF", f"{scen}/{s}", f"{scen} {kf}")
                continue
            best_rows = t.select(scen, Variant(s, best))
            r = _ratio(meds[best], ref.median)
            worse = [b for b in betas if b != best and meds[b] < ref.median]
            p = _mann_whitney_p(self.rt(best_rows).values, ref.values)
            ours = (f"{s} β={_fmt_beta(best)} {_fmt(meds[best])} vs {kf} {_fmt(ref.median)} "
                    f"({_fmt_ratio(r) if r is not None else '–'}, {_fmt_p(p)}); "
                    f"{len(worse)}/{len(betas) - 1} other β below {kf}")
            best_ok = r is not None and r > 1
            others_ok = len(worse) == len(betas) - 1
            if best_ok and others_ok:
                diff = "agrees"
            else:
                parts = []
                if not best_ok:
                    parts.append(f"best β not above {kf}")
                if not others_ok:
                    above = [_fmt_beta(b) for b in betas if b != best and b not in worse]
                    parts.append(f"β = {', '.join(above)} also at or above {kf}")
                diff = "differs: " + "; ".join(parts)
            self.add("000/best-beta-vs-SGIKF", f"{scen}/{s}", ours, diff)

    def single_vs_double(self, scen: str) -> None:
        t = self.t
        for single, double in (("SSGIKF", "DSGIKF"), ("SSGIFF", "DSGIFF")):
            a, b = t.select(scen, single), t.select(scen, double)
            q = f"{scen}/{single[1:]}"
            if not a or not b:
                self.missing("000/single-vs-double", q, f"{scen} {single} and {double}")
                continue
            sa, sb = self.rt(a), self.rt(b)
            r = _ratio(sa.median, sb.median)
            p = _mann_whitney_p(sa.values, sb.values)
            betas = (f" (β {_fmt_beta(a[0].get('beta'))} and {_fmt_beta(b[0].get('beta'))})"
                     if _is_fermi(single) else "")
            ours = (f"{single} {_fmt(sa.median)} vs {double} {_fmt(sb.median)}{betas}: "
                    f"{_fmt_ratio(r) if r is not None else '–'}, {_fmt_p(p)}")
            if r is None:
                diff = "undefined: double median is 0"
            elif r > 1:
                diff = f"agrees: single {_fmt_ratio(r)} double"
            else:
                diff = f"differs: single {_fmt_ratio(r)} double (paper: single better)"
            self.add("000/single-vs-double", q, ours, diff)

    # seed 001 -----------------------------------------------------------------------------

    def claims_001(self) -> None:
        t = self.t
        # §5, fig. 6: 40 % shorter time to locate both areas with 30 robots and imitation.
        scen = "SO-4.0x4.0"
        pool = [r for r in t.sweep if r.get("scenario") == scen and r.get("robots") == 30]
        source = "robots sweep"
        if not pool:
            pool = [r for r in t.comparison if r.get("scenario") == scen and r.get("robots") == 30]
            source = "arenas"
        pool = [r for r in pool if not t.variant(r).special]
        nc_rows = [r for r in pool if r.get("strategy") == "NC"]
        im_rows = [r for r in pool if r.get("strategy") != "NC"]
        if not nc_rows or not im_rows:
            self.missing("001/recruitment-reduction-30", "", f"{scen} with 30 robots, NC and "
                         "imitation")
        else:
            nc = summarize(nc_rows, "recruitment_time_s")
            im = summarize(im_rows, "recruitment_time_s")
            names = ", ".join(sorted({t.variant(r).label() for r in im_rows}))
            reduction = 1 - im.median / nc.median if nc.median else None
            if im.lower_bound:
                self.add("001/recruitment-reduction-30", "", f"imitation: recruitment not "
                         f"completed in {im.censored}/{im.n} replications",
                         "undefined: with imitation most runs never completed recruitment")
            elif reduction is None:
                self.missing("001/recruitment-reduction-30", "", "NC recruitment times")
            else:
                bound = "≥ " if nc.lower_bound else ""
                ours = (f"{bound}{100 * reduction:.0f} % shorter (NC {bound}"
                        f"{_fmt(nc.median)} s -> {names} {'≥ ' if im.lower_bound else ''}"
                        f"{_fmt(im.median)} s; {source} rows)")
                d = 100 * reduction - 40
                diff = (f"ours {100 * reduction:.0f} % vs paper 40 %: "
                        + ("the same" if round(d) == 0 else
                           f"{abs(d):.0f} points {'more' if d > 0 else 'less'} reduction"))
                if nc.lower_bound:
                    diff += " (ours is a bound: most NC runs never completed recruitment)"
                self.add("001/recruitment-reduction-30", "", ours, diff)
        arenas = [s for s in _PAPER_SCENARIOS["001"] if s in self.present
                  and any(r.get("scenario") == s for r in t.comparison)]
        # Local vs global imitation (strategies GLOBAL and GLOBAL_RB, one claim row each).
        global_strategies = sorted({str(r.get("strategy")) for r in t.comparison
                                    if "GLOBAL" in str(r.get("strategy")).upper()})
        if arenas and not global_strategies:
            self.missing("001/local-beats-global", "", "global imitation (strategy GLOBAL or "
                         "GLOBAL_RB) in any arena: not in these results")
        for arena in arenas if global_strategies else []:
            local = t.select(arena, "SSGIFF")
            for gs in global_strategies:
                where = arena if len(global_strategies) == 1 else f"{arena}/{gs}"
                glob = [r for r in t.comparison if r.get("scenario") == arena
                        and r.get("strategy") == gs]
                if not glob or not local:
                    self.missing("001/local-beats-global", where,
                                 f"{arena} global imitation ({gs})" if not glob
                                 else f"{arena} SSGIFF")
                    continue
                sg, sl = self.rt(glob), self.rt(local)
                r = _ratio(sl.median, sg.median)
                p = _mann_whitney_p(sl.values, sg.values)
                ours = (f"local {_fmt(sl.median)} vs {gs} {_fmt(sg.median)} "
                        f"({_fmt_ratio(r) if r else '–'}, {_fmt_p(p)})")
                if p is None:
                    diff = ("local higher" if r is not None and r > 1 else "local not higher") + (
                        "; significance not computed")
                elif r is not None and r > 1 and p < 0.05:
                    diff = "agrees"
                elif r is not None and r < 1 and p < 0.05:
                    diff = f"differs: {gs} significantly better"
                else:
                    diff = "differs: local not significantly better"
                self.add("001/local-beats-global", where, ours, diff)
        for arena in arenas:
            self.ceiling(arena)
        for arena in arenas:
            nc, best = self.rt(t.select(arena, "NC")), self.rt(t.select(arena, "SSGIFF"))
            if nc.median is None or best.median is None:
                self.missing("001/imitation-doubles", arena, f"{arena} NC and SSGIFF")
                continue
            r = _ratio(best.median, nc.median)
            beta = t.best_beta.get((arena, Variant("SSGIFF")))
            if r is None:
                self.add("001/imitation-doubles", arena, "NC median 0 round trips",
                         "ratio undefined")
                continue
            self.add("001/imitation-doubles", arena,
                     f"{_fmt_ratio(r)} (SSGIFF β={_fmt_beta(beta)} {_fmt(best.median)} / NC "
                     f"{_fmt(nc.median)})", _relative_words(r, 2.0, _fmt_ratio_short, "x"))
        arenas_kf = [a for a in arenas if t.select(a, "SSIKF")]
        if arenas and not arenas_kf:
            self.missing("001/covariance-vs-best-beta", "", "SSIKF (covariance knowledge) in any "
                         "arena")
        for arena in arenas_kf:
            kf, ff = t.select(arena, "SSIKF"), t.select(arena, "SSGIFF")
            if not ff:
                self.missing("001/covariance-vs-best-beta", arena, f"{arena} SSGIFF")
                continue
            sk, sf = self.rt(kf), self.rt(ff)
            p = _mann_whitney_p(sk.values, sf.values)
            beta = _fmt_beta(ff[0].get("beta"))
            ours = (f"SSIKF {_fmt(sk.median)} vs SSGIFF β={beta} {_fmt(sf.median)} "
                    f"({_fmt_ratio(sk.median / sf.median) if sf.median else '–'}, {_fmt_p(p)})")
            diff = ("agrees: not significantly different" if p is None or p >= 0.05
                    else "differs: significantly different at 5 %")
            self.add("001/covariance-vs-best-beta", arena, ours, diff)

    def ceiling(self, arena: str) -> None:
        t = self.t
        rows = [r for r in t.comparison if r.get("scenario") == arena]
        variants = t.strategy_variants(rows)
        ceiling = [v for v in variants if any(k == _SLIP_KEY and val == 0 for k, val in v.extras)]
        if not ceiling:
            self.missing("001/no-odometry-ceiling", arena, f"{arena} without odometry error "
                         f"({_SLIP_KEY} = 0)")
            return
        top = ceiling[0]
        top_s = self.rt(t.select(arena, top))
        others = [(v, self.rt(t.select(arena, v))) for v in variants if v != top]
        others = [(v, s) for v, s in others if s.median is not None]
        parts = [f"no odometry error {_fmt(top_s.median)}"]
        for v, s in others:
            eta = _ratio(s.median, top_s.median)
            parts.append(f"{v.label()} {_fmt(s.median)}"
                         + (f" (η = {eta:.2f})" if eta is not None else ""))
        above = [(v, s) for v, s in others if s.median > top_s.median]
        if not above:
            diff = "agrees: no odometry error has the highest median"
        else:
            diff = "differs: " + "; ".join(
                f"{v.label()} {round(100 * (s.median / top_s.median - 1))} % above it"
                for v, s in above)
        self.add("001/no-odometry-ceiling", arena, "; ".join(parts), diff)


def _fmt_ratio_short(x: float) -> str:
    """2.5 -> "2.5", 4.0 -> "4", 2.583 -> "2.58"."""
    return f"{x:.2f}".rstrip("0").rstrip(".")


def _range_words(lo: float, hi: float, paper_lo: float, paper_hi: float) -> str:
    head = f"ours {lo:.0f}-{hi:.0f} % vs paper {paper_lo:.0f}-{paper_hi:.0f} %"
    notes = []
    if lo < paper_lo:
        notes.append(f"lowest {paper_lo - lo:.0f} points below")
    if hi > paper_hi:
        notes.append(f"highest {hi - paper_hi:.0f} points above")
    if lo > paper_hi:
        notes = [f"all above, lowest by {lo - paper_hi:.0f} points"]
    if hi < paper_lo:
        notes = [f"all below, highest by {paper_lo - hi:.0f} points"]
    return f"{head}: " + ("within the paper's range" if not notes else "; ".join(notes))


# -- figures ----------------------------------------------------------------------------------

_METRICS = {
    "recruitment": ("recruitment_time_s", 1.0, "time until every robot visited both areas (s)"),
    "round_trips": ("round_trips_total", 1.0, "round trips nest-prey-nest (all robots)"),
    "on_path": ("on_path_fraction_mean", 100.0, "robots on the path, 2nd half (%)"),
}
_FIGURE_TITLES = {
    "recruitment": "Recruitment: time for every robot to visit both areas",
    "round_trips": "Retrieval: round trips per run",
    "beta_sweep": "Retrieval of the SGIFFs for each β",
    "on_path": "Stability: fraction of robots on the path in the second half of the run",
    "robots_sweep": "Swarm size: time to locate both areas and round trips vs number of robots",
    "parameter_sweep": "Parameter sweep: round trips and robots on the path vs a swept parameter",
}
_FIGURE_PAPER = {
    "recruitment": {"000": "000 fig. 13", "001": "001 fig. 6a"},
    "round_trips": {"000": "000 fig. 14", "001": "001 fig. 7"},
    "beta_sweep": {"000": "000 fig. 15", "001": "001 fig. 7 (β of local imitation)"},
    "on_path": {"000": "000 fig. 16", "001": "—"},
    "robots_sweep": {"000": "—", "001": "001 fig. 6b, 8"},
    "parameter_sweep": {"000": "—", "001": "—"},
}
_FILL = {"NC": "white", "comm": "0.78", "special": "0.5"}


def _fill(v: Variant) -> str:
    return _FILL["special"] if v.special else (_FILL["comm"] if v.communicates else _FILL["NC"])


def _paper_of(scenario: str) -> str | None:
    panel = _PAPER_PANEL.get(scenario)
    return panel[0] if panel else None


def _arena_text(scenario: str) -> str:
    """"1.2 x 1.7 m" for a shipped scenario, "" otherwise."""
    try:
        from swarmloc.deploy.scenario import builtin_names, scenario_data

        if scenario not in builtin_names():
            return ""
        arena = scenario_data(scenario)["world"]["arena"]
        return f"{_fmt(arena['width_m'])} x {_fmt(arena['height_m'])} m"
    except (ConfigError, OSError, KeyError, TypeError, ValueError):
        return ""


def _panel_title(letter: str, scenario: str, rows: Sequence[dict]) -> str:
    robots = _mode(r.get("robots") for r in rows)
    duration = _mode(r.get("duration_s") for r in rows)
    parts = [p for p in (f"{robots} robots" if robots is not None else "", _arena_text(scenario),
                         f"{_fmt(duration)} s" if duration is not None else "") if p]
    return f"({letter}) {scenario}: " + ", ".join(parts)


def _style_boxplot(ax, data, positions, widths, fills, labels=None):
    kwargs = {"tick_labels": labels} if labels is not None else {}
    bp = ax.boxplot(data, positions=positions, widths=widths, whis=1.5, patch_artist=True,
                    medianprops={"color": "black", "linewidth": 2.0},
                    boxprops={"edgecolor": "black", "linewidth": 1.0},
                    whiskerprops={"color": "black", "linewidth": 1.0},
                    capprops={"color": "black", "linewidth": 1.0},
                    flierprops={"marker": "o", "markerfacecolor": "none",
                                "markeredgecolor": "black", "markersize": 4},
                    manage_ticks=labels is not None, **kwargs)
    for patch, fill in zip(bp["boxes"], fills):
        patch.set_facecolor(fill)
    return bp


def _grid(n: int) -> tuple[int, int]:
    if n == 4:
        return 2, 2
    cols = min(n, 3)
    return math.ceil(n / cols), cols


def _new_figure(nrows: int, ncols: int, width: float, height: float):
    from matplotlib.figure import Figure

    fig = Figure(figsize=(max(width * ncols, 6.4), height * nrows), layout="constrained")
    axes = fig.subplots(nrows, ncols, squeeze=False)
    return fig, [ax for row in axes for ax in row]


def _save(fig, path: Path) -> None:
    fig.savefig(path, dpi=110, metadata={"Software": None})


def _n_text(ns: Iterable[int]) -> str:
    ns = sorted(set(ns))
    if not ns:
        return "no replications"
    return f"n = {ns[0]} per box" if len(ns) == 1 else f"n = {ns[0]}-{ns[-1]} per box"


def _strategy_figure(table: _Table, rows: Sequence[dict], kind: str, path: Path,
                     paper: str | None) -> str:
    """Boxes per variant, one panel per scenario (000 fig. 13, 14, 16; 001 fig. 6a, 7)."""
    from matplotlib.ticker import MaxNLocator

    metric, scale, ylabel = _METRICS[kind]
    scenarios = _scenarios(rows)
    fig, axes = _new_figure(*_grid(len(scenarios)), 4.6, 3.8)
    ns = []
    for i, scen in enumerate(scenarios):
        ax = axes[i]
        srows = [r for r in rows if r.get("scenario") == scen]
        variants = table.strategy_variants(srows)
        data, fills, labels, notes = [], [], [], []
        for v in variants:
            s = summarize(table.select(scen, v, srows, best=False), metric)
            data.append(np.asarray(s.values, float) * scale)
            fills.append(_fill(v))
            labels.append(v.label("\n"))
            notes.append(s.censored)
            ns.append(s.n)
        _style_boxplot(ax, data, list(range(1, len(data) + 1)), 0.6, fills, labels)
        ax.tick_params(axis="x", labelsize=7.5)
        ax.set_xlabel("strategy")
        ax.set_ylabel(ylabel if kind != "round_trips" else
                      f"round trips in {_fmt(_mode(r.get('duration_s') for r in srows))} s")
        ax.set_title(_panel_title("abcdefgh"[i % 8], scen, srows), fontsize=9.5)
        if kind == "recruitment":
            duration = _mode(r.get("duration_s") for r in srows)
            if duration is not None and any(notes):
                ax.axhline(duration, color="0.4", linestyle=":", linewidth=1)
                for x, k, d in zip(range(1, len(data) + 1), notes, data):
                    if k:
                        ax.annotate(f"{k}/{len(d)}\nnot reached", (x, duration),
                                    textcoords="offset points", xytext=(0, 3), ha="center",
                                    va="bottom", fontsize=7)
                ax.set_ylim(top=duration * 1.18)
        if kind == "on_path":
            ax.set_ylim(0, 100)
        if kind == "round_trips":
            ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.grid(axis="y", color="0.9")
        ax.set_axisbelow(True)
    for ax in axes[len(scenarios):]:
        ax.set_visible(False)
    ref = _FIGURE_PAPER[kind].get(paper or "", "")
    fig.suptitle(f"{_FIGURE_TITLES[kind]}\n({_n_text(ns)}"
                 + (f"; cf. seed {ref}" if ref and ref != "—" else "") + ")", fontsize=11)
    _save(fig, path)
    return _n_text(ns)


def _beta_figure(table: _Table, rows: Sequence[dict], path: Path, paper: str | None) -> str:
    """Boxes per β for each Fermi variant, one panel per scenario (000 fig. 15)."""
    from matplotlib.lines import Line2D
    from matplotlib.patches import Patch
    from matplotlib.ticker import MaxNLocator

    scenarios = [s for s in _scenarios(rows) if _fermi_bases(table, rows, s)]
    fig, axes = _new_figure(len(scenarios), 1, 9.0, 3.6)
    ns = []
    shades = ["white", "0.6", "0.85", "0.35"]
    for i, scen in enumerate(scenarios):
        ax = axes[i]
        srows = [r for r in rows if r.get("scenario") == scen]
        bases = _fermi_bases(table, rows, scen)
        betas = sorted({table.variant(r).beta for r in srows if table.variant(r).base in bases})
        k = len(bases)
        width = 0.8 / k
        handles = []
        for j, base in enumerate(bases):
            data, positions = [], []
            for x, beta in enumerate(betas):
                s = summarize(table.select(scen, Variant(base.strategy, beta, base.extras), srows,
                                           best=False), "round_trips_total")
                if s.n:
                    data.append(np.asarray(s.values, float))
                    positions.append(x + (j - (k - 1) / 2) * width)
                    ns.append(s.n)
            shade = shades[j % len(shades)]
            _style_boxplot(ax, data, positions, width * 0.85, [shade] * len(data))
            handles.append(Patch(facecolor=shade, edgecolor="black", label=base.label()))
        # The SGIKF of the same kind as a reference (the paper compares against it).
        for kf, style in (("SSGIKF", "--"), ("DSGIKF", ":")):
            ref = summarize(table.select(scen, kf, srows), "round_trips_total")
            if ref.median is not None:
                ax.axhline(ref.median, color="0.3", linestyle=style, linewidth=1)
                handles.append(Line2D([], [], color="0.3", linestyle=style,
                                      label=f"{kf} median"))
        ax.set_xticks(range(len(betas)), [_fmt_beta(b) for b in betas])
        ax.yaxis.set_major_locator(MaxNLocator(integer=True))
        ax.set_xlim(-0.6, len(betas) - 0.4)
        ax.set_xlabel("β (Fermi function parameter)")
        ax.set_ylabel(f"round trips in {_fmt(_mode(r.get('duration_s') for r in srows))} s")
        ax.set_title(_panel_title("abcdefgh"[i % 8], scen, srows), fontsize=9.5)
        ax.legend(handles=handles, fontsize=7.5, loc="best", frameon=False)
        ax.grid(axis="y", color="0.9")
        ax.set_axisbelow(True)
    ref = _FIGURE_PAPER["beta_sweep"].get(paper or "", "")
    fig.suptitle(f"{_FIGURE_TITLES['beta_sweep']}\n({_n_text(ns)}"
                 + (f"; cf. seed {ref}" if ref and ref != "—" else "") + ")", fontsize=11)
    _save(fig, path)
    return _n_text(ns)


def _fermi_bases(table: _Table, rows: Sequence[dict], scenario: str) -> list[Variant]:
    bases: dict[Variant, set] = defaultdict(set)
    for r in rows:
        if r.get("scenario") == scenario:
            v = table.variant(r)
            if v.beta is not None:
                bases[v.base].add(v.beta)
    return sorted((b for b, bs in bases.items() if len(bs) >= 2), key=Variant.sort_key)


def _sweep_figure(table: _Table, rows: Sequence[dict], scenario: str, path: Path) -> str:
    """Median and interquartile band vs number of robots, per variant (001 fig. 6b, 8)."""
    fig, axes = _new_figure(1, 2, 5.2, 3.8)
    by_variant: dict[Variant, list] = defaultdict(list)
    for r in rows:
        by_variant[table.variant(r)].append(r)
    markers = ["o", "s", "^", "D", "v", "P"]
    ns = []
    for ax, (metric, ylabel) in zip(axes, (
            ("recruitment_time_s", "time until every robot visited both areas (s)"),
            ("round_trips_total",
             f"round trips in {_fmt(_mode(r.get('duration_s') for r in rows))} s"))):
        for j, v in enumerate(sorted(by_variant, key=Variant.sort_key)):
            per_n: dict[int, list] = defaultdict(list)
            for r in by_variant[v]:
                per_n[r.get("robots")].append(r)
            xs = sorted(n for n in per_n if n is not None)
            stats = [summarize(per_n[n], metric) for n in xs]
            keep = [(x, s) for x, s in zip(xs, stats) if s.median is not None]
            if not keep:
                continue
            ns += [s.n for _, s in keep]
            x = [k for k, _ in keep]
            color = "black" if not v.communicates else ("0.45" if not v.special else "0.65")
            ax.fill_between(x, [s.q1 for _, s in keep], [s.q3 for _, s in keep], color=color,
                            alpha=0.18, linewidth=0)
            ax.plot(x, [s.median for _, s in keep], color=color, marker=markers[j % len(markers)],
                    markerfacecolor="white" if v.communicates else "black", markersize=4.5,
                    linewidth=1.3, label=v.label())
        ax.set_xlabel("number of robots")
        ax.set_ylabel(ylabel)
        ax.grid(color="0.92")
        ax.legend(fontsize=8, frameon=False)
    duration = _mode(r.get("duration_s") for r in rows)
    if duration is not None:
        axes[0].axhline(duration, color="0.4", linestyle=":", linewidth=1,
                        label="end of run (not reached)")
        axes[0].legend(fontsize=8, frameon=False)
    axes[0].set_title("(a) time to locate both areas", fontsize=9.5)
    axes[1].set_title("(b) round trips", fontsize=9.5)
    arena = _arena_text(scenario)
    fig.suptitle(f"{scenario}{' (' + arena + ')' if arena else ''}: median and interquartile band "
                 f"vs swarm size\n({_n_text(ns).replace('per box', 'per point')}; cf. seed 001 "
                 "fig. 6b, 8)", fontsize=10.5)
    _save(fig, path)
    return _n_text(ns).replace("per box", "per point")


def swept_parameters(table: _Table, rows: Sequence[dict]) -> list[str]:
    """Grid columns other than strategy, β and robots that take three or more numeric values in
    ``rows``: each gets a line figure (e.g. ``world.odometry.slip_fraction``)."""
    out = []
    for column in table._extra_columns:
        values = {r.get(column) for r in rows}
        if len(values) >= 3 and all(isinstance(v, (int, float)) and not isinstance(v, bool)
                                    for v in values):
            out.append(column)
    return out


def _parameter_figure(table: _Table, rows: Sequence[dict], column: str, path: Path) -> str:
    """Median and interquartile band of round trips and of robots on the path vs ``column``, one
    line per strategy (and β), one row of panels per scenario."""
    scenarios = _scenarios(rows)
    fig, axes = _new_figure(len(scenarios), 2, 5.2, 3.6)
    axes = np.asarray(axes).reshape(len(scenarios), 2)
    markers = ["o", "s", "^", "D", "v", "P"]
    short = column.rsplit(".", 1)[-1]
    ns = []
    for i, scen in enumerate(scenarios):
        lines: dict[Variant, list] = defaultdict(list)
        for r in rows:
            if r.get("scenario") == scen:
                v = table.variant(r)
                lines[Variant(v.strategy, v.beta, tuple(e for e in v.extras if e[0] != column))].append(r)
        for ax, (metric, scale, ylabel) in zip(axes[i], (
                ("round_trips_total", 1.0, "round trips (all robots)"),
                ("on_path_fraction_mean", 100.0, "robots on the path, 2nd half (%)"))):
            for j, v in enumerate(sorted(lines, key=Variant.sort_key)):
                per_x: dict[float, list] = defaultdict(list)
                for r in lines[v]:
                    per_x[r.get(column)].append(r)
                keep = [(x, summarize(per_x[x], metric)) for x in sorted(per_x)]
                keep = [(x, st) for x, st in keep if st.median is not None]
                if not keep:
                    continue
                ns += [st.n for _, st in keep]
                x = [k for k, _ in keep]
                color = "black" if not v.communicates else "0.45"
                ax.fill_between(x, [st.q1 * scale for _, st in keep], [st.q3 * scale for _, st in keep],
                                color=color, alpha=0.15, linewidth=0)
                ax.plot(x, [st.median * scale for _, st in keep], color=color,
                        marker=markers[j % len(markers)], markersize=4.5, linewidth=1.3,
                        markerfacecolor="white" if v.communicates else "black", label=v.label())
            ax.set_xlabel(short)
            ax.set_ylabel(ylabel)
            ax.grid(color="0.92")
            ax.legend(fontsize=8, frameon=False)
            ax.set_title(f"{scen}: {ylabel.split(' (')[0]}", fontsize=9.5)
    fig.suptitle(f"Median and interquartile band vs {short}\n"
                 f"({_n_text(ns).replace('per box', 'per point')})", fontsize=10.5)
    _save(fig, path)
    return _n_text(ns).replace("per box", "per point")


@dataclass(frozen=True)
class FigureStatus:
    """One figure of the report: drawn (its file, and the papers' panels it lacks) or not (why)."""

    kind: str
    experiment: str
    file: str | None
    note: str
    paper_ref: str
    missing_panels: tuple[str, ...] = ()


def _slug(text: str) -> str:
    return re.sub(r"[^A-Za-z0-9._-]+", "-", str(text)).strip("-") or "results"


def _draw_figures(table: _Table, out_dir: Path) -> list[FigureStatus]:
    """Draw every figure the rows can fill, per experiment. Figures the papers have but the rows
    cannot fill come back with ``file=None`` and the reason; figures of the papers' setups the
    rows lack panels for name those setups."""
    statuses: list[FigureStatus] = []
    experiments = sorted({str(r.get("experiment")) for r in table.rows})
    for exp in experiments:
        comp = [r for r in table.comparison if str(r.get("experiment")) == exp]
        sweep = [r for r in table.sweep if str(r.get("experiment")) == exp]
        papers = {_paper_of(s) for s in _scenarios(comp + sweep)} - {None}
        paper = next(iter(papers)) if len(papers) == 1 else None
        prefix = _slug(exp)
        setups = {s for p in papers for s in _PAPER_SCENARIOS[p]}

        def status(kind: str, file: str | None, note: str, drawn: Sequence[str] = (),
                   papers: set = papers, setups: set = setups, exp: str = exp) -> None:
            refs = sorted({_FIGURE_PAPER[kind][p] for p in papers} - {"—"})
            if file is None and papers and not refs:
                return  # not a figure of the papers of this experiment: nothing is missing
            missing = tuple(sorted(setups - set(drawn))) if file else ()
            if missing:
                note += f"; no panel for {', '.join(missing)} (no rows)"
            statuses.append(FigureStatus(kind, exp, file, note, "; ".join(refs) or "—", missing))

        scenarios = _scenarios(comp)
        for kind in ("recruitment", "round_trips", "on_path"):
            if not scenarios:
                status(kind, None, "not drawn: no rows at a fixed swarm size")
            elif kind == "on_path" and all(r.get("on_path_fraction_mean") is None for r in comp):
                status(kind, None, "not drawn: no on-path fraction in the rows")
            else:
                name = f"{prefix}_{kind}.png"
                n = _strategy_figure(table, comp, kind, out_dir / name, paper)
                status(kind, name, f"{', '.join(scenarios)}; {n}", scenarios)
        beta_scenarios = [s for s in scenarios if _fermi_bases(table, comp, s)]
        if beta_scenarios:
            name = f"{prefix}_beta_sweep.png"
            n = _beta_figure(table, comp, out_dir / name, paper)
            status("beta_sweep", name, f"{', '.join(beta_scenarios)}; {n}", beta_scenarios)
        else:
            status("beta_sweep", None, "not drawn: no SSGIFF/DSGIFF rows with two or more β "
                   "values")
        sweep_scenarios = _scenarios(sweep)
        for scen in sweep_scenarios:
            name = f"{prefix}_robots_sweep_{_slug(scen)}.png"
            n = _sweep_figure(table, [r for r in sweep if r.get("scenario") == scen], scen,
                              out_dir / name)
            statuses.append(FigureStatus("robots_sweep", exp, name, f"{scen}; {n}; a run that "
                                         "never completed recruitment counts at its duration",
                                         "001 fig. 6b, 8" if "001" in papers else "—"))
        if not sweep_scenarios:
            status("robots_sweep", None, "not drawn: no group varies the number of robots")
        for column in swept_parameters(table, comp):
            name = f"{prefix}_{_slug(column.rsplit('.', 1)[-1])}_sweep.png"
            n = _parameter_figure(table, comp, column, out_dir / name)
            statuses.append(FigureStatus("parameter_sweep", exp, name, f"{column}; {n}", "—"))
    return statuses


# -- the page ---------------------------------------------------------------------------------


def _md(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")


def _setting_table(table: _Table) -> list[str]:
    groups: dict[tuple, list] = defaultdict(list)
    for r in table.rows:
        groups[(str(r.get("experiment")), str(r.get("group")), str(r.get("setting")))].append(r)

    known = [s for ss in _PAPER_SCENARIOS.values() for s in ss]

    def order(item):
        (exp, group, _), rs = item
        scenario = str(rs[0].get("scenario"))
        rank = known.index(scenario) if scenario in known else len(known)
        return (exp, rank, scenario, group, table.variant(rs[0]).sort_key(),
                rs[0].get("robots") or 0)

    lines = [("| experiment | group | setting | scenario | variant | robots | n | round trips "
             "median [Q1-Q3] | recruitment time s median [Q1-Q3] | on path % median [Q1-Q3] |"),
             "|---|---|---|---|---|---:|---:|---|---|---|"]
    for (exp, group, setting), rs in sorted(groups.items(), key=order):
        r = rs[0]
        lines.append("| " + " | ".join(_md(x) for x in (
            exp, group, setting, r.get("scenario"), table.variant(r).label(), r.get("robots"),
            len(rs), _fmt_summary(summarize(rs, "round_trips_total")),
            _fmt_summary(summarize(rs, "recruitment_time_s")),
            _fmt_summary(summarize(rs, "on_path_fraction_mean"), 100.0, 2))) + " |")
    return lines


def build_report(rows: Sequence[dict], out_dir: str | Path, *, title: str, command: str,
                 seeds_note: str, reasons: dict[str, str] | None = None,
                 page_name: str = "README.md", results_name: str | None = None,
                 fixed: dict[tuple[str, str], dict[str, object]] | None = None) -> Path:
    """Write the figures (PNG) and the markdown page into ``out_dir``; return the page's path.

    ``rows`` as :func:`load_results` returns them. ``command`` is stated on the page as the way to
    regenerate it, ``seeds_note`` as the seeds (see :func:`describe_seeds`). ``reasons`` maps a
    claim id (or the bare id of :data:`paper_figures`, for all its rows) to the likely reason of a
    difference; the default is "not analysed yet". Only figures the rows can fill are drawn; the
    page lists the others and why. ``fixed`` maps (experiment, group) to the values the group
    fixes without a column in the results (see :func:`fixed_values_from_spec`); by default they
    are read from the shipped spec named like each experiment, if there is one.
    """
    rows = list(rows)
    if not rows:
        raise ValueError("no result rows: nothing to report")
    unknown = unknown_claim_ids(reasons or {})
    if unknown:
        raise ValueError(f"reasons for unknown claim id(s) {', '.join(unknown)} (known: "
                         f"{', '.join(paper_figures)}, optionally followed by /qualifier)")
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    table = _Table(rows, _fixed_values_of_shipped_specs(rows) if fixed is None else fixed)
    statuses = _draw_figures(table, out_dir)
    comparisons = compare_with_papers(table, reasons)

    experiments = sorted({str(r.get("experiment")) for r in rows})
    groups = sorted({str(r.get("group")) for r in rows})
    settings = {(str(r.get("experiment")), str(r.get("group")), str(r.get("setting")))
                for r in rows}
    lines = [f"# {title}", ""]
    lines.append(
        f"{len(rows)} runs: {len(settings)} settings of "
        f"experiment{'s' if len(experiments) > 1 else ''} "
        f"{', '.join(experiments)} (groups {', '.join(groups)}), scenarios "
        f"{', '.join(_scenarios(rows))}"
        + (f", from `{results_name}`" if results_name else "") + ". "
        "Values are medians over replications with the interquartile range in brackets; "
        "ratios are ratios of medians.")
    lines += ["", "## Regenerate", "", "```sh", command.strip(), "```", "", f"Seeds: {seeds_note}.",
              ""]

    lines += ["## Comparison with the papers", ""]
    if not comparisons:
        lines += [("None of the papers' setups (ES1-ES3 of seed 000, the SO arenas of seed 001) is "
                  "in these results: nothing to compare."), ""]
    else:
        lines += [
            ("Our value is measured from the runs above; the paper's is as published. Claim ids "
            "key the likely reasons (`reasons` of `build_report`, `--reasons` of "
            "`swarmloc report`)."), ""]
        present = set(_scenarios(rows))
        for paper in ("000", "001"):
            if not present & set(_PAPER_SCENARIOS[paper]):
                lines += [(f"Seed {paper}: none of {', '.join(_PAPER_SCENARIOS[paper])} in these "
                          "results; its claims are not compared."), ""]
        measured = [c for c in comparisons if c.measured]
        if measured:
            lines += ["| claim | source | paper | ours | difference | likely reason |",
                      "|---|---|---|---|---|---|"]
            for c in measured:
                lines.append("| " + " | ".join(_md(x) for x in (
                    f"{c.claim} `{c.id}`", f"{c.paper} {c.section}, {c.figure}", c.paper_value,
                    c.ours, c.difference, c.reason)) + " |")
            lines += [""]
        lines += [f"{len(measured)} of {len(comparisons)} comparisons measured.", ""]
        unmeasured = [c for c in comparisons if not c.measured]
        if unmeasured:
            lines += ["Not measured from these rows:", ""]
            lines += [f"- `{c.id}` {c.claim} ({c.paper} {c.section}, {c.figure}; paper: "
                      f"{c.paper_value}): not measured, {c.difference}." for c in unmeasured]
            lines += [""]

    lines += ["## Figures", "",
              ("Box plots as in seed 000 fig. 13: box from the first to the third quartile, bar at "
              "the median, whiskers to the farthest point within 1.5 interquartile ranges, "
              "outliers "
              "as circles. SSGIFF and DSGIFF appear at their best β (the most median round trips "
              "in that scenario) except in the β sweep. A replication in which some robot never "
              "visited both areas is counted at the run's duration (dotted line), a lower bound. "
              "Seed 000 fig. 16 plots the robots on the path over time; we show the mean fraction "
              "over the second half of each run."), "",
              "| figure | experiment | cf. paper | file | content |", "|---|---|---|---|---|"]
    for s in statuses:
        lines.append("| " + " | ".join(_md(x) for x in (
            _FIGURE_TITLES[s.kind], s.experiment, s.paper_ref,
            f"[{s.file}]({s.file})" if s.file else "—", s.note)) + " |")
    missing = [s for s in statuses if s.file is None]
    partial = [s for s in statuses if s.missing_panels]
    lines += [""]
    if missing or partial:
        lines += ["Missing from this report:", ""]
        lines += [f"- {_FIGURE_TITLES[s.kind]} ({s.paper_ref}), experiment {s.experiment}: "
                  f"{s.note}." for s in missing]
        lines += [f"- {_FIGURE_TITLES[s.kind]} ({s.paper_ref}), experiment {s.experiment}: no "
                  f"panel for {', '.join(s.missing_panels)} (no rows)." for s in partial]
        lines += [""]
    else:
        lines += ["Every figure of the papers' simulation results listed above is drawn.", ""]
    for s in statuses:
        if s.file:
            lines += [f"### {_FIGURE_TITLES[s.kind]} ({s.experiment})", "",
                      f"![{_FIGURE_TITLES[s.kind]}]({s.file})", "", f"{s.note}.", ""]

    lines += ["## Per setting", ""] + _setting_table(table) + [""]
    lines += [("Strategy names: NC = no communication (seed 001: no imitation); SSGIKF/DSGIKF = "
               "single/double social odometry with the induced Kalman gain, confidence = distance "
               "travelled; SSIKF/DSIKF = the same gain with the odometry covariance as confidence "
               "(seed 001: covariance knowledge); SSGIFF/DSGIFF = with the Fermi gain of "
               "parameter β (seed 001: local imitation). A variant in [brackets] is labelled with "
               "its group: two groups gave rows the results cannot otherwise tell apart."), ""]
    page = out_dir / page_name
    page.write_text("\n".join(lines))
    return page


# -- command line -----------------------------------------------------------------------------


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``swarmloc report RESULTS.csv [--out DIR] [--title ...]``."""
    p = subparsers.add_parser(
        "report", help="figures and a markdown page from experiment results",
        description="Box plots (PNG) and a markdown page from a results CSV of `swarmloc "
                    "experiment`, with our medians next to the papers' published numbers.")
    p.add_argument("results", metavar="RESULTS.csv", help="results file of `swarmloc experiment`")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="folder for the page and the figures (default: docs/<experiment>/)")
    p.add_argument("--title", default=None, help="title of the page")
    p.add_argument("--page", default="README.md", help="file name of the page (default README.md)")
    p.add_argument("--reasons", default=None, metavar="FILE",
                   help="TOML or JSON table: claim id = likely reason of the difference")
    p.add_argument("--spec", default=None, metavar="SPEC",
                   help="the experiment spec the results come from (shipped name or .toml), to "
                        "recover the values its groups fix (default: the shipped spec named like "
                        "the experiment)")
    p.add_argument("--regen-command", default=None, metavar="TEXT",
                   help="the command(s) the page states to regenerate it (default: this "
                        "report command); e.g. the experiment command and this one")
    p.set_defaults(func=main_report)
    return p


def _load_reasons(path: str) -> dict[str, str]:
    p = Path(path)
    try:
        text = p.read_text()
        if p.suffix == ".json":
            data = json.loads(text)
        else:
            import tomllib

            data = tomllib.loads(text)
    except OSError as exc:
        raise ConfigError(f"{p}: cannot read the reasons file: {exc.strerror or exc}") from None
    except ValueError as exc:
        raise ConfigError(f"{p}: not a reasons table: {exc}") from None
    if isinstance(data, dict) and isinstance(data.get("reasons"), dict):
        data = data["reasons"]
    if not isinstance(data, dict) or not all(isinstance(v, str) for v in data.values()):
        raise ConfigError(f"{p}: a reasons file maps claim ids to text (id = \"reason\")")
    unknown = unknown_claim_ids(data)
    if unknown:
        raise ConfigError(f"{p}: unknown claim id(s) {', '.join(sorted(unknown))} (known: "
                          f"{', '.join(paper_figures)}, optionally followed by /qualifier)")
    return dict(data)


def main_report(args) -> int:
    """``swarmloc report``: a missing or malformed results file raises ConfigError (exit 2)."""
    path = Path(args.results)
    if not path.is_file():
        raise ConfigError(f"{path}: no such results file (write one with `swarmloc experiment "
                          "SPEC`)")
    try:
        rows = load_results(path)
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    except OSError as exc:
        raise ConfigError(f"{path}: cannot read the results file: {exc.strerror or exc}") from None
    if not rows:
        raise ConfigError(f"{path}: the results file has a header but no rows")
    reasons = _load_reasons(args.reasons) if args.reasons else {}
    fixed = fixed_values_from_spec(args.spec) if args.spec else None
    experiments = sorted({str(r.get("experiment")) for r in rows})
    out = Path(args.out) if args.out else Path("docs") / _slug("-".join(experiments))
    title = args.title or (f"Experiment {', '.join(experiments)}: our results next to the "
                           "papers'")
    command = args.regen_command
    if not command:
        argv = ["swarmloc", "report", str(path), "--out", str(out)]
        if args.title:
            argv += ["--title", args.title]
        if args.page != "README.md":
            argv += ["--page", args.page]
        if args.reasons:
            argv += ["--reasons", args.reasons]
        if args.spec:
            argv += ["--spec", args.spec]
        command = shlex.join(argv)
    page = build_report(rows, out, title=title, command=command, seeds_note=describe_seeds(rows),
                        reasons=reasons, page_name=args.page, results_name=str(path), fixed=fixed)
    figures = sorted(out.glob("*.png"))
    print(f"wrote {page} ({len(rows)} runs, {len(figures)} figures in {out})")
    return 0


def main(argv: list[str] | None = None) -> int:
    """``python -m swarmloc.deploy.lab.epuck.report RESULTS.csv ...``, with the CLI's exit codes."""
    parser = argparse.ArgumentParser(prog="swarmloc")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(["report", *(sys.argv[1:] if argv is None else argv)])
    try:
        return args.func(args)
    except ConfigError as exc:
        print(f"swarmloc: error: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
