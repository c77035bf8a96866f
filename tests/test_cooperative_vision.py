"""Cooperative localization (seed 004 eq. 1-2) and potential-field navigation (eq. 3-5).

Expected values come from plain trigonometry on robots and objects placed at known world positions,
or from the paper's equations worked by hand, never from the code under test:

- eq. 1: f B = Z d (f = 190 px), so B = Z d / f;
- eq. 2: C^2 = A^2 + B^2 - 2 A B cos(alpha);
- eq. 3-5: U = k1 dist(q, goal)^2 + sum k2 / dist(q, o), so F_goal = 2 k1 (goal - q) and
  F_o = k2 / dist^2 away from the obstacle (inside its influence radius, zero outside).
"""

from __future__ import annotations

import dataclasses
import math

import numpy as np
import pytest

from swarmloc.agents.vision.cooperative import (
    FOCAL_PX,
    Detection,
    consistent,
    fresh,
    fuse,
    object_from_teammate,
    relative_heading_from_two_objects,
    size_distance_m,
    stereo_distance,
    stereo_relative_position,
    teammate_from_common_object,
    triangulate,
)
from swarmloc.agents.vision.potential_field import (
    BALL,
    OBSTACLE,
    FieldParams,
    assign_goals,
    potential,
    potential_field,
)

TOL = 1e-9


# ---------------------------------------------------------------------------------------------
# Plain-trig world helpers (independent of the code under test)
# ---------------------------------------------------------------------------------------------


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _in_frame(point, robot, heading) -> tuple[float, float]:
    """World point in the body frame of a robot at ``robot`` with ``heading``."""
    dx, dy = point[0] - robot[0], point[1] - robot[1]
    c, s = math.cos(heading), math.sin(heading)
    return (c * dx + s * dy, -s * dx + c * dy)


def _see(robot_id, robot, heading, obj, colour="pink", pan=None, t=0.0) -> Detection:
    x, y = _in_frame(obj, robot, heading)
    bearing = math.atan2(y, x)
    return Detection(
        robot_id, t, colour, bearing, bearing if pan is None else pan, 20.0, math.hypot(x, y)
    )


def _random_config(rng):
    p1 = rng.uniform(-2, 2, 2)
    p2 = rng.uniform(-2, 2, 2)
    obj = rng.uniform(-2, 2, 2)
    h1, h2 = rng.uniform(-math.pi, math.pi, 2)
    return p1, p2, obj, h1, h2


# ---------------------------------------------------------------------------------------------
# Detection record and freshness
# ---------------------------------------------------------------------------------------------


def test_detection_position_and_validation():
    d = Detection(1, 0.5, "pink", math.pi / 6, 0.0, 12.0, 2.0)
    np.testing.assert_allclose(d.position_m(), [2 * math.sqrt(3) / 2, 1.0], atol=TOL)
    with pytest.raises(dataclasses.FrozenInstanceError):
        d.distance_m = 3.0  # type: ignore[misc]


@pytest.mark.parametrize(
    "kwargs",
    [
        {"distance_m": 0.0},
        {"distance_m": -1.0},
        {"distance_m": float("nan")},
        {"size_px": 0.0},
        {"bearing_rad": 4.0},
        {"head_pan_rad": float("inf")},
        {"time_s": -1.0},
        {"robot_id": -2},
        {"colour": ""},
    ],
)
def test_detection_rejects_impossible_values(kwargs):
    base = {
        "robot_id": 0,
        "time_s": 1.0,
        "colour": "pink",
        "bearing_rad": 0.1,
        "head_pan_rad": 0.0,
        "size_px": 10.0,
        "distance_m": 1.0,
    }
    with pytest.raises(ValueError):
        Detection(**{**base, **kwargs})


def test_fresh_window():
    dets = [Detection(0, t, "pink", 0.0, 0.0, 10.0, 1.0) for t in (0.0, 0.9, 1.0, 2.5, 3.0, 3.5)]
    kept = [d.time_s for d in fresh(dets, now_s=3.0)]
    assert kept == [1.0, 2.5, 3.0]  # age 3.0 and 2.1 dropped, age 2.0 kept, future 3.5 dropped
    assert [d.time_s for d in fresh(dets, now_s=3.0, window_s=0.5)] == [2.5, 3.0]
    assert fresh([], now_s=1.0) == []
    with pytest.raises(ValueError):
        fresh(dets, now_s=3.0, window_s=-1.0)


def test_size_distance():
    # 0.08 m ball seen 19 px wide: Z = 190 * 0.08 / 19 = 0.8 m.
    assert float(size_distance_m(0.08, 19.0)) == pytest.approx(0.8, abs=TOL)
    assert math.isnan(float(size_distance_m(0.08, 0.0)))


# ---------------------------------------------------------------------------------------------
# Eq. 1: stereo
# ---------------------------------------------------------------------------------------------


def test_stereo_distance_eq1_hand():
    # R1 at (0, 0) and R2 at (0, 0.4), both facing +x, object at (2, 0.1):
    # x1 = 190 * 0.1 / 2 = 9.5 px, x2 = 190 * -0.3 / 2 = -28.5 px, d = 38 px, B = 2 * 38 / 190.
    assert float(stereo_distance(2.0, 38.0)) == pytest.approx(0.4, abs=TOL)
    assert FOCAL_PX == 190.0
    np.testing.assert_allclose(stereo_distance([1.0, 2.0], [19.0, -19.0]), [0.1, -0.2], atol=TOL)
    assert math.isnan(float(stereo_distance(0.0, 10.0)))
    with pytest.raises(ValueError):
        stereo_distance(1.0, 1.0, focal_px=0.0)


def test_stereo_relative_position_side_by_side():
    mine = _see(0, (0, 0), 0.0, (2, 0.1), pan=0.0)
    theirs = _see(1, (0, 0.4), 0.0, (2, 0.1), pan=0.0)
    np.testing.assert_allclose(stereo_relative_position(mine, theirs), [0.0, 0.4], atol=TOL)


def test_stereo_random_configurations_exact():
    rng = np.random.default_rng(4)
    solved = 0
    for _ in range(300):
        p1, p2, obj, h1, h2 = _random_config(rng)
        if math.dist(p1, obj) < 0.1 or math.dist(p2, obj) < 0.1:
            continue
        pan1 = _wrap(math.atan2(*_in_frame(obj, p1, h1)[::-1]) + rng.uniform(-0.4, 0.4))
        mine = _see(0, p1, h1, obj, pan=pan1)
        theirs = _see(1, p2, h2, obj)
        truth = _in_frame(p2, p1, h1)
        # Teammate's ray direction relative to my camera axis, from world geometry.
        ray2 = math.atan2(obj[1] - p2[1], obj[0] - p2[0]) - h1
        got = stereo_relative_position(mine, theirs, relative_heading_rad=h2 - h1)
        if math.cos(ray2 - pan1) * math.dist(p2, obj) <= 1e-9:
            assert got is None  # object at/behind the rectified teammate camera: no disparity
        else:
            solved += 1
            np.testing.assert_allclose(got, truth, atol=TOL)
    assert solved > 150


def test_stereo_degenerate_object_on_the_baseline():
    # Parallel cameras facing +x, object collinear with both robots: depth 0, no disparity.
    mine = _see(0, (0, 0), 0.0, (0, 1.0), pan=0.0)
    theirs = _see(1, (0, 0.4), 0.0, (0, 1.0), pan=0.0)
    assert stereo_relative_position(mine, theirs) is None


def test_stereo_refuses_different_objects():
    with pytest.raises(ValueError):
        stereo_relative_position(
            _see(0, (0, 0), 0, (1, 0), "pink"), _see(1, (0, 1), 0, (1, 0), "orange")
        )


# ---------------------------------------------------------------------------------------------
# Eq. 2: triangulation
# ---------------------------------------------------------------------------------------------


def test_triangulate_eq2_hand():
    # a = 3, b = 4, alpha = 90 deg: c = 5 (eq. 2). Vertex straight ahead at (3, 0); the ray to the
    # other point turns +90 deg from the ray back to me (pointing -x), i.e. points -y: other (3,-4).
    c, bearing = triangulate(3.0, 4.0, math.pi / 2, 0.0)
    assert float(c) == pytest.approx(5.0, abs=TOL)
    assert float(bearing) == pytest.approx(math.atan2(-4, 3), abs=TOL)
    # a = b = 1, alpha = 60 deg: equilateral, c = 1, other at bearing -60 deg.
    c, bearing = triangulate(1.0, 1.0, math.pi / 3, 0.0)
    assert (float(c), float(bearing)) == pytest.approx((1.0, -math.pi / 3), abs=TOL)


def test_triangulate_vectorised_random():
    rng = np.random.default_rng(7)
    a = rng.uniform(0.2, 3.0, 500)
    b = rng.uniform(0.0, 3.0, 500)
    alpha = rng.uniform(-math.pi, math.pi, 500)
    beta_v = rng.uniform(-math.pi, math.pi, 500)
    vertex = np.stack([a * np.cos(beta_v), a * np.sin(beta_v)], axis=1)
    other = vertex + np.stack(
        [b * np.cos(beta_v + np.pi + alpha), b * np.sin(beta_v + np.pi + alpha)], axis=1
    )
    c, bearing = triangulate(a, b, alpha, beta_v)
    ok = np.isfinite(c)
    assert ok.sum() == 500
    np.testing.assert_allclose(c * np.cos(bearing), other[:, 0], atol=TOL)
    np.testing.assert_allclose(c * np.sin(bearing), other[:, 1], atol=TOL)


def test_triangulate_degenerate_is_nan():
    c, bearing = triangulate([1.0, 0.0, 1.0], [1.0, 1.0, -1.0], [0.0, 1.0, 1.0], 0.0)
    assert np.all(np.isnan(c)) and np.all(np.isnan(bearing))  # c = 0; a = 0; b < 0


def test_teammate_from_common_object_random_exact():
    rng = np.random.default_rng(11)
    for _ in range(300):
        p1, p2, obj, h1, h2 = _random_config(rng)
        if min(math.dist(p1, obj), math.dist(p2, obj), math.dist(p1, p2)) < 0.05:
            continue
        got = teammate_from_common_object(_see(0, p1, h1, obj), _see(1, p2, h2, obj), h2 - h1)
        np.testing.assert_allclose(got, _in_frame(p2, p1, h1), atol=TOL)


@pytest.mark.parametrize(
    "p2, obj",
    [
        ((2.0, 0.0), (1.0, 0.0)),  # object between the robots
        ((1.0, 0.0), (2.0, 0.0)),  # teammate between me and the object
        ((3.0, 0.0), (2.0, 0.0)),
    ],  # object between, teammate beyond
)
def test_teammate_collinear_is_exact_not_wrong(p2, obj):
    got = teammate_from_common_object(_see(0, (0, 0), 0.0, obj), _see(1, p2, 0.3, obj), 0.3)
    np.testing.assert_allclose(got, p2, atol=TOL)


def test_teammate_coincident_robots_is_none():
    assert (
        teammate_from_common_object(_see(0, (0, 0), 0, (1, 1)), _see(1, (0, 0), 0, (1, 1))) is None
    )


def test_object_from_teammate_random_exact():
    # Experiment 3 / Fig. 3: I cannot see the ball; the teammate can.
    rng = np.random.default_rng(12)
    for _ in range(300):
        p1, p2, ball, h1, h2 = _random_config(rng)
        if min(math.dist(p1, p2), math.dist(p2, ball)) < 0.05:
            continue
        got = object_from_teammate(_in_frame(p2, p1, h1), h2 - h1, _see(1, p2, h2, ball))
        np.testing.assert_allclose(got, _in_frame(ball, p1, h1), atol=TOL)


def test_object_from_teammate_hand_and_degenerate():
    # Teammate 1 m ahead of me facing left (+90 deg); it sees the ball 2 m straight ahead of it:
    # the ball is at (1, 2) in my frame, 5^0.5 m away.
    theirs = Detection(1, 0.0, "pink", 0.0, 0.0, 10.0, 2.0)
    np.testing.assert_allclose(
        object_from_teammate((1.0, 0.0), math.pi / 2, theirs), [1.0, 2.0], atol=TOL
    )
    assert object_from_teammate((0.0, 0.0), 0.0, theirs) is None


def test_relative_heading_from_two_objects():
    rng = np.random.default_rng(13)
    for _ in range(200):
        p1, p2, obj_a, h1, h2 = _random_config(rng)
        obj_b = rng.uniform(-2, 2, 2)
        if (
            min(
                math.dist(obj_a, obj_b),
                math.dist(p1, obj_a),
                math.dist(p1, obj_b),
                math.dist(p2, obj_a),
                math.dist(p2, obj_b),
            )
            < 0.05
        ):
            continue
        mine = (_see(0, p1, h1, obj_a, "pink"), _see(0, p1, h1, obj_b, "orange"))
        theirs = (_see(1, p2, h2, obj_a, "pink"), _see(1, p2, h2, obj_b, "orange"))
        psi = relative_heading_from_two_objects(mine, theirs)
        assert _wrap(psi - (h2 - h1)) == pytest.approx(0.0, abs=TOL)
    same = (_see(0, (0, 0), 0, (1, 0), "pink"), _see(0, (0, 0), 0, (1, 0), "orange"))
    assert relative_heading_from_two_objects(same, same) is None


# ---------------------------------------------------------------------------------------------
# Consistency
# ---------------------------------------------------------------------------------------------


def test_consistency_rejects_planted_outlier():
    est = [(1.0, 1.0), (1.02, 0.99), (0.98, 1.01), (3.0, -2.0)]
    assert consistent(est, 0.1).tolist() == [True, True, True, False]
    np.testing.assert_allclose(fuse(est, 0.1), [1.0, 1.0], atol=TOL)


def test_fuse_contradictory_empty_single():
    assert fuse([(0.0, 0.0), (1.0, 0.0)], 0.1) is None  # two estimates that disagree
    assert fuse(np.zeros((0, 2)), 0.1) is None
    np.testing.assert_allclose(fuse([(0.3, -0.2)], 0.1), [0.3, -0.2])
    assert fuse([(0, 0), (0, 0), (5, 5), (6, 6)], 0.1) is None  # no strict majority
    with pytest.raises(ValueError):
        consistent([(0.0, float("nan"))], 0.1)
    with pytest.raises(ValueError):
        consistent([(0.0, 0.0)], -1.0)


def test_fusion_of_common_objects_rejects_wrong_size_distance():
    # Three objects seen by both robots; the teammate misjudges one object's size (+60 %).
    p1, h1, p2, h2 = (0.0, 0.0), 0.2, (0.3, 0.8), -0.4
    objects = [(2.0, 0.5), (1.5, -0.5), (2.5, 1.5)]
    estimates = []
    for k, obj in enumerate(objects):
        theirs = _see(1, p2, h2, obj)
        if k == 2:
            theirs = dataclasses.replace(theirs, distance_m=theirs.distance_m * 1.6)
        estimates.append(teammate_from_common_object(_see(0, p1, h1, obj), theirs, h2 - h1))
    assert consistent(estimates, 0.05).tolist() == [True, True, False]
    np.testing.assert_allclose(fuse(estimates, 0.05), _in_frame(p2, p1, h1), atol=TOL)


# ---------------------------------------------------------------------------------------------
# Eq. 3-5: potential field
# ---------------------------------------------------------------------------------------------

P = FieldParams(
    k1_per_s=1.0,
    k2_obstacle_m3_per_s=0.1,
    obstacle_radius_m=1.0,
    k2_teammate_m3_per_s=0.2,
    teammate_radius_m=0.8,
    max_speed_mps=10.0,
    min_distance_m=0.01,
)


def test_goal_straight_ahead():
    cmd = potential_field((0, 0), (1.5, 0), params=P)
    np.testing.assert_allclose(cmd.attraction, [3.0, 0.0], atol=TOL)  # 2 k1 (goal - q)
    np.testing.assert_allclose(cmd.velocity_mps, [3.0, 0.0], atol=TOL)
    assert cmd.heading_rad == pytest.approx(0.0, abs=TOL)
    sat = potential_field((0, 0), (1.5, 0), params=dataclasses.replace(P, max_speed_mps=0.3))
    np.testing.assert_allclose(sat.velocity_mps, [0.3, 0.0], atol=TOL)


def test_obstacle_inside_and_outside_radius():
    inside = potential_field((0, 0), None, obstacles_m=[(0.5, 0.0)], params=P)
    np.testing.assert_allclose(inside.repulsion, [-0.1 / 0.25, 0.0], atol=TOL)  # k2 / d^2
    assert inside.heading_rad == pytest.approx(math.pi, abs=TOL)
    outside = potential_field((0, 0), None, obstacles_m=[(1.5, 0.0)], params=P)
    np.testing.assert_allclose(outside.repulsion, [0.0, 0.0], atol=TOL)
    assert outside.heading_rad is None
    oblique = potential_field((0, 0), None, obstacles_m=[(0.3, 0.4)], params=P)
    np.testing.assert_allclose(oblique.repulsion, [-0.4 * 0.6, -0.4 * 0.8], atol=TOL)
    clamped = potential_field((0, 0), None, obstacles_m=[(0.005, 0.0)], params=P)
    np.testing.assert_allclose(clamped.repulsion, [-0.1 / 0.01**2, 0.0], rtol=TOL)


def test_goal_obstacle_and_teammate_combined():
    # Goal (1, 0): (2, 0). Obstacle (0.3, 0.4), d = 0.5: 0.4 * (-0.6, -0.8).
    # Teammate (0, 0.5): 0.2 / 0.25 = 0.8 along -y. Teammate (0, 0.9) is outside its 0.8 m radius.
    cmd = potential_field(
        (0, 0), (1, 0), obstacles_m=[(0.3, 0.4)], teammates_m=[(0, 0.5), (0, 0.9)], params=P
    )
    expected = np.array([2.0 - 0.24, -0.32 - 0.8])
    np.testing.assert_allclose(cmd.attraction + cmd.repulsion, expected, atol=TOL)
    np.testing.assert_allclose(cmd.velocity_mps, expected, atol=TOL)
    assert cmd.heading_rad == pytest.approx(math.atan2(expected[1], expected[0]), abs=TOL)
    # Shifting every position leaves the forces unchanged (the field is frame independent).
    shifted = potential_field(
        (2, -1), (3, -1), obstacles_m=[(2.3, -0.6)], teammates_m=[(2, -0.5), (2, -0.1)], params=P
    )
    np.testing.assert_allclose(shifted.velocity_mps, expected, atol=TOL)


def test_potential_values_and_gradient():
    # U = k1 * 1^2 + 0.1 / 0.5 + 0.2 / 0.5 = 1.6 (eq. 3-5).
    u = potential((0, 0), (1, 0), [(0.3, 0.4)], [(0, 0.5), (0, 0.9)], P)
    assert u == pytest.approx(1.0 + 0.2 + 0.4, abs=TOL)
    q, h = np.array([0.1, -0.05]), 1e-6
    grad = [
        (
            potential(q + e, (1, 0), [(0.3, 0.4)], [(0, 0.5)], P)
            - potential(q - e, (1, 0), [(0.3, 0.4)], [(0, 0.5)], P)
        )
        / (2 * h)
        for e in (np.array([h, 0.0]), np.array([0.0, h]))
    ]
    cmd = potential_field(q, (1, 0), [(0.3, 0.4)], [(0, 0.5)], P)
    np.testing.assert_allclose(cmd.attraction + cmd.repulsion, -np.array(grad), rtol=1e-6)


def test_at_goal_keeps_heading_and_repulsor_on_top_is_skipped():
    cmd = potential_field((1, 1), (1, 1), obstacles_m=[(1, 1)], params=P)
    np.testing.assert_allclose(cmd.velocity_mps, [0.0, 0.0])
    assert cmd.heading_rad is None


@pytest.mark.parametrize(
    "kwargs",
    [
        {"k1_per_s": -1.0},
        {"k2_obstacle_m3_per_s": float("nan")},
        {"max_speed_mps": 0.0},
        {"min_distance_m": 0.0},
        {"teammate_radius_m": -0.1},
    ],
)
def test_field_params_validated(kwargs):
    with pytest.raises(ValueError):
        FieldParams(**kwargs)


def test_field_params_frozen_and_bad_positions():
    with pytest.raises(dataclasses.FrozenInstanceError):
        P.k1_per_s = 2.0  # type: ignore[misc]
    with pytest.raises(ValueError):
        potential_field((0, 0), (1, 0), obstacles_m=[(float("nan"), 0.0)], params=P)


# ---------------------------------------------------------------------------------------------
# Goal assignment (§IV, experiments 1-3)
# ---------------------------------------------------------------------------------------------


def test_assign_goals_hand_cases():
    robots = [(0.0, 0.0), (1.0, 0.0)]
    # Obstacle (0.9, 0.5): distances 1.03 and 0.51 -> robot 1 takes it (Fig. 7a/b).
    assert assign_goals(robots, (0.9, 0.5), (0.0, 2.0)) == [BALL, OBSTACLE]
    assert assign_goals(robots, (0.1, -0.5), (0.0, 2.0)) == [OBSTACLE, BALL]
    # Experiment 1: no obstacle, both take the ball.
    assert assign_goals(robots, None, (0.5, 2.0)) == [BALL, BALL]
    # Tie: the lower index takes the obstacle.
    assert assign_goals(robots, (0.5, 0.7), (0.0, 2.0)) == [OBSTACLE, BALL]
    # Experiment 3 before the ball is shared: the ball's position is unknown.
    assert assign_goals(robots, (0.9, 0.5), None) == [None, OBSTACLE]
    # Three robots: only the nearest takes the obstacle.
    assert assign_goals([(0, 0), (2, 0), (4, 0)], (2.1, 0.2), (0, 3)) == [BALL, OBSTACLE, BALL]
    assert assign_goals(np.zeros((0, 2)), (1, 1), (0, 0)) == []
