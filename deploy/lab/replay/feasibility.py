"""When could a robot of a data set be localized from an unknown start? A bound from the data,
whatever the algorithm (issue 19).

From an unknown start a robot's pose (x, y, heading) is determined once its readings pin all
three down. One range-and-bearing reading of a known landmark leaves a one-parameter family
(any point of the circle of that range around the landmark, each with its own heading). Two
readings of distinct landmarks fix it, but only as well as the geometry allows: Dataset 6's
robot 1 sees landmarks 14 and 15, 0.18 m apart, from 6.5 m away in one direction for its
first 30 s, which leaves the robot anywhere on an arc of that circle (a particle filter
settles 2.4 m from the truth there with readings that fit). So the bound counts information,
not landmarks: the Fisher information of the pose carried by the readings of the last
``window_s`` seconds, ``J = sum_k H_k^T R_k^-1 H_k`` (``H_k`` the Jacobian of reading ``k``'s
range and bearing with respect to the pose, ``R_k`` the camera's noise), and the robot counts
as determined once the Cramér-Rao bound of its position, the largest std of ``J^-1``'s position
block, is under ``std_m`` (default 0.1 m: three stds within issue 19's 0.3 m).

The Jacobians are evaluated at the Vicon poses at the readings' times: the bound says what the
readings *could* tell a perfect estimator, an analysis of the data set, never an input of a
localizer. Within the window the odometry is taken as exact (the readings of one landmark from
two places then add parallax). Cooperatively, a teammate whose own bound has passed is a
landmark for a reading of it by this robot, and its reading of this robot is a position fix
(range along the line, range times bearing noise across it); iterated to a fixed point.

:func:`first_reading_times` gives the earliest time at which a robot has any fix at all: a
hard bound (before it the robot knows nothing of where it is). A robot whose bound is beyond
the 60 s of issue 19's target caps the success rate whatever the algorithm
(:func:`success_cap`).

The criterion and its thresholds are our choice (the seeds do not define observability).
Pure: no randomness.
"""

from __future__ import annotations

import math
from collections.abc import Mapping

import numpy as np

from swarmloc.agents.replay.localizers import CameraNoise
from swarmloc.world.replay.mrclam import MrclamDataset


def _reading_information(pose: np.ndarray, target_xy: np.ndarray, camera: CameraNoise,
                         position_only: bool = False) -> np.ndarray:
    """``(K, 3, 3)`` Fisher information on the pose of range-and-bearing readings of targets
    ``(K, 2)`` taken from poses ``(K, 3)``; with ``position_only``, of a teammate's reading of
    this robot (a position fix: range std along the line, range x bearing std across)."""
    d = target_xy - pose[:, :2]
    q = np.maximum(np.sum(d * d, axis=1), 1e-12)
    r = np.sqrt(q)
    var_r = np.square(camera.range_std(r))
    var_b = camera.bearing_std_rad**2
    info = np.zeros((pose.shape[0], 3, 3))
    u = d / r[:, None]  # unit vector robot -> target
    if position_only:
        n = np.column_stack([-u[:, 1], u[:, 0]])
        info[:, :2, :2] = (u[:, :, None] * u[:, None, :]) / var_r[:, None, None] \
            + (n[:, :, None] * n[:, None, :]) / (q * var_b)[:, None, None]
        return info
    h_r = np.column_stack([-u[:, 0], -u[:, 1], np.zeros(len(r))])
    h_b = np.column_stack([d[:, 1] / q, -d[:, 0] / q, -np.ones(len(r))])
    return (h_r[:, :, None] * h_r[:, None, :]) / var_r[:, None, None] \
        + (h_b[:, :, None] * h_b[:, None, :]) / var_b


def _events(dataset: MrclamDataset, rid: int, fixed_s: Mapping[int, float], cooperative: bool,
            start_s: float, camera: CameraNoise) -> tuple[np.ndarray, np.ndarray]:
    """Times (since the start, sorted) and information ``(K, 3, 3)`` of robot ``rid``'s
    readings with Vicon poses (see the module docstring)."""
    rec = dataset.robots[rid]
    times, infos = [], []

    def add(t_abs, target_xy, position_only=False):
        pose = rec.pose_at(t_abs)
        ok = np.isfinite(pose).all(axis=1) & np.isfinite(target_xy).all(axis=1)
        if ok.any():
            times.append(t_abs[ok] - start_s)
            infos.append(_reading_information(pose[ok], target_xy[ok], camera, position_only))

    lm = rec.landmark_measurements
    rows = dataset.landmarks.index_of(lm.subject)
    known = rows >= 0
    add(lm.time_s[known], dataset.landmarks.xy_m[rows[known]])
    if cooperative:
        rm = rec.robot_measurements
        for j in np.unique(rm.subject):
            if int(j) not in dataset.robots:
                continue
            sel = (rm.subject == j) & (rm.time_s - start_s >= fixed_s.get(int(j), math.inf))
            add(rm.time_s[sel], dataset.robots[int(j)].pose_at(rm.time_s[sel])[:, :2])
        for j, other in dataset.robots.items():
            if j == rid:
                continue
            om = other.robot_measurements
            sel = (om.subject == rid) & (om.time_s - start_s >= fixed_s.get(int(j), math.inf))
            add(om.time_s[sel], other.pose_at(om.time_s[sel])[:, :2], position_only=True)
    if not times:
        return np.zeros(0), np.zeros((0, 3, 3))
    time = np.concatenate(times)
    order = np.argsort(time, kind="stable")
    return time[order], np.concatenate(infos)[order]


def position_std_bound(time_s: np.ndarray, information: np.ndarray,
                       window_s: float) -> np.ndarray:
    """At each reading ``(K,)``: the Cramér-Rao bound of the position (the largest std of the
    inverse of the information summed over the readings of the last ``window_s`` seconds, that
    one included); inf where the information is singular."""
    if not time_s.size:
        return np.zeros(0)
    cumulative = np.concatenate([np.zeros((1, 3, 3)), np.cumsum(information, axis=0)])
    lo = np.searchsorted(time_s, time_s - window_s, side="left")
    total = cumulative[np.arange(1, time_s.size + 1)] - cumulative[lo]
    out = np.full(time_s.size, math.inf)
    # Singular (e.g. one reading): the pose's three numbers are not all pinned down.
    good = np.linalg.cond(total) < 1e12
    if good.any():
        cov = np.linalg.inv(total[good])
        out[good] = np.sqrt(np.maximum(np.linalg.eigvalsh(cov[:, :2, :2])[:, -1], 0.0))
    return out


def _fixed_point(dataset: MrclamDataset, cooperative: bool, first,
                 camera: CameraNoise) -> dict[int, float]:
    """Per robot, ``first(times, information)`` of its readings, teammates counting once their
    own time has passed: iterated until nothing changes."""
    start = dataset.time_span_s()[0]
    fixed = {rid: math.inf for rid in dataset.robot_ids}
    while True:  # each pass can only bring times earlier: a fixed point in at most N passes
        new = {rid: min(fixed[rid], first(*_events(dataset, rid, fixed, cooperative, start,
                                                    camera)))
               for rid in dataset.robot_ids}
        if new == fixed:
            return fixed
        fixed = new


def fix_times(dataset: MrclamDataset, window_s: float = 5.0, std_m: float = 0.1,
              cooperative: bool = False, camera: CameraNoise | None = None) -> dict[int, float]:
    """Per robot, seconds from the start until the readings of ``window_s`` seconds bound the
    position's std under ``std_m`` (see the module docstring; inf: never)."""
    if not window_s > 0.0 or not std_m > 0.0:
        raise ValueError(f"window_s and std_m must be > 0, got {window_s!r}, {std_m!r}")
    camera = camera or CameraNoise()

    def first(time, info):
        std = position_std_bound(time, info, window_s)
        hit = np.flatnonzero(std < std_m)
        return float(time[hit[0]]) if hit.size else math.inf

    return _fixed_point(dataset, cooperative, first, camera)


def first_reading_times(dataset: MrclamDataset, cooperative: bool = False) -> dict[int, float]:
    """Per robot, seconds from the start until its first reading of a landmark (or,
    cooperative, of or by a teammate already fixed by this criterion): a hard bound."""
    return _fixed_point(dataset, cooperative,
                        lambda time, info: float(time[0]) if time.size else math.inf,
                        CameraNoise())


def success_cap(times_s: Mapping[int, float], within_s: float) -> float:
    """The largest share of robots any algorithm could localize within ``within_s``: those whose
    bound is not later."""
    if not times_s:
        raise ValueError("no robots")
    return sum(t <= within_s for t in times_s.values()) / len(times_s)
