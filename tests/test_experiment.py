"""The experiment runner: bad specs refused before anything runs, plan sizes of the shipped specs,
rows equal to direct batch runs for the same seeds, and resuming after an interruption."""

from __future__ import annotations

import argparse
import csv
import re
import textwrap
from pathlib import Path

import numpy as np
import pytest
from grid_helpers import SMALL, read_rows

from swarmloc.config import ConfigError
from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.lab.experiment import (
    add_parser,
    load_spec,
    plan,
    run_experiment,
    shipped_specs,
)
from swarmloc.deploy.scenario import load_scenario

#: The shared smoke spec under its own name, its duration left to each test.
TINY = SMALL.format(name="tiny", replications=2, duration="{duration}")


def write_spec(tmp_path, text: str, name: str = "spec.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


def cli(argv: list[str]) -> int:
    parser = argparse.ArgumentParser(prog="swarmloc")
    add_parser(parser.add_subparsers(dest="command", required=True))
    args = parser.parse_args(argv)
    return args.func(args)


# ---------------------------------------------------------------------------------------------
# Bad specs are refused before any job runs
# ---------------------------------------------------------------------------------------------

GOOD_GROUP = """
[[group]]
name = "g"
scenarios = ["ES1"]
duration_s = 20.0
"""

BAD_SPECS = {
    "unknown top-level key": (
        'name = "bad"\nreplication = 2\n' + GOOD_GROUP + '[group.grid]\n"agent.strategy" = ["NC"]\n',
        r"unknown key 'replication'; did you mean 'replications'\?",
    ),
    "unknown group key": (
        'name = "bad"\n[[group]]\nname = "g"\nscenario = ["ES1"]\n',
        r"unknown key 'group\[0\]\.scenario'; did you mean 'scenarios'\?",
    ),
    "unknown strategy": (
        'name = "bad"\n' + GOOD_GROUP + '[group.grid]\n"agent.strategy" = ["NC", "SSGKIF"]\n',
        (r"group 'g', setting 'g/ES1/agent\.strategy=SSGKIF'.*unknown strategy 'SSGKIF'; "
         r"did you mean 'SSGIKF'\?"),
    ),
    "unknown scenario key": (
        'name = "bad"\n' + GOOD_GROUP + '[group.grid]\n"agent.betta" = [0.1]\n',
        r"unknown key 'agent\.betta'; did you mean 'beta'\?",
    ),
    "impossible value": (
        'name = "bad"\n' + GOOD_GROUP + '[group.set]\n"world.robots" = -1\n',
        r"group 'g', setting 'g/ES1'.*robots: must be in 1\.\.1048576, got -1",
    ),
    "empty grid list": (
        'name = "bad"\n' + GOOD_GROUP + '[group.grid]\n"agent.strategy" = []\n',
        r"grid 'agent\.strategy': empty list",
    ),
    "no replications": (
        'name = "bad"\nreplications = 0\n' + GOOD_GROUP,
        r"replications: must be >= 1, got 0",
    ),
    "unknown scenario": (
        'name = "bad"\n[[group]]\nname = "g"\nscenarios = ["ES9"]\n',
        r"group 'g', setting 'g/ES9': scenario 'ES9': no such file or shipped scenario",
    ),
    "seed set by a group": (
        'name = "bad"\n' + GOOD_GROUP + '[group.set]\n"world.seed" = 3\n',
        r"'world\.seed': seeds come from the spec's 'seed'",
    ),
}


@pytest.mark.parametrize("case", sorted(BAD_SPECS))
def test_bad_spec_refused_before_anything_runs(tmp_path, case):
    text, message = BAD_SPECS[case]
    spec_path = write_spec(tmp_path, text)
    out = tmp_path / "results.csv"
    with pytest.raises(ConfigError, match=message):
        run_experiment(load_spec(spec_path), out, workers=1, progress=False)
    assert not out.exists()
    with pytest.raises(ConfigError, match=message):
        cli(["experiment", str(spec_path), "--out", str(out)])
    assert not out.exists()


def test_unknown_shipped_spec_lists_the_shipped_ones():
    with pytest.raises(ConfigError, match=r"did you mean 'smoke'\?.*shipped: .*social-odometry-000"):
        load_spec("smoek")


# ---------------------------------------------------------------------------------------------
# Plans of the shipped specs
# ---------------------------------------------------------------------------------------------


def test_shipped_specs_load_and_plan():
    assert {"smoke", "social-odometry-000", "social-odometry-001"} <= set(shipped_specs())
    for name in shipped_specs():
        spec = load_spec(name)
        try:
            jobs = plan(spec)
        except ConfigError as exc:
            # The MRCLAM data lives outside the repository (../shared/data). Without it the plan
            # must refuse, naming the missing folder, rather than plan runs that cannot start.
            missing = re.search(r"MRCLAM data set folder '([^']*)' does not exist", str(exc))
            if missing is None or Path(missing.group(1)).is_dir():
                raise
            continue
        assert jobs, name
        assert len({(j.setting, j.seed) for j in jobs}) == len(jobs), name


def test_plan_of_seed_000_reproduction():
    spec = load_spec("social-odometry-000")
    jobs = plan(spec)
    # ES1-ES3 x {NC, SSGIKF, DSGIKF} + ES1-ES3 x {SSGIFF, DSGIFF} x 8 betas, 30 replications.
    assert len(jobs) == 3 * 3 * 30 + 3 * 2 * 8 * 30 == 1710
    settings = {j.setting for j in jobs}
    assert len(settings) == 3 * 3 + 3 * 2 * 8
    assert "no-fermi/ES1/agent.strategy=NC" in settings
    assert "fermi/ES3/agent.strategy=DSGIFF/agent.beta=1e-05" in settings
    assert {j.seed for j in jobs} == set(range(1, 31))
    assert all(j.seed == spec.seed + j.replication for j in jobs)
    assert all(o.startswith("world.seed=") for o in (j.overrides[-1] for j in jobs))


def test_plan_of_seed_001_reproduction():
    jobs = plan(load_spec("social-odometry-001"))
    # 4 arenas x (no imitation + no odometry error + covariance knowledge + global imitation by
    # a central system and by boards + 4 betas) + 8 swarm sizes x 2 strategies.
    assert len(jobs) == (4 * 9 + 8 * 2) * 30
    assert sum(j.setting.startswith("global-imitation/") for j in jobs) == 4 * 30
    assert sum(j.setting.startswith("global-imitation-boards/") for j in jobs) == 4 * 30


def test_dry_run_prints_the_plan_and_writes_nothing(tmp_path, capsys):
    out = tmp_path / "r.csv"
    assert cli(["experiment", "social-odometry-000", "--dry-run", "--out", str(out),
                "--replications", "2"]) == 0
    text = capsys.readouterr().out
    assert "57 settings x 2 replications = 114 jobs" in text
    assert "no-fermi/ES2/agent.strategy=DSGIKF" in text
    assert not out.exists()


# ---------------------------------------------------------------------------------------------
# Running: rows equal direct runs, resume, foreign files refused
# ---------------------------------------------------------------------------------------------

COLUMNS = ["experiment", "group", "setting", "scenario", "strategy", "beta", "robots", "duration_s",
           "seed", "replication", "agent.strategy", "recruitment_time_s", "robots_found_both",
           "round_trips_total", "on_path_fraction_mean", "lost_total", "departures", "departure_error_m_median",
           "wall_s", "config_hash"]


def _optional_float(text: str):
    return None if text == "" else float(text)


def test_rows_equal_direct_batch_runs(tmp_path):
    # 400 s rather than 20 s: by then robots have found areas, made round trips and got lost, so
    # the comparison covers non-zero metrics and both a reached and a missing recruitment time
    # (with issue 18's defaults SSGIKF seed 1 recruits every robot in 221 s, NC none by 400 s).
    spec = load_spec(write_spec(tmp_path, TINY.format(duration=400.0)))
    out = tmp_path / "results.csv"
    assert run_experiment(spec, out, workers=2, progress=False) == 4
    with open(out, newline="") as handle:
        assert next(csv.reader(handle)) == COLUMNS
    rows = read_rows(out)
    assert sorted((r["strategy"], int(r["seed"])) for r in rows) == [
        ("NC", 1), ("NC", 2), ("SSGIKF", 1), ("SSGIKF", 2)]
    for row in rows:
        seed = int(row["seed"])
        assert int(row["replication"]) == seed - 1
        assert row["agent.strategy"] == row["strategy"]
        direct = run_batch(load_scenario("ES1", ["world.duration_s=400.0",
                                                 f'agent.strategy="{row["strategy"]}"',
                                                 f"world.seed={seed}"]))
        m = direct.metrics
        assert _optional_float(row["recruitment_time_s"]) == m["recruitment_time_s"]
        assert int(row["robots_found_both"]) == m["robots_found_both"]
        assert int(row["round_trips_total"]) == m["round_trips_total"]
        assert _optional_float(row["on_path_fraction_mean"]) == m["on_path_fraction_mean"]
        assert int(row["lost_total"]) == int(direct.lost_count.sum())
        assert int(row["departures"]) == direct.departure_error_m.size
        if direct.departure_error_m.size:
            assert float(row["departure_error_m_median"]) == round(float(np.median(direct.departure_error_m)), 4)
        else:
            assert row["departure_error_m_median"] == ""
        assert (row["experiment"], row["group"], row["scenario"], row["robots"],
                float(row["duration_s"])) == ("tiny", "g", "ES1", "10", 400.0)
    # The comparison above is not vacuous.
    assert any(r["recruitment_time_s"] for r in rows) and not all(r["recruitment_time_s"] for r in rows)
    assert sum(int(r["round_trips_total"]) for r in rows) > 0


def test_resume_after_interruption(tmp_path):
    spec = load_spec(write_spec(tmp_path, TINY.format(duration=20.0)))
    out = tmp_path / "results.csv"
    assert run_experiment(spec, out, workers=2, progress=False, limit=1) == 1
    first = out.read_text().splitlines()
    assert len(first) == 2  # header + one row
    # A write cut short by a crash leaves a fragment without a newline: it is dropped and rerun.
    with open(out, "a") as handle:
        handle.write("tiny,g,g/ES1/agent.strate")
    assert run_experiment(spec, out, workers=2, progress=False) == 3
    lines = out.read_text().splitlines()
    assert lines[:2] == first
    rows = read_rows(out)
    assert len(rows) == 4
    assert len({(r["setting"], r["seed"]) for r in rows}) == 4
    assert run_experiment(spec, out, workers=2, progress=False) == 0
    assert out.read_text().splitlines() == lines


def test_foreign_results_file_refused(tmp_path):
    spec = load_spec(write_spec(tmp_path, TINY.format(duration=20.0)))
    out = tmp_path / "results.csv"
    out.write_text("a,b,c\n1,2,3\n")
    with pytest.raises(ConfigError, match="columns are not those of experiment 'tiny'"):
        run_experiment(spec, out, workers=1, progress=False)
    assert out.read_text() == "a,b,c\n1,2,3\n"

    # Same columns, another experiment's rows.
    other = tmp_path / "other.csv"
    other.write_text(",".join(COLUMNS) + "\n" + ",".join(["other"] + [""] * (len(COLUMNS) - 1)) + "\n")
    with pytest.raises(ConfigError, match="a row of experiment 'other', not 'tiny'"):
        run_experiment(spec, other, workers=1, progress=False)

    # Same experiment and setting ids, another configuration (here a shorter duration).
    mine = tmp_path / "mine.csv"
    assert run_experiment(spec, mine, workers=1, progress=False, limit=1) == 1
    before = mine.read_text()
    shorter = load_spec(write_spec(tmp_path, TINY.format(duration=10.0), "shorter.toml"))
    with pytest.raises(ConfigError, match="was run with another configuration"):
        run_experiment(shorter, mine, workers=1, progress=False)
    assert mine.read_text() == before
