"""Issue 19: the data's own bound on global localization (``deploy/lab/replay/feasibility.py``),
the two-landmark pose fix of the particle filter's proposal (``agents/replay/fixes.py``) and the
EKF's odometry self-calibration step (``agents/replay/ekf.py``).

The data sets here are built by hand with the answer known from the geometry: the expected
times are the times of the readings that were put in, not recomputed by the code under test.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.agents.replay.ekf import EkfParams, propagate_calibrated
from swarmloc.agents.replay.fixes import ReadingBuffer
from swarmloc.agents.replay.localizers import CameraNoise, MotionNoise
from swarmloc.deploy.lab.replay.feasibility import (
    first_reading_times,
    fix_times,
    position_std_bound,
    success_cap,
)
from swarmloc.world.replay.mrclam import Landmarks, Measurements, MrclamDataset, RobotRecord

#: A precise camera, so that the geometry alone decides (range 1 cm, bearing 1 mrad).
PRECISE = CameraNoise(range_std_m=0.01, range_fraction=0.0, bearing_std_rad=0.001)


def _readings(rows):
    """Measurements from ``(time_s, subject, range_m, bearing_rad)`` rows."""
    a = np.array(rows, dtype=np.float64).reshape(-1, 4)
    return Measurements(a[:, 0], a[:, 1].astype(np.int64), a[:, 2], a[:, 3])


def _robot(rid, pose, landmark_rows, robot_rows=()):
    t = np.arange(0.0, 20.0, 0.01)
    return RobotRecord(rid, t, np.tile(np.asarray(pose, dtype=np.float64), (t.size, 1)),
                       t, np.zeros(t.size), np.zeros(t.size), _readings(landmark_rows),
                       _readings(robot_rows))


def _dataset():
    """Landmarks 10 at (0, 0), 11 at (0, 4), 13 at (-0.1, 0) (right behind 10 seen from robot
    2). Robot 1 stands at (4, 2) facing -x: landmark 10 at t = 1, 2, 3, landmark 11 at t = 5.
    Robot 2 stands at (4, 0) facing -x: landmarks 10 and 13 (collinear with it) at t = 2 and
    2.1, again at 8 and 8.1. Robot 3 stands at (2, 2) facing +x, reads no landmark; it and
    robot 1 read each other at t = 0.5 (before robot 1 has any fix) and at t = 6."""
    lm = Landmarks(np.array([10, 11, 13]), np.array([[0.0, 0.0], [0.0, 4.0], [-0.1, 0.0]]),
                   np.zeros((3, 2)))
    r10, b10 = math.hypot(4, 2), math.atan2(-2, -4) - math.pi
    r11, b11 = math.hypot(4, 2), math.atan2(2, -4) - math.pi
    b10 = (b10 + math.pi) % (2 * math.pi) - math.pi
    b11 = (b11 + math.pi) % (2 * math.pi) - math.pi
    robot1 = _robot(1, (4.0, 2.0, math.pi),
                    [(1.0, 10, r10, b10), (2.0, 10, r10, b10), (3.0, 10, r10, b10),
                     (5.0, 11, r11, b11)],
                    [(0.5, 3, 2.0, 0.0), (6.0, 3, 2.0, 0.0)])
    robot2 = _robot(2, (4.0, 0.0, math.pi),
                    [(2.0, 10, 4.0, 0.0), (2.1, 13, 4.1, 0.0), (8.0, 10, 4.0, 0.0),
                     (8.1, 13, 4.1, 0.0)])
    robot3 = _robot(3, (2.0, 2.0, 0.0), [], [(0.5, 1, 2.0, 0.0), (6.0, 1, 2.0, 0.0)])
    return MrclamDataset("hand-made", 0.0, {}, lm, {1: robot1, 2: robot2, 3: robot3})


def test_two_distinct_landmarks_in_the_window_fix_the_pose_one_landmark_never_does():
    """Robot 1 is fixed at t = 5 (its first reading of a second landmark, 2 s after the last
    reading of the first: inside a 5 s window, outside a 1 s one); three readings of one
    landmark from one place never fix it."""
    ds = _dataset()
    assert fix_times(ds, window_s=5.0, std_m=0.1, camera=PRECISE)[1] == pytest.approx(5.0)
    assert fix_times(ds, window_s=1.0, std_m=0.1, camera=PRECISE)[1] == math.inf


def test_collinear_landmarks_leave_the_pose_undetermined():
    """Robot 2's two landmarks lie on one line through it, 0.1 m apart at 4 m: the heading and
    the lateral position trade off (lateral std about 0.001 rad x 4 m / (0.1 / 4) / ... > 0.1
    m), so the bound never falls under 0.1 m, though two distinct landmarks were read; a loose
    0.5 m bound is met at the first pair (t = 2.1)."""
    ds = _dataset()
    assert fix_times(ds, window_s=5.0, std_m=0.1, camera=PRECISE)[2] == math.inf
    assert fix_times(ds, window_s=5.0, std_m=0.5, camera=PRECISE)[2] == pytest.approx(2.1)


def test_a_fixed_teammate_fixes_a_robot_that_sees_no_landmark():
    """Robot 3 reads no landmark: alone never fixed; cooperative, at t = 6 (robot 1 is fixed at
    5; their mutual readings at 0.5 came before, when robot 1 knew nothing). Its hard bound
    (first reading of anything useful) is never alone and 6 s cooperative (robot 1's first
    reading is at 1 s, after their reading at 0.5)."""
    ds = _dataset()
    alone = fix_times(ds, window_s=5.0, std_m=0.1, camera=PRECISE)
    coop = fix_times(ds, window_s=5.0, std_m=0.1, cooperative=True, camera=PRECISE)
    assert alone[3] == math.inf
    assert coop[3] == pytest.approx(6.0)
    assert coop[1] == pytest.approx(5.0)
    assert first_reading_times(ds)[3] == math.inf
    assert first_reading_times(ds, cooperative=True)[3] == pytest.approx(6.0)
    assert first_reading_times(ds)[1] == pytest.approx(1.0)


def test_position_std_bound_of_two_perpendicular_readings():
    """Two landmarks at 1 m, one straight ahead and one to the left, range std 0.01 m, bearing
    std 0.001 rad, from the pose (0, 0, 0): x is pinned by the first's range (0.01 m) and, with
    the heading free, y by the second's range (0.01 m): the bound is 0.01 m within 1 %."""
    from swarmloc.deploy.lab.replay.feasibility import _reading_information

    pose = np.zeros((2, 3))
    info = _reading_information(pose, np.array([[1.0, 0.0], [0.0, 1.0]]), PRECISE)
    std = position_std_bound(np.array([0.0, 0.0]), info, window_s=1.0)
    assert std[0] == math.inf  # one reading: singular
    assert std[1] == pytest.approx(0.01, rel=0.01)


def test_success_cap_counts_robots_by_the_deadline():
    assert success_cap({1: 10.0, 2: 59.0, 3: 83.0, 4: math.inf}, 60.0) == 0.5
    with pytest.raises(ValueError, match="no robots"):
        success_cap({}, 60.0)


def test_reading_buffer_fix_recovers_the_pose_the_readings_were_taken_from():
    """The robot reads landmark A at (5, 1) from (1, 1, 0), then drives 0.5 m and turns 0.3 rad
    and reads landmark B at (2, 4): with a noise-free camera and no odometry noise every drawn
    pose is the true final pose within 1e-6."""
    exact = CameraNoise(range_std_m=1e-12, range_fraction=0.0, bearing_std_rad=1e-12)
    buffer = ReadingBuffer(window_s=2.0, odometry_std_m_per_s=0.0)
    start = np.array([1.0, 1.0, 0.0])
    a, b = np.array([5.0, 1.0]), np.array([2.0, 4.0])

    def reading(pose, target):
        d = target - pose[:2]
        return math.hypot(*d), math.atan2(d[1], d[0]) - pose[2]

    r, brg = reading(start, a)
    buffer.add(np.array([1]), a[None], np.array([r]), np.array([brg]), exact)
    assert buffer.fix_poses(4, np.random.default_rng(0)) is None  # one landmark: no fix
    d, turn = 0.5, 0.3
    end = np.array([1.0 + d * math.cos(turn / 2), 1.0 + d * math.sin(turn / 2), turn])
    buffer.move(d, turn, 0.5)
    r, brg = reading(end, b)
    buffer.add(np.array([2]), b[None], np.array([r]), np.array([brg]), exact)
    poses = buffer.fix_poses(4, np.random.default_rng(0))
    assert np.allclose(poses, end, atol=1e-6)
    buffer.move(0.0, 0.0, 1.6)  # older than the window: A is dropped, no fix
    assert buffer.fix_poses(4, np.random.default_rng(0)) is None


def test_calibrated_odometry_moves_by_the_scaled_command():
    """State (0, 0, 0, k_v = 0.9, k_w = 0.75, b_w = 0.01): a command of 0.1 m/s and 0.4 rad/s
    for 0.5 s turns (0.75 x 0.4 + 0.01) x 0.5 = 0.155 rad and moves 0.045 m along the
    mid-turn heading 0.0775 rad; the parameters stay, their covariance grows by the drift."""
    state = np.array([0.0, 0.0, 0.0, 0.9, 0.75, 0.01])
    new, cov = propagate_calibrated(state, np.zeros((6, 6)), 0.1, 0.4, 0.5, MotionNoise(),
                                    np.array([0.1, 0.2, 0.3]))
    assert new[2] == pytest.approx(0.155)
    assert new[0] == pytest.approx(0.045 * math.cos(0.0775))
    assert new[1] == pytest.approx(0.045 * math.sin(0.0775))
    assert np.array_equal(new[3:], state[3:])
    assert np.allclose(np.diag(cov)[3:], np.square([0.1, 0.2, 0.3]) * 0.5)


def test_ekf_params_reject_a_bad_odometry_prior():
    with pytest.raises(ValueError, match="odometry_prior_std"):
        EkfParams(odometry_prior_std=(0.1, 0.1))
    with pytest.raises(ValueError, match="odometry_drift_std"):
        EkfParams(odometry_drift_std=(0.1, -1.0, 0.1))


def test_report_bound_table_lists_each_robot_and_the_share_within_60_s():
    """The report's table (``deploy/lab/replay/report.py``): the hard bound alone is robot 1's
    first landmark reading (1 s), robot 2's (2 s) and never for robot 3 ('-'): 2 of 3 robots
    (67 %) within 60 s; cooperatively robot 3's first is its reading at 6 s (3/3)."""
    from swarmloc.deploy.lab.replay.report import bound_table

    lines = bound_table(_dataset())
    alone = next(line for line in lines if line.startswith("| first reading (hard bound), alone"))
    coop = next(line for line in lines
                if line.startswith("| first reading (hard bound), cooperative"))
    assert alone.split("|")[2:6] == [" 1.0 ", " 2.0 ", " - ", " 67% "]
    assert coop.split("|")[2:6] == [" 1.0 ", " 2.0 ", " 6.0 ", " 100% "]


# -- the odometry's share of the tracking error (deploy/lab/replay/motion_bound.py) --------------


def _circling(v_mps=0.1, omega_rad_s=0.2, gap=None):
    """A robot on a circle at a known speed and turn rate (Vicon at 100 Hz, optionally with a gap
    ``(t0, t1)``), whose commands were 0.9x its speed and 0.8x its turn rate, every 0.1 s."""
    t = np.arange(0.0, 30.0, 0.01)
    th = omega_rad_s * t
    r = v_mps / omega_rad_s
    pose = np.column_stack([r * np.sin(th), r * (1.0 - np.cos(th)), np.angle(np.exp(1j * th))])
    keep = np.ones(t.size, bool) if gap is None else (t < gap[0]) | (t > gap[1])
    odo_t = np.arange(0.0, 29.0, 0.1)
    return RobotRecord(1, t[keep], pose[keep], odo_t, np.full(odo_t.size, 0.9 * v_mps),
                       np.full(odo_t.size, 0.8 * omega_rad_s), _readings([]), _readings([]))


def test_vicon_velocities_are_the_motion_and_a_gap_gives_none():
    from swarmloc.deploy.lab.replay.motion_bound import vicon_velocities

    rec = _circling(gap=(10.0, 12.0))
    v, w = vicon_velocities(rec, rec.odometry_time_s)
    in_gap = (rec.odometry_time_s > 9.5) & (rec.odometry_time_s < 12.5)
    assert np.all(np.isnan(v[(rec.odometry_time_s > 10.1) & (rec.odometry_time_s < 11.9)]))
    # A chord of the circle is a hair shorter than the arc: 0.1 s at 0.2 rad/s, relative 1.7e-5.
    np.testing.assert_allclose(v[~in_gap], 0.1, rtol=1e-4)
    np.testing.assert_allclose(w[~in_gap], 0.2, rtol=1e-6)


def test_odometry_variants():
    from swarmloc.deploy.lab.replay.motion_bound import odometry_variant

    rec = _circling()
    assert odometry_variant(rec, "commands") is rec
    later = odometry_variant(rec, "commands-later", lag_s=0.2)
    np.testing.assert_allclose(later.odometry_time_s, rec.odometry_time_s + 0.2)
    np.testing.assert_array_equal(later.odometry_omega_rad_s, rec.odometry_omega_rad_s)
    # Gains fitted against Vicon undo the commands' 0.9x and 0.8x.
    gains = odometry_variant(rec, "commands-later-vicon-gains", lag_s=0.2)
    np.testing.assert_allclose(gains.odometry_v_mps, 0.1, rtol=1e-4)
    np.testing.assert_allclose(gains.odometry_omega_rad_s, 0.2, rtol=1e-6)
    oracle = odometry_variant(rec, "vicon-velocities")
    np.testing.assert_allclose(oracle.odometry_omega_rad_s, 0.2, rtol=1e-6)
    with pytest.raises(ValueError, match="variant: expected one of commands"):
        odometry_variant(rec, "wheel-model")
