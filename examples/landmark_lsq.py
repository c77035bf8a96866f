"""A real-data landmark localizer of one's own (docs/extending.md): dead reckoning, reset at every
tick that sees enough landmarks by a least-squares pose fit to that tick's readings.

It is deliberately simple, a snapshot estimator with no memory beyond the odometry, so it shows the
contract rather than an algorithm to beat the EKF with:

- ``step(obs)``: check the observation, apply the camera calibration (``calibrated``: read
  ``self.setup`` each step, the self-calibrating wrapper updates it), propagate the odometry
  (``propagate``), then fit ``(x, y, theta)`` to the tick's landmark ranges and bearings with
  scipy's ``least_squares``, each residual divided by the camera's noise;
- ``estimate()``: the pose; ``outgoing()``: nothing (it does not cooperate);
- parameters from ``--param KEY=VALUE`` (or a scenario's ``params``): ``min_landmarks`` (2),
  ``max_step_m`` (a fit further than this from the dead-reckoned pose is a misread: 1.0).

Run it: ``swarmloc --plugin examples/landmark_lsq.py mrclam DATA --algorithm lsq-fix``.
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from swarmloc.agents.replay.localizers import (
    Algorithm,
    LandmarkSetup,
    calibrated,
    check_observation,
    predicted_range_bearing,
    propagate,
    register,
    wrap_angle,
)

DEFAULTS = {"min_landmarks": 2, "max_step_m": 1.0}


class LsqFix:
    def __init__(self, setup: LandmarkSetup, rng: np.random.Generator, params: dict):
        unknown = set(params) - set(DEFAULTS)
        if unknown:
            raise ValueError(f"{min(unknown)}: unknown lsq-fix parameter (known: {', '.join(DEFAULTS)})")
        p = {**DEFAULTS, **params}
        if int(p["min_landmarks"]) < 2 or float(p["max_step_m"]) <= 0:
            raise ValueError("min_landmarks must be >= 2 and max_step_m > 0")
        self.min_landmarks, self.max_step_m = int(p["min_landmarks"]), float(p["max_step_m"])
        self.setup = setup
        self.pose = setup.initial_pose.copy()
        self.covariance = setup.initial_covariance()
        self.fixes = 0

    def step(self, obs) -> None:
        check_observation(obs, self.setup.robot_id)
        obs = calibrated(obs, self.setup.camera)
        self.pose, self.covariance = propagate(self.pose, self.covariance, obs.odometry_v_mps,
                                               obs.odometry_omega_rad_s, obs.odometry_dt_s, self.setup.motion)
        index = {int(i): k for k, i in enumerate(self.setup.landmark_ids)}
        seen = [(index[int(i)], r, b) for i, r, b in zip(obs.landmark_ids, obs.landmark_range_m,
                                                         obs.landmark_bearing_rad, strict=True) if int(i) in index]
        if len(seen) < self.min_landmarks:
            return
        xy = self.setup.landmark_xy_m[[k for k, _, _ in seen]]
        range_m = np.array([r for _, r, _ in seen])
        bearing_rad = np.array([b for _, _, b in seen])
        cam = self.setup.camera
        range_std = cam.range_std_m + cam.range_fraction * range_m

        def residuals(pose: np.ndarray) -> np.ndarray:
            r, b = predicted_range_bearing(pose[None, :], xy)
            return np.concatenate([(r[0] - range_m) / range_std, wrap_angle(b[0] - bearing_rad) / cam.bearing_std_rad])

        fit = least_squares(residuals, self.pose, method="trf")
        if fit.success and np.hypot(*(fit.x[:2] - self.pose[:2])) <= self.max_step_m:
            self.pose = np.array([fit.x[0], fit.x[1], float(wrap_angle(fit.x[2]))])
            self.fixes += 1

    def estimate(self) -> np.ndarray:
        return self.pose.copy()

    def outgoing(self) -> bytes | None:
        return None


register(Algorithm("lsq-fix", "dead reckoning reset by a least-squares fix on each tick's landmarks",
                   lambda setup, rng, params: LsqFix(setup, rng, dict(params or {}))))
