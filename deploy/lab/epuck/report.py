"""Report: box plots and a markdown page from experiment results, next to the papers' numbers.

``swarmloc report RESULTS.csv`` reads the tidy results of ``swarmloc experiment`` (one row per
setting and replication) and writes, into one folder, PNG figures in the style of seed 000
figures 13-16 and seed 001 figures 6-8, and a markdown page with:

- a comparison table: each published claim (:data:`~swarmloc.deploy.lab.epuck.claims.paper_figures`,
  with the section and figure it comes from, compared in :mod:`~swarmloc.deploy.lab.epuck.claims`), our measured value (medians over replications, ratios of medians), the difference
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

import csv
import json
import math
import shlex
from collections import defaultdict
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from swarmloc.config import ConfigError
from swarmloc.deploy.lab.epuck.claims import (
    _PAPER_PANEL,
    _PAPER_SCENARIOS,
    Variant,
    _fixed_values_of_shipped_specs,
    _fmt_beta,
    _scenarios,
    _Table,
    compare_with_papers,
    fixed_values_from_spec,
    paper_figures,
    unknown_claim_ids,
)
from swarmloc.deploy.lab.report import (  # noqa: F401 (add_parser, main, main_report: the command)
    FigureStatus,
    ReportTemplate,
    _fmt,
    _fmt_summary,
    _grid,
    _md,
    _mode,
    _n_text,
    _new_figure,
    _ratio,
    _save,
    _slug,
    _style_boxplot,
    add_parser,
    describe_seeds,
    main,
    main_report,
    summarize,
)

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
        values = {repr(v) if isinstance(v, list) else v for v in (r.get(column) for r in rows)}
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


def _lost_per_trip(rows: Sequence[dict]) -> list[dict]:
    """Each row's lost events per round trip (no value where either is missing or no trip)."""
    return [{"lost_per_round_trip": _ratio(r.get("lost_total"), r.get("round_trips_total"))} for r in rows]


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

    # Issue 42's diagnostic of retrieval: lost events per round trip and the median error of the
    # target estimate at departure (batch.DepartureErrors); "–" for rows made before it.
    lines = [("| experiment | group | setting | scenario | variant | robots | n | round trips "
             "median [Q1-Q3] | recruitment time s median [Q1-Q3] | on path % median [Q1-Q3] "
             "| lost per round trip median | departure error m median |"),
             "|---|---|---|---|---|---:|---:|---|---|---|---|---|"]
    for (exp, group, setting), rs in sorted(groups.items(), key=order):
        r = rs[0]
        lines.append("| " + " | ".join(_md(x) for x in (
            exp, group, setting, r.get("scenario"), table.variant(r).label(), r.get("robots"),
            len(rs), _fmt_summary(summarize(rs, "round_trips_total")),
            _fmt_summary(summarize(rs, "recruitment_time_s")),
            _fmt_summary(summarize(rs, "on_path_fraction_mean"), 100.0, 2),
            _fmt_summary(summarize(_lost_per_trip(rs), "lost_per_round_trip"), 1.0, 2),
            _fmt_summary(summarize(rs, "departure_error_m_median"), 1.0, 2))) + " |")
    return lines


def build_report(rows: Sequence[dict], out_dir: str | Path, *, title: str, command: str,
                 seeds_note: str, reasons: dict[str, str] | None = None,
                 page_name: str = "README.md", results_name: str | None = None,
                 fixed: dict[tuple[str, str], dict[str, object]] | None = None,
                 variant: str | None = None) -> Path:
    """Write the figures (PNG) and the markdown page into ``out_dir``; return the page's path.

    ``rows`` as :func:`load_results` returns them. ``command`` is stated on the page as the way to
    regenerate it, ``seeds_note`` as the seeds (see :func:`describe_seeds`). ``reasons`` maps a
    claim id (or the bare id of :data:`paper_figures`, for all its rows) to the likely reason of a
    difference; the default is "not analysed yet". Only figures the rows can fill are drawn; the
    page lists the others and why. ``fixed`` maps (experiment, group) to the values the group
    fixes without a column in the results (see :func:`fixed_values_from_spec`); by default they
    are read from the shipped spec named like each experiment, if there is one. ``variant``: read
    the rows against the defaults of that named variant instead of today's (a value equal to the
    default is no box label; the claims compare the boxes without one), for results made under
    earlier defaults (e.g. ``v1-defaults``).
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
    if variant is not None:
        from swarmloc.deploy.scenario import variant_overrides

        try:
            variant_overrides(variant)
        except ConfigError as exc:
            raise ValueError(str(exc)) from None
    table = _Table(rows, _fixed_values_of_shipped_specs(rows) if fixed is None else fixed, variant)
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


def write_from_args(paths: list[Path], args) -> Path:
    """The e-puck template of ``swarmloc report``: ConfigError for a malformed results file."""
    rows = []
    for path in paths:
        try:
            rows += load_results(path)
        except ValueError as exc:
            raise ConfigError(str(exc)) from None
        except OSError as exc:
            raise ConfigError(f"{path}: cannot read the results file: {exc.strerror or exc}") from None
    if not rows:
        raise ConfigError(f"{', '.join(map(str, paths))}: the results file has a header but no rows")
    reasons = _load_reasons(args.reasons) if args.reasons else {}
    fixed = fixed_values_from_spec(args.spec) if args.spec else None
    experiments = sorted({str(r.get("experiment")) for r in rows})
    out = Path(args.out) if args.out else Path("docs") / _slug("-".join(experiments))
    title = args.title or (f"Experiment {', '.join(experiments)}: our results next to the "
                           "papers'")
    variant = getattr(args, "variant", None)  # absent from a Namespace built by hand
    command = args.regen_command
    if not command:
        argv = ["swarmloc", "report", *map(str, paths), "--out", str(out)]
        if args.title:
            argv += ["--title", args.title]
        if args.page != "README.md":
            argv += ["--page", args.page]
        if args.reasons:
            argv += ["--reasons", args.reasons]
        if args.spec:
            argv += ["--spec", args.spec]
        if variant:
            argv += ["--variant", variant]
        command = shlex.join(argv)
    return build_report(rows, out, title=title, command=command, seeds_note=describe_seeds(rows),
                        reasons=reasons, page_name=args.page,
                        results_name=", ".join(map(str, paths)), fixed=fixed, variant=variant)


#: This family's template of ``swarmloc report`` (named by its ``Family.report``, ``swarmloc.families``).
TEMPLATE = ReportTemplate("foraging", frozenset(REQUIRED_COLUMNS), write_from_args)
