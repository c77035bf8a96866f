"""Laser rangefinders, unicycle motion and relative observations of the map-based laser robots.

Seeds 002 (MR-SSGA, §4) and 003 (CFS-GA, §V, table I):

- :func:`cast_rays`: the observation model, eq. 4 of 002. A beam leaving the robot at
  ``(l_x, l_y)`` with absolute direction ``theta_j`` hits the line ``a x + b y + c = 0`` of a wall
  segment at distance ``|a l_x + b l_y + c| / |a cos(theta_j) + b sin(theta_j)|``; the reading is
  the nearest such hit on any segment, or the maximum range ``l`` when nothing lies within it.
- :func:`scan`: eq. 4 plus the beam noise ``n_b`` (Gaussian, sigma_b), clipped to ``[0, l]``.
- :func:`unicycle_model` and :func:`unicycle_step`: eq. 3 of 002, the unicycle driven by the
  displacement ``delta_s`` and rotation ``delta_phi`` with the average heading
  ``phi + delta_phi / 2``. The world moves the true robot with noisy increments; the robot's
  odometry reports the commanded ones (so the agents' kinematic update, which applies the reported
  odometry to every hypothesis with :func:`unicycle_model`, drifts from the truth).
- :func:`relative_observation` and :func:`visible_pairs`: noisy relative distance and orientation
  of a teammate within range and line of sight (002 §3.2, table 2; 003 §IV-B, table I).

Parameters: :class:`LaserParams`, :class:`MotionNoise`, :class:`RelativeNoise`, each with
``mr_ssga()`` (table 2 of 002) and ``cfs_ga()`` (table I of 003) constructors.

How :func:`cast_rays` is fast: for pose ``o`` and segment ends ``a``, ``b`` let
``w1 = a - o``, ``w2 = b - o`` and ``c = w1 x w2`` (2-D cross product). A beam of direction ``d``
hits the segment iff ``A = (w1 x d) / c >= 0`` and ``B = (d x w2) / c >= 0`` (``d`` lies in the
cone spanned by ``w1`` and ``w2``), at distance ``1 / (A + B)``: the same distance as eq. 4, with
no division inside the ``(P, L, S)`` loop. ``A`` and ``B`` for all beams come from one batched
matrix product, then ``max`` over segments of ``copysign(A + B, min(A, B))`` gives the nearest
hit. This stage runs in float32 over chunks of poses that fit the cache (range error about
1e-6 m); the per-pose and per-segment terms are float64.

Random draws (fixed order, so a run is deterministic given ``rng``): :func:`scan` makes one
``rng.normal(size=(P, L))`` call; :func:`unicycle_step` one ``rng.normal(size=(N, 2))``;
:func:`relative_observation` one ``rng.normal(size=(K, 3))``. They draw even when a noise is 0.
All functions work on a batch: poses ``(N, 3)`` = ``(x_m, y_m, theta_rad)``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from swarmloc.world.laser.maps import SegmentMap, line_of_sight

#: Upper bound on float32 elements of the (poses, beams, 2 * segments) product per chunk:
#: about 0.5 MB, so the intermediate arrays stay in cache and are not page-faulted in afresh on
#: every call (a 2 MB chunk spent two thirds of a 300 x 18 cast in page faults).
_CHUNK_ELEMENTS = 1 << 17


def _check_finite_nonneg(value, name: str, positive: bool = False) -> float:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if isinstance(value, (bool, str)) or not math.isfinite(number) or number < 0.0:
        raise ValueError(f"{name} must be a finite number >= 0, got {value!r}")
    if positive and number == 0.0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return number


def _poses(poses_m: np.ndarray, name: str = "poses") -> np.ndarray:
    poses = np.asarray(poses_m, dtype=np.float64)
    if poses.ndim != 2 or poses.shape[1] != 3:
        raise ValueError(
            f"{name} must have shape (N, 3) = (x_m, y_m, theta_rad), got {poses.shape}"
        )
    return poses


def wrap_angle(angle_rad: np.ndarray) -> np.ndarray:
    """Angles wrapped to ``[-pi, pi)``."""
    return (np.asarray(angle_rad) + math.pi) % (2.0 * math.pi) - math.pi


# --------------------------------------------------------------------------------------------
# Ray casting (eq. 4 of 002)
# --------------------------------------------------------------------------------------------


def _cast_chunk(
    segments_m: np.ndarray, poses: np.ndarray, beam_angles_rad: np.ndarray, max_range_m: float
) -> np.ndarray:
    n_segments = segments_m.shape[0]
    n_poses, n_beams = poses.shape[0], beam_angles_rad.shape[0]
    ox, oy = poses[:, 0:1], poses[:, 1:2]
    w1x, w1y = segments_m[:, 0] - ox, segments_m[:, 1] - oy  # (P, S)
    w2x, w2y = segments_m[:, 2] - ox, segments_m[:, 3] - oy
    cross12 = w1x * w2y - w1y * w2x
    # 1 / c carries the orientation: dividing by a negative c swaps the roles of the two ends.
    # A segment seen edge-on (c = 0) has no width and is never hit.
    with np.errstate(divide="ignore"):
        inv_cross = np.where(cross12 != 0.0, 1.0 / np.where(cross12 != 0.0, cross12, 1.0), 0.0)
    # A = (w1 x d) / c = d . (-w1y, w1x) / c ;  B = (d x w2) / c = d . (w2y, -w2x) / c
    coeff = np.empty((n_poses, 2, 2 * n_segments), dtype=np.float32)
    coeff[:, 0, :n_segments] = -w1y * inv_cross
    coeff[:, 1, :n_segments] = w1x * inv_cross
    coeff[:, 0, n_segments:] = w2y * inv_cross
    coeff[:, 1, n_segments:] = -w2x * inv_cross
    angles = poses[:, 2:3] + beam_angles_rad  # (P, L)
    directions = np.empty((n_poses, n_beams, 2), dtype=np.float32)
    directions[..., 0] = np.cos(angles)
    directions[..., 1] = np.sin(angles)
    products = np.matmul(directions, coeff)  # (P, L, 2S)
    a_part, b_part = products[..., :n_segments], products[..., n_segments:]
    inverse_range = a_part + b_part
    # Keep 1/t where the beam is inside the segment's cone, make it <= 0 elsewhere.
    np.copysign(inverse_range, np.minimum(a_part, b_part), out=inverse_range)
    nearest_inverse = inverse_range.max(axis=-1).astype(np.float64)  # (P, L)
    hit = nearest_inverse * max_range_m > 1.0
    return np.where(hit, 1.0 / np.where(hit, nearest_inverse, 1.0), max_range_m)


def cast_rays(
    world_map: SegmentMap,
    poses_m: np.ndarray,
    beam_angles_rad: np.ndarray,
    max_range_m: float,
) -> np.ndarray:
    """Noise-free laser ranges, eq. 4 of 002: ``(P, L)`` metres.

    ``poses_m`` ``(P, 3)`` are the sensor poses; ``beam_angles_rad`` ``(L,)`` the beam directions
    relative to the heading. Each entry is the distance to the nearest wall along the beam, or
    ``max_range_m`` when no wall lies closer. Walls are two-sided; a beam through a segment's end
    counts as a hit. Precision about 1e-6 m (see the module docstring).
    """
    poses = _poses(poses_m)
    beams = np.asarray(beam_angles_rad, dtype=np.float64)
    if beams.ndim != 1:
        raise ValueError(f"beam_angles_rad must have shape (L,), got {beams.shape}")
    max_range_m = _check_finite_nonneg(max_range_m, "max_range_m", positive=True)
    n_poses, n_beams = poses.shape[0], beams.shape[0]
    if n_poses == 0 or n_beams == 0:
        return np.full((n_poses, n_beams), max_range_m)
    segments = world_map.segments_m
    chunk = max(1, _CHUNK_ELEMENTS // (n_beams * 2 * segments.shape[0]))
    if n_poses <= chunk:
        return _cast_chunk(segments, poses, beams, max_range_m)
    out = np.empty((n_poses, n_beams))
    for start in range(0, n_poses, chunk):
        stop = min(start + chunk, n_poses)
        out[start:stop] = _cast_chunk(segments, poses[start:stop], beams, max_range_m)
    return out


def single_scan_crb(
    world_map: SegmentMap,
    poses_m: np.ndarray,
    beam_angles_rad: np.ndarray,
    max_range_m: float,
    noise_std_m: float,
    step: float = 1e-4,
) -> np.ndarray:
    """Cramér-Rao bound of one scan (eq. 4 of 002 plus Gaussian noise of ``noise_std_m``) on the
    position, pose unknown: ``sqrt(tr [J^-1]_xy)`` in metres for each of ``poses_m`` ``(P, 3)``,
    with the Fisher information ``J = H^T H / sigma^2`` and ``H`` the ``(L, 3)`` derivatives of
    the noise-free ranges in x, y and heading (central differences of :func:`cast_rays`, which
    is exact). Beams at maximum range carry no information (their derivative is zero); ``inf``
    where ``J`` is singular (a pose the scan cannot fix, such as a corridor's axis). The RMS
    position error of any unbiased estimator from that one scan is at least this (issue 43)."""
    poses = _poses(poses_m)
    sigma = _check_finite_nonneg(noise_std_m, "noise_std_m", positive=True)
    jacobian = np.empty((poses.shape[0], len(beam_angles_rad), 3))
    for axis in range(3):
        shift = np.zeros(3)
        shift[axis] = step
        ahead = cast_rays(world_map, poses + shift, beam_angles_rad, max_range_m)
        behind = cast_rays(world_map, poses - shift, beam_angles_rad, max_range_m)
        jacobian[..., axis] = (ahead - behind) / (2.0 * step)
    # A beam whose end crosses a segment's end between the two casts has no derivative there.
    jacobian[np.abs(jacobian) > 1.0 / step] = 0.0
    info = np.einsum("pla,plb->pab", jacobian, jacobian) / sigma**2
    out = np.full(poses.shape[0], math.inf)
    for i, matrix in enumerate(info):
        if np.linalg.cond(matrix) < 1e12:
            covariance = np.linalg.inv(matrix)
            out[i] = math.sqrt(max(0.0, covariance[0, 0] + covariance[1, 1]))
    return out


@dataclass(frozen=True)
class LaserParams:
    """A ring of ``n_beams`` laser beams evenly spread over 360 deg (the first along the heading),
    with maximum range and Gaussian range noise (eq. 4 of 002, ``n_b``)."""

    n_beams: int = 8
    max_range_m: float = 6.0
    noise_std_m: float = 0.10

    def __post_init__(self) -> None:
        if isinstance(self.n_beams, bool) or not isinstance(self.n_beams, (int, np.integer)):
            raise TypeError(f"n_beams must be an integer, got {self.n_beams!r}")
        if self.n_beams < 1:
            raise ValueError(f"n_beams must be >= 1, got {self.n_beams}")
        _check_finite_nonneg(self.max_range_m, "max_range_m", positive=True)
        _check_finite_nonneg(self.noise_std_m, "noise_std_m")

    @property
    def beam_angles_rad(self) -> np.ndarray:
        """Beam directions relative to the heading, ``(n_beams,)``, from 0 in steps of 360/L deg."""
        return np.arange(self.n_beams) * (2.0 * math.pi / self.n_beams)

    @classmethod
    def mr_ssga(cls) -> LaserParams:
        """Table 2 of 002: L = 8 beams, beam range l = 6 m, sigma_b = 10 cm."""
        return cls(n_beams=8, max_range_m=6.0, noise_std_m=0.10)

    @classmethod
    def cfs_ga(cls) -> LaserParams:
        """Table I of 003: L = 18 beams, l = 8 m, Q_l = 0.1 m (labelled a variance but given in
        metres; read as the standard deviation, like sigma_b of 002)."""
        return cls(n_beams=18, max_range_m=8.0, noise_std_m=0.10)


def scan(
    world_map: SegmentMap, poses_m: np.ndarray, params: LaserParams, rng: np.random.Generator
) -> np.ndarray:
    """Noisy laser scans ``(P, L)``: eq. 4 plus Gaussian noise of ``params.noise_std_m``, clipped to
    ``[0, params.max_range_m]``. One ``rng.normal`` draw of shape ``(P, L)``."""
    ranges = cast_rays(world_map, poses_m, params.beam_angles_rad, params.max_range_m)
    noise = rng.normal(0.0, 1.0, size=ranges.shape) * params.noise_std_m
    return np.clip(ranges + noise, 0.0, params.max_range_m)


# --------------------------------------------------------------------------------------------
# Unicycle (eq. 3 of 002)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MotionNoise:
    """Standard deviations of the true speed and turn rate around the commanded ones
    (the system noise ``n_s`` of eq. 3). Over a step of ``dt_s`` the increments' standard
    deviations are ``speed_std_mps * dt_s`` and ``turn_rate_std_rad_s * dt_s``."""

    speed_std_mps: float = 0.03
    turn_rate_std_rad_s: float = 0.2

    def __post_init__(self) -> None:
        _check_finite_nonneg(self.speed_std_mps, "speed_std_mps")
        _check_finite_nonneg(self.turn_rate_std_rad_s, "turn_rate_std_rad_s")

    @classmethod
    def mr_ssga(cls) -> MotionNoise:
        """Table 2 of 002: sigma_s = [3 cm/s, 0.2 rad/s]."""
        return cls(speed_std_mps=0.03, turn_rate_std_rad_s=0.2)

    @classmethod
    def cfs_ga(cls) -> MotionNoise:
        """Table I of 003: Q_m = [0.05 m/s, 0.1 rad/s] (labelled variances, in the units of a
        standard deviation; read as standard deviations)."""
        return cls(speed_std_mps=0.05, turn_rate_std_rad_s=0.1)


def unicycle_model(poses_m: np.ndarray, delta_s_m, delta_phi_rad) -> np.ndarray:
    """Eq. 3 of 002 without noise: ``x + delta_s cos(phi~)``, ``y + delta_s sin(phi~)``,
    ``phi + delta_phi`` with ``phi~ = phi + delta_phi / 2``; heading wrapped to ``[-pi, pi)``.

    ``delta_s_m`` and ``delta_phi_rad`` are scalars or ``(N,)``. Returns new poses ``(N, 3)``.
    """
    poses = _poses(poses_m)
    delta_s = np.asarray(delta_s_m, dtype=np.float64)
    delta_phi = np.asarray(delta_phi_rad, dtype=np.float64)
    heading_mid = poses[:, 2] + delta_phi / 2.0
    out = np.empty_like(poses)
    out[:, 0] = poses[:, 0] + delta_s * np.cos(heading_mid)
    out[:, 1] = poses[:, 1] + delta_s * np.sin(heading_mid)
    out[:, 2] = wrap_angle(poses[:, 2] + delta_phi)
    return out


@dataclass(frozen=True)
class MotionStep:
    """What one :func:`unicycle_step` produces.

    ``poses_m`` ``(N, 3)``: the true new poses (world side, never shown to the robot).
    ``odometry_delta_s_m`` and ``odometry_delta_phi_rad`` ``(N,)``: the increments the robot's
    odometry reports (the commanded ones).
    """

    poses_m: np.ndarray
    odometry_delta_s_m: np.ndarray
    odometry_delta_phi_rad: np.ndarray


def unicycle_step(
    poses_m: np.ndarray,
    v_mps,
    omega_rad_s,
    dt_s: float,
    noise: MotionNoise,
    rng: np.random.Generator,
) -> MotionStep:
    """Move robots by eq. 3 of 002 for ``dt_s`` seconds with noisy true motion.

    The odometry reports ``(v dt, omega dt)``; the robot truly moves by
    ``((v + n_v) dt, (omega + n_omega) dt)`` with ``n_v ~ N(0, speed_std^2)`` and
    ``n_omega ~ N(0, turn_rate_std^2)``. One ``rng.normal`` draw of shape ``(N, 2)``.
    """
    poses = _poses(poses_m)
    dt_s = _check_finite_nonneg(dt_s, "dt_s")
    n = poses.shape[0]
    v = np.broadcast_to(np.asarray(v_mps, dtype=np.float64), (n,))
    omega = np.broadcast_to(np.asarray(omega_rad_s, dtype=np.float64), (n,))
    std = np.array([noise.speed_std_mps, noise.turn_rate_std_rad_s])
    draws = rng.normal(0.0, 1.0, size=(n, 2)) * std
    odometry_s, odometry_phi = v * dt_s, omega * dt_s
    true_s = (v + draws[:, 0]) * dt_s
    true_phi = (omega + draws[:, 1]) * dt_s
    return MotionStep(
        poses_m=unicycle_model(poses, true_s, true_phi),
        odometry_delta_s_m=odometry_s.copy(),
        odometry_delta_phi_rad=odometry_phi.copy(),
    )


# --------------------------------------------------------------------------------------------
# Relative observations of teammates
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RelativeNoise:
    """Gaussian noise on a teammate's measured distance and on both measured angles (bearing of
    the teammate and its relative heading), plus the range of robot visibility."""

    distance_std_m: float = 0.05
    orientation_std_rad: float = math.radians(3.0)
    range_m: float = 8.0

    def __post_init__(self) -> None:
        _check_finite_nonneg(self.distance_std_m, "distance_std_m")
        _check_finite_nonneg(self.orientation_std_rad, "orientation_std_rad")
        _check_finite_nonneg(self.range_m, "range_m", positive=True)

    @classmethod
    def mr_ssga(cls) -> RelativeNoise:
        """Table 2 of 002: sigma_d = 5 cm, sigma_o = 3 (printed as rad; 3 rad would make the
        orientation meaningless, so read as 3 deg), visibility V = 8 m."""
        return cls(distance_std_m=0.05, orientation_std_rad=math.radians(3.0), range_m=8.0)

    @classmethod
    def cfs_ga(cls) -> RelativeNoise:
        """Table I of 003: Q_rd = 0.2 m, Q_ro = 0.1 rad (read as standard deviations),
        communication range c_r = 4 m."""
        return cls(distance_std_m=0.2, orientation_std_rad=0.1, range_m=4.0)


@dataclass(frozen=True)
class RelativeObservation:
    """Robot ``j`` as robot ``i`` measures it, per pair ``(K,)``; NaN where not ``visible``.

    ``distance_m``: distance between the two robots. ``bearing_rad``: direction of ``j`` in ``i``'s
    frame. ``relative_heading_rad``: ``theta_j - theta_i``. Angles wrapped to ``[-pi, pi)``.
    """

    distance_m: np.ndarray
    bearing_rad: np.ndarray
    relative_heading_rad: np.ndarray
    visible: np.ndarray


def relative_observation(
    poses_m: np.ndarray,
    i,
    j,
    world_map: SegmentMap,
    range_m: float,
    noise: RelativeNoise,
    rng: np.random.Generator,
) -> RelativeObservation:
    """Noisy distance and orientation of robots ``j`` seen from robots ``i`` (index arrays or
    scalars, broadcast to ``(K,)``). A pair is visible when ``i != j``, the true distance is at most
    ``range_m`` and no wall blocks the line of sight. One ``rng.normal`` draw of shape ``(K, 3)``
    (distance, bearing, relative heading), made for every pair."""
    poses = _poses(poses_m)
    range_m = _check_finite_nonneg(range_m, "range_m", positive=True)
    i_idx, j_idx = np.broadcast_arrays(np.atleast_1d(np.asarray(i)), np.atleast_1d(np.asarray(j)))
    if i_idx.ndim != 1 or not (
        np.issubdtype(i_idx.dtype, np.integer) and np.issubdtype(j_idx.dtype, np.integer)
    ):
        raise ValueError("i and j must be integer indices or 1-D integer arrays")
    n = poses.shape[0]
    if i_idx.size and (min(i_idx.min(), j_idx.min()) < 0 or max(i_idx.max(), j_idx.max()) >= n):
        raise ValueError(f"robot indices must lie in [0, {n})")
    draws = rng.normal(0.0, 1.0, size=(i_idx.size, 3))
    pose_i, pose_j = poses[i_idx], poses[j_idx]
    delta = pose_j[:, :2] - pose_i[:, :2]
    distance = np.hypot(delta[:, 0], delta[:, 1])
    visible = (i_idx != j_idx) & (distance <= range_m)
    if np.any(visible):
        visible[visible] = line_of_sight(world_map, pose_i[visible], pose_j[visible])
    bearing = np.arctan2(delta[:, 1], delta[:, 0]) - pose_i[:, 2]
    heading = pose_j[:, 2] - pose_i[:, 2]
    nan = np.nan
    return RelativeObservation(
        distance_m=np.where(visible, np.abs(distance + draws[:, 0] * noise.distance_std_m), nan),
        bearing_rad=np.where(
            visible, wrap_angle(bearing + draws[:, 1] * noise.orientation_std_rad), nan
        ),
        relative_heading_rad=np.where(
            visible, wrap_angle(heading + draws[:, 2] * noise.orientation_std_rad), nan
        ),
        visible=visible,
    )


def visible_pairs(world_map: SegmentMap, poses_m: np.ndarray, range_m: float) -> np.ndarray:
    """Ordered pairs ``(i, j)``, ``i != j``, within ``range_m`` and in line of sight: ``(K, 2)``
    int, sorted. Neighbours come from a KD-tree, line of sight from :func:`line_of_sight`."""
    poses = _poses(poses_m)
    range_m = _check_finite_nonneg(range_m, "range_m", positive=True)
    if poses.shape[0] < 2:
        return np.empty((0, 2), dtype=np.int64)
    pairs = cKDTree(poses[:, :2]).query_pairs(range_m, output_type="ndarray")
    if pairs.size == 0:
        return np.empty((0, 2), dtype=np.int64)
    clear = line_of_sight(world_map, poses[pairs[:, 0], :2], poses[pairs[:, 1], :2])
    pairs = pairs[clear]
    both = np.concatenate([pairs, pairs[:, ::-1]], axis=0).astype(np.int64)
    return both[np.lexsort((both[:, 1], both[:, 0]))]
