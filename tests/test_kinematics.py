"""Differential-drive kinematics and odometry covariance of the e-puck (seed 000 §3.3, eq. 1-11).

Every expected value is written out by hand from the paper's equations with plain ``math``:

- eq. 3: d_theta = (dU_r - dU_l) / b;  eq. 4: d_rho = (dU_r + dU_l) / 2;
- eq. 7: x += d_rho cos(theta + d_theta/2), y += d_rho sin(theta + d_theta/2), theta += d_theta;
- eq. 9-11: P_k = A P A^T + W Q W^T, Q = diag(k_r |dU_r|, k_l |dU_l|), columns of W ordered
  (right, left) as u = [dU_r, dU_l]^T of eq. 8.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.protocol.epuck import (
    EpuckBody,
    displacement,
    integrate_pose,
    propagate_covariance,
)

WHEELBASE_M = 0.053


def _one(x_m: float, y_m: float, theta_rad: float) -> np.ndarray:
    return np.array([[x_m, y_m, theta_rad]])


def _arr(value_m: float) -> np.ndarray:
    return np.array([value_m])


# ---------------------------------------------------------------------------------------------
# Body constants
# ---------------------------------------------------------------------------------------------


def test_metres_per_step_is_wheel_circumference_over_1000_steps():
    body = EpuckBody()
    # 41 mm wheel, 1000 steps per revolution: pi * 0.041 / 1000 = 1.28805e-4 m per step.
    assert body.metres_per_step == pytest.approx(math.pi * 0.041 / 1000, rel=1e-12)
    assert body.metres_per_step == pytest.approx(1.2880529879718e-4, rel=1e-9)


def test_max_speed_is_about_0_1288_mps():
    body = EpuckBody()
    # 1000 steps/s, one wheel revolution per second (seed 000 §3.1).
    assert body.max_speed_mps == pytest.approx(0.1288, abs=1e-4)
    assert body.max_speed_mps == pytest.approx(1000 * math.pi * 0.041 / 1000, rel=1e-12)


def test_body_constants_match_the_paper():
    body = EpuckBody()
    assert body.wheelbase_m == pytest.approx(0.053)
    assert body.body_radius_m == pytest.approx(0.035)
    assert body.steps_per_revolution == 1000
    assert body.max_wheel_speed_steps_s == pytest.approx(1000.0)


# ---------------------------------------------------------------------------------------------
# Eq. 3-4
# ---------------------------------------------------------------------------------------------


def test_displacement_eq_3_and_4_hand_values():
    du_left_m = np.array([0.010, 0.002, -0.004, 0.0])
    du_right_m = np.array([0.010, 0.008, 0.004, 0.0053])
    rho_m, dtheta_rad = displacement(du_left_m, du_right_m, WHEELBASE_M)
    # eq. 4: (dU_r + dU_l) / 2
    assert rho_m == pytest.approx([0.010, 0.005, 0.0, 0.00265], abs=1e-15)
    # eq. 3: (dU_r - dU_l) / b
    assert dtheta_rad == pytest.approx(
        [0.0, 0.006 / 0.053, 0.008 / 0.053, 0.1], rel=1e-12, abs=1e-15
    )


def test_displacement_left_turn_is_positive_angle():
    # Right wheel travels further: counter-clockwise (positive) turn.
    _, dtheta_rad = displacement(_arr(0.0), _arr(0.01), WHEELBASE_M)
    assert dtheta_rad[0] > 0


# ---------------------------------------------------------------------------------------------
# Eq. 7
# ---------------------------------------------------------------------------------------------


def test_straight_motion_moves_along_heading():
    theta_rad = 0.7
    out = integrate_pose(_one(1.0, 2.0, theta_rad), _arr(0.03), _arr(0.03), WHEELBASE_M)
    assert out[0, 0] == pytest.approx(1.0 + 0.03 * math.cos(0.7), abs=1e-15)
    assert out[0, 1] == pytest.approx(2.0 + 0.03 * math.sin(0.7), abs=1e-15)
    assert out[0, 2] == pytest.approx(0.7, abs=1e-15)


def test_straight_motion_accumulates_exactly_over_many_steps():
    pose = _one(0.0, 0.0, math.pi / 2)
    for _ in range(100):
        pose = integrate_pose(pose, _arr(0.001), _arr(0.001), WHEELBASE_M)
    # 100 x 1 mm north.
    assert pose[0, 0] == pytest.approx(0.0, abs=1e-12)
    assert pose[0, 1] == pytest.approx(0.1, abs=1e-12)
    assert pose[0, 2] == pytest.approx(math.pi / 2, abs=1e-12)


def test_pure_rotation_turns_in_place():
    # dU_r = -dU_l: d_rho = 0, d_theta = 2 * 0.01 / 0.053 = 0.37735849... rad
    out = integrate_pose(_one(0.4, -0.2, 0.1), _arr(-0.01), _arr(0.01), WHEELBASE_M)
    assert out[0, 0] == pytest.approx(0.4, abs=1e-15)
    assert out[0, 1] == pytest.approx(-0.2, abs=1e-15)
    assert out[0, 2] == pytest.approx(0.1 + 0.02 / 0.053, abs=1e-12)
    assert out[0, 2] == pytest.approx(0.4773584905660377, abs=1e-12)


def test_pure_rotation_clockwise():
    out = integrate_pose(_one(0.0, 0.0, 0.0), _arr(0.0053), _arr(-0.0053), WHEELBASE_M)
    assert out[0, :2] == pytest.approx([0.0, 0.0], abs=1e-15)
    assert out[0, 2] == pytest.approx(-0.2, abs=1e-12)


def test_arc_uses_chord_at_half_turn_angle():
    # dU_l = 0.004 m, dU_r = 0.012 m from (0.5, 0.5, 0.3):
    #   d_rho = 0.008 m, d_theta = 0.008 / 0.053 = 0.150943396... rad
    #   zeta = 0.3 + 0.0754716981... = 0.3754716981...
    #   x = 0.5 + 0.008 cos(zeta), y = 0.5 + 0.008 sin(zeta)
    out = integrate_pose(_one(0.5, 0.5, 0.3), _arr(0.004), _arr(0.012), WHEELBASE_M)
    zeta_rad = 0.3 + 0.5 * (0.008 / 0.053)
    assert zeta_rad == pytest.approx(0.37547169811320757, rel=1e-14)
    assert out[0, 0] == pytest.approx(0.5 + 0.008 * math.cos(zeta_rad), abs=1e-15)
    assert out[0, 1] == pytest.approx(0.5 + 0.008 * math.sin(zeta_rad), abs=1e-15)
    # numerically: cos(0.3754717) = 0.9303347..., sin = 0.3667114...
    assert out[0, 0] == pytest.approx(0.50744268, abs=1e-8)
    assert out[0, 1] == pytest.approx(0.50293369, abs=1e-8)
    assert out[0, 2] == pytest.approx(0.3 + 0.008 / 0.053, abs=1e-12)


def test_arc_chord_is_shorter_than_the_arc_and_differs_from_start_heading():
    # The chord length is exactly d_rho (eq. 7), not the wheel-average arc bent in any way.
    out = integrate_pose(_one(0.0, 0.0, 0.0), _arr(0.0), _arr(0.0265), WHEELBASE_M)
    # d_rho = 0.01325 m, d_theta = 0.5 rad, zeta = 0.25 rad
    assert math.hypot(out[0, 0], out[0, 1]) == pytest.approx(0.01325, abs=1e-15)
    assert math.atan2(out[0, 1], out[0, 0]) == pytest.approx(0.25, abs=1e-12)
    assert out[0, 2] == pytest.approx(0.5, abs=1e-12)


def test_arc_heading_wraps_to_minus_pi_pi():
    # From theta = 3.0 turning left by d_theta = 0.5 rad (dU_r - dU_l = 0.0265 m):
    # 3.5 rad wraps to 3.5 - 2 pi = -2.78318530718 rad; the chord angle stays 3.25 rad.
    out = integrate_pose(_one(0.0, 0.0, 3.0), _arr(0.01), _arr(0.0365), WHEELBASE_M)
    d_rho_m = (0.01 + 0.0365) / 2
    assert out[0, 2] == pytest.approx(3.5 - 2 * math.pi, abs=1e-12)
    assert out[0, 2] == pytest.approx(-2.7831853071795862, abs=1e-12)
    assert -math.pi <= out[0, 2] < math.pi
    assert out[0, 0] == pytest.approx(d_rho_m * math.cos(3.25), abs=1e-15)
    assert out[0, 1] == pytest.approx(d_rho_m * math.sin(3.25), abs=1e-15)


def test_heading_wraps_clockwise_past_minus_pi():
    # From -3.0 turning right by 0.5 rad -> -3.5 -> -3.5 + 2 pi = 2.78318530718 rad
    out = integrate_pose(_one(0.0, 0.0, -3.0), _arr(0.0265), _arr(0.0), WHEELBASE_M)
    assert out[0, 2] == pytest.approx(-3.5 + 2 * math.pi, abs=1e-12)


def test_integrate_pose_is_batched_and_does_not_mutate_input():
    pose = np.array([[0.0, 0.0, 0.0], [1.0, 1.0, math.pi / 2]])
    before = pose.copy()
    out = integrate_pose(pose, np.array([0.01, -0.01]), np.array([0.01, 0.01]), WHEELBASE_M)
    np.testing.assert_array_equal(pose, before)
    assert out[0] == pytest.approx([0.01, 0.0, 0.0], abs=1e-15)
    assert out[1] == pytest.approx([1.0, 1.0, math.pi / 2 + 0.02 / 0.053], abs=1e-12)


# ---------------------------------------------------------------------------------------------
# Eq. 9-11
# ---------------------------------------------------------------------------------------------


def _eq11_by_hand(theta_rad, du_left_m, du_right_m, b_m):
    """A (3x3) and W (3x2) of eq. 11, written element by element from the paper."""
    d_theta = (du_right_m - du_left_m) / b_m
    d_rho = (du_right_m + du_left_m) / 2
    zeta = theta_rad + d_theta / 2
    c, s = math.cos(zeta), math.sin(zeta)
    a = np.array([[1.0, 0.0, -d_rho * s], [0.0, 1.0, d_rho * c], [0.0, 0.0, 1.0]])
    w = np.array(
        [
            [0.5 * c - d_rho / (2 * b_m) * s, 0.5 * c + d_rho / (2 * b_m) * s],
            [0.5 * s + d_rho / (2 * b_m) * c, 0.5 * s - d_rho / (2 * b_m) * c],
            [1 / b_m, -1 / b_m],
        ]
    )
    return a, w


def test_one_straight_step_from_zero_covariance_is_w_q_wt():
    # theta = 0, dU_l = dU_r = 0.01 m, b = 0.053 m, k_r = 0.02 m, k_l = 0.005 m.
    # zeta = 0, d_rho = 0.01: d_rho/(2b) = 0.01/0.106 = 0.0943396226415...
    w = np.array(
        [
            [0.5, 0.5],
            [0.09433962264150944, -0.09433962264150944],
            [18.867924528301888, -18.867924528301888],
        ]
    )
    # Q = diag(k_r |dU_r|, k_l |dU_l|) = diag(2e-4, 5e-5)
    q = np.array([[2e-4, 0.0], [0.0, 5e-5]])
    expected = w @ q @ w.T
    # A few entries written out: P_xx = 0.25 (q_r + q_l); P_xy = 0.5 a (q_r - q_l);
    # P_thth = (q_r + q_l) / b^2.
    assert expected[0, 0] == pytest.approx(0.25 * 2.5e-4)
    assert expected[0, 1] == pytest.approx(0.5 * 0.09433962264150944 * 1.5e-4)
    assert expected[2, 2] == pytest.approx(2.5e-4 / 0.053**2)

    p = propagate_covariance(
        np.zeros((1, 3, 3)),
        _one(0.0, 0.0, 0.0),
        _arr(0.01),
        _arr(0.01),
        WHEELBASE_M,
        k_right_m=0.02,
        k_left_m=0.005,
    )
    np.testing.assert_allclose(p[0], expected, rtol=1e-12, atol=1e-18)


def test_right_and_left_error_constants_are_not_swapped():
    # Only the right wheel is noisy: the y-theta correlation sign is that of the right column.
    p = propagate_covariance(
        np.zeros((1, 3, 3)),
        _one(0.0, 0.0, 0.0),
        _arr(0.01),
        _arr(0.01),
        WHEELBASE_M,
        k_right_m=0.01,
        k_left_m=0.0,
    )
    q_r = 0.01 * 0.01
    # right column of W at zeta = 0: (0.5, d_rho/(2b), 1/b)
    col = np.array([0.5, 0.01 / 0.106, 1 / 0.053])
    np.testing.assert_allclose(p[0], q_r * np.outer(col, col), rtol=1e-12, atol=1e-18)
    assert p[0, 0, 1] > 0  # a swapped column would give -0.5 * d_rho/(2b) * q


@pytest.mark.parametrize(
    "theta_rad, du_left_m, du_right_m",
    [(0.3, 0.004, 0.012), (-2.5, 0.01, -0.002), (3.1, -0.006, -0.009), (1.2, 0.0, 0.0053)],
)
def test_general_step_matches_eq_9_to_11_written_out(theta_rad, du_left_m, du_right_m):
    rng = np.random.default_rng(11)
    m = rng.normal(size=(3, 3)) * 1e-3
    p0 = m @ m.T  # a valid (PSD) prior
    k_r_m, k_l_m = 0.003, 0.007
    a, w = _eq11_by_hand(theta_rad, du_left_m, du_right_m, WHEELBASE_M)
    q = np.diag([k_r_m * abs(du_right_m), k_l_m * abs(du_left_m)])
    expected = a @ p0 @ a.T + w @ q @ w.T
    out = propagate_covariance(
        p0[None],
        _one(0.1, 0.2, theta_rad),
        _arr(du_left_m),
        _arr(du_right_m),
        WHEELBASE_M,
        k_right_m=k_r_m,
        k_left_m=k_l_m,
    )
    np.testing.assert_allclose(out[0], expected, rtol=1e-10, atol=1e-16)


def test_eq_11_jacobians_are_derivatives_of_eq_7():
    """Finite differences of eq. 7 (written here in plain math) reproduce A and W."""

    def f(x, y, th, du_r, du_l):
        d_rho = (du_r + du_l) / 2
        d_th = (du_r - du_l) / WHEELBASE_M
        return np.array(
            [x + d_rho * math.cos(th + d_th / 2), y + d_rho * math.sin(th + d_th / 2), th + d_th]
        )

    x, y, th, du_r, du_l = 0.2, -0.1, 0.9, 0.011, 0.004
    h = 1e-7
    a_num = np.column_stack(
        [
            (f(x + h, y, th, du_r, du_l) - f(x - h, y, th, du_r, du_l)) / (2 * h),
            (f(x, y + h, th, du_r, du_l) - f(x, y - h, th, du_r, du_l)) / (2 * h),
            (f(x, y, th + h, du_r, du_l) - f(x, y, th - h, du_r, du_l)) / (2 * h),
        ]
    )
    w_num = np.column_stack(
        [
            (f(x, y, th, du_r + h, du_l) - f(x, y, th, du_r - h, du_l)) / (2 * h),
            (f(x, y, th, du_r, du_l + h) - f(x, y, th, du_r, du_l - h)) / (2 * h),
        ]
    )
    # Probe the implementation with unit covariances: with P = e_i e_i^T and Q = 0 the result is
    # the outer product of column i of A; with P = 0 and Q = diag(1, 0)*... column of W.
    for i in range(3):
        p0 = np.zeros((1, 3, 3))
        p0[0, i, i] = 1.0
        out = propagate_covariance(
            p0, _one(x, y, th), _arr(du_l), _arr(du_r), WHEELBASE_M, k_right_m=0.0, k_left_m=0.0
        )
        np.testing.assert_allclose(out[0], np.outer(a_num[:, i], a_num[:, i]), atol=1e-7)
    out_r = propagate_covariance(
        np.zeros((1, 3, 3)),
        _one(x, y, th),
        _arr(du_l),
        _arr(du_r),
        WHEELBASE_M,
        k_right_m=1.0 / du_r,
        k_left_m=0.0,
    )
    np.testing.assert_allclose(out_r[0], np.outer(w_num[:, 0], w_num[:, 0]), rtol=1e-6, atol=1e-7)
    out_l = propagate_covariance(
        np.zeros((1, 3, 3)),
        _one(x, y, th),
        _arr(du_l),
        _arr(du_r),
        WHEELBASE_M,
        k_right_m=0.0,
        k_left_m=1.0 / du_l,
    )
    np.testing.assert_allclose(out_l[0], np.outer(w_num[:, 1], w_num[:, 1]), rtol=1e-6, atol=1e-7)


def test_covariance_is_symmetric_positive_semidefinite_along_a_random_path():
    rng = np.random.default_rng(5)
    n = 16
    pose = np.column_stack([rng.uniform(-1, 1, n), rng.uniform(-1, 1, n), rng.uniform(-3, 3, n)])
    cov = np.zeros((n, 3, 3))
    for _ in range(200):
        du_l = rng.uniform(-0.013, 0.013, n)
        du_r = rng.uniform(-0.013, 0.013, n)
        cov = propagate_covariance(cov, pose, du_l, du_r, WHEELBASE_M, 0.01, 0.01)
        pose = integrate_pose(pose, du_l, du_r, WHEELBASE_M)
        np.testing.assert_allclose(cov, cov.transpose(0, 2, 1), rtol=1e-12, atol=1e-18)
        eig = np.linalg.eigvalsh(cov)
        assert (eig >= -1e-12 * eig.max(axis=1, keepdims=True)).all()


def test_trace_grows_and_lateral_variance_grows_faster_than_linearly_on_a_straight_line():
    """Driving straight along x (theta = 0), 100 steps of 1 cm per wheel, k_r = k_l = 0.01 m.

    - the trace grows at every step (each step adds W Q W^T, which is PSD and non-zero);
    - the longitudinal variance P_xx grows *linearly*: + 0.25 (q_r + q_l) per step, since
      A's x-theta entry -d_rho sin(0) is zero;
    - the lateral variance P_yy grows *faster than linearly*: the heading variance grows
      linearly (+ (q_r + q_l)/b^2 per step) and y integrates heading error times d_rho, so
      P_yy's per-step increment itself increases (convex, ~ n^3).
    """
    d_m, k_m, b = 0.01, 0.01, WHEELBASE_M
    pose = _one(0.0, 0.0, 0.0)
    cov = np.zeros((1, 3, 3))
    traces, p_xx, p_yy = [0.0], [0.0], [0.0]
    for _ in range(100):
        cov = propagate_covariance(cov, pose, _arr(d_m), _arr(d_m), b, k_m, k_m)
        pose = integrate_pose(pose, _arr(d_m), _arr(d_m), b)
        traces.append(np.trace(cov[0]))
        p_xx.append(cov[0, 0, 0])
        p_yy.append(cov[0, 1, 1])
    assert np.all(np.diff(traces) > 0)

    # Hand recurrence (scalars): s = q_r + q_l, a = d/(2b), c = 1/b
    s, a, c = 2 * k_m * d_m, d_m / (2 * b), 1 / b
    yy = yt = tt = 0.0
    for _ in range(100):
        yy, yt, tt = (
            yy + 2 * d_m * yt + d_m**2 * tt + a * a * s,
            yt + d_m * tt + a * c * s,
            tt + c * c * s,
        )
    assert p_yy[-1] == pytest.approx(yy, rel=1e-10)
    assert cov[0, 2, 2] == pytest.approx(tt, rel=1e-10)
    assert p_xx[-1] == pytest.approx(100 * 0.25 * s, rel=1e-12)  # linear

    inc_yy = np.diff(p_yy)
    assert np.all(np.diff(inc_yy) > 0)  # strictly convex: faster than linear
    assert p_yy[100] > 2 * p_yy[50] * 3  # roughly cubic: doubling distance gives ~8x
    inc_xx = np.diff(p_xx)
    np.testing.assert_allclose(inc_xx, 0.25 * s, rtol=1e-9)


def test_zero_travel_leaves_covariance_unchanged():
    rng = np.random.default_rng(3)
    m = rng.normal(size=(4, 3, 3)) * 1e-2
    cov = m @ m.transpose(0, 2, 1)
    pose = np.column_stack([rng.uniform(-1, 1, 4), rng.uniform(-1, 1, 4), rng.uniform(-3, 3, 4)])
    out = propagate_covariance(cov, pose, np.zeros(4), np.zeros(4), WHEELBASE_M, 0.01, 0.02)
    np.testing.assert_array_equal(out, cov)
