"""The comparison page of any spec's results (deploy/lab/generic_report.py, issue 48): a user's
own laser spec gets a table of every setting's metrics read from its rows, box plots, and a
Regenerate section that runs as written (spec, plugins)."""

from __future__ import annotations

import re
import textwrap

import pandas as pd

import swarmloc
from swarmloc.deploy.cli import main as cli
from swarmloc.deploy.lab.generic_report import metric_columns
from swarmloc.deploy.lab.report import results_family


def test_a_users_laser_spec_gets_a_comparison_page_from_its_rows(tmp_path, capsys):
    spec = tmp_path / "mine.toml"
    spec.write_text(textwrap.dedent("""
        name = "mine"
        family = "laser"
        replications = 2
        [[group]]
        name = "g"
        scenarios = ["laser-collab-three-rooms"]
        [group.grid]
        "algorithm.name" = ["cfsga", "ssga"]
        [group.set]
        "world.steps" = 20
    """))
    rows = tmp_path / "mine.csv"
    df = swarmloc.experiment(spec, out=rows, workers=1, progress=False)
    assert results_family([rows]) == "laser"
    # the family's page by default, which points at the generic one for a spec of one's own
    assert cli(["report", str(rows), "--out", str(tmp_path / "laser-page")]) == 0
    assert "--family generic" in capsys.readouterr().err
    out = tmp_path / "page"
    assert cli(["report", str(rows), "--out", str(out), "--spec", str(spec), "--family", "generic"]) == 0
    assert "generic report" in capsys.readouterr().out
    page = (out / "README.md").read_text()
    # one table row per setting, each metric's median as the rows give it
    metrics = metric_columns(df)
    assert "final_error_m" in metrics and "cpu_s" in metrics
    for setting, group in df.groupby("setting"):
        line = next(x for x in page.splitlines() if x.startswith(f"| {setting} |"))
        cells = [c.strip() for c in line.strip("|").split("|")]
        assert cells[1] == str(len(group))
        median = float(re.match(r"([-\d.e+]+) \[", cells[2 + metrics.index("final_error_m")]).group(1))
        assert abs(median - group["final_error_m"].median()) <= 0.005 * abs(median) + 1e-9
    assert (out / "comparison.png").stat().st_size > 1000
    regen = page.split("## Regenerate")[1]
    assert f"swarmloc experiment {spec} --out {rows}" in regen and "--family generic" in regen


def test_a_shipped_specs_results_keep_their_familys_template(tmp_path):
    rows = tmp_path / "r.csv"
    pd.DataFrame({"experiment": ["laser-table3"], "group": ["g"], "setting": ["s"]}).to_csv(rows, index=False)
    assert results_family([rows]) == "laser"
