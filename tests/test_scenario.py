"""Scenarios, strict configuration loading, the CLI's refusals, and batch-run determinism.

Shipped values come from seed 000 table 2 (ES1-ES3) and seed 001 §4.1 (SO-*), written out here.
"""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.config import ConfigError, apply_overrides, from_dict, parse_value
from swarmloc.deploy.cli import main
from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.scenario import (
    VARIANTS,
    Scenario,
    builtin_names,
    load_scenario,
    variant_overrides,
)
from swarmloc.world.epuck.foraging import WorldConfig

SO_NAMES = ["SO-3.0x3.0", "SO-3.5x3.5", "SO-4.0x4.0", "SO-4.5x4.5"]


# ---------------------------------------------------------------------------------------------
# Shipped scenarios
# ---------------------------------------------------------------------------------------------


def test_shipped_scenario_names():
    assert builtin_names() == sorted(["ES1", "ES2", "ES3", "ES3-tiled"] + SO_NAMES)


@pytest.mark.parametrize("name", ["ES1", "ES2", "ES3", "ES3-tiled"] + SO_NAMES)
def test_every_shipped_scenario_loads(name):
    s = load_scenario(name)
    assert isinstance(s, Scenario)
    assert s.name == name
    assert s.description


# Seed 000 table 2: area (m), initial radius (m), nest/prey radius (m), robots, duration (s).
TABLE_2 = {
    "ES1": ((1.2, 1.7), 0.2, 0.1, 10, 1800.0),
    "ES2": ((3.0, 4.25), 0.5, 0.1, 50, 7200.0),
    "ES3": ((6.0, 8.5), 0.5, 0.1, 100, 7200.0),
}


@pytest.mark.parametrize("name", sorted(TABLE_2))
def test_es_scenarios_match_table_2_of_seed_000(name):
    (width_m, height_m), initial_m, area_radius_m, robots, duration_s = TABLE_2[name]
    w = load_scenario(name).world
    assert (w.arena.width_m, w.arena.height_m) == (width_m, height_m)
    assert w.arena.initial_radius_m == initial_m
    assert w.arena.nest_radius_m == area_radius_m
    assert w.arena.prey_radius_m == area_radius_m
    assert w.robots == robots
    assert w.duration_s == duration_s
    assert w.medium.range_m == 0.15  # seed 000 §6.1: 15 cm range-and-bearing
    assert w.tick_s == 0.1  # 10 Hz controller clock (seed 000 §5)


@pytest.mark.parametrize("name", SO_NAMES)
def test_so_scenarios_match_seed_001(name):
    s = load_scenario(name)
    side_m = float(name.split("-")[1].split("x")[0])
    assert (s.world.arena.width_m, s.world.arena.height_m) == (side_m, side_m)
    assert s.world.robots == 30
    assert s.world.duration_s == 3600.0
    assert s.world.medium.range_m == 0.25


def test_areas_lie_inside_their_arena_for_every_shipped_scenario():
    for name in builtin_names():
        a = load_scenario(name).world.arena
        for (cx, cy), r in ((a.nest_centre_m, a.nest_radius_m), (a.prey_centre_m, a.prey_radius_m)):
            assert r <= cx <= a.width_m - r
            assert r <= cy <= a.height_m - r


# ---------------------------------------------------------------------------------------------
# Strict loading: unknown keys, wrong types, impossible values
# ---------------------------------------------------------------------------------------------


def test_unknown_key_names_the_path_and_suggests_the_closest():
    with pytest.raises(ConfigError) as err:
        load_scenario("ES1", ["world.robts=3"])
    msg = str(err.value)
    assert "world.robts" in msg
    assert "'robots'" in msg


def test_unknown_nested_key_names_the_full_path():
    with pytest.raises(ConfigError) as err:
        load_scenario("ES1", ["world.medium.rnage_m=0.2"])
    assert "world.medium.rnage_m" in str(err.value)
    assert "'range_m'" in str(err.value)


def test_unknown_top_level_section():
    with pytest.raises(ConfigError, match="'wrold'"):
        load_scenario("ES1", ["wrold.robots=3"])


@pytest.mark.parametrize("override", ['world.robots="ten"', "world.robots=ten"])
def test_wrong_type_names_the_field(override):
    with pytest.raises(ConfigError, match=r"world\.robots"):
        load_scenario("ES1", [override])


@pytest.mark.parametrize(
    "override, path",
    [
        ("world.duration_s=true", r"world\.duration_s"),  # a bool is not a number
        ("world.robots=3.5", r"world\.robots"),  # a float is not an int
        ("agent.strategy=5", r"agent\.strategy"),
        ("world.arena.nest_centre_m=[0.5]", r"world\.arena\.nest_centre_m"),
        ("world.medium=3", r"world\.medium"),
    ],
)
def test_more_wrong_types_name_the_field(override, path):
    with pytest.raises(ConfigError, match=path):
        load_scenario("ES1", [override])


@pytest.mark.parametrize(
    "override, field",
    [
        ("world.duration_s=-1.0", "duration_s"),
        ("world.odometry.slip_fraction=1.5", "slip_fraction"),
        ("world.odometry.substeps=0", "substeps"),
        ("agent.p_after_fusion='prior'", "p_after_fusion"),
        ("agent.sends='nest'", "sends"),
        ("world.arena.nest_centre_m=[5.0, 0.255]", "nest"),
        ("world.robots=1000", "robots"),  # 1000 e-pucks cover 3.85 m^2 of a 2.04 m^2 arena
        ("world.robots=0", "robots"),
        ("world.tick_s=0.0", "tick_s"),
        ("world.medium.loss_far=1.5", "loss_far"),
        ("agent.strategy='SSGKIF'", "SSGIKF"),
        ("agent.cruise_speed_steps_s=-10.0", "cruise_speed_steps_s"),
    ],
)
def test_impossible_values_are_refused_naming_the_field(override, field):
    with pytest.raises(ConfigError) as err:
        load_scenario("ES1", [override])
    assert field in str(err.value)


def test_wrong_type_error_is_a_value_error_subclass():
    # Callers that catch ValueError (the CLI) also catch configuration errors.
    assert issubclass(ConfigError, ValueError)


def test_from_dict_accepts_int_for_float_and_keeps_defaults():
    w = from_dict(WorldConfig, {"duration_s": 60, "robots": 4})
    assert w.duration_s == 60.0 and isinstance(w.duration_s, float)
    assert w.robots == 4
    assert w.tick_s == 0.1


# ---------------------------------------------------------------------------------------------
# Overrides
# ---------------------------------------------------------------------------------------------


def test_apply_overrides_parses_values_like_toml():
    data = {"world": {"robots": 10}}
    out = apply_overrides(
        data,
        [
            "world.robots=3",
            "world.duration_s=0.5",
            "world.flag=true",
            "agent.strategy=NC",
            'agent.name="quoted"',
            "world.arena.nest_centre_m=[1, 2.5]",
        ],
    )
    assert out["world"]["robots"] == 3 and type(out["world"]["robots"]) is int
    assert out["world"]["duration_s"] == 0.5 and type(out["world"]["duration_s"]) is float
    assert out["world"]["flag"] is True
    assert out["agent"]["strategy"] == "NC"
    assert out["agent"]["name"] == "quoted"
    assert out["world"]["arena"]["nest_centre_m"] == [1, 2.5]
    assert data == {"world": {"robots": 10}}  # the input is not modified


def test_parse_value_examples():
    assert parse_value("3") == 3
    assert parse_value("-2") == -2
    assert parse_value("1e-3") == 0.001
    assert parse_value("false") is False
    assert parse_value("SSGIFF") == "SSGIFF"


@pytest.mark.parametrize("bad", ["world.robots", "=3", "  =3"])
def test_apply_overrides_refuses_malformed_items(bad):
    with pytest.raises(ConfigError, match="KEY=VALUE"):
        apply_overrides({}, [bad])


def test_apply_overrides_refuses_a_value_used_as_a_table():
    with pytest.raises(ConfigError, match="'robots' is not a table"):
        apply_overrides({"world": {"robots": 10}}, ["world.robots.x=1"])


def test_overrides_reach_the_loaded_scenario():
    s = load_scenario(
        "ES2", ["world.robots=7", "agent.strategy=DSGIFF", "agent.beta=0.001", "world.seed=42"]
    )
    assert s.world.robots == 7
    assert s.agent.strategy == "DSGIFF"
    assert s.agent.beta == 0.001
    assert s.world.seed == 42
    assert s.world.arena.width_m == 3.0  # the rest is ES2's


# The e-puck defaults before issue 18, written out from the code they were (git show
# 950bdf5-era AgentConfig / OdometryConfig), and the readings of the seeds that replaced them.
V0_VALUES = {"p_after_fusion": "fused", "sends": "both", "give_up_factor": 0.0, "encounter_memory": 4,
             "odometry_k_m": 1.37e-4, "substeps": 1, "confidence_unit_m": 0.01}
#: Issue 18's first defaults (the readings, giving up after twice the distance, p in cm).
V1_VALUES = {"p_after_fusion": "distance", "sends": "last-visited", "give_up_factor": 2.0,
             "encounter_memory": 16, "odometry_k_m": 1.37e-5, "substeps": 10, "confidence_unit_m": 0.01}
#: Today's: giving up after 4 times the distance, p in metres (docs/so-000-untested/).
READING_VALUES = {**V1_VALUES, "give_up_factor": 4.0, "confidence_unit_m": 1.0}


def _issue_18_values(s: Scenario) -> dict:
    return {"p_after_fusion": s.agent.p_after_fusion, "sends": s.agent.sends,
            "give_up_factor": s.agent.give_up_factor, "encounter_memory": s.agent.encounter_memory,
            "odometry_k_m": s.agent.odometry_k_m, "substeps": s.world.odometry.substeps,
            "confidence_unit_m": s.agent.confidence_unit_m}


@pytest.mark.parametrize("name", ["ES1", "ES3", "SO-4.0x4.0"])
def test_defaults_are_the_seeds_readings_and_the_variants_the_old_ones(name):
    assert _issue_18_values(load_scenario(name)) == READING_VALUES
    assert _issue_18_values(load_scenario(name, variant_overrides("v0-defaults"))) == V0_VALUES
    assert _issue_18_values(load_scenario(name, variant_overrides("v1-defaults"))) == V1_VALUES


@pytest.mark.parametrize("variant, cruise_steps_s", [(None, 800.0), ("top-speed", 1000.0)])
def test_the_sikfs_odometry_constant_follows_the_cruise_speed(variant, cruise_steps_s):
    """``agent.odometry_k_m`` is the variance per metre that the world's slip gives at cruise
    speed: U(-s, s) per wheel and sub-step has variance s^2 / 3 on a sub-step's travel d, and a
    metre holds 1 / d sub-steps, so k = s^2 d / 3. The top-speed variant moves both (3 digits)."""
    s = load_scenario("ES1", variant_overrides(variant))
    world = s.world
    assert s.agent.cruise_speed_steps_s == cruise_steps_s
    substep_m = cruise_steps_s * world.body.metres_per_step * world.tick_s / world.odometry.substeps
    expected = world.odometry.slip_fraction ** 2 * substep_m / 3.0
    assert s.agent.odometry_k_m == pytest.approx(expected, rel=5e-3)
    # Only the speed and its constant: every reading of the seeds stays today's.
    assert _issue_18_values(s) == {**READING_VALUES, "odometry_k_m": s.agent.odometry_k_m}


def test_cli_variant_is_applied_before_set_and_an_unknown_one_is_refused(capsys, no_run):
    from swarmloc.deploy import cli

    args = cli.build_parser().parse_args(["batch", "ES1", "--variant", "v0-defaults", "--set", "world.odometry.substeps=3"])
    s = cli.load_from_args(args)
    assert (s.agent.sends, s.agent.encounter_memory, s.world.odometry.substeps) == ("both", 4, 3)
    code = main(["batch", "ES1", "--variant", "v1-nosuch"])
    err = capsys.readouterr().err
    assert code == 2 and "v1-nosuch" in err and "v0-defaults" in err


def test_spec_groups_named_after_a_variant_set_its_values():
    """An experiment group named like a variant (e.g. ``v0-defaults``) spells the variant's values
    in its ``set`` table: the spec means the same whatever today's defaults are."""
    from swarmloc.deploy.lab.experiment import load_spec, shipped_specs

    checked = 0
    for name in shipped_specs():
        spec = load_spec(name)
        for group in spec.groups:
            variant = next((v for v in VARIANTS if group.name == v or group.name.startswith(f"{v}-")), None)
            if variant is None:
                continue
            fixed = dict(group.set)
            for item in VARIANTS[variant]:
                key, _, text = item.partition("=")
                assert fixed.get(key) == parse_value(text), f"{name}/{group.name}: {key}"
            checked += 1
    assert checked >= 1


# ---------------------------------------------------------------------------------------------
# Files
# ---------------------------------------------------------------------------------------------


def test_scenario_from_a_toml_file(tmp_path):
    path = tmp_path / "mine.toml"
    path.write_text(
        'name = "mine"\n[world]\nrobots = 4\nduration_s = 12.0\n[agent]\nstrategy = "NC"\n'
    )
    s = load_scenario(str(path))
    assert (s.name, s.world.robots, s.world.duration_s, s.agent.strategy) == ("mine", 4, 12.0, "NC")


def test_malformed_toml_names_the_file(tmp_path):
    path = tmp_path / "broken.toml"
    path.write_text("[world\nrobots = = 3\n")
    with pytest.raises(ConfigError) as err:
        load_scenario(str(path))
    assert "broken.toml" in str(err.value)
    assert "TOML" in str(err.value)


def test_missing_file_names_the_file(tmp_path):
    path = tmp_path / "absent.toml"
    with pytest.raises(ConfigError) as err:
        load_scenario(str(path))
    assert "absent.toml" in str(err.value)


def test_unknown_scenario_name_suggests_a_shipped_one():
    with pytest.raises(ConfigError) as err:
        load_scenario("ES4")
    assert "ES4" in str(err.value)
    assert "did you mean" in str(err.value)


def test_bad_key_in_a_file_names_the_path(tmp_path):
    path = tmp_path / "typo.toml"
    path.write_text("[world]\nrobots = 4\n[world.arena]\nwidht_m = 2.0\n")
    with pytest.raises(ConfigError, match=r"world\.arena\.widht_m.*'width_m'"):
        load_scenario(str(path))


# ---------------------------------------------------------------------------------------------
# CLI refusals: exit code 2, a message naming the problem, nothing run
# ---------------------------------------------------------------------------------------------


@pytest.fixture
def no_run(monkeypatch):
    """Make any attempt to actually run a batch fail the test loudly."""
    from swarmloc.deploy.lab.epuck import batch

    def boom(*args, **kwargs):
        raise AssertionError("the CLI ran a batch despite a bad configuration")

    monkeypatch.setattr(batch, "run_batch", boom)


def test_cli_unknown_override_key_exits_2(capsys, no_run):
    code = main(["batch", "ES1", "--set", "world.robts=3"])
    captured = capsys.readouterr()
    assert code == 2
    assert "world.robts" in captured.err
    assert "'robots'" in captured.err
    assert captured.out == ""


def test_cli_unknown_scenario_exits_2(capsys, no_run):
    code = main(["batch", "nosuch"])
    captured = capsys.readouterr()
    assert code == 2
    assert "nosuch" in captured.err
    assert captured.out == ""


def test_cli_impossible_robot_count_exits_2(capsys, no_run):
    code = main(["batch", "ES1", "--robots", "1000"])
    assert code == 2
    assert "robots" in capsys.readouterr().err


def test_cli_bad_strategy_exits_2_with_suggestion(capsys, no_run):
    code = main(["batch", "ES1", "--strategy", "SSGKIF"])
    assert code == 2
    assert "SSGIKF" in capsys.readouterr().err


# ---------------------------------------------------------------------------------------------
# Determinism of the batch engine
# ---------------------------------------------------------------------------------------------


@pytest.fixture(scope="module")
def es1_runs():
    short = ["world.duration_s=30.0"]
    a = run_batch(load_scenario("ES1", short + ["world.seed=5"]))
    b = run_batch(load_scenario("ES1", short + ["world.seed=5"]))
    c = run_batch(load_scenario("ES1", short + ["world.seed=6"]))
    return a, b, c


def test_same_seed_gives_identical_metrics_and_poses(es1_runs):
    a, b, _ = es1_runs
    assert a.metrics == b.metrics
    np.testing.assert_array_equal(a.final_pose, b.final_pose)
    np.testing.assert_array_equal(a.pose_estimate, b.pose_estimate)
    np.testing.assert_array_equal(a.lost_count, b.lost_count)


def test_different_seed_gives_different_final_poses(es1_runs):
    a, _, c = es1_runs
    assert not np.array_equal(a.final_pose, c.final_pose)
    # 10 robots over 300 ticks of 0.1 s.
    assert a.final_pose.shape == (10, 3)
    assert len(a.metrics["on_path_series"]) == 30  # one sample per simulated second


def test_batch_robots_stay_inside_the_arena(es1_runs):
    a, _, _ = es1_runs
    r = 0.035
    assert (a.final_pose[:, 0] >= r - 1e-9).all() and (a.final_pose[:, 0] <= 1.2 - r + 1e-9).all()
    assert (a.final_pose[:, 1] >= r - 1e-9).all() and (a.final_pose[:, 1] <= 1.7 - r + 1e-9).all()


def test_scenarios_command_lists_every_family(capsys):
    from swarmloc.deploy.cli import main

    assert main(["scenarios"]) == 0
    rows = [line.split()[:2] for line in capsys.readouterr().out.splitlines()]
    families = {family for _, family in rows}
    assert families == {"foraging", "laser", "vision", "replay"}
    assert ["ES3", "foraging"] in rows and ["vision-exp3", "vision"] in rows


def test_every_key_value_of_the_command_line_is_read_one_way():
    # Issue 48: KEY=VALUE was parsed three ways (TOML for --set, a TOML copy in the experiment
    # engine, JSON for mrclam --param); one reading now, config.parse_assignment.
    from swarmloc.config import ConfigError, apply_overrides, parse_assignment
    from swarmloc.deploy.lab.experiment import _parse_sets
    from swarmloc.deploy.lab.replay.mrclam import _parse_params

    items = ['a=1', 'b = 0.5', 'c="x y"', 'd=true', 'e=[1, 2]', 'f=plain text', 'g.h=1e9']
    expected = {"a": 1, "b": 0.5, "c": "x y", "d": True, "e": [1, 2], "f": "plain text", "g.h": 1e9}
    assert dict(parse_assignment(i) for i in items) == expected
    assert _parse_params(items) == expected
    assert _parse_sets(items) == expected
    assert apply_overrides({}, ["g.h=1e9", 'c="x y"']) == {"g": {"h": 1e9}, "c": "x y"}
    for bad, flag in (("=3", "--param"), ("novalue", "--set")):
        with pytest.raises(ConfigError, match=rf"{flag} '{bad}': expected KEY=VALUE"):
            parse_assignment(bad, flag)
