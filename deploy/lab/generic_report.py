"""A report for any spec's results: the comparison page of a user's own experiment (issue 48).

The families' templates (``deploy/lab/<family>/report.py``) put the shipped specs' rows next to
the papers' figures; a user's spec (a new localizer against the baselines, a sweep of one's own)
has no paper to meet, and before this page ``swarmloc report`` wrote little more than "Not in
these results: laser-table3, ...". This template reads the rows it is given and nothing else (no
re-run): one table row per setting (experiment, group, setting), with the number of runs and the
median [Q1-Q3] of every metric the rows carry, and box plots of the first metrics, one panel
each, one box per setting. The metrics are the numeric columns that are not the setting's own
(lead columns, grid keys, seeds): each family's rows say what they measure (for e-pucks round
trips and robots on the path, for laser robots settled runs, final errors and settle steps, for
the real-data family each robot's RMSE), and CPU time where the rows have it.

``swarmloc report RESULTS.csv --family generic`` writes it (and ``swarmloc report`` suggests it
when no row comes from a shipped spec: the family templates stay the default, as they were).
Its "Regenerate" section gives the spec (``--spec``, else the shipped spec of that name, else a
placeholder) and the plugins this command loaded (``--plugin``), so that it runs as written.
"""

from __future__ import annotations

import argparse
import os
import shlex
from collections.abc import Sequence
from pathlib import Path

#: Columns that describe a run rather than measure it.
_NOT_METRICS = {"experiment", "group", "setting", "scenario", "seed", "replication", "config_hash",
                "robots", "duration_s", "beta", "family"}
#: Columns that measure the machine, not the algorithm: tabled last, never plotted first.
_COST = ("cpu_s", "wall_s")
#: Box plots drawn (one panel per metric).
MAX_PLOTS = 6


def metric_columns(df, constant: bool = False) -> list[str]:
    """The numeric columns of ``df`` that measure something: neither a description of the run
    nor a grid key (dotted) nor empty; those that vary, or (``constant``) those that do not."""
    import pandas as pd

    out = []
    for col in df.columns:
        if col in _NOT_METRICS or "." in col:
            continue
        values = pd.to_numeric(df[col], errors="coerce")
        if values.notna().sum() == 0:
            continue
        if (values.nunique(dropna=True) <= 1 and col not in _COST) != constant:
            continue
        out.append(col)
    return sorted(out, key=lambda c: (c in _COST, out.index(c)))


def _summary(values) -> str:
    """``median [Q1-Q3]`` of a column's values, formatted as every report formats figures."""
    from swarmloc.deploy.lab.report import _fmt

    v = values.dropna()
    if v.empty:
        return "–"
    q1, med, q3 = (float(x) for x in v.quantile([0.25, 0.5, 0.75]))
    return f"{_fmt(med)} [{_fmt(q1)}-{_fmt(q3)}]"


def _regenerate(paths: Sequence[Path], out_dir: Path, spec: str | None, experiments: list[str]) -> list[str]:
    from swarmloc.deploy.lab.experiment import shipped_specs
    from swarmloc.registry import PLUGINS_ENV

    plugins = [p for p in os.environ.get(PLUGINS_ENV, "").split(os.pathsep) if p]
    plugin_args = "".join(f" --plugin {shlex.quote(p)}" for p in plugins)
    if spec is None:
        spec = experiments[0] if len(experiments) == 1 and experiments[0] in shipped_specs() else "YOUR_SPEC.toml"
    experiment = (f"swarmloc experiment {shlex.quote(spec)} --out {shlex.quote(str(paths[0]))}{plugin_args}"
                  if len(paths) == 1 else f"swarmloc experiment {shlex.quote(spec)}{plugin_args}")
    report = (f"swarmloc report {' '.join(shlex.quote(str(p)) for p in paths)} --out {shlex.quote(str(out_dir))}"
              f" --family generic{plugin_args}")
    return [experiment, report]


def write(paths: list[Path], args: argparse.Namespace) -> Path:
    """The page ``README.md`` (or ``--page``) and its figure in ``--out`` (default
    ``docs/<experiment>``); returns the page's path."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt
    import pandas as pd

    from swarmloc.config import ConfigError

    frames = []
    for path in paths:
        try:
            frames.append(pd.read_csv(path))
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{path}: not a results file ({exc})") from None
    df = pd.concat(frames, ignore_index=True)
    missing = {"experiment", "group", "setting"} - set(df.columns)
    if missing:
        raise ConfigError(f"{paths[0]}: not a results file of `swarmloc experiment` (no column "
                          f"{', '.join(sorted(missing))})")
    experiments = sorted(df["experiment"].astype(str).unique())
    out_dir = Path(args.out) if getattr(args, "out", None) else Path("docs") / experiments[0]
    out_dir.mkdir(parents=True, exist_ok=True)
    metrics = metric_columns(df)
    keys = ["experiment", "group", "setting"]
    settings = df.groupby(keys, sort=False)
    title = getattr(args, "title", None) or f"{', '.join(experiments)}: comparison"
    lines = [f"# {title}", "",
             f"{len(df)} runs of {settings.ngroups} settings, from {', '.join(str(p) for p in paths)}. "
             "Each cell: median [Q1-Q3] over the setting's runs (seeds "
             f"{int(df['seed'].min())}-{int(df['seed'].max())})." if "seed" in df.columns else "", ""]
    header = ["setting", "n", *metrics]
    lines += ["| " + " | ".join(header) + " |", "|" + "---|" * len(header)]
    for (_, _, setting), rows in settings:
        cells = [str(setting), str(len(rows))] + [_summary(pd.to_numeric(rows[m], errors="coerce")) for m in metrics]
        lines.append("| " + " | ".join(cells) + " |")
    same = metric_columns(df, constant=True)
    if same:
        values = {m: pd.to_numeric(df[m], errors="coerce").dropna().iloc[0] for m in same}
        from swarmloc.deploy.lab.report import _fmt

        lines += ["", "The same in every run: " + ", ".join(f"{m} {_fmt(float(v))}" for m, v in values.items()) + "."]
    plotted = [m for m in metrics if m not in _COST][:MAX_PLOTS]
    if plotted:
        names = [str(s) for (_, _, s), _ in settings]
        fig, axes = plt.subplots(len(plotted), 1, figsize=(max(6.0, 0.9 * len(names) + 2), 2.6 * len(plotted)),
                                 squeeze=False)
        for ax, metric in zip(axes[:, 0], plotted, strict=True):
            data = [pd.to_numeric(rows[metric], errors="coerce").dropna().to_numpy() for _, rows in settings]
            ax.boxplot(data, tick_labels=[str(i + 1) for i in range(len(names))])
            ax.set_ylabel(metric)
        axes[-1, 0].set_xlabel("setting (numbered as in the table)")
        fig.tight_layout()
        figure = out_dir / "comparison.png"
        fig.savefig(figure, dpi=90)
        plt.close(fig)
        lines += ["", "![box plots of the metrics, one box per setting](comparison.png)", "",
                  "Settings, by number: " + "; ".join(f"{i + 1} `{n}`" for i, n in enumerate(names))]
    lines += ["", "## Regenerate", "", "```bash", *_regenerate(paths, out_dir, getattr(args, "spec", None),
                                                               experiments), "```", ""]
    page = out_dir / (getattr(args, "page", None) or "README.md")
    page.write_text("\n".join(lines))
    return page


def _template():
    from swarmloc.deploy.lab.report import ReportTemplate

    return ReportTemplate("generic", frozenset({"experiment", "group", "setting"}), write)


TEMPLATE = _template()
