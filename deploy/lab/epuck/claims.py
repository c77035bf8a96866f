"""The e-puck report's comparison with the papers (seeds 000 and 001): claims, variants, table.

:data:`paper_figures` lists the published results of seed 000 (social odometry, figures 13-16)
and seed 001 (imitation dynamics, figures 6-8) by claim id. A box of the report is a
:class:`Variant` (a strategy, its beta, and any grid value that differs from the default); the
rows of ``swarmloc experiment`` grouped by setup and variant form the table the report draws
from, and :func:`compare_with_papers` turns it into one :class:`~swarmloc.deploy.lab.report.Comparison`
per claim the rows can speak to. Values a group fixes in its spec's ``set`` table are read back
from the shipped spec (:func:`fixed_values_from_spec`). The page and the figures are
:mod:`swarmloc.deploy.lab.epuck.report`'s.
"""

from __future__ import annotations

import math
from collections import Counter, defaultdict
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.config import ConfigError
from swarmloc.deploy.lab.report import (
    Comparison,
    PaperFigure,
    Summary,
    _fmt,
    _fmt_p,
    _fmt_ratio,
    _fmt_ratio_short,
    _mann_whitney_p,
    _mode,
    _range_words,
    _ratio,
    _reason_for,
    _relative_words,
    summarize,
)

# -- variants' grid keys ----------------------------------------------------------------------

#: Grid keys that already have a column of their own (or are the x axis of a sweep): never part
#: of a variant's label.
_MAPPED_GRID_KEYS = frozenset({"agent.strategy", "agent.beta", "world.robots", "world.seed",
                               "world.duration_s", "scenario"})
_SLIP_KEY = "world.odometry.slip_fraction"
#: Pseudo grid key naming a row's group, added to a variant only when two groups would otherwise
#: give the same box (their difference is not in the rows).
_GROUP_EXTRA = "group"


# -- the papers' numbers ----------------------------------------------------------------------

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


def _fmt_beta(beta: float | None) -> str:
    if beta is None:
        return "–"
    if beta >= 1 and float(beta).is_integer():
        return str(int(beta))
    mantissa, exponent = f"{beta:.0e}".split("e")
    if float(f"{mantissa}e{exponent}") != beta:
        return f"{beta:g}"
    return f"{mantissa}e{int(exponent)}"


# -- variants: what a box stands for ----------------------------------------------------------


def _is_fermi(strategy: str | None) -> bool:
    from swarmloc.agents.epuck.social_odometry import STRATEGIES

    known = STRATEGIES.get(strategy) if strategy in STRATEGIES else None
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


_NO_VALUE = object()


def _shipped_value(column: str, scenario, variant: str | None = None) -> object:
    """The value of the dotted key ``column`` in the shipped scenario ``scenario`` as it loads
    today (its file, else the code's default), or under the named ``variant``
    (``swarmloc.deploy.scenario.VARIANTS``); ``_NO_VALUE`` if there is no such scenario or key.
    Issue 18's ablation sets every reading in every group, so "the default" of a column is what
    a run without that setting does now (or under ``variant``: results made under earlier
    defaults are read against those), not the most common value among the groups."""
    from swarmloc.deploy.scenario import builtin_names, load_scenario, variant_overrides

    if not isinstance(scenario, str) or scenario not in builtin_names():
        return _NO_VALUE
    node = load_scenario(scenario, variant_overrides(variant)).to_dict()
    for part in column.split("."):
        if not isinstance(node, dict) or part not in node:
            return _NO_VALUE
        node = node[part]
    return node


def _same_value(a, b) -> bool:
    """Equal as settings: lists and tuples alike, ints and floats alike."""
    def norm(v):
        if isinstance(v, (list, tuple)):
            return [norm(x) for x in v]
        if isinstance(v, (int, float)) and not isinstance(v, bool):
            return float(v)
        return v
    return norm(a) == norm(b)


#: Settings of the communication process of an encounter (issue 42): they act only on robots
#: that exchange messages, so an NC row is today's NC whatever they say.
ENCOUNTER_COLUMNS = frozenset({"agent.encounter_messages", "agent.encounter_combine",
                               "agent.encounter_stop", "agent.encounter_window_s"})


def _communicates(strategy: str) -> bool:
    from swarmloc.agents.epuck.social_odometry import STRATEGIES

    return strategy in STRATEGIES and STRATEGIES.get(strategy).communicates


class _Table:
    """The rows with what the figures and claims need: each row's variant, which rows belong to a
    sweep over the number of robots, and the best β of each Fermi variant."""

    def __init__(self, rows: Sequence[dict],
                 fixed: dict[tuple[str, str], dict[str, object]] | None = None,
                 variant: str | None = None):
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
        self._shipped_values: dict[tuple, object] = {}
        self._defaults_variant = variant
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

    def _shipped(self, column: str, scenario) -> object:
        key = (column, scenario)
        if key not in self._shipped_values:
            self._shipped_values[key] = _shipped_value(column, scenario, self._defaults_variant)
        return self._shipped_values[key]

    def _variant(self, row: dict) -> Variant:
        strategy = row.get("strategy") or "?"
        extras = []
        silent = not _communicates(strategy)
        for column, default in self._extra_columns.items():
            value = row.get(column)
            if value is None:
                continue
            if silent and column in ENCOUNTER_COLUMNS:
                continue  # a robot that sends nothing has no encounter: the run is the same
            # A value is the default if the row's shipped scenario has it today (file or code
            # default); for a scenario the report cannot load, the most common value is.
            shipped = self._shipped(column, row.get("scenario"))
            if shipped is not _NO_VALUE:
                if _same_value(value, shipped):
                    continue
            elif default is not None and repr(value) == default:
                continue
            # A list value (a position) as a tuple: a variant is a dictionary key.
            extras.append((column, tuple(value) if isinstance(value, list) else value))
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


# -- comparison with the papers ---------------------------------------------------------------


def unknown_claim_ids(ids: Iterable[str]) -> list[str]:
    """The ids that are neither a claim of :data:`paper_figures` nor one followed by /qualifier."""
    return sorted(k for k in ids
                  if not any(k == base or k.startswith(base + "/") for base in paper_figures))


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
