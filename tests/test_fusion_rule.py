"""A social odometry fusion rule of the user's (agents/epuck/fusion.py), run by the compiled
kernels: registered and checked, equal bit for bit to the built-in gain it restates, fused as
computed by hand, refused with a clear message when wrong, and run as processes (the worked
example of docs/extending.md, examples/fusion_rule.py)."""

from __future__ import annotations

import csv
import json
import math
from pathlib import Path

import numpy as np
import pytest
from processes import run_swarmloc
from test_encounter import CROSSINGS, NEST_SENT, _brain, _feed, _points

from swarmloc.agents.epuck.fusion import FUSION_RULES, FusionRule
from swarmloc.agents.epuck.social_odometry import STRATEGIES, Strategy
from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.scenario import load_scenario

EXAMPLE = Path(__file__).resolve().parents[1] / "examples" / "fusion_rule.py"


def kalman_gain(p_own, p_other, beta):  # seed 000 eq. 20, the expressions of the kernel
    total = p_own + p_other
    return p_own / total if total > 0.0 else 0.5


def kalman_confidence(p_own, p_other, g, beta):  # eq. 22
    return (1.0 - g) * p_own


def half_gain(p_own, p_other, beta):
    return 0.5


def min_confidence(p_own, p_other, g, beta):
    return min(p_own, p_other)


@pytest.fixture(scope="module")
def rules():
    """Two rules and their strategies, registered for this module and removed after."""
    made = [FusionRule("test-kalman", kalman_gain, kalman_confidence), FusionRule("test-half", half_gain, min_confidence)]
    strategies = [Strategy("TEST_SK", communicates=True, double=False, gain="test-kalman"),
                  Strategy("TEST_HALF", communicates=True, double=False, gain="test-half")]
    for r in made:
        FUSION_RULES.register(r)
    for s in strategies:
        STRATEGIES.register(s)
    yield
    for s in strategies:
        STRATEGIES.unregister(s.name)
    for r in made:
        FUSION_RULES.unregister(r.name)


def _run(strategy: str, seed: int = 5):
    return run_batch(load_scenario("ES1", [f"agent.strategy={strategy!r}".replace("'", '"'), f"world.seed={seed}",
                                           "world.duration_s=600"]))


def test_a_rule_restating_the_kalman_gain_runs_bit_for_bit_as_sgikf(rules):
    mine, builtin, half = _run("TEST_SK"), _run("SSGIKF"), _run("TEST_HALF")
    assert mine.metrics == builtin.metrics
    np.testing.assert_array_equal(mine.final_pose, builtin.final_pose)
    np.testing.assert_array_equal(mine.pose_estimate, builtin.pose_estimate)
    # the rule is what the kernels call: another rule gives another run
    assert not np.array_equal(half.final_pose, builtin.final_pose)


def test_an_encounter_fuses_with_the_rule_as_computed_by_hand(rules):
    brain = _brain(strategy="TEST_HALF", encounter_messages=1, p_after_fusion="fused")
    _feed(brain, CROSSINGS[:1])
    point = _points(CROSSINGS[:1])[0]
    # g = 0.5, p = min(3, 1): the receiver's nest (1, 0) at p 3 m, the partner's at p 1 m
    np.testing.assert_allclose(brain.goal_xy[0, 0], 0.5 * np.array([1.0, 0.0]) + 0.5 * point, rtol=0, atol=1e-12)
    assert brain.goal_p_m[0, 0] == min(3.0, NEST_SENT[2])


@pytest.mark.parametrize(("gain", "confidence", "message"), [
    (lambda a, b, beta: 1.5, kalman_confidence, r"gain 1.5 outside \[0, 1\] at p_own=0.0"),
    (kalman_gain, lambda a, b, g, beta: a - b, r"confidence -0.001 is not a finite p >= 0 at p_own=0.0, p_other=0.001"),
    (lambda a, b, beta: 0.5 if object() else 0.0, kalman_confidence, r"gain \(.*test_fusion_rule.py:\d+\) does not compile with numba"),
    (kalman_gain, lambda a, b, g, beta: math.sqrt(a - b), r"raised ValueError \(math domain error\)"),
])
def test_a_rule_the_kernels_cannot_run_is_refused_at_registration(gain, confidence, message):
    with pytest.raises(ValueError, match=r"fusion rule 'bad' \(registered at .*test_fusion_rule.py:\d+\): " + message):
        FUSION_RULES.register(FusionRule("bad", gain, confidence))
    assert "bad" not in FUSION_RULES


def test_a_builtin_name_and_an_unknown_gain_are_refused_naming_the_valid_ones():
    with pytest.raises(ValueError, match="'kalman' is a built-in gain"):
        FUSION_RULES.register(FusionRule("kalman", kalman_gain, kalman_confidence))
    with pytest.raises(ValueError, match=r"gain: 'ci' is not one the compiled brain implements .*or a fusion rule "
                                         r"registered before the strategy"):
        STRATEGIES.register(Strategy("MINE_CI", communicates=True, double=False, gain="ci"))


def _batch_json(tmp_path, strategy: str) -> dict:
    done = run_swarmloc(["--plugin", str(EXAMPLE), "batch", "ES1", "--json", "--strategy", strategy, *SETTINGS],
                        cwd=tmp_path, timeout_s=600)
    assert done.returncode == 0, done.stderr[-2000:]
    return json.loads(done.stdout)["metrics"]


#: 6 robots, 200 s: robots meet and fuse (SFCI's run differs from SSGIKF's), in seconds of wall time.
SETTINGS = ["--robots", "6", "--seed", "7", "--duration-s", "200"]


def test_the_example_rule_runs_as_processes_equal_to_the_batch_engine(tmp_path):
    # the plugin is loaded by the child processes only (--plugin), as a user runs it
    done = run_swarmloc(["--plugin", str(EXAMPLE), "run", "ES1", "--strategy", "SFCI", *SETTINGS, "--quiet",
                         "--run", "fci", "--out", str(tmp_path / "runs")], cwd=tmp_path, timeout_s=600)
    assert done.returncode == 0, done.stderr[-2000:]
    result = json.loads((tmp_path / "runs" / "fci" / "results.json").read_text())
    assert result["strategy"] == "SFCI" and result["reason"] == "completed"
    batch = _batch_json(tmp_path, "SFCI")
    assert result["metrics"] == batch
    assert batch != _batch_json(tmp_path, "SSGIKF"), "the rule changed the run: robots met and fused"


@pytest.mark.integration
def test_the_example_rule_runs_in_its_experiment_and_gets_the_report(tmp_path):
    spec = EXAMPLE.with_name("fci-vs-baselines.toml")
    out = tmp_path / "fci.csv"
    done = run_swarmloc(["--plugin", str(EXAMPLE), "experiment", str(spec), "--replications", "2",
                         "--duration-s", "300", "--out", str(out), "--quiet"], cwd=tmp_path, timeout_s=600)
    assert done.returncode == 0, done.stderr[-2000:]
    rows = list(csv.DictReader(out.open()))
    assert sorted({r["agent.strategy"] for r in rows}) == sorted(["SFCI", "DFCI", "SSGIKF", "DSGIKF", "SSGIFF", "NC"])
    assert len(rows) == 12
    report = run_swarmloc(["--plugin", str(EXAMPLE), "report", str(out), "--family", "generic", "--spec", str(spec),
                           "--out", "rep"], cwd=tmp_path, timeout_s=300)
    assert report.returncode == 0, report.stderr[-2000:]
    page = (tmp_path / "rep" / "README.md").read_text()
    assert "agent.strategy=SFCI" in page and f"--plugin {EXAMPLE}" in page
