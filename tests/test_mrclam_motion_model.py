"""The EKF's options for MRCLAM's velocity commands and overconfident teammates (issue 19): the
command classes of the odometry self-calibration, the command lag, the offset only while
moving, the teammate's position std floor, and the motion bound that fits the class model
against Vicon (``deploy/lab/replay/motion_bound.py``)."""

import math

import numpy as np
import pytest
from mrclam_synthetic import empty_observation, small_setup

from swarmloc.agents.replay.ekf import EkfLocalizer, EkfParams, command_class, propagate_calibrated
from swarmloc.agents.replay.localizers import (
    CameraNoise,
    LandmarkSetup,
    MotionNoise,
    TeammateReport,
)
from swarmloc.world.replay.mrclam import Measurements, RobotRecord
from swarmloc.world.replay.replay import Message

DRIFT = np.array([1e-3, 1e-3, 1e-4])


def test_command_class_splits_straight_left_and_right_at_the_threshold():
    assert [command_class(w, 0.1) for w in (0.0, 0.09, -0.09, 0.1, 0.4, -0.1, -0.4)] == \
        [0, 0, 0, 1, 1, 2, 2]
    assert command_class(0.4, 0.0) == 0  # one set: every command in it


def test_each_command_moves_by_its_own_class_set():
    """Sets: straight (1, 1, 0), left (k_v 0.5), right (k_w 0.5). Over 0.5 s, 0.1 m/s at
    0.4 rad/s moves 0.025 m and turns 0.2 rad; at -0.4 rad/s, 0.05 m and -0.1 rad; at 0.05
    rad/s (straight), 0.05 m and 0.025 rad. Only the set used gets a Jacobian column."""
    state = np.array([0.0, 0.0, 0.0, 1, 1, 0, 0.5, 1, 0, 1, 0.5, 0])
    cov = np.zeros((12, 12))
    for omega, dist, turn, used in ((0.4, 0.025, 0.2, 1), (-0.4, 0.05, -0.1, 2),
                                    (0.05, 0.05, 0.025, 0)):
        new, _ = propagate_calibrated(state, cov, 0.1, omega, 0.5, MotionNoise(), DRIFT, 0.1)
        assert new[2] == pytest.approx(turn)
        assert math.hypot(new[0], new[1]) == pytest.approx(dist)
        assert math.atan2(new[1], new[0]) == pytest.approx(turn / 2)
        assert np.array_equal(new[3:], state[3:])
        # Only the set used moves the pose: its parameters gain covariance with the pose.
        prior = np.zeros((12, 12))
        prior[3:, 3:] = np.eye(9) * 0.01
        _, out = propagate_calibrated(state, prior, 0.1, omega, 0.5, MotionNoise(), DRIFT, 0.1)
        for k in range(3):
            coupled = np.any(out[:3, 3 + 3 * k:6 + 3 * k] != 0.0)
            assert coupled == (k == used)


def test_class_jacobian_matches_finite_differences():
    """The covariance propagation's Jacobian (zero motion noise and drift) against central
    differences of the motion itself, for a state whose every entry matters."""
    state = np.array([0.3, -0.2, 0.7, 1.1, 0.9, 0.02, 0.7, 0.8, -0.03, 0.95, 1.2, 0.01])
    quiet = MotionNoise(speed_fraction=0.0, speed_std_mps=0.0, turn_fraction=0.0,
                        turn_std_rad_s=0.0, turn_per_speed_rad_m=0.0)
    for omega in (0.02, 0.4, -0.4):
        jac = np.zeros((12, 12))
        for i in range(12):
            e = np.zeros(12)
            e[i] = 1e-6
            hi, _ = propagate_calibrated(state + e, np.zeros((12, 12)), 0.08, omega, 0.3, quiet,
                                         np.zeros(3), 0.1)
            lo, _ = propagate_calibrated(state - e, np.zeros((12, 12)), 0.08, omega, 0.3, quiet,
                                         np.zeros(3), 0.1)
            jac[:, i] = (hi - lo) / 2e-6
        for i in range(12):  # covariance e_i e_i^T propagates to column i times itself
            unit = np.zeros((12, 12))
            unit[i, i] = 1.0
            _, out = propagate_calibrated(state, unit, 0.08, omega, 0.3, quiet, np.zeros(3), 0.1)
            np.testing.assert_allclose(out, np.outer(jac[:, i], jac[:, i]), atol=1e-8)


def test_a_robot_told_to_stand_still_does_not_turn_by_the_offset():
    state = np.array([1.0, 2.0, 0.5, 1.0, 1.0, 0.05])
    new, _ = propagate_calibrated(state, np.zeros((6, 6)), 0.0, 0.0, 1.0, MotionNoise(), DRIFT)
    assert np.array_equal(new[:3], state[:3])
    moving, _ = propagate_calibrated(state, np.zeros((6, 6)), 0.0, 0.1, 1.0, MotionNoise(), DRIFT)
    assert moving[2] == pytest.approx(0.5 + 0.1 + 0.05)  # turning in place: offset applies


def _setup():
    return LandmarkSetup(robot_id=1, landmark_ids=np.arange(1, 9),
                         landmark_xy_m=np.array([[np.cos(a) * 3, np.sin(a) * 3]
                                                 for a in np.linspace(0, 2 * np.pi, 8, False)]),
                         initial_pose=np.zeros(3),
                         camera=CameraNoise(range_std_m=0.02, range_fraction=0.0,
                                            bearing_std_rad=0.01))


def test_a_lagged_command_moves_the_estimate_as_the_same_command_given_later():
    """Lag 0.1 s at 0.02 s ticks: the filter fed the commands as they come moves exactly as one
    without lag fed them five ticks later (zeros before)."""
    rng = np.random.default_rng(3)
    commands = [(float(v), float(w)) for v, w in zip(rng.uniform(0, 0.1, 60),
                                                     rng.uniform(-0.5, 0.5, 60))]
    lagged = EkfLocalizer(_setup(), EkfParams(odometry_lag_s=0.1))
    later = EkfLocalizer(_setup())
    shifted = [(0.0, 0.0)] * 5 + commands
    for k, ((v, w), (v_late, w_late)) in enumerate(zip(commands, shifted)):
        lagged.step(empty_observation(tick=k, odometry_v_mps=v, odometry_omega_rad_s=w))
        later.step(empty_observation(tick=k, odometry_v_mps=v_late, odometry_omega_rad_s=w_late))
        assert np.array_equal(lagged.pose, later.pose)
        assert np.array_equal(lagged.covariance, later.covariance)
    assert np.linalg.norm(lagged.pose[:2]) > 0.05  # it did move


def test_class_calibration_learns_that_the_robot_slows_in_turns():
    """A robot that drives the commanded 0.1 m/s straight ahead but 0.07 m/s while turning
    (0.7x, as Dataset 6's robots do), seen by exact readings of 8 landmarks every 0.2 s for
    300 s: the straight set learns k_v 1.0 and both turning sets 0.7, within 0.05; a single set
    learns one speed between them."""
    dt = 0.02
    pattern = [(0.1, 0.0)] * 250 + [(0.1, 0.4)] * 100 + [(0.1, 0.0)] * 250 + [(0.1, -0.4)] * 100
    truth = np.zeros(3)
    params = {"odometry_calibration": True, "odometry_prior_std": (0.3, 0.0, 0.0)}
    classes = EkfLocalizer(_setup(), EkfParams(**params, odometry_turn_class_rad_s=0.1))
    single = EkfLocalizer(_setup(), EkfParams(**params))
    setup = _setup()
    for k in range(int(300 / dt)):
        v, w = pattern[k % len(pattern)]
        true_v = v * (0.7 if w else 1.0)
        mid = truth[2] + 0.5 * w * dt
        truth = truth + [true_v * dt * math.cos(mid), true_v * dt * math.sin(mid), w * dt]
        kw = {}
        if k % 10 == 9:
            d = setup.landmark_xy_m - truth[:2]
            kw = {"landmark_ids": setup.landmark_ids, "landmark_range_m": np.hypot(d[:, 0], d[:, 1]),
                      "landmark_bearing_rad": np.arctan2(d[:, 1], d[:, 0]) - truth[2]}
        obs = empty_observation(tick=k, time_s=(k + 1) * dt, odometry_v_mps=v,
                                odometry_omega_rad_s=w, **kw)
        classes.step(obs)
        single.step(obs)
    (straight, left, right) = [s[0] for s in classes.odometry_calibration]
    assert straight == pytest.approx(1.0, abs=0.05)
    assert left == pytest.approx(0.7, abs=0.05)
    assert right == pytest.approx(0.7, abs=0.05)
    (k_v,) = [s[0] for s in single.odometry_calibration]
    assert 0.75 < k_v < 0.97


def _fused_with(report_cov, **params):
    """Robot 1 (at the origin, std 0.05 m) after teammate 2, at (1, 0) facing back, reports
    seeing it 0.9 m ahead: a position fix at (0.1, 0)."""
    ekf = EkfLocalizer(small_setup(cooperative=True), EkfParams(**params))
    report = TeammateReport(2, 0, np.array([1.0, 0.0, math.pi]), report_cov,
                            np.array([[1.0, 0.9, 0.0]]), np.zeros((0, 3)))
    ekf.step(empty_observation(received=(Message(2, report.encode()),)))
    assert ekf.teammate_updates == 1
    return ekf.estimate()


def test_teammate_floor_adds_its_variance_to_the_teammates_position():
    """A floor ``f`` fuses as a report whose x and y variances are ``f^2 / inflation`` larger;
    a floored teammate pulls the robot less than half as far as a confident one."""
    tiny = np.diag([1e-8, 1e-8, 1e-8])
    bare = _fused_with(tiny)
    floored = _fused_with(tiny, teammate_floor_std_m=0.1)
    as_report = _fused_with(tiny + np.diag([0.01 / 2.0, 0.01 / 2.0, 0.0]))
    np.testing.assert_allclose(floored, as_report, atol=1e-12)
    assert bare[0] > 0.04 and 0.0 < floored[0] < 0.5 * bare[0]


def test_motion_options_reject_bad_values_by_name():
    with pytest.raises(ValueError, match="teammate_floor_std_m"):
        EkfParams(teammate_floor_std_m=-0.1)
    with pytest.raises(ValueError, match="odometry_lag_s"):
        EkfParams(odometry_lag_s=-0.1)
    with pytest.raises(TypeError, match="odometry_turn_class_rad_s"):
        EkfParams(odometry_turn_class_rad_s="0.1")


def _two_class_robot():
    """Vicon at 100 Hz of a robot that alternates 10 s straight at 0.1 m/s with 10 s turning left
    at 0.4 rad/s and 0.07 m/s, commanded 0.1 m/s throughout (0 and 0.4 rad/s), every 0.1 s."""
    t = np.arange(0.0, 80.0, 0.01)
    turning = (t // 10.0) % 2 == 1
    v = np.where(turning, 0.07, 0.1)
    w = np.where(turning, 0.4, 0.0)
    th = np.concatenate([[0.0], np.cumsum(w[:-1] * 0.01)])
    mid = th + 0.5 * w * 0.01
    x = np.concatenate([[0.0], np.cumsum(v[:-1] * 0.01 * np.cos(mid[:-1]))])
    y = np.concatenate([[0.0], np.cumsum(v[:-1] * 0.01 * np.sin(mid[:-1]))])
    pose = np.column_stack([x, y, np.angle(np.exp(1j * th))])
    odo_t = np.arange(0.0, 79.0, 0.1)
    odo_turning = (odo_t // 10.0) % 2 == 1
    empty = Measurements(np.zeros(0), np.zeros(0, np.int64), np.zeros(0), np.zeros(0))
    return RobotRecord(1, t, pose, odo_t, np.full(odo_t.size, 0.1),
                       np.where(odo_turning, 0.4, 0.0), empty, empty), odo_turning


def test_motion_bound_class_fit_recovers_each_class_speed_where_one_gain_cannot():
    from swarmloc.deploy.lab.replay.motion_bound import odometry_variant

    rec, turning = _two_class_robot()
    inside = np.ones(turning.size, bool)  # leave out the intervals that straddle a switch
    switch = np.flatnonzero(np.diff(turning.astype(int))) + 1
    for s in switch:
        inside[max(s - 1, 0):s + 1] = False
    classes = odometry_variant(rec, "commands-later-vicon-classes", lag_s=0.0)
    np.testing.assert_allclose(classes.odometry_v_mps[inside & ~turning], 0.1, rtol=0.02)
    np.testing.assert_allclose(classes.odometry_v_mps[inside & turning], 0.07, rtol=0.02)
    np.testing.assert_allclose(classes.odometry_omega_rad_s[inside & turning], 0.4, rtol=0.02)
    gains = odometry_variant(rec, "commands-later-vicon-gains", lag_s=0.0)
    assert 0.075 < gains.odometry_v_mps[0] < 0.095  # one gain: between the two
    # Fitted on the first 10 s (straight only): the turning commands are left as they are.
    early = odometry_variant(rec, "commands-later-vicon-classes", lag_s=0.0, fit_s=10.0)
    np.testing.assert_array_equal(early.odometry_v_mps[turning], 0.1)
