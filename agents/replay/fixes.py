"""Pose fixes from two or more landmark readings: the proposal of a global localizer (issue 19).

One range-and-bearing reading of a known landmark puts the robot anywhere on a circle (the
sensor resetting of :func:`swarmloc.agents.replay.populations.sensor_resetting_poses`); two
readings of *distinct* landmarks fix the whole pose: the landmarks' separation seen in the
robot's frame against their separation in the world gives the heading, then either reading the
position (the feasibility bound of :mod:`swarmloc.deploy.lab.replay.feasibility` counts exactly
these). The readings of one camera frame rarely hold two landmarks, so :class:`ReadingBuffer`
keeps the landmark readings of the last ``window_s`` seconds as points in the robot's current
frame, carried along by the odometry (a reading ``age`` seconds old has the odometry's error
over ``age`` seconds on it), and :meth:`ReadingBuffer.fix_poses` draws poses from them: each
draw perturbs every buffered point by the camera's noise and the odometry's, then fits the
rigid transform from the robot's frame to the world (2-D Procrustes, closed form, least
squares over all the buffered readings).

Mixture MCL (S. Thrun, D. Fox, W. Burgard, F. Dellaert, "Robust Monte Carlo localization for
mobile robots", Artificial Intelligence 128, 2001) draws part of the particles from the
measurement (the dual proposal); drawing them from a two-landmark fix rather than one reading
is our choice for MRCLAM's sparse landmarks. Pure: the generator is passed in.
"""

from __future__ import annotations

import math
from collections import deque

import numpy as np

from swarmloc.agents.replay.localizers import CameraNoise, wrap_angle


class ReadingBuffer:
    """The landmark readings of the last ``window_s`` seconds, as points in the robot's current
    frame (see the module docstring). ``odometry_std_m_per_s``: the spread added per second of
    a reading's age (the odometry's drift, on top of the camera's noise)."""

    def __init__(self, window_s: float = 2.0, odometry_std_m_per_s: float = 0.03):
        if not window_s > 0.0 or not odometry_std_m_per_s >= 0.0:
            raise ValueError(f"window_s must be > 0 and odometry_std_m_per_s >= 0, got "
                             f"{window_s!r}, {odometry_std_m_per_s!r}")
        self.window_s = float(window_s)
        self.odometry_std_m_per_s = float(odometry_std_m_per_s)
        #: (age_s, landmark_id, world xy (2,), body xy (2,), camera std at it)
        self._items: deque = deque()

    def __len__(self) -> int:
        return len(self._items)

    def move(self, distance_m: float, turn_rad: float, dt_s: float) -> None:
        """The robot moved ``distance_m`` along its mid-turn heading, then turned: every point
        is carried into the new frame; readings older than ``window_s`` are dropped."""
        if not self._items:
            return
        half = 0.5 * turn_rad
        tx, ty = distance_m * math.cos(half), distance_m * math.sin(half)
        c, s = math.cos(turn_rad), math.sin(turn_rad)
        kept = deque()
        for age, lid, world, body, std in self._items:
            age += dt_s
            if age > self.window_s:
                continue
            x, y = body[0] - tx, body[1] - ty
            kept.append((age, lid, world, np.array([c * x + s * y, -s * x + c * y]), std))
        self._items = kept

    def add(self, landmark_ids: np.ndarray, landmarks_xy: np.ndarray, range_m: np.ndarray,
            bearing_rad: np.ndarray, camera: CameraNoise) -> None:
        """This tick's readings of known landmarks (``landmarks_xy`` their world positions)."""
        for lid, world, r, b in zip(landmark_ids, landmarks_xy, range_m, bearing_rad):
            std = float(camera.range_std(r)) + float(r) * camera.bearing_std_rad
            self._items.append((0.0, int(lid), np.asarray(world, dtype=np.float64),
                                np.array([r * math.cos(b), r * math.sin(b)]), std))

    def distinct_landmarks(self) -> int:
        return len({item[1] for item in self._items})

    def fix_poses(self, n: int, rng: np.random.Generator) -> np.ndarray | None:
        """``(n, 3)`` poses drawn from the buffered readings (see the module docstring), or
        None while they hold fewer than two distinct landmarks."""
        if self.distinct_landmarks() < 2:
            return None
        world = np.array([item[2] for item in self._items])  # (K, 2)
        body = np.array([item[3] for item in self._items])
        std = np.array([item[4] + self.odometry_std_m_per_s * item[0] for item in self._items])
        pts = body[None] + rng.normal(size=(n, *body.shape)) * std[None, :, None]  # (n, K, 2)
        w = 1.0 / np.square(std)  # weighted least squares
        w = w / w.sum()
        cb = np.einsum("k,nkd->nd", w, pts)
        cw = w @ world
        b = pts - cb[:, None, :]
        v = world - cw
        cross = np.einsum("k,nk->n", w, b[..., 0] * v[None, :, 1] - b[..., 1] * v[None, :, 0])
        dot = np.einsum("k,nk->n", w, b[..., 0] * v[None, :, 0] + b[..., 1] * v[None, :, 1])
        theta = np.arctan2(cross, dot)
        c, s = np.cos(theta), np.sin(theta)
        out = np.empty((n, 3))
        out[:, 0] = cw[0] - (c * cb[:, 0] - s * cb[:, 1])
        out[:, 1] = cw[1] - (s * cb[:, 0] + c * cb[:, 1])
        out[:, 2] = wrap_angle(theta)
        return out
