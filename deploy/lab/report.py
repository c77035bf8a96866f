"""The report engine: what every experiment report of the lab is made of, whatever the family.

A report puts our measured values next to a paper's published ones. This module holds the parts
that know no robot family: a published claim (:class:`PaperFigure`) and one row of the comparison
table (:class:`Comparison`, with the reason looked up by claim id, :data:`DEFAULT_REASON` when
none is given); the small statistics (:func:`summarize`: median and quartiles over replications,
a Mann-Whitney p-value, seed ranges in words); number formatting; the box-plot style of the
papers' figures on Agg-rendered :class:`matplotlib.figure.Figure` objects (no pyplot, no global
state); and the page's figure list and markdown escaping. The e-puck report
(:mod:`swarmloc.deploy.lab.epuck.report`) is built from them.
"""

from __future__ import annotations

import math
import re
from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

# -- the papers' claims -----------------------------------------------------------------------


@dataclass(frozen=True)
class PaperFigure:
    """One published number or finding, with where it comes from."""

    paper: str  # seed id: "000" (social odometry, journal) or "001" (imitation dynamics)
    section: str
    figure: str
    claim: str
    value: str  # as the paper states it
    number: float | tuple[float, float] | None = None  # for the arithmetic, when there is one
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


def _mode(values: Iterable) -> object:
    counted = Counter(v for v in values if v is not None)
    return counted.most_common(1)[0][0] if counted else None


# -- comparison rows --------------------------------------------------------------------------


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


def _reason_for(claim_id: str, reasons: dict[str, str]) -> str:
    key = claim_id
    while key:
        if key in reasons:
            return reasons[key]
        if "/" not in key.split("/", 1)[-1]:
            break
        key = key.rsplit("/", 1)[0]
    return DEFAULT_REASON


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


# -- the page ---------------------------------------------------------------------------------


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


def _md(text: object) -> str:
    return str(text).replace("|", "\\|").replace("\n", " ")
