"""The e-puck body: hardware constants and differential-drive kinematics.

This is part of the contract between the world and the agents: the world integrates the *true*
wheel motion with these equations, the agent integrates the encoder counts it receives with the
same equations (dead reckoning). Both sides must agree on what one encoder step is in metres and
where the sensors sit on the body, so the numbers live here and nowhere else.

Sources:
- seed 000 §3.1 and §6.1: body radius 3.5 cm, wheelbase about 53 mm, 1000 steps per wheel
  revolution, at most 1000 steps/s, 8 IR proximity sensors and 3 ground sensors;
- seed 000 eq. 1-7 (equivalently seed 001 eq. 1-4): wheel displacement to pose increment;
- seed 000 eq. 9-11: propagation of the odometry covariance with Q from eq. 10.

All functions work on a batch of robots: arrays with a leading robot axis.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Angles of the 8 IR proximity sensors in the robot frame (rad, counter-clockwise from the
#: heading), as on the e-puck: IR0 front-right ... IR7 front-left.
IR_SENSOR_ANGLES_RAD = np.deg2rad(np.array([-17.0, -49.0, -90.0, -150.0, 150.0, 90.0, 49.0, 17.0]))

#: Positions of the 3 ground sensors in the robot frame (m): front of the body, left to right.
GROUND_SENSOR_OFFSETS_M = np.array([[0.030, 0.010], [0.030, 0.0], [0.030, -0.010]])


#: Controller state codes an agent reports in every Act (bits 0-1: its target, 0 none = wander,
#: 1 nest, 2 prey; bit 2: it knows both areas). The world reads them for the stability metric.
STATE_TARGET_MASK = 3
STATE_KNOWS_BOTH = 4


#: on_path of every state code 0..7 (bits 0-2), looked up rather than computed: one numpy call.
_ON_PATH_BY_CODE = np.array(
    [(code & STATE_TARGET_MASK) != 0 and (code & STATE_KNOWS_BOTH) != 0 for code in range(8)]
)


def on_path(state: np.ndarray) -> np.ndarray:
    """Robots that forage between the two areas (seed 000 §6.1.3): a target and both known."""
    return _ON_PATH_BY_CODE[np.asarray(state) & (STATE_TARGET_MASK | STATE_KNOWS_BOTH)]


def ground_sensor_point(pose: np.ndarray) -> np.ndarray:
    """Where the middle ground sensor of each robot is, ``(N, 2)``: what "standing on an area"
    means, for the world's metrics and the agent's stored goal locations alike."""
    ahead = GROUND_SENSOR_OFFSETS_M[1, 0]
    return pose[:, :2] + ahead * np.stack((np.cos(pose[:, 2]), np.sin(pose[:, 2])), axis=1)


@dataclass(frozen=True)
class EpuckBody:
    """Physical constants of an e-puck (seed 000 §3.1, §6.1)."""

    body_radius_m: float = 0.035
    wheelbase_m: float = 0.053
    wheel_diameter_m: float = 0.041
    steps_per_revolution: int = 1000
    max_wheel_speed_steps_s: float = 1000.0

    @property
    def metres_per_step(self) -> float:
        """Linear wheel travel of one encoder step, the c_m of seed 001 eq. 1."""
        return math.pi * self.wheel_diameter_m / self.steps_per_revolution

    @property
    def max_speed_mps(self) -> float:
        return self.max_wheel_speed_steps_s * self.metres_per_step


def wrap_angle(angle_rad: np.ndarray | float) -> np.ndarray | float:
    """Wrap angles to [-pi, pi)."""
    return (np.asarray(angle_rad) + np.pi) % (2.0 * np.pi) - np.pi


def displacement(du_left_m: np.ndarray, du_right_m: np.ndarray, wheelbase_m: float):
    """Linear and angular displacement of the body centre (seed 000 eq. 3 and 4).

    Returns ``(delta_rho_m, delta_theta_rad)``.
    """
    delta_theta_rad = (du_right_m - du_left_m) / wheelbase_m
    delta_rho_m = (du_right_m + du_left_m) / 2.0
    return delta_rho_m, delta_theta_rad


def integrate_pose(
    pose: np.ndarray, du_left_m: np.ndarray, du_right_m: np.ndarray, wheelbase_m: float
) -> np.ndarray:
    """Move poses ``(N, 3)`` = (x_m, y_m, theta_rad) by wheel displacements (seed 000 eq. 7).

    The arc is approximated by its chord, as in the paper; heading is wrapped to [-pi, pi).
    """
    delta_rho_m, delta_theta_rad = displacement(du_left_m, du_right_m, wheelbase_m)
    zeta = pose[:, 2] + delta_theta_rad / 2.0
    out = np.empty_like(pose)
    out[:, 0] = pose[:, 0] + delta_rho_m * np.cos(zeta)
    out[:, 1] = pose[:, 1] + delta_rho_m * np.sin(zeta)
    out[:, 2] = wrap_angle(pose[:, 2] + delta_theta_rad)
    return out


def propagate_covariance(
    cov: np.ndarray,
    pose: np.ndarray,
    du_left_m: np.ndarray,
    du_right_m: np.ndarray,
    wheelbase_m: float,
    k_right_m: float,
    k_left_m: float,
) -> np.ndarray:
    """Odometry covariance ``(N, 3, 3)`` one step on (seed 000 eq. 9-11).

    ``P_k = A P_{k-1} A^T + W Q W^T`` with ``Q = diag(k_r |dU_r|, k_l |dU_l|)`` (eq. 10);
    ``pose`` is the pose *before* the step. ``k_right_m``/``k_left_m`` are the error constants of
    eq. 10 in metres (variance per metre of wheel travel).
    """
    b = wheelbase_m
    delta_rho_m, delta_theta_rad = displacement(du_left_m, du_right_m, b)
    zeta = pose[:, 2] + delta_theta_rad / 2.0
    c, s = np.cos(zeta), np.sin(zeta)
    n = pose.shape[0]
    a = np.zeros((n, 3, 3))
    a[:, 0, 0] = a[:, 1, 1] = a[:, 2, 2] = 1.0
    a[:, 0, 2] = -delta_rho_m * s
    a[:, 1, 2] = delta_rho_m * c
    w = np.empty((n, 3, 2))
    half_rho_b = delta_rho_m / (2.0 * b)
    # Columns: right wheel, left wheel, matching u_k = [dU_r, dU_l]^T of eq. 8.
    w[:, 0, 0] = 0.5 * c - half_rho_b * s
    w[:, 0, 1] = 0.5 * c + half_rho_b * s
    w[:, 1, 0] = 0.5 * s + half_rho_b * c
    w[:, 1, 1] = 0.5 * s - half_rho_b * c
    w[:, 2, 0] = 1.0 / b
    w[:, 2, 1] = -1.0 / b
    q = np.zeros((n, 2, 2))
    q[:, 0, 0] = k_right_m * np.abs(du_right_m)
    q[:, 1, 1] = k_left_m * np.abs(du_left_m)
    return a @ cov @ a.transpose(0, 2, 1) + w @ q @ w.transpose(0, 2, 1)
