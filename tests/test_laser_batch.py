"""Tests of the laser world (world/laser/world.py), the in-process runner (deploy/lab/laser/runner.py)
and the laser experiments and report (deploy/lab/laser/experiment.py, deploy/lab/laser/report.py).

Expected values come from hand geometry (distances and walls of the built-in maps, see
world/laser/maps.py), from the laws of the noise (loss rate: binomial, tolerance stated), or from an
independent computation (a dead-reckoning localizer written here, ``cast_rays``).
"""

from __future__ import annotations

import csv
import dataclasses
import math
import textwrap

import numpy as np
import pytest

from swarmloc.agents.laser.localizer import LaserObservation, LocalizerSetup
from swarmloc.config import ConfigError
from swarmloc.deploy.lab.experiment import load_spec, plan
from swarmloc.deploy.lab.laser.experiment import columns, row, run_job
from swarmloc.deploy.lab.laser.experiment import settings as laser_settings
from swarmloc.deploy.lab.laser.report import (
    curve_tail_indexes,
    settle_index,
    table3_indexes,
    wilson_interval,
    write_report,
)
from swarmloc.deploy.lab.laser.runner import (
    ALGORITHMS,
    AlgorithmConfig,
    LaserScenario,
    MetricsConfig,
    decode_series_mm,
    encode_series_mm,
    load_laser_scenario,
    map_rotations,
    run_laser,
    summarize,
    symmetric_position_error,
)
from swarmloc.world.laser.laser import LaserParams, cast_rays, unicycle_model
from swarmloc.world.laser.maps import SegmentMap, build_map, distance_to_walls
from swarmloc.world.laser.world import (
    DriverConfig,
    Kidnap,
    LaserWorld,
    LaserWorldConfig,
    RadioConfig,
    RobotPath,
)

# ---------------------------------------------------------------------------------------------
# Helpers: still robots, a dead-reckoning localizer
# ---------------------------------------------------------------------------------------------


def still_config(starts, map_name: str = "office", steps: int = 10, **world) -> LaserWorldConfig:
    """Robots that stay where they start (their only waypoint is their start)."""
    paths = tuple(RobotPath(start=s, waypoints=(s[:2],)) for s in starts)
    return LaserWorldConfig(map=map_name, robots=len(starts), steps=steps, paths=paths,
                            driver=DriverConfig(mode="waypoints"), **world)


class DeadReckoning:
    """Knows its start and integrates its odometry with eq. 3; broadcasts its id."""

    def __init__(self, setup: LocalizerSetup, start, rng: np.random.Generator):
        self.setup, self.pose, self.rng = setup, np.array(start, dtype=float), rng
        self.heard: list[tuple[int, int, bytes]] = []  # (step, sender, payload)
        self.steps = 0

    def step(self, obs: LaserObservation) -> None:
        self.pose = unicycle_model(self.pose[None, :], obs.odometry_delta_s_m,
                                   obs.odometry_delta_phi_rad)[0]
        self.heard += [(obs.step, m.sender_id, m.payload) for m in obs.received]
        self.steps += 1

    def estimate(self) -> np.ndarray:
        return self.pose.copy()

    def outgoing(self) -> bytes | None:
        return bytes([self.setup.robot_id])


def dead_reckoning_factory(starts):
    def build(setup, params, rng):
        return DeadReckoning(setup, starts[setup.robot_id], rng)

    return build


# Corridor of the office map: y in [5, 7], the south wall y = 5 has doors at x in [1.5, 2.5],
# [7, 8], [10.5, 11.5], [18, 19]; rooms below it. Robots at y = 6 are 1 m from both walls.
SENDER = (8.0, 6.0, 0.0)
IN_RANGE = (11.9, 6.0, math.pi)  # 3.9 m east along the corridor
OUT_OF_RANGE = (3.9, 6.0, 0.0)  # 4.1 m west
# Below the corridor's south wall: the segment from SENDER to it crosses y = 5 at
# x = 8 + 0.5 * (1 / 1.8) = 8.28, on the wall piece x in [8, 10.5]: blocked. 1.87 m away.
BEHIND_WALL = (8.5, 4.2, 0.0)


def payloads_heard(world: LaserWorld, robot: int) -> set[int]:
    return {m.sender_id for m in world.observe()[robot].received}


# ---------------------------------------------------------------------------------------------
# The radio medium: range, line of sight, loss, timing
# ---------------------------------------------------------------------------------------------


def test_radio_reaches_robots_in_range_and_sight_only():
    config = still_config([SENDER, IN_RANGE, OUT_OF_RANGE, BEHIND_WALL])
    world = LaserWorld(config)
    world.step([b"hello", None, None, None])
    heard = [payloads_heard(world, r) for r in range(4)]
    assert heard == [set(), {0}, set(), set()]
    message = world.observe()[1].received[0]
    assert (message.sender_id, message.payload) == (0, b"hello")


def test_radio_without_line_of_sight_requirement_reaches_behind_walls():
    config = still_config([SENDER, IN_RANGE, OUT_OF_RANGE, BEHIND_WALL],
                          radio=RadioConfig(range_m=4.0, line_of_sight=False))
    world = LaserWorld(config)
    world.step([b"x", None, None, None])
    assert [payloads_heard(world, r) for r in range(4)] == [set(), {0}, set(), {0}]


def test_radio_delivers_at_the_next_step_only():
    world = LaserWorld(still_config([SENDER, IN_RANGE]))
    assert world.observe()[1].received == ()
    world.step([b"a", None])
    assert payloads_heard(world, 1) == {0}
    world.step([None, None])
    assert world.observe()[1].received == ()


def test_radio_loss_rate_matches_its_probability():
    # Three robots in the corridor, all within 4 m of each other: 6 directed deliveries a step.
    starts = [(6.0, 6.0, 0.0), (8.0, 6.0, 0.0), (9.5, 6.0, 0.0)]
    steps, loss = 1200, 0.3
    config = still_config(starts, steps=steps,
                          radio=RadioConfig(range_m=4.0, loss_probability=loss))
    world = LaserWorld(config)
    delivered = 0
    for _ in range(steps - 1):
        world.step([b"p", b"q", b"r"])
        delivered += sum(len(o.received) for o in world.observe())
    trials = 6 * (steps - 1)
    # Binomial: std of the rate = sqrt(0.3 * 0.7 / 7194) = 0.0054; tolerance 4.6 std.
    assert abs((1 - delivered / trials) - loss) < 0.025


def test_outgoing_payloads_are_checked():
    world = LaserWorld(still_config([SENDER, IN_RANGE]))
    with pytest.raises(ValueError, match="outgoing: expected a list of 2"):
        world.step([None])
    with pytest.raises(TypeError, match=r"outgoing\[1\]: expected bytes or None, got str"):
        world.step([None, "text"])
    with pytest.raises(ValueError, match=r"outgoing\[0\]: payload of 40000 bytes exceeds"):
        world.step([bytes(40000), None])


# ---------------------------------------------------------------------------------------------
# Sensing, kidnapping
# ---------------------------------------------------------------------------------------------


def test_scan_and_sightings_follow_the_true_poses():
    config = still_config([SENDER, IN_RANGE, BEHIND_WALL],
                          laser=LaserParams(n_beams=18, max_range_m=8.0, noise_std_m=0.0))
    world = LaserWorld(config)
    obs = world.observe()
    expected = cast_rays(world.map, world.true_poses, config.laser.beam_angles_rad, 8.0)
    np.testing.assert_allclose(np.stack([o.ranges_m for o in obs]), expected, atol=1e-9)
    # Along the corridor nothing lies within 8 m east; the west wall is exactly 8 m away.
    np.testing.assert_allclose(obs[0].ranges_m[[0, 9]], [8.0, 8.0], atol=1e-5)
    # Robot 0 sees robot 1 (3.9 m east, relative heading pi), not robot 2 (behind the wall).
    assert [s.robot_id for s in obs[0].sightings] == [1]
    sighting = obs[0].sightings[0]
    assert sighting.distance_m == pytest.approx(3.9, abs=4 * 0.2)  # Q_rd = 0.2 m
    assert abs(sighting.bearing_rad) < 4 * 0.1
    assert abs(abs(sighting.relative_heading_rad) - math.pi) < 4 * 0.1
    assert obs[2].sightings == ()


def test_kidnap_moves_the_true_pose_and_not_the_localizer():
    starts = [SENDER]
    config = still_config(starts, laser=LaserParams(n_beams=8, max_range_m=8.0, noise_std_m=0.0))
    world = LaserWorld(config)
    brain = DeadReckoning(world.localizer_setup(0), starts[0], np.random.default_rng(0))
    brain.step(world.observe()[0])
    before = brain.estimate()
    target = (16.0, 2.5, 1.0)  # south-east room
    world.kidnap(0, target)
    np.testing.assert_allclose(world.true_poses[0], target)
    np.testing.assert_allclose(brain.estimate(), before)  # nobody told the robot
    obs = world.observe()[0]
    assert (obs.odometry_delta_s_m, obs.odometry_delta_phi_rad) == (0.0, 0.0)
    expected = cast_rays(world.map, np.array([target]), config.laser.beam_angles_rad, 8.0)[0]
    np.testing.assert_allclose(obs.ranges_m, expected, atol=1e-9)  # sensed at the new pose


def test_scheduled_kidnap_jumps_the_error_of_a_dead_reckoning_robot():
    start, target = (8.0, 6.0, 0.0), (16.0, 2.5, 1.0)
    config = dataclasses.replace(
        still_config([start], steps=12, motion=dataclasses.replace(
            LaserWorldConfig().motion, speed_std_mps=0.0, turn_rate_std_rad_s=0.0)),
        kidnaps=(Kidnap(robot=0, step=5, pose=target),))
    scenario = LaserScenario(world=config, algorithm=AlgorithmConfig(name="cfsga"))
    result = run_laser(scenario, algorithm=dead_reckoning_factory([start]))
    error = result.position_error_m[:, 0]
    np.testing.assert_allclose(error[:5], 0.0, atol=1e-12)
    np.testing.assert_allclose(error[5:], math.hypot(16.0 - 8.0, 2.5 - 6.0), atol=1e-9)
    np.testing.assert_allclose(result.true_poses[5:, 0], np.tile(target, (7, 1)), atol=1e-12)
    assert result.summary["kidnap_step"] == 5
    assert result.summary["recovered"] is False


def test_kidnap_with_resume_waits_at_the_waypoint_then_goes_on():
    # One robot in the corridor: to (10, 6), kidnapped at step 80 to (16, 6), then to (18, 6).
    path = RobotPath(start=(6.0, 6.0, 0.0), waypoints=((10.0, 6.0), (18.0, 6.0)))
    config = LaserWorldConfig(map="office", robots=1, steps=140, paths=(path,),
                              driver=DriverConfig(mode="waypoints"),
                              kidnaps=(Kidnap(robot=0, step=80, pose=(16.0, 6.0, 0.0),
                                              resume_waypoint=1),))
    world = LaserWorld(config)
    xs = []
    while not world.done:
        world.step([None])
        xs.append(world.true_poses[0, 0])
    # 4 m at 0.1 m per step: there by step ~45, then it waits (no motion while standing).
    assert abs(xs[70] - 10.0) < 0.2 and xs[70] == xs[78]
    assert abs(xs[79] - 16.0) < 1e-9  # step() leading to step 80 applies the kidnap
    assert abs(xs[-1] - 18.0) < 0.25


# ---------------------------------------------------------------------------------------------
# The driver
# ---------------------------------------------------------------------------------------------


@pytest.mark.parametrize("map_name", ["office", "three_rooms_corridor", "symmetric"])
def test_driver_keeps_robots_in_free_space_and_moving(map_name):
    config = LaserWorldConfig(map=map_name, robots=6, steps=300, seed=3)
    world = LaserWorld(config)
    poses = [world.true_poses]
    while not world.done:
        world.step([None] * 6)
        poses.append(world.true_poses)
    poses = np.stack(poses)  # (T, N, 3)
    gap = distance_to_walls(world.map, poses.reshape(-1, 3))
    assert gap.min() >= config.driver.robot_radius_m
    x_min, y_min, x_max, y_max = world.map.bounds_m
    assert poses[..., 0].min() > x_min and poses[..., 0].max() < x_max
    assert poses[..., 1].min() > y_min and poses[..., 1].max() < y_max
    travel = np.hypot(*np.diff(poses[..., :2], axis=0).transpose(2, 0, 1)).sum(axis=0)
    # At most 0.2 m/s x 0.5 s a step; a robot that keeps driving covers well over half that.
    assert np.all(travel > 0.5 * 0.1 * 300)
    # No step is longer than the commanded speed plus 5 std of the speed noise.
    steps_m = np.hypot(*np.diff(poses[..., :2], axis=0).transpose(2, 0, 1))
    assert steps_m.max() < (0.2 + 5 * config.motion.speed_std_mps) * 0.5


def test_waypoint_driver_reaches_its_goal_through_doors():
    # Office: south-west room (2.5, 2.5) to the north-east room (16, 10): two doors, a corridor.
    path = RobotPath(start=(2.5, 2.5, 0.0), waypoints=((16.0, 10.0),))
    config = LaserWorldConfig(map="office", robots=1, steps=400, paths=(path,),
                              driver=DriverConfig(mode="waypoints"))
    world = LaserWorld(config)
    while not world.done:
        world.step([None])
    assert math.hypot(world.true_poses[0, 0] - 16.0, world.true_poses[0, 1] - 10.0) < 0.2


# ---------------------------------------------------------------------------------------------
# Determinism
# ---------------------------------------------------------------------------------------------


def test_same_seed_same_errors_and_another_seed_differs():
    scenario = load_laser_scenario("laser-collab-three-rooms",
                                   ["world.steps=25", "algorithm.population=40"])
    a = run_laser(scenario, seed=7)
    b = run_laser(scenario, seed=7)
    c = run_laser(scenario, seed=8)
    np.testing.assert_array_equal(a.position_error_m, b.position_error_m)
    np.testing.assert_array_equal(a.true_poses, b.true_poses)
    assert a.summary == b.summary
    assert not np.array_equal(a.true_poses, c.true_poses)


def test_trajectories_do_not_depend_on_what_robots_send():
    scenario = load_laser_scenario("laser-collab-three-rooms",
                                   ["world.steps=25", "algorithm.population=40"])
    coop = run_laser(scenario, seed=3, cooperative=True)
    alone = run_laser(scenario, seed=3, cooperative=False)
    np.testing.assert_array_equal(coop.true_poses, alone.true_poses)


# ---------------------------------------------------------------------------------------------
# Configuration errors
# ---------------------------------------------------------------------------------------------

BAD_WORLDS = {
    "unknown map": ({"map": "ofice"}, ValueError, r"map: unknown map 'ofice'; did you mean 'office'"),
    "no robots": ({"robots": 0}, ValueError, r"robots: must be in 1\.\.4096"),
    "steps": ({"steps": 0}, ValueError, r"steps: must be >= 1"),
    "dt": ({"dt_s": -0.5}, ValueError, r"dt_s: must be > 0"),
    "paths count": ({"robots": 2, "paths": (RobotPath(start=(2.5, 2.5, 0.0)),)}, ValueError,
                    r"paths: give one path per robot \(2\), got 1"),
    "waypoint mode without paths": ({"driver": DriverConfig(mode="waypoints")}, ValueError,
                                    r"paths: driver mode 'waypoints' needs one path per robot"),
    "start in a wall": ({"paths": (RobotPath(start=(4.0, 2.0, 0.0)),)}, ValueError,
                        r"paths\[0\]\.start: \(4\.0, 2\.0\) is 0\.000 m from a wall"),
    "outside": ({"paths": (RobotPath(start=(25.0, 2.0, 0.0)),)}, ValueError,
                r"paths\[0\]\.start: \(25\.0, 2\.0\) is not inside map 'office' bounds"),
    "kidnap step": ({"steps": 10, "kidnaps": (Kidnap(robot=0, step=10),)}, ValueError,
                    r"kidnaps\[0\]\.step: must be < steps \(10\), got 10"),
    "kidnap robot": ({"kidnaps": (Kidnap(robot=1, step=3),)}, ValueError,
                     r"kidnaps\[0\]\.robot: must be < robots \(1\), got 1"),
}


@pytest.mark.parametrize("case", sorted(BAD_WORLDS))
def test_bad_world_config_is_refused_naming_the_field(case):
    kwargs, error, pattern = BAD_WORLDS[case]
    with pytest.raises(error, match=pattern):
        LaserWorldConfig(**kwargs)


def test_enclosed_waypoint_is_refused():
    # The fully symmetric map's central pillar (4..6 x 4..6 m) is hollow: free to the grid,
    # but unreachable.
    with pytest.raises(ValueError, match=r"paths\[0\]\.waypoints\[0\]: \(5\.0, 5\.0\) is enclosed"):
        LaserWorldConfig(map="symmetric", paths=(RobotPath(start=(1.0, 1.0, 0.0),
                                                           waypoints=((5.0, 5.0),)),),
                         driver=DriverConfig(mode="waypoints"))


@pytest.mark.parametrize("kwargs, pattern", [
    ({"loss_probability": 1.5}, r"loss_probability: must be in \[0, 1\]"),
    ({"range_m": 0.0}, r"range_m: must be > 0"),
])
def test_bad_radio_is_refused(kwargs, pattern):
    with pytest.raises(ValueError, match=pattern):
        RadioConfig(**kwargs)


def test_bad_driver_is_refused():
    with pytest.raises(ValueError, match=r"mode: unknown driver mode 'waypoint'; did you mean 'waypoints'"):
        DriverConfig(mode="waypoint")
    with pytest.raises(ValueError, match=r"grid_cell_m: must be below clearance_m"):
        DriverConfig(grid_cell_m=0.5)


def test_scenario_file_errors_name_the_key(tmp_path):
    path = tmp_path / "s.toml"
    path.write_text('name = "s"\n[world]\nrobot = 2\n')
    with pytest.raises(ConfigError, match=r"unknown key 'world\.robot'; did you mean 'robots'"):
        load_laser_scenario(path)
    with pytest.raises(ConfigError, match=r"unknown algorithm 'cfs-ga'; did you mean 'cfsga'"):
        load_laser_scenario("laser-kidnap-office", ['algorithm.name="cfs-ga"'])
    with pytest.raises(ConfigError, match=r"population_sise"):
        load_laser_scenario("laser-kidnap-office", ["algorithm.params.population_sise=3"])
    with pytest.raises(ConfigError, match=r"no such file or shipped scenario; did you mean "
                                          r"'laser-kidnap-office'"):
        load_laser_scenario("laser-kidnap-ofice")


# ---------------------------------------------------------------------------------------------
# Summary, symmetry, series
# ---------------------------------------------------------------------------------------------


def test_summary_by_hand():
    metrics = MetricsConfig(settle_error_m=0.15, final_window_steps=3, localized_error_m=0.5)
    # Robot 0 settles at step 4 (0.2 at step 3 is the last value above 0.15); robot 1 never.
    error = np.array([[1.0, 1.0], [0.1, 2.0], [0.1, 2.0], [0.2, 0.1], [0.1, 0.2],
                      [0.1, 0.3], [0.05, 0.4]])
    out = summarize(error, np.zeros_like(error), [], metrics, sightings=np.array([0, 0, 2, 2, 0, 0, 0]))
    assert out["settle_step"] is None and out["settled_robots"] == 1
    assert out["final_error_m"] == pytest.approx(((0.1 + 0.1 + 0.05) / 3 + 0.3) / 2)
    assert out["localized"] is True and out["first_contact_step"] == 2
    # Kidnap at step 5: settled before it (from step 1, 4 steps >= the window), settles again
    # from step 7 (2 steps after the kidnap).
    kidnapped = np.array([[1.0], [0.1], [0.1], [0.1], [0.1], [3.0], [3.0], [0.1], [0.1], [0.1],
                          [0.1]])
    out = summarize(kidnapped, np.zeros_like(kidnapped), [(0, 5)], metrics)
    assert out["settled_before_kidnap"] is True and out["kidnap_step"] == 5
    assert out["recover_steps"] == 2 and out["recovered"] is True and out["settle_step"] == 7


def test_map_rotations_and_symmetric_error():
    # An L-shape has no rotational symmetry; a square room with a centred pillar has 3.
    square = SegmentMap("sq", np.array([[0, 0, 4, 0], [4, 0, 4, 4], [4, 4, 0, 4], [0, 4, 0, 0],
                                        [1.5, 1.5, 2.5, 1.5]]))
    assert map_rotations(square) == ()
    room = build_map("symmetric_rooms")  # 18 x 10, invariant under a half turn about (9, 5)
    assert map_rotations(room) == pytest.approx((math.pi,))
    # The fully symmetric map is invariant under the square's symmetries: three quarter turns.
    assert map_rotations(build_map("symmetric")) == pytest.approx(
        (math.pi / 2, math.pi, 3 * math.pi / 2))
    truth = np.array([[1.0, 1.0, 0.3]])
    twin = np.array([[17.0, 9.0, 0.3 + math.pi]])  # the half-turn image of the truth
    assert symmetric_position_error(twin, truth, "symmetric_rooms")[0] == pytest.approx(0.0, abs=1e-12)
    assert symmetric_position_error(twin, truth, "office")[0] == pytest.approx(math.hypot(16, 8))


def test_series_round_trip_and_bad_text():
    errors = np.array([[0.0123, 1.5], [2.0004, 0.0]])
    np.testing.assert_allclose(decode_series_mm(encode_series_mm(errors)), [[0.012, 1.5], [2.0, 0.0]])
    with pytest.raises(ValueError, match="position_error_mm"):
        decode_series_mm("1 2;3")
    with pytest.raises(ValueError, match="position_error_mm"):
        decode_series_mm("a b")


def test_wilson_interval_and_settle_index():
    lo, hi = wilson_interval(0, 10)  # the textbook value: upper bound 0.2775
    assert lo == 0.0 and hi == pytest.approx(0.2775, abs=1e-4)
    lo, hi = wilson_interval(5, 10)  # symmetric around 1/2
    assert lo + hi == pytest.approx(1.0)
    assert settle_index(np.array([1.0, 0.1, 0.2, 0.1, 0.1])) == 3
    assert settle_index(np.array([0.1, 0.1, 0.3])) is None


# ---------------------------------------------------------------------------------------------
# End to end with the real algorithms; experiments and report
# ---------------------------------------------------------------------------------------------

SMALL = {"ssga": 30, "simple_ga": 30, "cfsga": 40, "amcl": 200}


@pytest.mark.parametrize("algorithm", sorted(SMALL))
def test_runner_end_to_end_with_each_algorithm(algorithm):
    scenario = load_laser_scenario("laser-collab-three-rooms", [
        "world.steps=12", f'algorithm.name="{algorithm}"',
        f"algorithm.population={SMALL[algorithm]}"])
    result = run_laser(scenario, seed=2)
    assert result.position_error_m.shape == (12, 3)
    assert np.all(np.isfinite(result.estimates))
    assert result.summary["first_contact_step"] == 0  # they start 3.5 m apart in the corridor


def test_amcl_localizes_the_office_robot_before_the_kidnap():
    # The kidnap path's first 120 steps, AMCL with 1000-3000 particles: a real localization run.
    scenario = load_laser_scenario("laser-kidnap-office", [
        'algorithm.name="amcl"', "world.steps=120", "world.kidnaps=[]",
        "algorithm.params.min_particles=1000", "algorithm.params.max_particles=3000"])
    result = run_laser(scenario, seed=1)
    assert result.summary["final_error_m"] < 0.3


def test_shipped_laser_specs_plan_the_papers_trial_counts():
    sizes = {name: len(plan(load_spec(name))) for name in
             ("laser-table3", "laser-kidnap", "laser-collab", "laser-robustness")}
    # 3 algorithms x 2 populations x 100 + MR-SSGA refined x 2 x 50; (3 + modern AMCL without
    # recovery + Player AMCL) x 100 + (Player AMCL with injection, CFS-GA refined) x 50;
    # 2 modes x (003's three corridors x 100 + the one corridor and its long variant x 50);
    # (3 algorithms + modern AMCL without recovery + Player AMCL) x 2 maps x 250, and Player
    # AMCL's two other readings x 2 maps x 100.
    assert sizes == {"laser-table3": 700, "laser-kidnap": 600, "laser-collab": 400,
                     "laser-robustness": 2900}


def test_job_row_and_report(tmp_path):
    spec_path = tmp_path / "laser-kidnap.toml"
    spec_path.write_text(textwrap.dedent("""\
        name = "laser-kidnap"
        family = "laser"
        replications = 1
        [[group]]
        name = "g"
        scenarios = ["laser-kidnap-office"]
        duration_s = 15.0
        [group.grid]
        "algorithm.name" = ["cfsga", "amcl"]
        [group.set]
        "algorithm.population" = 40
        "world.kidnaps" = []
    """))
    spec = load_spec(spec_path)
    jobs = plan(spec)
    assert [j.overrides[-2:] for j in jobs] == [("world.steps=30", "world.seed=1")] * 2
    header = columns(spec)
    results = tmp_path / "results.csv"
    with results.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for job in jobs:
            out = run_job(job)
            line = row(spec, job, out)
            assert len(line) == len(header)
            assert decode_series_mm(line[header.index("position_error_mm")]).shape == (30, 1)
            writer.writerow(["" if v is None else v for v in line])
    page = write_report([results], tmp_path / "report", command="test")
    text = page.read_text()
    assert "003 fig. 3" in text and "| CFS-GA | 1 |" in text and "| modern AMCL | 1 |" in text
    assert (tmp_path / "report" / "fig3_kidnap.png").stat().st_size > 0
    assert ALGORITHMS.get("amcl").label == "modern AMCL"
    assert ALGORITHMS.get("amcl-player").label == "Player AMCL"


def _report_of_spec(spec_path, tmp_path, edit=None) -> str:
    """Run every job of the spec at ``spec_path`` in process, write the rows (``edit(header,
    line)`` may change a row first) and return the text of the report written from them."""
    spec = load_spec(spec_path)
    header = columns(spec)
    results = tmp_path / "results.csv"
    with results.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(header)
        for job in plan(spec):
            line = row(spec, job, run_job(job))
            if edit is not None:
                edit(header, line)
            writer.writerow(["" if v is None else v for v in line])
    return write_report([results], tmp_path / "report", command="test").read_text()


def test_table3_indexes_by_hand():
    # Over trials of each trial's final team error: min, max, mean.
    assert table3_indexes([0.3, 0.1, 0.2, 0.6]) == pytest.approx((0.1, 0.6, 0.3))
    assert all(math.isnan(v) for v in table3_indexes([]))
    # The other reading: two trials averaged into one curve [1, 1, 0.5, 0.3] (steps 0-3); its
    # last quarter is step 3 alone, its last half steps 2-3.
    runs = np.array([[1.0, 1.5, 0.6, 0.2], [1.0, 0.5, 0.4, 0.4]])
    assert curve_tail_indexes(runs, 0.25) == pytest.approx((0.3, 0.3, 0.3))
    assert curve_tail_indexes(runs, 0.5) == pytest.approx((0.3, 0.5, 0.4))


def test_aliased_rooms_has_no_rotation_so_no_twin_error():
    assert map_rotations(build_map("aliased_rooms")) == ()
    truth = np.array([[1.0, 1.0, 0.3]])
    twin = np.array([[17.0, 9.0, 0.3 + math.pi]])  # the half-turn image: a wrong pose here
    assert symmetric_position_error(twin, truth, "aliased_rooms")[0] == pytest.approx(
        math.hypot(16, 8))


def test_table3_spec_and_report_section(tmp_path):
    """The shipped table-3 spec runs the three algorithms on the aliased floor; its report
    section names the floor and the definition of the indexes, and shows no symmetry column for
    a floor without symmetry."""
    shipped = laser_settings(load_spec("laser-table3"))
    assert {s.strategy for s in shipped} == {"ssga", "simple_ga", "amcl"}
    assert {s.scenario for s in shipped} == {"laser-table3-aliased-rooms"}
    spec_path = tmp_path / "laser-table3.toml"
    spec_path.write_text(textwrap.dedent("""\
        name = "laser-table3"
        family = "laser"
        replications = 1
        [[group]]
        name = "g"
        scenarios = ["laser-table3-aliased-rooms"]
        [group.grid]
        "algorithm.name" = ["ssga", "amcl"]
        [group.set]
        "algorithm.population" = 20
        "world.steps" = 8
    """))
    text = _report_of_spec(spec_path, tmp_path)
    assert "`aliased_rooms`" in text and "laser-table3-aliased-rooms.toml" in text
    assert "What the indexes are over" in text
    assert "up to the symmetry" not in text
    assert (tmp_path / "report" / "table3_floor.png").stat().st_size > 0
    assert "| 20 | MR-SSGA | 1 |" in text and "| 20 | modern AMCL | 1 |" in text


def test_robustness_report_shows_a_named_variant_as_its_own_row(tmp_path):
    """A robustness group named otherwise than its algorithm (amcl-no-recovery) gets a row of
    its own, without the paper's figure, instead of being pooled with the plain algorithm."""
    spec_path = tmp_path / "laser-robustness.toml"
    spec_path.write_text(textwrap.dedent("""\
        name = "laser-robustness"
        family = "laser"
        replications = 1
        [[group]]
        name = "amcl"
        scenarios = ["laser-robust-office"]
        [group.set]
        "algorithm.name" = "amcl"
        "algorithm.population" = 200
        "world.steps" = 6
        [[group]]
        name = "amcl-no-recovery"
        scenarios = ["laser-robust-office"]
        [group.set]
        "algorithm.name" = "amcl"
        "algorithm.population" = 200
        "algorithm.params.recovery" = false
        "world.steps" = 6
        [[group]]
        name = "amcl-player"
        scenarios = ["laser-robust-office"]
        [group.set]
        "algorithm.name" = "amcl-player"
        "algorithm.population" = 200
        "world.steps" = 6
    """))
    text = _report_of_spec(spec_path, tmp_path)
    rows = [line for line in text.splitlines()
            if line.startswith(("| Player AMCL", "| modern AMCL"))]
    assert len(rows) == 3, rows
    player, plain, variant = rows  # Player's first: the filter the paper ran
    assert player.startswith("| Player AMCL | ") and "| 35 % |" in player
    # The paper's 35 % is Player's AMCL's, not the modern filter's nor its variant's.
    assert plain.startswith("| modern AMCL | ") and "(n = 1)" in plain and "| – |" in plain
    assert variant.startswith("| modern AMCL (amcl-no-recovery) | ") and "(n = 1)" in variant
    assert "| – |" in variant  # no paper figure for a variant the paper did not run


def test_collab_report_shows_one_block_per_scenario_with_a_paired_comparison(tmp_path):
    """The fig. 4 section has a table and a figure for 003's scenario (with the paper's figures)
    and one for a variant (without them); both with the per-seed comparison."""
    spec_path = tmp_path / "laser-collab.toml"
    spec_path.write_text(textwrap.dedent("""\
        name = "laser-collab"
        family = "laser"
        replications = 2
        [[group]]
        name = "collab"
        scenarios = ["laser-collab-three-corridors"]
        [group.grid]
        "algorithm.cooperative" = [true, false]
        [group.set]
        "algorithm.population" = 30
        "world.steps" = 6
        [[group]]
        name = "collab-long-corridor"
        scenarios = ["laser-collab-three-rooms-long-corridor"]
        [group.grid]
        "algorithm.cooperative" = [true, false]
        [group.set]
        "algorithm.population" = 30
        "world.steps" = 6
    """))
    # Settling steps set by hand for the variant, (seed, collaborative) -> step: collaboration
    # is 4 steps sooner on seed 1 and 2 steps later on seed 2, so the median gain is 1; per mode
    # the steps are {3, 6} and {7, 4}: medians 4.5 and 5.5, quartiles (linear) 3.75-5.25 and
    # 4.75-6.25, shown truncated.
    settle = {(1, True): 3, (1, False): 7, (2, True): 6, (2, False): 4}

    def set_settling(header, line):
        at = {name: header.index(name) for name in ("scenario", "cooperative", "seed", "settle_step")}
        if line[at["scenario"]] == "laser-collab-three-rooms-long-corridor":
            line[at["settle_step"]] = settle[(int(line[at["seed"]]), bool(int(line[at["cooperative"]])))]

    text = _report_of_spec(spec_path, tmp_path, set_settling)
    section = text.split("## 003 fig. 4")[1].split("\n## ")[0]
    assert section.index("`laser-collab-three-corridors.toml`") < section.index(
        "`laser-collab-three-rooms-long-corridor.toml`")
    rows = [line for line in section.splitlines()
            if line.startswith(("| collaborative", "| autonomous"))]
    assert len(rows) == 4, rows
    assert "| about 100 |" in rows[0] and "| almost 300 |" in rows[1]
    assert all("| 2 |" in r and "| – |" in r for r in rows[2:])  # no paper figure for ours
    assert "| 100 % | 4 (3-5) |" in rows[2] and "| 100 % | 5 (4-6) |" in rows[3]
    assert section.count("Paired by seed") == 2
    assert ("of the 2 seeds where both modes settle, collaboration settles sooner in 1 and "
            "later in 1, by 1 iteration at the median") in section
    for figure in ("fig4_collab.png", "fig4_floor.png",
                   "fig4_laser-collab-three-rooms-long-corridor.png"):
        assert f"![{figure}]({figure})" in section
        assert (tmp_path / "report" / figure).stat().st_size > 0
