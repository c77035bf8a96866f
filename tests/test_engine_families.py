"""One experiment engine for every family (issue 16): vision, laser and MRCLAM replay specs run
through ``swarmloc experiment`` (spec checks, plan, pool, resume, tidy rows) and their reports
through ``swarmloc report``; the rows equal direct runs of each family's runner for the same seeds.

Expected values come from the runners called directly (``run_vision``, ``run_replay`` +
``score``, ``run_laser``), never from the engine under test.
"""

from __future__ import annotations

import csv
import dataclasses
import json
import math
import textwrap

import numpy as np
import pytest
from grid_helpers import read_rows

from swarmloc.config import ConfigError
from swarmloc.deploy.cli import main as cli_main
from swarmloc.deploy.lab.experiment import (
    FAMILIES,
    family,
    list_specs,
    load_spec,
    plan,
    run_experiment,
    shipped_specs,
    with_overrides,
)
from swarmloc.deploy.lab.report import results_family, template, template_names
from swarmloc.families import FAMILIES as ROBOT_FAMILIES
from swarmloc.registry import Registry


def write_spec(tmp_path, text: str, name: str = "spec.toml"):
    path = tmp_path / name
    path.write_text(textwrap.dedent(text))
    return path


# ---------------------------------------------------------------------------------------------
# The family table
# ---------------------------------------------------------------------------------------------


def test_one_registry_holds_each_familys_experiment_hooks_and_report():
    # Issue 48: one Family definition; the engine's and the reports' families are its entries
    assert FAMILIES is ROBOT_FAMILIES and isinstance(FAMILIES, Registry)
    assert set(FAMILIES.names()) >= {"foraging", "laser", "vision", "replay"}
    assert template_names() == [*FAMILIES.names(), "generic"]
    for name in FAMILIES:
        hooks = family(name)
        for hook in ("settings", "run_job", "columns", "row"):
            assert callable(getattr(hooks, hook)), (name, hook)
        assert template(name).family == name
    # the e-puck family's former experiment name still works, and names the same entry
    assert FAMILIES.get("epuck") is FAMILIES.get("foraging") and "epuck" not in FAMILIES.names()
    assert FAMILIES.canonical("epuck") == "foraging" and family("epuck") is family("foraging")
    with pytest.raises(ValueError, match="already registered"):
        FAMILIES.register("vision", FAMILIES.get("vision"))


def test_a_family_without_experiment_hooks_or_frames_is_refused_by_name(tmp_path):
    from swarmloc.deploy.observe.frames import frame_source
    from swarmloc.families import Family

    FAMILIES.register("bare", dataclasses.replace(FAMILIES.get("laser"), experiment=None, report=None, frames=None))
    try:
        with pytest.raises(ValueError, match="family 'bare' has no experiment hooks"):
            family("bare")
        path = write_spec(tmp_path, 'name = "x"\nfamily = "bare"\n[[group]]\nname = "g"\nscenarios = ["a"]\n')
        with pytest.raises(ConfigError, match=r"family: expected one of foraging, laser, vision, replay"):
            load_spec(path)
        assert template("bare") is template("generic")  # its rows get the generic page
        with pytest.raises(ValueError, match="family 'bare' has no frame source"):
            frame_source(type("Served", (), {"family": "bare"})())
        assert isinstance(FAMILIES.get("bare"), Family)
    finally:
        FAMILIES.unregister("bare")


def test_unknown_family_names_the_known_ones(tmp_path):
    path = write_spec(tmp_path, 'name = "x"\nfamily = "visoin"\n[[group]]\nname = "g"\n'
                                'scenarios = ["vision-exp1"]\n')
    with pytest.raises(ConfigError, match=r"family: expected one of foraging, laser, vision, replay"):
        load_spec(path)


def test_list_shows_every_shipped_spec_of_every_family(capsys):
    listed = {name: (family, jobs) for name, family, jobs, _ in list_specs()}
    assert set(listed) == set(shipped_specs())
    assert {f for f, _ in listed.values()} == {"foraging", "laser", "vision", "replay"}
    assert listed["vision"] == ("vision", 3 * 2 * 30 + 2 * 3 * 3 * 30 + 3 * 2 * 30 + 4 * 30)
    # global: 4 algorithms x alone/coop x 40 seeds; deterministic: 3 x 2; kidnap: 4 x 2 x 3
    # seeds; stochastic: 3 x 2 x 3 seeds; reference: 2 x 2 x 2 calibrations; each camera on
    # its own readings: the hybrid cooperative from an unknown start (40 seeds), the
    # cooperative EKF and hybrid from the known start.
    assert listed["mrclam6"] == ("replay", 4 * 2 * 40 + 3 * 2 + 4 * 2 * 3 + 3 * 2 * 3
                                 + 2 * 2 * 2 + 40 + 2)
    assert cli_main(["experiment", "--list"]) == 0
    out = capsys.readouterr().out
    for name in shipped_specs():
        assert name in out
    assert "mrclam6" in out and "replay" in out and "vision" in out


def test_retired_verbs_name_the_new_command(capsys):
    assert cli_main(["vision-experiment", "all", "--runs", "30", "--both"]) == 2
    assert "swarmloc experiment vision" in capsys.readouterr().err
    assert cli_main(["laser-experiment"]) == 2
    assert "swarmloc experiment laser-table3" in capsys.readouterr().err
    assert cli_main(["mrclam", "/nowhere", "--all"]) == 2
    assert "swarmloc experiment mrclam6" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# Bad spec values name the problem
# ---------------------------------------------------------------------------------------------

VISION_GROUP = """
name = "bad"
family = "vision"
replications = 1
[[group]]
name = "g"
scenarios = ["vision-exp1"]
"""

BAD = {
    "group replications": (VISION_GROUP + "replications = 0\n",
                           r"replications: must be >= 1, got 0"),
    "vision key": (VISION_GROUP + '[group.set]\n"agent.sharring" = true\n',
                   r"group 'g', setting 'g/vision-exp1'.*sharring"),
    "vision seed": (VISION_GROUP + '[group.set]\n"world.seed" = 3\n', r"world\.seed"),
    "replay seed key": (('name = "bad"\nfamily = "replay"\n[[group]]\nname = "g"\n'
                         'scenarios = ["mrclam6"]\n[group.set]\nseed = 3\n'),
                        r"group 'g' key 'seed': seeds come from the spec's 'seed'"),
    "replay algorithm": (('name = "bad"\nfamily = "replay"\n[[group]]\nname = "g"\n'
                          'scenarios = ["mrclam6"]\n[group.grid]\nalgorithm = ["ekf", "ekff"]\n'),
                         r"setting 'g/mrclam6/algorithm=ekff'.*unknown algorithm 'ekff'; did you mean 'ekf'.*--plugin"),
    "replay scenario of another family": (
        'name = "bad"\nfamily = "replay"\n[[group]]\nname = "g"\nscenarios = ["ES1"]\n',
        r"scenario 'ES1' is a foraging scenario, not a replay scenario"),
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_spec_values_are_refused_before_anything_runs(tmp_path, case):
    text, message = BAD[case]
    out = tmp_path / "results.csv"
    with pytest.raises(ConfigError, match=message):
        run_experiment(load_spec(write_spec(tmp_path, text)), out, workers=1, progress=False)
    assert not out.exists()


def test_missing_data_set_folder_is_named(tmp_path):
    spec = with_overrides(load_spec("mrclam6"), fixed=[f"dataset={tmp_path / 'nowhere'}"])
    with pytest.raises(ConfigError, match=r"MRCLAM data set folder '.*nowhere' does not exist.*"
                                          r"--set dataset=PATH"):
        plan(spec)
    assert cli_main(["experiment", "mrclam6", "--dry-run", "--set",
                     f"dataset={tmp_path / 'nowhere'}"]) == 2


def test_set_may_not_fix_a_grid_key():
    with pytest.raises(ConfigError, match=r"--set algorithm: group 'deterministic' varies it"):
        with_overrides(load_spec("mrclam6"), fixed=["algorithm=ekf"])


# ---------------------------------------------------------------------------------------------
# Vision through the engine
# ---------------------------------------------------------------------------------------------

VISION_TINY = """\
name = "vision-tiny"
family = "vision"
replications = 2
seed = 4

[[group]]
name = "main"
scenarios = ["vision-exp1"]
[group.grid]
"agent.sharing" = [true, false]

[[group]]
name = "jitter"
description = "jittered start headings"
scenarios = ["vision-exp2"]
replications = 1
duration_s = 1.0
[group.set]
"setup.heading_jitter_rad" = 0.15
"""


def test_vision_spec_runs_resumes_and_equals_direct_runs(tmp_path, capsys):
    from swarmloc.deploy.lab.vision.runner import load_vision_scenario, run_vision

    spec = load_spec(write_spec(tmp_path, VISION_TINY))
    out = tmp_path / "vision.csv"
    assert run_experiment(spec, out, workers=1, progress=False, limit=2) == 2
    assert run_experiment(spec, out, workers=2, progress=False) == 3  # resumed: the other 3
    assert run_experiment(spec, out, workers=1, progress=False) == 0
    rows = read_rows(out)
    assert sorted((r["setting"], r["seed"]) for r in rows) == [
        ("jitter/vision-exp2", "4"),
        ("main/vision-exp1/agent.sharing=false", "4"), ("main/vision-exp1/agent.sharing=false", "5"),
        ("main/vision-exp1/agent.sharing=true", "4"), ("main/vision-exp1/agent.sharing=true", "5")]
    for r in rows:
        overrides = ["setup.heading_jitter_rad=0.15", "setup.duration_s=1.0"] if (
            r["group"] == "jitter") else []
        direct, _ = run_vision(load_vision_scenario(r["scenario"], overrides), int(r["seed"]),
                               None if r["group"] == "jitter" else r["sharing"] == "True")
        for key, value in direct.items():
            if key in ("experiment", "cpu_s"):
                continue
            assert r[key] == ("" if value is None else str(value)), (r["setting"], key)
    # Seed 004 §IV-A in miniature (seed 4): without sharing the robots collide, with it not.
    main = [r for r in rows if r["group"] == "main" and r["seed"] == "4"]
    on = next(r for r in main if r["sharing"] == "True")
    off = next(r for r in main if r["sharing"] == "False")
    assert on["collisions"] == "0" and on["all_reached"] == "True"
    assert int(off["collisions"]) >= 1
    # The report: vision template chosen from the columns (the spec is not shipped).
    assert results_family([out]) == "vision"
    report = tmp_path / "report"
    assert cli_main(["report", str(out), "--out", str(report), "--spec",
                     str(tmp_path / "spec.toml"), "--detection-n", "0"]) == 0
    page = (report / "README.md").read_text()
    assert "| vision-exp1 | collisions without sharing |" in page
    assert "jittered start headings:" in page and "Group `jitter` of the spec" in page
    assert "swarmloc experiment vision-tiny" in page
    assert len(read_rows(report / "results.csv")) == 5  # every group's runs
    for name in ("vision_trajectories.png", "vision_summary.png"):
        assert (report / name).stat().st_size > 0


# ---------------------------------------------------------------------------------------------
# MRCLAM replay through the engine (a synthetic data set in the published format)
# ---------------------------------------------------------------------------------------------


@pytest.fixture()
def synthetic_folder(tmp_path):
    from swarmloc.world.replay.mrclam import SyntheticConfig, synthesize, write_dataset

    data = synthesize(SyntheticConfig(n_robots=3, n_landmarks=8, duration_s=20.0),
                      np.random.default_rng(11))
    return write_dataset(data, tmp_path / "Synthetic")


REPLAY_TINY = """\
name = "replay-tiny"
family = "replay"
replications = 2
seed = 0

[[group]]
name = "ekf"
scenarios = ["mrclam6"]
replications = 1
duration_s = 6.0
[group.grid]
algorithm = ["ekf"]
cooperative = [false, true]

[[group]]
name = "pf"
scenarios = ["mrclam6"]
duration_s = 6.0
[group.set]
algorithm = "pf"
"""


def test_replay_spec_runs_resumes_and_equals_direct_runs(tmp_path, synthetic_folder):
    from swarmloc.deploy.lab.replay.mrclam import (
        ReplayConfig,
        consistency,
        run_replay,
        score,
        trajectory_errors,
    )
    from swarmloc.world.replay.mrclam import load_dataset

    spec = with_overrides(load_spec(write_spec(tmp_path, REPLAY_TINY)),
                          fixed=[f'dataset="{synthetic_folder}"'])
    out = tmp_path / "replay.csv"
    assert run_experiment(spec, out, workers=1, progress=False, limit=1) == 1
    assert run_experiment(spec, out, workers=2, progress=False) == 3
    assert run_experiment(spec, out, workers=1, progress=False) == 0
    rows = read_rows(out)
    assert len(rows) == 4 * 3  # a row per job and robot
    with open(out, newline="") as handle:
        header = next(csv.reader(handle))
    assert len(header) == len(set(header))  # grid keys with a lead column are not repeated
    dataset = load_dataset(synthetic_folder)
    for (algorithm, cooperative, seed) in {(r["algorithm"], r["cooperative"], r["seed"])
                                           for r in rows}:
        config = ReplayConfig(algorithm=algorithm, cooperative=cooperative == "True",
                              seed=int(seed), duration_s=6.0)
        result = run_replay(dataset, config)
        expected = score(result)
        consistent, trajectories = consistency(result), trajectory_errors(result)
        for r in rows:
            if (r["algorithm"], r["cooperative"], r["seed"]) != (algorithm, cooperative, seed):
                continue
            rid = int(r["robot"])
            for key in ("position_rmse_m", "heading_rmse_rad", "final_error_m", "scored_ticks"):
                assert float(r[key]) == expected[rid][key], (r["setting"], key)
            # issue 46's columns: NEES of position and heading, NIS, evo's APE/RPE
            for key in ("position_nees_mean", "heading_nees_mean", "heading_nees_in_95"):
                assert float(r[key]) == pytest.approx(consistent[rid][key], nan_ok=True), key
            assert float(r["ape_rmse_m"]) == pytest.approx(trajectories[rid]["ape_rmse_m"])
            # the EKF tallies its NIS, the particle filter has none (NaN, not 0)
            assert math.isnan(float(r["landmark_nis_mean"])) == (algorithm == "pf"), r["landmark_nis_mean"]
            if algorithm == "ekf":
                assert 0.0 < float(r["heading_nees_mean"]) < 100.0
    # The report: replay template from the columns; its tables and one plot per configuration.
    assert results_family([out]) == "replay"
    report = tmp_path / "report"
    assert cli_main(["report", str(out), "--out", str(report), "--spec",
                     str(tmp_path / "spec.toml"), "--set", f'dataset="{synthetic_folder}"']) == 0
    table = (report / "results.md").read_text()
    assert "| ekf |" in table and "| ekf+coop |" in table and "| pf (2 seeds) |" in table
    assert sorted(p.name for p in report.glob("trajectories_*.png")) == [
        "trajectories_ekf.png", "trajectories_ekf_coop.png", "trajectories_pf.png"]
    # NEES and covariance trace over time, for the localizers that give a covariance
    assert sorted(p.name for p in report.glob("consistency_*.png")) == [
        "consistency_ekf.png", "consistency_ekf_coop.png"]
    assert "Heading NEES mean" in table and "Landmark NIS mean" in table and "APE RMSE [m]" in table
    assert len(read_rows(report / "results.csv")) == 12


# ---------------------------------------------------------------------------------------------
# Laser through the engine's pool (the in-process hooks are tested in test_laser_batch.py)
# ---------------------------------------------------------------------------------------------


def test_laser_spec_runs_in_the_pool_and_resumes(tmp_path):
    from swarmloc.deploy.lab.laser.runner import load_laser_scenario, run_laser

    spec = load_spec(write_spec(tmp_path, """\
        name = "laser-tiny"
        family = "laser"
        replications = 2
        seed = 3
        [[group]]
        name = "g"
        scenarios = ["laser-kidnap-office"]
        duration_s = 2.0
        [group.set]
        "algorithm.population" = 40
        "world.kidnaps" = []
        "world.robots" = 1
        """))
    out = tmp_path / "laser.csv"
    assert run_experiment(spec, out, workers=1, progress=False, limit=1) == 1
    assert run_experiment(spec, out, workers=1, progress=False) == 1
    rows = read_rows(out)
    assert [r["seed"] for r in sorted(rows, key=lambda r: r["seed"])] == ["3", "4"]
    job = plan(spec)[1]
    direct = run_laser(load_laser_scenario(job.scenario, list(job.overrides)))
    row = next(r for r in rows if r["seed"] == "4")
    assert float(row["final_error_m"]) == round(direct.summary["final_error_m"], 6)
    assert results_family([out]) == "laser"
    report = tmp_path / "report"
    assert cli_main(["report", str(out), "--out", str(report)]) == 0
    page = (report / "README.md").read_text()
    assert "swarmloc experiment laser-tiny --replications 2 --out results/laser-tiny.csv" in page
    assert len(read_rows(report / "results.csv")) == 2


def test_swarmloc_batch_runs_a_scenario_of_any_family_as_its_experiment_job(capsys):
    # Issue 48: `batch` refused laser scenarios while its help listed laser algorithms; it now
    # runs any family with experiment hooks, one job in this process, the row the engine writes.
    from swarmloc.deploy.lab.laser.runner import load_laser_scenario, run_laser

    assert cli_main(["batch", "laser-collab-three-rooms", "--algorithm", "ssga", "--seed", "4",
                     "--set", "world.steps=30", "--json"]) == 0
    row = json.loads(capsys.readouterr().out)
    assert row["algorithm"] == "ssga" and int(row["seed"]) == 4 and int(row["steps"]) == 30
    # the same run as the laser runner's, in this process
    direct = run_laser(load_laser_scenario("laser-collab-three-rooms",
                                           ['algorithm.name="ssga"', "world.seed=4", "world.steps=30"]))
    assert float(row["final_error_m"]) == pytest.approx(direct.summary["final_error_m"], abs=1e-3)
    assert cli_main(["batch", "laser-collab-three-rooms", "--record", "x.mcap"]) == 2
    assert "the batch engine records e-puck runs" in capsys.readouterr().err
