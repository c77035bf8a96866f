"""Tests of the pure world models: arena, sensors, range-and-bearing medium, foraging metrics.

Geometry is checked against hand-computed values and against a plain-loop reference; noise and
loss against their laws with stated statistical tolerances (fixed seeds, so deterministic).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy import optimize, stats

from swarmloc.agents.epuck.foraging import NEST, PREY
from swarmloc.agents.epuck.foraging import classify_ground as agent_classify_ground
from swarmloc.protocol.epuck import GROUND_SENSOR_OFFSETS_M, IR_SENSOR_ANGLES_RAD
from swarmloc.world.epuck.arena import (
    AREA_NEST,
    AREA_NONE,
    AREA_PREY,
    GROUND_BLACK,
    GROUND_GREY,
    GROUND_WHITE,
    Arena,
    Disc,
    area_at,
    ground_reflectance,
    resolve_collisions,
)
from swarmloc.world.epuck.medium import Deliveries, RabMedium, deliver, loss_probability
from swarmloc.world.epuck.metrics import ForagingMetrics
from swarmloc.world.epuck.sensors import SensorParams, ground_sensors, ir_proximity

R = 0.035  # e-puck body radius (m)
NO_NOISE = SensorParams(ir_noise_fraction=0.0, ground_noise_fraction=0.0)
LOSSLESS = {"loss_near": 0.0, "loss_far": 0.0}


def unit_arena(side_m: float = 1.0) -> Arena:
    return Arena(
        side_m,
        side_m,
        nest=Disc((0.25 * side_m, 0.5 * side_m), 0.1),
        prey=Disc((0.75 * side_m, 0.5 * side_m), 0.1),
    )


def big_arena(side_m: float) -> Arena:
    return Arena(side_m, side_m, nest=Disc((0.3, 0.3), 0.1), prey=Disc((0.7, 0.3), 0.1))


# ---------------------------------------------------------------------------------------- arena


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"width_m": 0.0}, "width_m"),
        ({"height_m": -1.0}, "height_m"),
        ({"width_m": math.inf}, "width_m"),
        ({"nest": Disc((0.05, 0.5), 0.1)}, "nest"),
        ({"prey": Disc((0.5, 0.95), 0.1)}, "prey"),
        ({"prey": Disc((0.4, 0.5), 0.1)}, "prey"),  # overlaps the nest at (0.25, 0.5)
    ],
)
def test_arena_validation_names_the_field(kwargs, field):
    base = {
        "width_m": 1.0,
        "height_m": 1.0,
        "nest": Disc((0.25, 0.5), 0.1),
        "prey": Disc((0.75, 0.5), 0.1),
    }
    base.update(kwargs)
    with pytest.raises(ValueError, match=field):
        Arena(**base)


def test_disc_validation_and_touching_discs_allowed():
    with pytest.raises(ValueError, match="radius_m"):
        Disc((0.5, 0.5), 0.0)
    with pytest.raises(ValueError, match="centre_m"):
        Disc((0.5, math.nan), 0.1)
    Arena(1.0, 1.0, nest=Disc((0.3, 0.5), 0.1), prey=Disc((0.5, 0.5), 0.1))  # touching: fine


def test_area_and_reflectance():
    arena = unit_arena()
    pts = np.array(
        [
            [0.25, 0.5],  # nest centre
            [0.35, 0.5],  # nest rim counts as inside
            [0.75, 0.59],  # prey
            [0.5, 0.5],  # white floor
            [0.751, 0.601],  # just outside prey
        ]
    )
    np.testing.assert_array_equal(
        area_at(pts, arena), [AREA_NEST, AREA_NEST, AREA_PREY, AREA_NONE, AREA_NONE]
    )
    assert area_at(pts, arena).dtype == np.int8
    np.testing.assert_array_equal(
        ground_reflectance(pts, arena),
        [GROUND_BLACK, GROUND_BLACK, GROUND_GREY, GROUND_WHITE, GROUND_WHITE],
    )
    # Arbitrary leading axes.
    assert area_at(pts.reshape(5, 1, 2), arena).shape == (5, 1)
    assert (GROUND_WHITE, GROUND_GREY, GROUND_BLACK) == (1.0, 0.5, 0.1)


def test_two_overlapping_robots_end_exactly_two_radii_apart():
    arena = unit_arena()
    pos = np.array([[0.5, 0.5], [0.55, 0.5]])
    out = resolve_collisions(pos, R, arena)
    assert out is not pos
    np.testing.assert_array_equal(pos, [[0.5, 0.5], [0.55, 0.5]])  # input untouched
    assert math.dist(out[0], out[1]) == pytest.approx(2 * R, abs=1e-12)
    np.testing.assert_allclose(out.mean(axis=0), [0.525, 0.5], atol=1e-12)  # split evenly
    np.testing.assert_allclose(out[:, 1], 0.5, atol=1e-12)  # along the centre line
    # Diagonal overlap, one iteration is enough for a lone pair.
    out = resolve_collisions(np.array([[0.5, 0.5], [0.53, 0.54]]), R, arena, iterations=1)
    assert math.dist(out[0], out[1]) == pytest.approx(2 * R, abs=1e-12)


def test_only_movable_robot_is_pushed():
    arena = unit_arena()
    pos = np.array([[0.5, 0.5], [0.55, 0.5]])
    out = resolve_collisions(pos, R, arena, movable=np.array([False, True]))
    np.testing.assert_array_equal(out[0], [0.5, 0.5])
    np.testing.assert_allclose(out[1], [0.5 + 2 * R, 0.5], atol=1e-12)
    out = resolve_collisions(pos, R, arena, movable=np.array([False, False]))
    np.testing.assert_array_equal(out, pos)


def test_wall_clamp_and_coincident_robots():
    arena = unit_arena()
    out = resolve_collisions(np.array([[0.01, 0.5], [1.2, 1.2], [0.5, -3.0]]), R, arena)
    np.testing.assert_allclose(out, [[R, 0.5], [1 - R, 1 - R], [0.5, R]], atol=1e-15)
    # Immovable robots are not clamped either.
    out = resolve_collisions(np.array([[0.01, 0.5]]), R, arena, movable=np.array([False]))
    np.testing.assert_array_equal(out, [[0.01, 0.5]])
    # Same centre: split along x, lower index towards -x.
    out = resolve_collisions(np.array([[0.5, 0.5], [0.5, 0.5]]), R, arena)
    np.testing.assert_allclose(out, [[0.5 - R, 0.5], [0.5 + R, 0.5]], atol=1e-12)


def test_crowd_is_separated_and_stays_inside():
    arena = unit_arena()
    rng = np.random.default_rng(3)
    pos = rng.uniform(0, 1, size=(120, 2))

    def worst_overlap(p):
        d = np.hypot(*(p[:, None, :] - p[None, :, :]).transpose(2, 0, 1))
        d[np.diag_indices(len(p))] = np.inf
        return max(0.0, 2 * R - d.min())

    before = worst_overlap(pos)
    out = resolve_collisions(pos, R, arena, iterations=60)
    assert before > 0.03
    assert worst_overlap(out) < 1e-3
    assert (out >= R).all() and (out <= 1 - R).all()
    np.testing.assert_array_equal(out, resolve_collisions(pos, R, arena, iterations=60))


@settings(max_examples=40, deadline=None)
@given(
    xy=st.lists(st.tuples(st.floats(-0.5, 1.5), st.floats(-0.5, 1.5)), min_size=1, max_size=20),
    mask=st.lists(st.booleans(), min_size=20, max_size=20),
)
def test_collision_invariants(xy, mask):
    arena = unit_arena()
    pos = np.array(xy)
    movable = np.array(mask[: len(xy)])
    out = resolve_collisions(pos, R, arena, movable=movable)
    np.testing.assert_array_equal(out[~movable], pos[~movable])
    assert (out[movable] >= R - 1e-12).all()
    assert (out[movable, 0] <= 1 - R + 1e-12).all() and (out[movable, 1] <= 1 - R + 1e-12).all()


# -------------------------------------------------------------------------------------- sensors


def ir_reference(pose, radius_m, arena, range_m):
    """Plain-loop ray casting: textbook ray-circle quadratic and ray-plane walls."""
    n = len(pose)
    out = np.zeros((n, 8))
    for i in range(n):
        for s in range(8):
            ang = pose[i, 2] + IR_SENSOR_ANGLES_RAD[s]
            u = np.array([math.cos(ang), math.sin(ang)])
            o = pose[i, :2] + radius_m * u
            best = math.inf
            for k, wall in ((0, 0.0), (0, arena.width_m), (1, 0.0), (1, arena.height_m)):
                if u[k] != 0:
                    t = (wall - o[k]) / u[k]
                    if t >= 0:
                        best = min(best, t)
            for j in range(n):
                if j == i:
                    continue
                f = o - pose[j, :2]
                bq = 2 * f @ u
                cq = f @ f - radius_m**2
                if cq <= 0:
                    best = 0.0
                    continue
                dq = bq * bq - 4 * cq
                if dq >= 0:
                    t = (-bq - math.sqrt(dq)) / 2
                    if t >= 0:
                        best = min(best, t)
            out[i, s] = min(max(1 - best / range_m, 0.0), 1.0)
    return out


def test_ir_wall_in_front_hand_computed():
    arena = unit_arena()
    pose = np.array([[0.945, 0.5, 0.0]])  # facing the wall x = 1, 2 cm gap
    got = ir_proximity(pose, R, arena, NO_NOISE, np.random.default_rng(0))[0]
    c17 = math.cos(math.radians(17))
    d = (1.0 - (0.945 + R * c17)) / c17  # = 0.022513 m along the +-17 deg rays
    expected = 1 - d / 0.04
    assert expected == pytest.approx(0.43718, abs=1e-5)
    assert got[0] == pytest.approx(expected, abs=1e-12)
    assert got[7] == pytest.approx(expected, abs=1e-12)
    np.testing.assert_array_equal(got[1:7], 0.0)  # 49 deg rays: 4.9 cm, beyond range


def test_ir_side_wall_hand_computed():
    arena = unit_arena()
    pose = np.array([[0.5, 0.05, 0.0]])  # wall y = 0 on the right-hand side
    got = ir_proximity(pose, R, arena, NO_NOISE, np.random.default_rng(0))[0]
    s49 = math.sin(math.radians(49))
    expected = np.zeros(8)
    expected[1] = 1 - ((0.05 - R * s49) / s49) / 0.04  # 0.21873
    expected[2] = 1 - (0.05 - R) / 0.04  # 0.625: IR2 looks straight at the wall
    assert expected[1] == pytest.approx(0.21873, abs=1e-5)
    np.testing.assert_allclose(got, expected, atol=1e-12)
    # Rotating the robot by +90 deg and the arena with it: same readings off the wall x = 1.
    got = ir_proximity(
        np.array([[0.95, 0.5, math.pi / 2]]), R, arena, NO_NOISE, np.random.default_rng(0)
    )[0]
    np.testing.assert_allclose(got, expected, atol=1e-12)


def test_ir_robot_in_front_ray_circle_distance():
    arena = unit_arena()
    pose = np.array([[0.5, 0.5, 0.0], [0.59, 0.5, 0.0]])  # 2 cm gap straight ahead
    got = ir_proximity(pose, R, arena, NO_NOISE, np.random.default_rng(0))

    # Independent check: first root of |o + t u - c| = R found numerically.
    u = np.array([math.cos(math.radians(-17)), math.sin(math.radians(-17))])
    o = pose[0, :2] + R * u
    t = optimize.brentq(lambda t: np.linalg.norm(o + t * u - pose[1, :2]) - R, 0.0, 0.035)
    assert t == pytest.approx(0.027989, abs=1e-6)  # by hand from the quadratic
    assert got[0, 0] == pytest.approx(1 - t / 0.04, abs=1e-12)
    assert got[0, 7] == pytest.approx(1 - t / 0.04, abs=1e-12)
    np.testing.assert_array_equal(got[0, 1:7], 0.0)
    # The robot ahead: its +-150 deg rear sensors pass beside the follower (miss).
    np.testing.assert_array_equal(got[1], 0.0)

    # Overlapping bodies (centres 5 cm apart): the front sensor spots are inside -> 1.
    got = ir_proximity(
        np.array([[0.5, 0.5, 0.0], [0.55, 0.5, 0.0]]), R, arena, NO_NOISE, np.random.default_rng(0)
    )
    assert got[0, 0] == 1.0 and got[0, 7] == 1.0


def test_ir_matches_loop_reference():
    arena = unit_arena(0.6)
    rng = np.random.default_rng(11)
    pose = np.column_stack(
        [rng.uniform(0, 0.6, 60), rng.uniform(0, 0.6, 60), rng.uniform(-np.pi, np.pi, 60)]
    )
    pose[:, :2] = resolve_collisions(pose[:, :2], R, arena, iterations=3)
    got = ir_proximity(pose, R, arena, NO_NOISE, np.random.default_rng(0))
    ref = ir_reference(pose, R, arena, 0.04)
    assert (ref > 0).sum() > 60  # the scene really has obstacles in range
    np.testing.assert_allclose(got, ref, atol=1e-12)


def test_ir_noise_is_multiplicative_and_bounded():
    # A tall arena holds a column of robots 20 cm apart (out of each other's IR range), all
    # facing the wall x = 1 from 2 cm: the same clean reading for each.
    n = 5000
    arena = Arena(1.0, 0.2 * n + 1.0, nest=Disc((0.2, 0.2), 0.1), prey=Disc((0.5, 0.2), 0.1))
    pose = np.column_stack([np.full(n, 0.945), 0.5 + 0.2 * np.arange(n), np.zeros(n)])
    clean = ir_proximity(pose, R, arena, NO_NOISE, np.random.default_rng(0))
    np.testing.assert_allclose(clean[:, 0], clean[0, 0], atol=1e-12)
    vals = ir_proximity(pose, R, arena, SensorParams(), np.random.default_rng(5))
    ratio = vals[:, 0] / clean[0, 0]
    assert ratio.min() >= 0.8 and ratio.max() <= 1.2
    sd = 0.2 / math.sqrt(3)
    assert abs(ratio.mean() - 1) < 5 * sd / math.sqrt(n)
    assert ratio.std() == pytest.approx(sd, rel=0.03)
    np.testing.assert_array_equal(vals[:, 1:7], 0.0)  # nothing in range stays 0
    # Touching a wall (value 1) never exceeds 1 after noise.
    touching = ir_proximity(
        np.array([[0.5, R, 0.0]]), R, unit_arena(), SensorParams(), np.random.default_rng(1)
    )[0]
    assert touching.max() <= 1.0 and touching[2] >= 0.8


def test_ground_sensors_positions_and_values():
    arena = unit_arena()
    rng = np.random.default_rng(0)
    pose = np.array([[0.25, 0.5, 0.3], [0.75, 0.5, -2.0], [0.5, 0.8, 1.0]])
    np.testing.assert_allclose(
        ground_sensors(pose, arena, NO_NOISE, rng),
        [[0.1] * 3, [0.5] * 3, [1.0] * 3],
    )
    # Heading +y: robot-frame (0.03, +0.01) (left) maps to world (-0.01, +0.03).
    assert GROUND_SENSOR_OFFSETS_M[0, 1] > 0
    straddle = np.array([[0.355, 0.47, math.pi / 2]])  # left sensor 9.5 cm from nest centre
    np.testing.assert_allclose(ground_sensors(straddle, arena, NO_NOISE, rng), [[0.1, 1.0, 1.0]])


def test_ground_noise_bounds_and_spread():
    arena = unit_arena()
    rng = np.random.default_rng(8)
    n = 20000
    pose = np.column_stack([np.full(n, 0.5), np.full(n, 0.8), rng.uniform(-np.pi, np.pi, n)])
    ratio = ground_sensors(pose, arena, SensorParams(), rng).ravel() / GROUND_WHITE
    assert ratio.min() >= 0.7 and ratio.max() < 1.3
    sd = 0.3 / math.sqrt(3)
    assert abs(ratio.mean() - 1) < 5 * sd / math.sqrt(ratio.size)
    assert ratio.std() == pytest.approx(sd, rel=0.02)


def classify_ground(readings):
    """The agent's ground perception, in the world's AREA_* codes: the world's sensor bands and
    the agent's thresholds must fit each other."""
    code = agent_classify_ground(readings)
    return np.where(code == NEST, AREA_NEST, np.where(code == PREY, AREA_PREY, AREA_NONE))


def test_classify_ground_band_edges():
    readings = np.array(
        [
            [0.07, 1.0, 1.0],
            [1.3, 0.13, 1.3],  # black edges -> nest
            [0.35, 0.7, 0.7],
            [1.0, 1.0, 0.65],  # grey edges -> prey
            [0.7, 1.3, 1.0],  # white edges -> none
            [0.1, 0.5, 1.0],  # nest wins over prey
        ]
    )
    got = classify_ground(readings)
    np.testing.assert_array_equal(
        got, [AREA_NEST, AREA_NEST, AREA_PREY, AREA_PREY, AREA_NONE, AREA_NEST]
    )


def test_classify_ground_never_wrong_over_noisy_samples():
    arena = unit_arena()
    rng = np.random.default_rng(21)
    n = 30000
    # Half the robots near the disc rims so that many straddle two colours.
    centre = np.where(rng.random(n)[:, None] < 0.5, [0.25, 0.5], [0.75, 0.5])
    ang = rng.uniform(-np.pi, np.pi, n)
    rad = rng.uniform(0.0, 0.16, n)
    near = centre + rad[:, None] * np.column_stack([np.cos(ang), np.sin(ang)])
    anywhere = rng.uniform(0.05, 0.95, size=(n, 2))
    xy = np.where((np.arange(n) % 2 == 0)[:, None], near, anywhere)
    pose = np.column_stack([xy, rng.uniform(-np.pi, np.pi, n)])
    truth = ground_sensors(pose, arena, NO_NOISE, rng)
    expected = np.where(
        (truth == GROUND_BLACK).any(1),
        AREA_NEST,
        np.where((truth == GROUND_GREY).any(1), AREA_PREY, AREA_NONE),
    )
    mixed = (truth != truth[:, :1]).any(1).sum()
    assert mixed > 300  # the sample really exercises straddling robots
    for _ in range(3):
        readings = ground_sensors(pose, arena, SensorParams(), rng)
        np.testing.assert_array_equal(classify_ground(readings), expected)


# --------------------------------------------------------------------------------------- medium


@pytest.mark.parametrize(
    "kwargs, field",
    [
        ({"range_m": 0.005}, "range_m"),
        ({"near_m": 0.0}, "near_m"),
        ({"range_noise_m": -0.1}, "range_noise_m"),
        ({"bearing_noise_rad": 4.0}, "bearing_noise_rad"),
        ({"bearing_noise_rad": math.nan}, "bearing_noise_rad"),
        ({"loss_near": -0.01}, "loss_near"),
        ({"loss_far": 1.5}, "loss_far"),
        ({"max_payload_bytes": 0}, "max_payload_bytes"),
        ({"max_payload_bytes": 62.5}, "max_payload_bytes"),
        ({"max_received_per_tick": 0}, "max_received_per_tick"),
        ({"max_received_per_tick": True}, "max_received_per_tick"),
    ],
)
def test_medium_validation_names_the_field(kwargs, field):
    with pytest.raises(ValueError, match=field):
        RabMedium(**kwargs)


def test_loss_probability_is_the_linear_law():
    m = RabMedium()
    d = np.array([0.0, 0.005, 0.01, 0.08, 0.15, 0.3])
    np.testing.assert_allclose(
        loss_probability(d, m), [0.01, 0.01, 0.01, 0.01 + 0.49 * 0.5, 0.5, 0.5], atol=1e-15
    )


def random_swarm(n, side_m, seed):
    rng = np.random.default_rng(seed)
    return np.column_stack(
        [rng.uniform(0, side_m, n), rng.uniform(0, side_m, n), rng.uniform(-np.pi, np.pi, n)]
    )


def test_delivers_exactly_the_pairs_in_range_and_nothing_beyond():
    pose = random_swarm(300, 1.5, 1)
    sending = np.random.default_rng(2).random(300) < 0.5
    m = RabMedium(range_noise_m=0.0, bearing_noise_rad=0.0, max_received_per_tick=1000, **LOSSLESS)
    got = deliver(pose, sending, m, np.random.default_rng(3))
    d = np.hypot(*(pose[:, None, :2] - pose[None, :, :2]).transpose(2, 0, 1))  # d[s, r]
    s_idx, r_idx = np.nonzero((d <= 0.15) & sending[:, None] & ~np.eye(300, dtype=bool))
    order = np.lexsort((s_idx, r_idx))
    np.testing.assert_array_equal(got.sender, s_idx[order])
    np.testing.assert_array_equal(got.receiver, r_idx[order])
    np.testing.assert_allclose(got.range_m, d[s_idx[order], r_idx[order]], atol=1e-15)
    assert got.sender.dtype == np.int64 and got.receiver.dtype == np.int64
    assert len(got) > 200

    # Default (lossy, noisy, capped) medium: still nothing beyond range, sorted output.
    got = deliver(pose, np.ones(300, bool), RabMedium(), np.random.default_rng(4))
    assert (d[got.sender, got.receiver] <= 0.15).all()
    assert (got.sender != got.receiver).all()
    key = got.receiver * 300 + got.sender
    assert (np.diff(key) > 0).all()
    assert np.bincount(got.receiver).max() <= 4
    assert (got.range_m >= 0).all()
    assert (got.bearing_rad >= -np.pi).all() and (got.bearing_rad < np.pi).all()


def test_bearing_geometry_in_receiver_frame():
    m = RabMedium(range_noise_m=0.0, bearing_noise_rad=0.0, **LOSSLESS)
    pose = np.array(
        [
            [0.0, 0.0, math.pi / 2],  # 0: receiver heading +y
            [0.1, 0.0, 0.0],  # 1: on the receiver's right
            [0.0, 0.1, 0.0],  # 2: straight ahead of robot 0
        ]
    )
    got = deliver(pose, np.array([False, True, True]), m, np.random.default_rng(0))
    to0 = got.receiver == 0
    np.testing.assert_array_equal(got.sender[to0], [1, 2])
    np.testing.assert_allclose(got.bearing_rad[to0], [-math.pi / 2, 0.0], atol=1e-12)
    np.testing.assert_allclose(got.range_m[to0], [0.1, 0.1], atol=1e-12)
    # Robot 1 (heading +x) hears 2 at (-0.1, +0.1) relative: 135 deg to its left.
    to1 = got.receiver == 1
    np.testing.assert_array_equal(got.sender[to1], [2])
    np.testing.assert_allclose(got.bearing_rad[to1], [3 * math.pi / 4], atol=1e-12)
    # Directly behind wraps to -pi.
    got = deliver(
        np.array([[0.0, 0.0, 0.0], [-0.1, 0.0, 0.0]]),
        np.array([False, True]),
        m,
        np.random.default_rng(0),
    )
    assert got.bearing_rad[0] == pytest.approx(-math.pi, abs=1e-12)


def pairs_at(distance_m, n_pairs):
    """n_pairs sender->receiver pairs at a given distance, 0.5 m apart from each other."""
    side = math.ceil(math.sqrt(n_pairs))
    g = np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2)[:n_pairs] * 0.5
    heading = np.random.default_rng(n_pairs).uniform(-np.pi, np.pi, 2 * n_pairs)
    xy = np.concatenate([g, g + [distance_m, 0.0]])
    return np.column_stack([xy, heading])


def test_range_and_bearing_noise_uniform_within_bounds():
    n_pairs = 12000  # both directions: 24,000 samples
    m = RabMedium(**LOSSLESS)
    pose = pairs_at(0.1, n_pairs)
    got = deliver(pose, np.ones(len(pose), bool), m, np.random.default_rng(7))
    assert len(got) == 2 * n_pairs
    rel = pose[got.sender, :2] - pose[got.receiver, :2]
    true_bearing = np.arctan2(rel[:, 1], rel[:, 0]) - pose[got.receiver, 2]
    errors = {
        "range": (got.range_m - 0.1, 0.025),
        "bearing": (np.angle(np.exp(1j * (got.bearing_rad - true_bearing))), math.radians(20)),
    }
    for name, (err, bound) in errors.items():
        sd = bound / math.sqrt(3)
        assert err.min() >= -bound - 1e-12 and err.max() <= bound + 1e-12, name
        assert err.min() < -0.99 * bound and err.max() > 0.99 * bound, name
        assert abs(err.mean()) < 5 * sd / math.sqrt(err.size), name  # 5 sigma of the mean
        assert err.std() == pytest.approx(sd, rel=0.02), name
        assert stats.kstest(err, stats.uniform(-bound, 2 * bound).cdf).pvalue > 1e-3, name


def test_measured_range_clipped_at_zero():
    pose = pairs_at(0.01, 3000)
    got = deliver(pose, np.ones(len(pose), bool), RabMedium(**LOSSLESS), np.random.default_rng(1))
    assert (got.range_m >= 0).all()
    # P(0.01 + U(-0.025, 0.025) < 0) = 0.3.
    assert abs((got.range_m == 0).mean() - 0.3) < 4 * math.sqrt(0.3 * 0.7 / len(got))


@pytest.mark.parametrize("distance_m", [0.005, 0.01, 0.04, 0.08, 0.12, 0.149])
def test_loss_rate_follows_the_linear_law(distance_m):
    n_pairs = 10000  # both directions: 20,000 independent trials
    pose = pairs_at(distance_m, n_pairs)
    got = deliver(pose, np.ones(len(pose), bool), RabMedium(), np.random.default_rng(99))
    trials = 2 * n_pairs
    p = float(loss_probability(np.array(distance_m), RabMedium()))
    lost = 1 - len(got) / trials
    assert abs(lost - p) < 4 * math.sqrt(p * (1 - p) / trials), (lost, p)


def test_cap_keeps_the_nearest_with_ties_by_sender_index():
    m = RabMedium(max_received_per_tick=4, **LOSSLESS)
    dists = [0.02, 0.1, 0.03, 0.12, 0.05, 0.07, 0.04]
    angles = np.linspace(0, 2 * np.pi, len(dists), endpoint=False)
    pose = np.zeros((1 + len(dists), 3))
    pose[1:, 0] = np.array(dists) * np.cos(angles)
    pose[1:, 1] = np.array(dists) * np.sin(angles)
    sending = np.array([False] + [True] * len(dists))
    got = deliver(pose, sending, m, np.random.default_rng(0))
    np.testing.assert_array_equal(got.sender[got.receiver == 0], [1, 3, 5, 7])
    assert np.bincount(got.receiver).max() <= 4

    tie = np.array([[0.0, 0.0, 0.0], [0.05, 0.0, 0.0], [-0.05, 0.0, 0.0], [0.0, 0.05, 0.0]])
    for cap, kept in ((1, [1]), (2, [1, 2])):
        m = RabMedium(max_received_per_tick=cap, **LOSSLESS)
        got = deliver(
            tie[[0, 3, 2, 1]], np.array([False, True, True, True]), m, np.random.default_rng(0)
        )
        # Senders are now indices 1 (0, 0.05), 2 (-0.05, 0), 3 (0.05, 0): all at 5 cm.
        np.testing.assert_array_equal(got.sender[got.receiver == 0], kept)


def test_documented_draw_order():
    pose = random_swarm(40, 0.4, 5)
    sending = np.arange(40) % 3 != 0
    m = RabMedium(max_received_per_tick=1000)
    got = deliver(pose, sending, m, np.random.default_rng(42))

    # Rebuild by hand: candidates in (receiver, sender) order, loss, then range, then bearing.
    rng = np.random.default_rng(42)
    cand = [
        (r, s)
        for r in range(40)
        for s in range(40)
        if s != r and sending[s] and math.dist(pose[s, :2], pose[r, :2]) <= m.range_m
    ]
    d = np.array([math.dist(pose[s, :2], pose[r, :2]) for r, s in cand])
    keep = rng.random(len(cand)) >= loss_probability(d, m)
    kept = [c for c, k in zip(cand, keep) if k]
    assert 0 < len(kept) < len(cand)
    range_noise = rng.uniform(-m.range_noise_m, m.range_noise_m, len(kept))
    bearing_noise = rng.uniform(-m.bearing_noise_rad, m.bearing_noise_rad, len(kept))
    np.testing.assert_array_equal(got.receiver, [r for r, _ in kept])
    np.testing.assert_array_equal(got.sender, [s for _, s in kept])
    np.testing.assert_allclose(got.range_m, np.maximum(d[keep] + range_noise, 0), atol=1e-15)
    rel = np.array([pose[s, :2] - pose[r, :2] for r, s in kept])
    heading = np.array([pose[r, 2] for r, _ in kept])
    want = np.arctan2(rel[:, 1], rel[:, 0]) - heading + bearing_noise
    np.testing.assert_allclose(np.angle(np.exp(1j * (got.bearing_rad - want))), 0, atol=1e-12)


def test_deliver_edge_cases():
    m = RabMedium()
    for pose, sending in (
        (np.zeros((0, 3)), np.zeros(0, bool)),
        (np.zeros((1, 3)), np.ones(1, bool)),
        (np.array([[0, 0, 0], [0.05, 0, 0]]), np.zeros(2, bool)),  # nobody sends
        (np.array([[0, 0, 0], [0.5, 0, 0]]), np.ones(2, bool)),  # out of range
    ):
        got = deliver(pose, sending, m, np.random.default_rng(0))
        assert isinstance(got, Deliveries) and len(got) == 0
        assert got.sender.dtype == np.int64 and got.range_m.dtype == np.float64
    with pytest.raises(ValueError, match="sending"):
        deliver(np.zeros((2, 3)), np.ones(3, bool), m, np.random.default_rng(0))


# ------------------------------------------------------------------------------- determinism


def test_same_seed_same_arrays():
    arena = unit_arena(2.0)
    pose = random_swarm(200, 2.0, 9)

    def run(seed):
        rng = np.random.default_rng(seed)
        ir = ir_proximity(pose, R, arena, SensorParams(), rng)
        gr = ground_sensors(pose, arena, SensorParams(), rng)
        rab = deliver(pose, np.ones(200, bool), RabMedium(), rng)
        return [ir, gr, rab.sender, rab.receiver, rab.range_m, rab.bearing_rad]

    a, b, c = run(1), run(1), run(2)
    for x, y in zip(a, b):
        np.testing.assert_array_equal(x, y)
    assert not np.array_equal(a[0], c[0])


# -------------------------------------------------------------------------------------- metrics

N_, E_, P_ = AREA_NONE, AREA_NEST, AREA_PREY
SCRIPT = np.array(
    [
        # tick: 0   1   2   3   4   5   6   7   8   9  10
        [N_, E_, E_, N_, P_, N_, E_, P_, E_, E_, N_],  # 2 trips (ticks 6 and 8)
        [P_, P_, N_, E_, N_, P_, N_, N_, E_, N_, N_],  # prey first: 1 trip (tick 8)
        [N_, N_, N_, N_, N_, E_, N_, N_, N_, P_, N_],  # both areas found at tick 9, no trip
    ]
).T
ON_PATH_COUNT = [0, 1, 1, 2, 2, 3, 3, 3, 2, 3, 3]


def run_metrics(n_ticks):
    m = ForagingMetrics(3, dt_s=0.1, sample_every_ticks=2)
    for tick in range(n_ticks):
        on_path = np.arange(3) < ON_PATH_COUNT[tick]
        m.update(tick, SCRIPT[tick].astype(np.int8), on_path)
    return m


def test_metrics_scripted_trajectory():
    m = run_metrics(11)
    np.testing.assert_array_equal(m.first_visit_tick, [[1, 4], [3, 0], [5, 9]])
    s = m.summary()
    json.dumps(s)
    assert s["recruitment_time_s"] == pytest.approx(0.9)
    assert s["robots_found_both"] == 3
    assert s["round_trips_total"] == 3
    assert s["round_trips_per_robot"] == [2, 1, 0]
    np.testing.assert_allclose(
        s["on_path_series"], [[0.0, 0], [0.2, 1], [0.4, 2], [0.6, 3], [0.8, 2], [1.0, 3]]
    )
    assert all(isinstance(c, int) for _, c in s["on_path_series"])
    # Second half: ticks >= 5 -> samples at 6, 8, 10 -> counts 3, 2, 3 of 3 robots.
    assert s["on_path_fraction_mean"] == pytest.approx(8 / 9)


def test_metrics_not_everyone_recruited_and_validation():
    s = run_metrics(9).summary()
    assert s["recruitment_time_s"] is None
    assert s["robots_found_both"] == 2
    assert s["round_trips_per_robot"] == [2, 1, 0]
    m = ForagingMetrics(2, dt_s=0.1)
    m.update(0, np.zeros(2, np.int8), np.zeros(2, bool))
    with pytest.raises(ValueError, match="tick"):
        m.update(0, np.zeros(2, np.int8), np.zeros(2, bool))
    with pytest.raises(ValueError, match="area"):
        m.update(1, np.zeros(3, np.int8), np.zeros(2, bool))
    with pytest.raises(ValueError, match="dt_s"):
        ForagingMetrics(2, dt_s=0.0)
    assert ForagingMetrics(2, 0.1).summary()["on_path_fraction_mean"] is None
