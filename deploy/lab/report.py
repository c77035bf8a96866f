"""The report engine: what every experiment report of the lab is made of, whatever the family.

A report puts our measured values next to a paper's published ones. This module holds the parts
that know no robot family: a published claim (:class:`PaperFigure`) and one row of the comparison
table (:class:`Comparison`, with the reason looked up by claim id, :data:`DEFAULT_REASON` when
none is given); the small statistics (:func:`summarize`: median and quartiles over replications,
a Mann-Whitney p-value, seed ranges in words); number formatting; the box-plot style of the
papers' figures on Agg-rendered :class:`matplotlib.figure.Figure` objects (no pyplot, no global
state); and the page's figure list and markdown escaping. The e-puck report
(:mod:`swarmloc.deploy.lab.epuck.report`) is built from them.

It is also the report command, ``swarmloc report RESULTS.csv [RESULTS.csv ...] [--out DIR]``:
the results files name their family (the ``experiment`` column's shipped spec, else the columns
its results files always have, else ``--family``), and that family's template
(its ``Family.report``, a :class:`ReportTemplate`) writes the page and the figures: e-puck
``deploy/lab/epuck/report.py``, laser ``deploy/lab/laser/report.py``, vision
``deploy/lab/vision/report.py``, replay ``deploy/lab/replay/report.py``.
"""

from __future__ import annotations

import argparse
import csv
import math
import re
import sys
from collections import Counter, defaultdict
from collections.abc import Callable, Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.config import ConfigError
from swarmloc.registry import resolve

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


# -- the report command: one engine, a template per family ------------------------------------


@dataclass(frozen=True)
class ReportTemplate:
    """How one family's results become a page: ``write(paths, args)`` writes the page and its
    figures (``args``: the options of ``swarmloc report``) and returns the page's path."""

    family: str
    #: Columns every results file of the family has: tell a file's family when its experiment is
    #: no shipped spec.
    columns: frozenset[str]
    write: Callable[[list[Path], argparse.Namespace], Path]


#: Any spec's results, read as they are (a user's own experiment): deploy/lab/generic_report.py.
GENERIC = "generic"
_GENERIC_TEMPLATE = "swarmloc.deploy.lab.generic_report:TEMPLATE"


def template_names() -> list[str]:
    """``--family`` values: every family (``swarmloc.families``) with a report template, then
    :data:`GENERIC`."""
    from swarmloc.families import FAMILIES

    return [name for name, entry in FAMILIES.items() if entry.report is not None] + [GENERIC]


def template(name: str) -> ReportTemplate:
    """The report template of family ``name`` (its ``Family.report``), or the generic page's;
    a family without its own template is reported by the generic page. ValueError if unknown."""
    from swarmloc.families import FAMILIES

    if name == GENERIC:
        return resolve(_GENERIC_TEMPLATE)
    entry = FAMILIES.get(name)
    return resolve(entry.report if entry.report is not None else _GENERIC_TEMPLATE)


#: The family of a file nothing else tells (its template's loader names what is missing).
DEFAULT_FAMILY = "foraging"


def _header_and_experiments(path: Path) -> tuple[list[str], set[str]]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            reader = csv.reader(handle)
            header = [h.strip() for h in next(reader, [])]
            col = header.index("experiment") if "experiment" in header else None
            names = {row[col] for row in reader if col is not None and len(row) > col}
    except (OSError, UnicodeDecodeError, csv.Error):
        return [], set()
    return header, names


def results_family(paths: Sequence[Path], family: str | None = None) -> str:
    """The family whose template reports ``paths``: ``family`` if given, else the family of the
    shipped spec each file's ``experiment`` names, else the template whose columns the file has,
    else :data:`DEFAULT_FAMILY`. Files of two families are a ConfigError."""
    if family is not None:
        if family == GENERIC:
            return family
        from swarmloc.families import FAMILIES

        return FAMILIES.canonical(family)
    from swarmloc.deploy.lab.experiment import load_spec, shipped_specs

    shipped = set(shipped_specs())
    found: dict[str, str] = {}
    for path in paths:
        header, experiments = _header_and_experiments(Path(path))
        families = set()
        for name in sorted(experiments & shipped):
            families.add(load_spec(name).family)
        if not families:
            families = {name for name in template_names()
                        if name != GENERIC and template(name).columns <= set(header)}
        if len(families) > 1:
            raise ConfigError(f"{path}: rows of families {', '.join(sorted(families))}; "
                              f"give --family or one file per family")
        found[str(path)] = next(iter(families), DEFAULT_FAMILY)
    if len(set(found.values())) > 1:
        raise ConfigError("results of several families: "
                          + ", ".join(f"{p} ({f})" for p, f in found.items())
                          + "; report one family at a time")
    return next(iter(found.values()), DEFAULT_FAMILY)


def main_report(args) -> int:
    """``swarmloc report``: a missing or malformed results file raises ConfigError (exit 2)."""
    paths = [Path(p) for p in args.results]
    for path in paths:
        if not path.is_file():
            raise ConfigError(f"{path}: no such results file (write one with `swarmloc experiment "
                              "SPEC`)")
    name = results_family(paths, args.family)
    page = template(name).write(paths, args)
    out = page.parent
    print(f"wrote {page} ({name} report, {len(sorted(out.glob('*.png')))} figures in {out})")
    if name != GENERIC and not _shipped_experiments(paths):
        # A spec of one's own: the family's page compares with the papers' figures, which it
        # may not reproduce; the generic page tables whatever its settings measured.
        print(f"note: no shipped spec made these rows; for the comparison of every setting's "
              f"metrics, read from the rows: swarmloc report {' '.join(map(str, paths))} --family "
              f"{GENERIC} --out DIR", file=sys.stderr)
    return 0


def _shipped_experiments(paths: Sequence[Path]) -> set[str]:
    from swarmloc.deploy.lab.experiment import shipped_specs

    found: set[str] = set()
    for path in paths:
        found |= _header_and_experiments(Path(path))[1]
    return found & set(shipped_specs())


def add_parser(subparsers) -> argparse.ArgumentParser:
    """Register ``swarmloc report RESULTS.csv [RESULTS.csv ...] [--out DIR] ...``."""
    p = subparsers.add_parser(
        "report", help="figures and a markdown page from experiment results",
        description="The page and figures of a family's report from results files of `swarmloc "
                    "experiment`, our values next to the papers'. The family comes from the "
                    "results (or --family).")
    p.add_argument("results", metavar="RESULTS.csv", nargs="+",
                   help="results file(s) of `swarmloc experiment` (one family)")
    p.add_argument("--out", default=None, metavar="DIR",
                   help="folder for the page and the figures (default: the family's, e.g. "
                        "docs/<experiment>/, docs/laser, docs/vision, docs/mrclam)")
    p.add_argument("--family", default=None, metavar="FAMILY",
                   help="the results' family (default: told by the results); 'generic': the "
                        "comparison page of any spec's rows (a spec of one's own)")
    p.add_argument("--title", default=None, help="e-puck: title of the page")
    p.add_argument("--page", default="README.md", help="e-puck: file name of the page")
    p.add_argument("--reasons", default=None, metavar="FILE",
                   help="e-puck: TOML or JSON table: claim id = likely reason of the difference "
                        "(laser: reasons.toml in the report folder)")
    p.add_argument("--spec", default=None, metavar="SPEC",
                   help="the experiment spec the results come from (shipped name or .toml), to "
                        "recover what its groups fix (default: the shipped spec named like the "
                        "experiment)")
    p.add_argument("--variant", default=None, metavar="NAME",
                   help="e-puck: read the results against the defaults of this named variant "
                        "(e.g. v1-defaults for results made under issue 18's first defaults) "
                        "instead of today's")
    p.add_argument("--regen-command", default=None, metavar="TEXT",
                   help="the command(s) the page states to regenerate it (default: the "
                        "experiment and report commands)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="replay: a scenario key for the runs replayed for the figures, e.g. "
                        "--set dataset=PATH (repeatable)")
    p.add_argument("--detection-n", type=int, default=200, metavar="N",
                   help="vision: placements per bin of the detection table (0: no table)")
    p.set_defaults(func=main_report)
    return p


def main(argv: list[str] | None = None) -> int:
    """``python -m swarmloc.deploy.lab.report RESULTS.csv ...``, with the CLI's exit codes."""
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
