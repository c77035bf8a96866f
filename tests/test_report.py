"""The report generator: results CSV in; PNG box plots and a markdown page with the papers'
numbers out.

Synthetic results with known values, so that every number the page must show is computed by hand
here: ES1 round trips NC 10, 12, 14 and SSGIKF 30, 31, 32 give medians 12 and 31, a ratio of
31 / 12 = 2.58 against the paper's 2.5 (000 §6.1.2), 3 % higher.
"""

from __future__ import annotations

import argparse
import csv
from pathlib import Path

import pytest

from swarmloc.config import ConfigError
from swarmloc.deploy.lab import report as engine_report
from swarmloc.deploy.lab.epuck import claims, report
from swarmloc.deploy.lab.epuck.report import add_parser, build_report, load_results

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
GRID = ["agent.strategy", "agent.beta", "world.robots", "world.odometry.slip_fraction"]
COLUMNS = ["experiment", "group", "setting", "scenario", "strategy", "beta", "robots",
           "duration_s", "seed", "replication", *GRID, "recruitment_time_s", "robots_found_both",
           "round_trips_total", "on_path_fraction_mean", "lost_total", "wall_s"]


def _rows(experiment, group, scenario, strategy, beta, robots, duration_s, round_trips,
          recruitment, on_path, grid_robots=False):
    """One row per replication; ``recruitment`` None = some robot never found both areas."""
    setting = f"{scenario}/{strategy}" + (f"/beta={beta:g}" if beta is not None else "") + (
        f"/robots={robots}" if grid_robots else "")
    out = []
    for rep, (rt, rec, op) in enumerate(zip(round_trips, recruitment, on_path)):
        out.append({
            "experiment": experiment, "group": group, "setting": setting, "scenario": scenario,
            "strategy": strategy, "beta": "" if beta is None else beta, "robots": robots,
            "duration_s": duration_s, "seed": rep + 1, "replication": rep,
            "agent.strategy": strategy, "agent.beta": "" if beta is None else beta,
            "world.robots": robots if grid_robots else "", "world.odometry.slip_fraction": "",
            "recruitment_time_s": "" if rec is None else rec,
            "robots_found_both": robots if rec is not None else robots - 1,
            "round_trips_total": rt, "on_path_fraction_mean": op, "lost_total": 0, "wall_s": 0.5,
        })
    return out


def _no_fermi_es1():
    return (_rows("000", "no-fermi", "ES1", "NC", None, 10, 1800.0, [10, 12, 14],
                  [800.0, 1000.0, None], [0.10, 0.10, 0.12])
            + _rows("000", "no-fermi", "ES1", "SSGIKF", None, 10, 1800.0, [30, 31, 32],
                    [200.0, 250.0, 300.0], [0.60, 0.62, 0.64])
            + _rows("000", "no-fermi", "ES1", "DSGIKF", None, 10, 1800.0, [25, 26, 27],
                    [250.0, 250.0, 250.0], [0.55, 0.56, 0.57]))


def _full():
    rows = _no_fermi_es1()
    for strategy, best in (("SSGIFF", [35, 36, 37]), ("DSGIFF", [33, 34, 35])):
        rows += _rows("000", "fermi", "ES1", strategy, 1e-2, 10, 1800.0, best,
                      [250.0] * 3, [0.6] * 3)
        rows += _rows("000", "fermi", "ES1", strategy, 1.0, 10, 1800.0, [20, 21, 22],
                      [250.0] * 3, [0.5] * 3)
    for n in (1, 5, 10):  # seed 001 fig. 6b/8: a sweep over the number of robots
        for strategy, beta in (("NC", None), ("SSGIFF", 1e-2)):
            rows += _rows("001", "robots", "SO-4.0x4.0", strategy, beta, n, 3600.0,
                          [n, n + 1, n + 2], [1000.0, 1100.0, 1200.0], [0.3] * 3,
                          grid_robots=True)
    return rows


def _write(path: Path, rows, columns=COLUMNS) -> Path:
    with path.open("w", newline="") as f:
        writer = csv.DictWriter(f, columns, extrasaction="ignore")
        writer.writeheader()
        writer.writerows(rows)
    return path


def _line(page: str, claim_id: str) -> str:
    lines = [line for line in page.splitlines() if f"`{claim_id}`" in line]
    assert len(lines) == 1, f"expected one table row for {claim_id}, got {lines}"
    return lines[0]


def test_load_results_parses_types(tmp_path):
    rows = load_results(_write(tmp_path / "r.csv", _full()))
    assert len(rows) == 3 * 3 + 4 * 3 + 6 * 3
    nc = rows[0]
    assert nc["strategy"] == "NC" and nc["experiment"] == "000" and nc["setting"] == "ES1/NC"
    assert nc["round_trips_total"] == 10 and isinstance(nc["round_trips_total"], int)
    assert nc["duration_s"] == 1800.0 and nc["beta"] is None and nc["agent.beta"] is None
    assert nc["world.odometry.slip_fraction"] is None
    assert rows[2]["recruitment_time_s"] is None  # empty: never reached
    fermi = next(r for r in rows if r["strategy"] == "SSGIFF")
    assert fermi["beta"] == pytest.approx(1e-2) and fermi["agent.beta"] == pytest.approx(1e-2)
    sweep = next(r for r in rows if r["group"] == "robots")
    assert sweep["world.robots"] == 1


def test_load_results_rejects_files_that_are_not_results(tmp_path):
    columns = [c for c in COLUMNS if c not in ("round_trips_total", "seed")]
    path = _write(tmp_path / "other.csv", _no_fermi_es1(), columns)
    with pytest.raises(ValueError, match="missing column.*seed.*round_trips_total"):
        load_results(path)
    (tmp_path / "empty.csv").write_text("")
    with pytest.raises(ValueError, match="experiment"):
        load_results(tmp_path / "empty.csv")
    bad = _no_fermi_es1()
    bad[1]["round_trips_total"] = "many"
    with pytest.raises(ValueError, match="line 3, column 'round_trips_total'"):
        load_results(_write(tmp_path / "bad.csv", bad))


def test_build_report_figures_and_comparison(tmp_path):
    rows = load_results(_write(tmp_path / "r.csv", _full()))
    out = tmp_path / "docs"
    page_path = build_report(rows, out, title="Synthetic", command="swarmloc report r.csv",
                             seeds_note="seeds 1-3",
                             reasons={"000/retrieval-ratio-ES1": "fewer collisions"})
    assert page_path == out / "README.md"
    for name in ("000_recruitment.png", "000_round_trips.png", "000_on_path.png",
                 "000_beta_sweep.png", "001_robots_sweep_SO-4.0x4.0.png"):
        data = (out / name).read_bytes()
        assert len(data) > 1000 and data[:8] == PNG_SIGNATURE, name
        assert f"]({name})" in page_path.read_text()
    page = page_path.read_text()
    assert "swarmloc report r.csv" in page and "seeds 1-3" in page

    # Retrieval, ES1: medians 31 and 12, ratio 2.58 vs the paper's 2.5 (3 % higher).
    row = _line(page, "000/retrieval-ratio-ES1/SSGIKF")
    assert "2.58x (SSGIKF 31 / NC 12 round trips)" in row
    assert "about 2.5x" in row and "ours 2.58x vs paper 2.5x: 3 % higher" in row
    assert "fewer collisions" in row  # a reason given for the bare id covers its rows
    assert "2.17x (DSGIKF 26 / NC 12" in _line(page, "000/retrieval-ratio-ES1/DSGIKF")
    # Recruitment: NC 800, 1000, never (counted at 1800 s) -> median 1000 s; communication pooled
    # median 250 s -> 4x, the paper's value.
    row = _line(page, "000/recruitment-speedup-ES1")
    assert "4.00x (NC 1000 s / communication 250 s" in row and "the same" in row
    # Best β: 1e-2 gives medians 36 (SSGIFF) and 34 (DSGIFF), β = 1 gives 21.
    row = _line(page, "000/best-beta-ES1/SSGIFF")
    assert "β = 1e-2 (median 36; next β = 1: 21)" in row and "| the same |" in row
    # On the path: NC median 10 %, at most 20 % in the paper.
    assert "| 10 % | agrees: at most 20 % |" in _line(page, "000/on-path-NC/ES1")
    # Single vs double SGIKF: 31 vs 26.
    assert "agrees: single 1.19x double" in _line(page, "000/single-vs-double/ES1/SGIKF")
    # A setup of the paper with no rows is said to be not measured.
    assert "not measured" in _line(page, "000/retrieval-SGIKF-ES2/SSGIKF")
    assert "not analysed yet" in _line(page, "000/on-path-NC/ES1")  # default reason
    # Per-setting table: n, median and IQR of round trips.
    assert "| ES1/NC | ES1 | NC | 10 | 3 | 12 [11-13] | 1000 [900-1400] (1 not reached) |" in page


def test_partial_results_still_give_a_page_naming_what_is_missing(tmp_path, capsys):
    results = _write(tmp_path / "smoke.csv", _no_fermi_es1())
    reasons = tmp_path / "reasons.toml"
    reasons.write_text('"000/retrieval-ratio-ES1/SSGIKF" = "our NC is a better explorer"\n')
    out = tmp_path / "out"
    code = report.main([str(results), "--out", str(out), "--reasons", str(reasons),
                        "--title", "Smoke"])
    assert code == 0
    page = (out / "README.md").read_text()
    assert page.startswith("# Smoke")
    assert sorted(p.name for p in out.glob("*.png")) == [
        "000_on_path.png", "000_recruitment.png", "000_round_trips.png"]
    missing = page.split("Missing from this report:")[1].split("###")[0]
    assert "000 fig. 15" in missing and "not drawn: no SSGIFF/DSGIFF rows" in missing
    assert "no panel for ES2, ES3" in missing
    assert "our NC is a better explorer" in _line(page, "000/retrieval-ratio-ES1/SSGIKF")
    assert "every setting (3) uses run seeds 1-3 (3 replications)" in page
    assert f"swarmloc report {results} --out {out} --title Smoke --reasons {reasons}" in page
    assert "Seed 001: none of" in page  # the other paper's claims are not compared


def test_cli_refuses_missing_and_malformed_results(tmp_path, capsys):
    parser = argparse.ArgumentParser(prog="swarmloc")
    add_parser(parser.add_subparsers(dest="command", required=True))
    missing = tmp_path / "nope.csv"
    args = parser.parse_args(["report", str(missing)])
    assert args.func is engine_report.main_report
    with pytest.raises(ConfigError, match="nope.csv: no such results file"):
        args.func(args)
    assert report.main([str(missing)]) == 2
    assert "nope.csv: no such results file" in capsys.readouterr().err
    other = tmp_path / "other.csv"
    other.write_text("a,b\n1,2\n")
    assert report.main([str(other)]) == 2
    assert "missing column(s) experiment, group" in capsys.readouterr().err
    results = _write(tmp_path / "r.csv", _no_fermi_es1())
    typo = tmp_path / "reasons.toml"
    typo.write_text('"000/retrieval-ratio-ES9" = "typo"\n')
    assert report.main([str(results), "--out", str(tmp_path / "out"), "--reasons", str(typo)]) == 2
    assert "unknown claim id(s) 000/retrieval-ratio-ES9" in capsys.readouterr().err
    assert not (tmp_path / "out").exists() and not (tmp_path / "docs").exists()


def test_values_a_group_fixes_tell_no_odometry_error_from_local_imitation(tmp_path):
    # Seed 001 spec layout: slip_fraction = 0 is a group's fixed value, not a column, so the
    # no-odometry-error rows look like local imitation at beta 1e-2 unless the spec says otherwise.
    def arena(group, strategy, beta, round_trips):
        return _rows("so-001", group, "SO-4.0x4.0", strategy, beta, 30, 3600.0, round_trips,
                     [900.0] * 3, [0.5] * 3)

    rows = load_results(_write(tmp_path / "r.csv", (
        arena("no-imitation", "NC", None, [20, 21, 22])
        + arena("covariance-knowledge", "SSIKF", None, [50, 52, 54])
        + arena("local-imitation", "SSGIFF", 1e-3, [40, 41, 42])
        + arena("local-imitation", "SSGIFF", 1e-2, [60, 62, 64])
        + arena("no-odometry-error", "SSGIFF", 1e-2, [90, 91, 92]))))
    fixed = {("so-001", "no-odometry-error"): {"world.odometry.slip_fraction": 0.0}}
    by_id = {c.id: c for c in claims.compare_with_papers(rows, fixed=fixed)}
    ceiling = by_id["001/no-odometry-ceiling/SO-4.0x4.0"]
    assert ceiling.ours.startswith("no odometry error 91; NC 21")
    assert "SSGIFF β=1e-2 62 (η = 0.68)" in ceiling.ours  # 62 / 91; not merged with 91
    assert ceiling.difference == "agrees: no odometry error has the highest median"
    doubles = by_id["001/imitation-doubles/SO-4.0x4.0"].ours
    assert doubles.startswith("2.95x (SSGIFF β=1e-2 62 / NC 21)")  # 62 / 21
    assert by_id["001/covariance-vs-best-beta/SO-4.0x4.0"].ours.startswith("SSIKF 52 vs SSGIFF")

    # Without the spec's values the two groups are still kept apart, labelled by group.
    by_id = {c.id: c for c in claims.compare_with_papers(rows, fixed={})}
    assert not by_id["001/no-odometry-ceiling/SO-4.0x4.0"].measured
    table = claims._Table(rows, {})
    labels = {table.variant(r).label() for r in table.rows}
    assert {"SSGIFF β=1e-2 [no-odometry-error]", "SSGIFF β=1e-2 [local-imitation]", "NC",
            "SSIKF"} <= labels


def test_a_value_is_the_default_when_the_shipped_scenario_has_it_not_when_it_is_most_common(tmp_path):
    # Issue 18's ablation layout: every group fixes the reading, and most groups fix the old value
    # ("both"); the default variant is still the one a run without the setting makes today
    # (AgentConfig.sends = "last-visited"), and an unshipped scenario falls back to the mode.
    def group(name, scenario, round_trips):
        return _rows("abl", name, scenario, "SSGIKF", None, 10, 1800.0, round_trips, [300.0] * 3, [0.5] * 3)

    rows = load_results(_write(tmp_path / "r.csv", (
        group("v0", "ES1", [10, 11, 12]) + group("v0-bis", "ES1", [13, 14, 15])
        + group("text", "ES1", [40, 41, 42]) + group("v0", "ES9", [1, 2, 3])
        + group("text", "ES9", [4, 5, 6]) + group("v0-bis", "ES9", [7, 8, 9]))))
    fixed = {("abl", "v0"): {"agent.sends": "both"}, ("abl", "v0-bis"): {"agent.sends": "both"},
             ("abl", "text"): {"agent.sends": "last-visited"}}
    table = claims._Table(rows, fixed)
    labels = {(r["scenario"], r["group"]): table.variant(r).label() for r in table.rows}
    assert labels[("ES1", "text")] == "SSGIKF"
    assert labels[("ES1", "v0")].startswith("SSGIKF sends=both")
    assert labels[("ES9", "text")] == "SSGIKF sends=last-visited"  # ES9 is not shipped: the mode
    assert labels[("ES9", "v0")].startswith("SSGIKF")
    assert "sends" not in labels[("ES9", "v0")]


def test_results_made_under_earlier_defaults_are_read_against_that_variant(tmp_path):
    # so-000-readings: its all-text group was issue 18's first defaults (give up after twice the
    # distance, p in cm: the variant v1-defaults), today's give up after 4 and count metres.
    def group(name, round_trips):
        return _rows("abl", name, "ES1", "SSGIKF", None, 10, 1800.0, round_trips, [300.0] * 3, [0.5] * 3)

    rows = load_results(_write(tmp_path / "r.csv", group("all-text", [40, 41, 42]) + group("today", [50, 51, 52])))
    fixed = {("abl", "all-text"): {"agent.give_up_factor": 2.0, "agent.confidence_unit_m": 0.01},
             ("abl", "today"): {"agent.give_up_factor": 4.0, "agent.confidence_unit_m": 1.0}}
    today = claims._Table(rows, fixed)
    then = claims._Table(rows, fixed, "v1-defaults")
    label = {(name, r["group"]): table.variant(r).label()
             for name, table in (("today", today), ("then", then)) for r in table.rows}
    assert label[("today", "today")] == "SSGIKF"
    assert label[("today", "all-text")] == "SSGIKF confidence_unit_m=0.01, give_up_factor=2"
    assert label[("then", "all-text")] == "SSGIKF"
    assert label[("then", "today")] == "SSGIKF confidence_unit_m=1, give_up_factor=4"
    # The claims read the box without a label: 41 under v1-defaults, 51 today.
    ours = {name: {c.id: c.ours for c in claims.compare_with_papers(table)}
            for name, table in (("today", today), ("then", then))}
    assert ours["then"]["000/simulation-ES1-SGIKF/SSGIKF"] == "median 41"
    assert ours["today"]["000/simulation-ES1-SGIKF/SSGIKF"] == "median 51"
    with pytest.raises(ValueError, match="variant 'v9': no such variant"):
        build_report(rows, tmp_path / "out", title="t", command="c", seeds_note="s", fixed=fixed,
                     variant="v9")


def test_a_numeric_grid_column_with_three_values_gets_a_line_figure(tmp_path):
    # The ES2 slip sweep's shape: NC and SSGIKF at slips 0.2, 0.1, 0.05; medians by hand.
    rows = []
    for slip, nc_rt, kf_rt in ((0.2, [8, 9, 10], [20, 21, 22]), (0.1, [18, 19, 20], [40, 41, 42]),
                               (0.05, [28, 29, 30], [60, 61, 62])):
        for strategy, rts in (("NC", nc_rt), ("SSGIKF", kf_rt)):
            part = _rows("slip", "ES2", "ES2", strategy, None, 50, 7200.0, rts, [None] * 3,
                         [0.5] * 3)
            for r in part:
                r["world.odometry.slip_fraction"] = slip
                r["setting"] += f"/slip={slip}"
            rows += part
    results = load_results(_write(tmp_path / "slip.csv", rows))
    table = claims._Table(results)
    assert report.swept_parameters(table, results) == ["world.odometry.slip_fraction"]
    # two values only: no sweep
    assert report.swept_parameters(table, [r for r in results
                                           if r["world.odometry.slip_fraction"] != 0.05]) == []
    page = build_report(results, tmp_path / "out", title="slip", command="c", seeds_note="s")
    name = "slip_slip_fraction_sweep.png"
    assert (tmp_path / "out" / name).read_bytes()[:8] == PNG_SIGNATURE
    assert f"]({name})" in page.read_text()
    assert "| ES2/SSGIKF/slip=0.05 | ES2 | SSGIKF slip_fraction=0.05 | 50 | 3 | 61 [60.5-61.5]" in (
        page.read_text())
