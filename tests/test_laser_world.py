"""Tests of the laser robots' world models (world/laser/maps.py, world/laser/laser.py; seeds 002 and 003).

Geometry against hand-computed values and a plain per-ray loop; noise against its law with stated
tolerances (fixed seeds, so deterministic).
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.world.laser.laser import (
    LaserParams,
    MotionNoise,
    RelativeNoise,
    cast_rays,
    relative_observation,
    scan,
    unicycle_model,
    unicycle_step,
    visible_pairs,
)
from swarmloc.world.laser.maps import (
    MAPS,
    MapRegistry,
    SegmentMap,
    build_map,
    distance_to_walls,
    free_space_sample,
    line_of_sight,
    office_map,
)

RANGE_TOL_M = 1e-5  # cast_rays computes its inner products in float32


def box_map(width_m: float = 4.0, height_m: float = 2.0) -> SegmentMap:
    w, h = width_m, height_m
    return SegmentMap("box", np.array([[0, 0, w, 0], [w, 0, w, h], [w, h, 0, h], [0, h, 0, 0]]))


def reference_ray(segments_m, x, y, angle, max_range_m) -> float:
    """Textbook ray-segment intersection, one ray at a time."""
    dx, dy = math.cos(angle), math.sin(angle)
    best = max_range_m
    for x1, y1, x2, y2 in segments_m:
        ex, ey = x2 - x1, y2 - y1
        denom = dx * ey - dy * ex
        if abs(denom) < 1e-12:
            continue
        wx, wy = x1 - x, y1 - y
        t = (wx * ey - wy * ex) / denom
        u = (wx * dy - wy * dx) / denom
        if t >= 0.0 and 0.0 <= u <= 1.0:
            best = min(best, t)
    return best


# ---------------------------------------------------------------- ray casting


def test_centre_of_box_axis_beams():
    ranges = cast_rays(box_map(), np.array([[2.0, 1.0, 0.0]]), np.radians([0, 90, 180, 270]), 10.0)
    np.testing.assert_allclose(ranges, [[2.0, 1.0, 2.0, 1.0]], atol=RANGE_TOL_M)


def test_heading_rotates_beams():
    ranges = cast_rays(
        box_map(), np.array([[2.0, 1.0, math.pi / 2]]), np.array([0.0, math.pi / 2]), 10.0
    )
    np.testing.assert_allclose(ranges, [[1.0, 2.0]], atol=RANGE_TOL_M)


def test_diagonal_beams_by_hand():
    world = box_map()
    # From (1, 0.5) at 45 deg: the top wall y = 2 is reached after 1.5 / sin 45 = 2.1213 m,
    # at x = 2.5 < 4, before the right wall.
    r = cast_rays(world, np.array([[1.0, 0.5, 0.0]]), np.array([math.pi / 4]), 10.0)
    assert r[0, 0] == pytest.approx(1.5 * math.sqrt(2.0), abs=RANGE_TOL_M)
    # From the centre towards the corner (4, 2): the corner itself, sqrt(2^2 + 1^2) away.
    angle = math.atan2(1.0, 2.0)
    r = cast_rays(world, np.array([[2.0, 1.0, 0.0]]), np.array([angle]), 10.0)
    assert r[0, 0] == pytest.approx(math.sqrt(5.0), abs=RANGE_TOL_M)
    # 30 deg from (0.5, 0.5): the top wall at 1.5 / sin 30 = 3 m (x = 3.098 < 4).
    r = cast_rays(world, np.array([[0.5, 0.5, 0.0]]), np.array([math.radians(30)]), 10.0)
    assert r[0, 0] == pytest.approx(3.0, abs=RANGE_TOL_M)


def test_parallel_segment_is_not_hit():
    # A wall along the beam (y = 0, ahead of the robot) and one parallel beside it.
    world = SegmentMap("parallel", np.array([[1.0, 0.0, 3.0, 0.0], [1.0, 0.5, 3.0, 0.5]]))
    r = cast_rays(world, np.array([[0.0, 0.0, 0.0], [0.0, 0.25, 0.0]]), np.array([0.0]), 5.0)
    np.testing.assert_allclose(r, [[5.0], [5.0]])


def test_beyond_max_range_returns_max_range():
    world = box_map(40.0, 2.0)
    r = cast_rays(world, np.array([[1.0, 1.0, 0.0]]), np.array([0.0, math.pi, math.pi / 2]), 6.0)
    np.testing.assert_allclose(r, [[6.0, 1.0, 1.0]], atol=RANGE_TOL_M)
    # A wall exactly at max range counts as a miss or hit alike: both give max range.
    r = cast_rays(box_map(), np.array([[2.0, 1.0, 0.0]]), np.array([0.0]), 2.0)
    assert r[0, 0] == pytest.approx(2.0, abs=RANGE_TOL_M)


def test_wall_behind_the_robot_is_not_hit():
    world = SegmentMap("one", np.array([[-1.0, -1.0, -1.0, 1.0]]), bounds_m=(-2, -2, 2, 2))
    r = cast_rays(world, np.array([[0.0, 0.0, 0.0]]), np.array([0.0, math.pi]), 5.0)
    np.testing.assert_allclose(r, [[5.0, 1.0]], atol=RANGE_TOL_M)


@pytest.mark.parametrize("map_name", ["office", "symmetric_rooms", "wall_two_landmarks"])
def test_batched_equals_per_ray_loop(map_name):
    world = build_map(map_name)
    rng = np.random.default_rng(42)
    x0, y0, x1, y1 = world.bounds_m
    poses = np.column_stack(
        [rng.uniform(x0, x1, 40), rng.uniform(y0, y1, 40), rng.uniform(-math.pi, math.pi, 40)]
    )
    beams = np.sort(rng.uniform(0.0, 2 * math.pi, 13))
    got = cast_rays(world, poses, beams, 8.0)
    want = np.array(
        [[reference_ray(world.segments_m, x, y, th + b, 8.0) for b in beams] for x, y, th in poses]
    )
    np.testing.assert_allclose(got, want, atol=RANGE_TOL_M)


def test_chunked_equals_single_batch():
    world = office_map()
    rng = np.random.default_rng(1)
    poses = free_space_sample(world, 3000, rng)
    beams = LaserParams.cfs_ga().beam_angles_rad
    whole = cast_rays(world, poses, beams, 8.0)
    parts = np.concatenate(
        [cast_rays(world, poses[k : k + 7], beams, 8.0) for k in range(0, 3000, 7)]
    )
    np.testing.assert_array_equal(whole, parts)
    assert whole.shape == (3000, 18)


def test_empty_batches():
    assert cast_rays(box_map(), np.empty((0, 3)), np.zeros(4), 5.0).shape == (0, 4)
    assert cast_rays(box_map(), np.zeros((3, 3)) + 1.0, np.zeros(0), 5.0).shape == (3, 0)


# ---------------------------------------------------------------- laser parameters and scans


def test_laser_params_from_tables():
    mr = LaserParams.mr_ssga()
    assert (mr.n_beams, mr.max_range_m, mr.noise_std_m) == (8, 6.0, 0.10)
    cfs = LaserParams.cfs_ga()
    assert (cfs.n_beams, cfs.max_range_m, cfs.noise_std_m) == (18, 8.0, 0.10)
    np.testing.assert_allclose(np.degrees(cfs.beam_angles_rad), np.arange(0, 360, 20))
    with pytest.raises(ValueError, match="n_beams"):
        LaserParams(n_beams=0)
    with pytest.raises(ValueError, match="max_range_m"):
        LaserParams(max_range_m=-1.0)


def test_scan_noise_mean_and_std_match_sigma():
    # Robot in the middle of a 4 x 2 m box: true ranges 2, 1, 2, 1 m, far from both clip limits.
    params = LaserParams(n_beams=4, max_range_m=10.0, noise_std_m=0.10)
    poses = np.tile([2.0, 1.0, 0.0], (20000, 1))
    readings = scan(box_map(), poses, params, np.random.default_rng(7))
    errors = readings - np.array([2.0, 1.0, 2.0, 1.0])
    # 80,000 samples: the standard error of the mean is 0.1 / sqrt(8e4) = 3.5e-4 m, of the
    # standard deviation about 2.5e-4 m; tolerances are 4 standard errors.
    assert abs(errors.mean()) < 1.5e-3
    assert errors.std() == pytest.approx(0.10, abs=1e-3)


def test_scan_is_clipped_and_deterministic():
    params = LaserParams(n_beams=8, max_range_m=1.0, noise_std_m=0.5)
    poses = np.tile([2.0, 1.0, 0.3], (500, 1))
    a = scan(box_map(), poses, params, np.random.default_rng(3))
    b = scan(box_map(), poses, params, np.random.default_rng(3))
    np.testing.assert_array_equal(a, b)
    assert a.min() >= 0.0 and a.max() <= 1.0


# ---------------------------------------------------------------- unicycle


def test_unicycle_straight_without_noise():
    step = unicycle_step(
        np.array([[1.0, 2.0, math.pi / 2]]),
        0.5,
        0.0,
        2.0,
        MotionNoise(0.0, 0.0),
        np.random.default_rng(0),
    )
    np.testing.assert_allclose(step.poses_m, [[1.0, 3.0, math.pi / 2]], atol=1e-12)
    np.testing.assert_allclose(step.odometry_delta_s_m, [1.0])
    np.testing.assert_allclose(step.odometry_delta_phi_rad, [0.0])


def test_unicycle_arc_without_noise():
    # Eq. 3: delta_s = 1 m, delta_phi = pi/2, average heading pi/4: moves by (cos, sin)(pi/4).
    step = unicycle_step(
        np.array([[0.0, 0.0, 0.0]]),
        1.0,
        math.pi / 2,
        1.0,
        MotionNoise(0.0, 0.0),
        np.random.default_rng(0),
    )
    h = math.sqrt(0.5)
    np.testing.assert_allclose(step.poses_m, [[h, h, math.pi / 2]], atol=1e-12)
    # Heading wraps to [-pi, pi).
    out = unicycle_model(np.array([[0.0, 0.0, 3.0]]), 0.0, 1.0)
    assert out[0, 2] == pytest.approx(4.0 - 2 * math.pi)


def test_unicycle_noise_statistics():
    noise = MotionNoise.cfs_ga()
    n, dt = 40000, 0.5
    step = unicycle_step(np.zeros((n, 3)), 0.4, 0.0, dt, noise, np.random.default_rng(5))
    np.testing.assert_allclose(step.odometry_delta_s_m, 0.2)
    heading = step.poses_m[:, 2]
    # delta_phi ~ N(0, (0.1 * 0.5)^2); 4 standard errors of the std estimate (0.05 / sqrt(2n)).
    assert heading.std() == pytest.approx(
        noise.turn_rate_std_rad_s * dt, abs=4 * 0.05 / math.sqrt(2 * n)
    )
    travelled = np.hypot(step.poses_m[:, 0], step.poses_m[:, 1])
    assert travelled.mean() == pytest.approx(0.2, abs=1e-3)


# ---------------------------------------------------------------- maps


def test_line_of_sight_blocked_and_clear():
    world = SegmentMap("wall", np.array([[1.0, -1.0, 1.0, 1.0]]), bounds_m=(-2, -2, 3, 2))
    a = np.array([[0.0, 0.0], [0.0, 0.0], [0.0, 0.0], [0.0, 1.5], [1.0, -1.0]])
    b = np.array([[2.0, 0.0], [0.5, 0.0], [2.0, 1.5], [2.0, 1.5], [1.0, -2.0]])
    # crossing; short of the wall; crossing near its end; passing above; collinear touching its end
    np.testing.assert_array_equal(line_of_sight(world, a, b), [False, True, False, True, False])


def test_line_of_sight_in_office():
    world = office_map()
    # Two points in the corridor see each other; a room behind a wall does not.
    a = np.array([[1.0, 6.0], [2.5, 3.0]])
    b = np.array([[19.0, 6.0], [6.0, 3.0]])
    np.testing.assert_array_equal(line_of_sight(world, a, b), [True, False])


def test_free_space_samples_inside_and_clear():
    rng = np.random.default_rng(11)
    for name in MAPS.names():
        world = build_map(name)
        poses = free_space_sample(world, 500, rng, clearance_m=0.3)
        assert poses.shape == (500, 3)
        x0, y0, x1, y1 = world.bounds_m
        assert np.all((poses[:, 0] >= x0 + 0.3) & (poses[:, 0] <= x1 - 0.3))
        assert np.all((poses[:, 1] >= y0 + 0.3) & (poses[:, 1] <= y1 - 0.3))
        assert np.all((poses[:, 2] >= -math.pi) & (poses[:, 2] < math.pi))
        # Brute force distance to every wall.
        seg = world.segments_m
        for x, y, _ in poses[:50]:
            for x1s, y1s, x2s, y2s in seg:
                ex, ey = x2s - x1s, y2s - y1s
                u = min(1.0, max(0.0, ((x - x1s) * ex + (y - y1s) * ey) / (ex * ex + ey * ey)))
                assert math.hypot(x - x1s - u * ex, y - y1s - u * ey) >= 0.3
        assert np.all(distance_to_walls(world, poses) >= 0.3)


def test_free_space_sample_is_seeded():
    world = office_map()
    a = free_space_sample(world, 10, np.random.default_rng(2))
    b = free_space_sample(world, 10, np.random.default_rng(2))
    np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("name", MAPS.names())
def test_named_maps_build_and_are_non_degenerate(name):
    world = build_map(name)
    assert world.name == name
    seg = world.segments_m
    assert seg.shape[1] == 4 and seg.shape[0] >= 3
    assert np.all(np.hypot(seg[:, 2] - seg[:, 0], seg[:, 3] - seg[:, 1]) > 1e-3)
    assert world.width_m > 0 and world.height_m > 0
    assert not seg.flags.writeable
    # Every map is seen by the laser from somewhere: some beam hits a wall.
    poses = free_space_sample(world, 20, np.random.default_rng(0))
    assert np.any(cast_rays(world, poses, LaserParams.cfs_ga().beam_angles_rad, 8.0) < 8.0)


def test_symmetric_map_is_fully_symmetric():
    seg = build_map("symmetric").segments_m

    def canon(s):
        a, b = np.round(s[:, :2], 9) + 0.0, np.round(s[:, 2:], 9) + 0.0
        rows = [tuple(sorted([tuple(p), tuple(q)])) for p, q in zip(a, b, strict=True)]
        return sorted(rows)

    centre = np.array([5.0, 5.0])
    for transform in (lambda p: np.column_stack([-p[:, 1], p[:, 0]]), lambda p: p * [-1, 1]):
        moved = np.column_stack(
            [transform(seg[:, :2] - centre) + centre, transform(seg[:, 2:] - centre) + centre]
        )
        assert canon(moved) == canon(seg)


def _canonical_walls(segments_m: np.ndarray) -> list:
    a, b = np.round(segments_m[:, :2], 9) + 0.0, np.round(segments_m[:, 2:], 9) + 0.0
    return sorted(tuple(sorted([tuple(p), tuple(q)])) for p, q in zip(a, b, strict=True))


def test_aliased_rooms_has_five_alike_rooms_by_hand():
    """002 fig. 8 as we read it: every room of `aliased_rooms` gives the same scan from the same
    place in it. From (1.5, 1.0) facing +x in the 6 x 4 m south-west room (door at x in
    [2.5, 3.5] on y = 4, which no beam crosses), by hand: 4.5 east, 3 / sin 45 up-right to y = 4,
    3 north, 1.5 / cos 45 up-left to x = 0, 1.5 west, 1 / sin 45 down-left and down-right to
    y = 0, 1 south. The same pose shifted by 6 or 12 m (south rooms) or turned by a half turn
    about the middle of the corridor in front of a room (north rooms) reads the same."""
    world = build_map("aliased_rooms")
    beams = LaserParams.mr_ssga().beam_angles_rad
    r2 = math.sqrt(2.0)
    by_hand = np.array([4.5, 3 * r2, 3.0, 1.5 * r2, 1.5, r2, 1.0, r2])
    south = [(1.5 + dx, 1.0, 0.0) for dx in (0.0, 6.0, 12.0)]
    # Half turn about (3 + dx, 5): (1.5, 1) -> (4.5 + dx, 9), heading 0 -> pi.
    north = [(4.5 + dx, 9.0, math.pi) for dx in (0.0, 6.0)]
    ranges = cast_rays(world, np.array(south + north), beams, 6.0)
    np.testing.assert_allclose(ranges, np.tile(by_hand, (5, 1)), atol=RANGE_TOL_M)
    # The sixth place, where symmetric_rooms has its north-east room, is the hall: the same pose
    # there (north wall 1 m away, the hall open towards the corridor) reads differently.
    hall = cast_rays(world, np.array([[16.5, 9.0, math.pi]]), beams, 6.0)[0]
    assert np.max(np.abs(hall - by_hand)) > 1.0


def test_aliased_rooms_is_unique_but_symmetric_rooms_is_not():
    """The half turn about the centre (9, 5) carries symmetric_rooms onto itself, but not
    aliased_rooms; nor does either mirror through the centre lines."""
    centre = np.array([9.0, 5.0])
    turns = {
        "half turn": lambda p: -p,
        "mirror x": lambda p: p * [-1.0, 1.0],
        "mirror y": lambda p: p * [1.0, -1.0],
    }

    def moved(seg, transform):
        return np.column_stack(
            [transform(seg[:, :2] - centre) + centre, transform(seg[:, 2:] - centre) + centre]
        )

    symmetric = build_map("symmetric_rooms").segments_m
    assert _canonical_walls(moved(symmetric, turns["half turn"])) == _canonical_walls(symmetric)
    aliased = build_map("aliased_rooms").segments_m
    for transform in turns.values():
        assert _canonical_walls(moved(aliased, transform)) != _canonical_walls(aliased)


def test_segment_map_validation():
    with pytest.raises(ValueError, match="zero-length"):
        SegmentMap("bad", np.array([[0, 0, 1, 0], [1, 1, 1, 1]]))
    with pytest.raises(ValueError, match="shape"):
        SegmentMap("bad", np.zeros((2, 3)))
    with pytest.raises(ValueError, match="finite"):
        SegmentMap("bad", np.array([[0, 0, np.nan, 1]]))
    with pytest.raises(ValueError, match="beyond bounds"):
        SegmentMap("bad", np.array([[0, 0, 5, 0]]), bounds_m=(0, 0, 4, 4))


def test_registry_rejects_duplicates_and_suggests():
    registry = MapRegistry()
    registry.register("box", box_map)
    with pytest.raises(ValueError, match="already registered"):
        registry.register("box", box_map)
    with pytest.raises(KeyError, match="did you mean 'office'"):
        build_map("ofice")
    assert set(MAPS.names()) == {
        "office",
        "symmetric_rooms",
        "aliased_rooms",
        "wall_two_landmarks",
        "symmetric",
        "three_rooms_corridor",
        "three_corridors",
    }


# ---------------------------------------------------------------- relative observations


def test_relative_observation_range_and_line_of_sight():
    world = office_map()
    poses = np.array(
        [[6.0, 6.0, 0.0], [9.0, 6.0, math.pi / 2], [6.0, 3.0, 0.0], [19.0, 6.0, 0.0]]
    )  # 0, 1 and 3 in the corridor; 2 in the room below robot 0, behind a wall
    obs = relative_observation(
        poses,
        0,
        np.array([1, 2, 3, 0]),
        world,
        8.0,
        RelativeNoise(0.0, 0.0),
        np.random.default_rng(0),
    )
    np.testing.assert_array_equal(obs.visible, [True, False, False, False])  # wall; range; self
    assert obs.distance_m[0] == pytest.approx(3.0)
    assert obs.bearing_rad[0] == pytest.approx(0.0)
    assert obs.relative_heading_rad[0] == pytest.approx(math.pi / 2)
    assert np.all(np.isnan(obs.distance_m[1:]))
    # Seen from robot 1 (heading pi/2), robot 0 lies at -x, i.e. at bearing pi/2 (its left).
    back = relative_observation(
        poses, 1, 0, world, 8.0, RelativeNoise(0.0, 0.0), np.random.default_rng(0)
    )
    assert back.bearing_rad[0] == pytest.approx(math.pi / 2)
    assert back.relative_heading_rad[0] == pytest.approx(-math.pi / 2)


def test_relative_observation_noise():
    noise = RelativeNoise.cfs_ga()
    poses = np.array([[2.0, 6.0, 0.0], [5.0, 6.0, 0.0]])
    n = 20000
    obs = relative_observation(
        poses, np.zeros(n, int), np.ones(n, int), office_map(), 4.0, noise, np.random.default_rng(9)
    )
    assert obs.distance_m.std() == pytest.approx(0.2, abs=4e-3)
    assert obs.distance_m.mean() == pytest.approx(3.0, abs=6e-3)
    assert obs.bearing_rad.std() == pytest.approx(0.1, abs=2e-3)


def test_visible_pairs():
    world = office_map()
    poses = np.array([[6.0, 6.0, 0.0], [9.0, 6.0, 0.0], [6.0, 3.0, 0.0], [19.0, 6.0, 0.0]])
    np.testing.assert_array_equal(visible_pairs(world, poses, 8.0), [[0, 1], [1, 0]])
    assert visible_pairs(world, poses[:1], 8.0).shape == (0, 2)
