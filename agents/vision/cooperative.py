"""Cooperative localization from shared colour detections (seed 004 §II-III, eq. 1 and 2).

Seed 004's vision robots have one camera each, recognise objects by colour and know their sizes, so
each detection carries a size-based distance. Teammates share their detections ("Telepathy", §III)
and a robot that receives one looks for its own (or earlier remote) detections of the same colour in
the last 2 s (:func:`fresh`), then estimates where the teammate is:

- by stereo, eq. 1 ``f * B = Z * d`` with ``f = 190 px`` (:func:`stereo_distance`,
  :func:`stereo_relative_position`);
- by the law of cosines, eq. 2 ``C^2 = A^2 + B^2 - 2 A B cos(alpha)`` (:func:`triangulate`,
  :func:`teammate_from_common_object`), which also places an object that only the teammate sees in
  my frame (:func:`object_from_teammate`, Fig. 3 and experiment 3);
- and several such estimates (one per common object, stereo and triangle) are checked against each
  other and fused, rejecting contradictory ones (:func:`consistent`, :func:`fuse`), the paper's
  "triangulation ... to detect errors provoked by wrong size based distance estimation".

Frames and units: every robot's body frame has x forward, y to the left; bearings are counter-
clockwise from forward, in radians, in ``[-pi, pi]``; distances in metres; image coordinates in
pixels, positive to the left of the optical axis (``x_px = f tan(bearing - pan)``).

Choices where the paper is ambiguous
------------------------------------
- **Relative heading.** One common object fixes a teammate's position only if the two robots'
  headings are related (the paper's robots share "the position of the ball ... and the angle of the
  neck" and start side by side, facing the ball). Every pairwise function therefore takes
  ``relative_heading_rad`` (teammate heading minus mine; 0 = parallel bodies, experiment 1's set-up;
  otherwise from odometry). With two objects seen in common (Fig. 2) it is recovered from the
  detections alone by :func:`relative_heading_from_two_objects`.
- **Disparity with non-parallel cameras.** Eq. 1 holds for a rectified pair. The teammate's ray is
  rotated into my camera's orientation (my pan axis), i.e. the standard rotation rectification, and
  the disparity is ``d = x_mine - x_teammate`` of the rectified image positions. Eq. 1 gives the
  lateral baseline at the common depth ``Z``; when the two depths differ (``Z1 != Z2``) the exact
  lateral offset is ``(Z1 x1 - Z2 x2) / f``, i.e. eq. 1 with ``Z = Z2`` plus ``(Z1 - Z2) x1 / f``,
  and the depth offset is ``Z1 - Z2``. An object at or behind either rectified camera plane
  (``Z <= 0``, e.g. collinear with the two robots when they stand side by side) has no disparity:
  the result is ``None``.
- **Angles in eq. 2.** Eq. 2 gives the third side; the angle at my vertex is taken from the same
  triangle in ``atan2`` form (``atan2(-b sin a, a - b cos a)``), identical to the law-of-cosines
  angle but well conditioned for (near-)collinear triangles, where ``arccos`` loses precision. A
  triangle whose result side is (near) zero has no direction: ``None``.
- **Freshness.** A detection is fresh when ``0 <= now - t <= window`` (2 s, §III). Detections from
  the future (clock skew) are dropped too, rather than trusted.
- **Consistency.** Estimates are compared with their component-wise median; those farther than
  ``tolerance_m`` are rejected; if fewer than a strict majority survive (two estimates that
  disagree, say), the set is contradictory and :func:`fuse` returns ``None``. A single estimate
  cannot be checked and is accepted.
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from dataclasses import dataclass

import numpy as np

#: Seed 004 §II: "For an Aibo, we heuristically estimated f to be equal to 190 pixels."
FOCAL_PX = 190.0
#: Seed 004 §III: remote and local colour events are matched over the last 2 seconds.
FRESH_WINDOW_S = 2.0
#: Below this a length (m) is treated as zero: a direction from it would be meaningless.
_EPS_M = 1e-9


def wrap_rad(angle_rad):
    """Wrap angles to ``[-pi, pi)``."""
    return (np.asarray(angle_rad, dtype=float) + np.pi) % (2.0 * np.pi) - np.pi


def _finite(name: str, value: float) -> None:
    if not isinstance(value, (int, float, np.integer, np.floating)) or not math.isfinite(value):
        raise ValueError(f"{name} must be a finite number, got {value!r}")


@dataclass(frozen=True)
class Detection:
    """One colour detection as a robot shares it with its team (seed 004 §III, "Telepathy").

    ``bearing_rad`` is the object's bearing in the *robot (body) frame*, i.e. head pan plus the
    angle of the blob off the optical axis; ``head_pan_rad`` is the pan of the camera in the body
    frame at capture time (the "angle of the neck" the Aibos share), so the blob's image position
    is ``f tan(bearing_rad - head_pan_rad)``. ``distance_m`` is the size-based distance.
    Impossible values raise :class:`ValueError` on construction.
    """

    robot_id: int
    time_s: float
    colour: str
    bearing_rad: float
    head_pan_rad: float
    size_px: float
    distance_m: float

    def __post_init__(self) -> None:
        if not isinstance(self.robot_id, (int, np.integer)) or self.robot_id < 0:
            raise ValueError(f"robot_id must be a non-negative int, got {self.robot_id!r}")
        if not isinstance(self.colour, str) or not self.colour:
            raise ValueError(f"colour must be a non-empty string, got {self.colour!r}")
        for name in ("time_s", "bearing_rad", "head_pan_rad", "size_px", "distance_m"):
            _finite(name, getattr(self, name))
        if self.time_s < 0.0:
            raise ValueError(f"time_s must be >= 0, got {self.time_s}")
        if abs(self.bearing_rad) > math.pi or abs(self.head_pan_rad) > math.pi:
            raise ValueError("bearing_rad and head_pan_rad must lie in [-pi, pi]")
        if self.size_px <= 0.0:
            raise ValueError(f"size_px must be > 0, got {self.size_px}")
        if self.distance_m <= 0.0:
            raise ValueError(f"distance_m must be > 0, got {self.distance_m}")

    def position_m(self) -> np.ndarray:
        """The object's position in the observer's body frame, ``(2,)`` metres."""
        return self.distance_m * np.array([math.cos(self.bearing_rad), math.sin(self.bearing_rad)])


def fresh(
    detections: Iterable[Detection], now_s: float, window_s: float = FRESH_WINDOW_S
) -> list[Detection]:
    """The detections whose age ``now_s - time_s`` lies in ``[0, window_s]`` (seed 004 §III)."""
    if not window_s >= 0.0:
        raise ValueError(f"window_s must be >= 0, got {window_s}")
    return [d for d in detections if 0.0 <= now_s - d.time_s <= window_s]


def size_distance_m(object_size_m, size_px, focal_px: float = FOCAL_PX):
    """Monocular size-based distance of an object of known size (pinhole, ``Z = f S / s``)."""
    if not focal_px > 0.0:
        raise ValueError(f"focal_px must be > 0, got {focal_px}")
    size_px = np.asarray(size_px, dtype=float)
    with np.errstate(divide="ignore", invalid="ignore"):
        return np.where(
            size_px > 0.0, focal_px * np.asarray(object_size_m, float) / size_px, np.nan
        )


def stereo_distance(depth_m, disparity_px, focal_px: float = FOCAL_PX):
    """Baseline between two rectified cameras from eq. 1, ``f * B = Z * d``: ``B = Z d / f``.

    Signed: with ``d = x_1 - x_2`` (image x positive to the left), ``B`` is how far camera 2
    stands to the left of camera 1. Vectorised; ``NaN`` where ``depth_m <= 0`` (no disparity).
    """
    if not focal_px > 0.0:
        raise ValueError(f"focal_px must be > 0, got {focal_px}")
    depth_m = np.asarray(depth_m, dtype=float)
    return np.where(depth_m > 0.0, depth_m * np.asarray(disparity_px, float) / focal_px, np.nan)


def stereo_relative_position(
    mine: Detection,
    theirs: Detection,
    relative_heading_rad: float = 0.0,
    focal_px: float = FOCAL_PX,
) -> np.ndarray | None:
    """The teammate's position in my body frame from one object both see, by stereo (eq. 1).

    The teammate's ray is rectified to my camera axis (``head_pan_rad`` of ``mine``); depths
    ``Z_i = dist_i cos(phi_i)``, image positions ``x_i = f tan(phi_i)``, disparity ``d = x1 - x2``.
    Lateral offset ``stereo_distance(Z2, d) + (Z1 - Z2) x1 / f``, depth offset ``Z1 - Z2``, rotated
    back by my pan. ``None`` when either depth is not positive (see the module docstring).
    """
    if mine.colour != theirs.colour:
        raise ValueError(f"not the same object: {mine.colour!r} vs {theirs.colour!r}")
    axis_rad = mine.head_pan_rad
    phi1 = float(wrap_rad(mine.bearing_rad - axis_rad))
    phi2 = float(wrap_rad(theirs.bearing_rad + relative_heading_rad - axis_rad))
    z1 = mine.distance_m * math.cos(phi1)
    z2 = theirs.distance_m * math.cos(phi2)
    if z1 <= _EPS_M or z2 <= _EPS_M:
        return None
    x1_px = focal_px * math.tan(phi1)
    x2_px = focal_px * math.tan(phi2)
    lateral_m = float(stereo_distance(z2, x1_px - x2_px, focal_px)) + (z1 - z2) * x1_px / focal_px
    depth_m = z1 - z2
    c, s = math.cos(axis_rad), math.sin(axis_rad)
    return np.array([c * depth_m - s * lateral_m, s * depth_m + c * lateral_m])


def triangulate(vertex_distance_m, other_distance_m, angle_at_vertex_rad, vertex_bearing_rad):
    """Solve a triangle me - vertex - other by the law of cosines (eq. 2).

    Inputs: my distance ``a`` to the vertex and its bearing in my frame, the vertex's distance
    ``b`` to the other point, and the signed angle ``alpha`` at the vertex from the ray
    vertex->me to the ray vertex->other (counter-clockwise positive). Returns
    ``(distance_m, bearing_rad)`` of the other point in my frame: ``c^2 = a^2 + b^2 - 2ab cos
    alpha`` (eq. 2) and ``bearing = vertex_bearing + atan2(-b sin alpha, a - b cos alpha)``.
    Vectorised; ``NaN`` (both outputs) where ``a`` or ``c`` is (near) zero or inputs are negative.
    """
    a = np.asarray(vertex_distance_m, dtype=float)
    b = np.asarray(other_distance_m, dtype=float)
    alpha = np.asarray(angle_at_vertex_rad, dtype=float)
    c2 = a * a + b * b - 2.0 * a * b * np.cos(alpha)  # eq. 2
    c = np.sqrt(np.maximum(c2, 0.0))
    bearing = wrap_rad(vertex_bearing_rad + np.arctan2(-b * np.sin(alpha), a - b * np.cos(alpha)))
    bad = (a <= _EPS_M) | (b < 0.0) | (c <= _EPS_M) | ~np.isfinite(c) | ~np.isfinite(bearing)
    return np.where(bad, np.nan, c), np.where(bad, np.nan, bearing)


def _polar(distance_m, bearing_rad) -> np.ndarray | None:
    distance_m, bearing_rad = float(distance_m), float(bearing_rad)
    if not (math.isfinite(distance_m) and math.isfinite(bearing_rad)):
        return None
    return distance_m * np.array([math.cos(bearing_rad), math.sin(bearing_rad)])


def teammate_from_common_object(
    mine: Detection, theirs: Detection, relative_heading_rad: float = 0.0
) -> np.ndarray | None:
    """The teammate's position in my frame from one object both see, by eq. 2 (Fig. 2).

    Triangle me - object - teammate: ``A = mine.distance_m``, ``B = theirs.distance_m`` and the
    angle at the object between the two rays, ``alpha = (beta_2 + psi) - beta_1`` (``psi`` the
    teammate's heading relative to mine). ``None`` when the robots coincide.
    """
    if mine.colour != theirs.colour:
        raise ValueError(f"not the same object: {mine.colour!r} vs {theirs.colour!r}")
    alpha = wrap_rad(theirs.bearing_rad + relative_heading_rad - mine.bearing_rad)
    return _polar(*triangulate(mine.distance_m, theirs.distance_m, alpha, mine.bearing_rad))


def object_from_teammate(
    teammate_position_m: Sequence[float],
    relative_heading_rad: float,
    theirs: Detection,
) -> np.ndarray | None:
    """An object only the teammate sees, in my frame, by eq. 2 (Fig. 3, experiment 3).

    Triangle me - teammate - object: ``a = |teammate|``, ``b = theirs.distance_m``, angle at the
    teammate from its ray to me (bearing ``beta_t + pi`` in my frame) to its ray to the object
    (``beta_2 + psi``). ``None`` when the teammate is at my position.
    """
    t = np.asarray(teammate_position_m, dtype=float)
    bearing_t = math.atan2(t[1], t[0])
    alpha = wrap_rad(theirs.bearing_rad + relative_heading_rad - bearing_t - math.pi)
    return _polar(*triangulate(float(np.hypot(*t)), theirs.distance_m, alpha, bearing_t))


def relative_heading_from_two_objects(
    mine: tuple[Detection, Detection], theirs: tuple[Detection, Detection]
) -> float | None:
    """Teammate heading minus mine from two objects both robots see (Fig. 2).

    The segment object1 -> object2 has direction ``theta_mine`` in my frame and ``theta_theirs``
    in the teammate's; ``psi = theta_mine - theta_theirs``. ``None`` if the two objects coincide in
    either view (the direction is undefined).
    """
    for m, t in zip(mine, theirs, strict=True):
        if m.colour != t.colour:
            raise ValueError(f"not the same object: {m.colour!r} vs {t.colour!r}")
    seg_mine = mine[1].position_m() - mine[0].position_m()
    seg_theirs = theirs[1].position_m() - theirs[0].position_m()
    if np.hypot(*seg_mine) <= _EPS_M or np.hypot(*seg_theirs) <= _EPS_M:
        return None
    psi = math.atan2(seg_mine[1], seg_mine[0]) - math.atan2(seg_theirs[1], seg_theirs[0])
    return float(wrap_rad(psi))


def consistent(estimates, tolerance_m: float) -> np.ndarray:
    """Inlier mask of ``(N, 2)`` position estimates: within ``tolerance_m`` of their median.

    The median is component-wise; it ignores a minority of contradictory estimates.
    """
    if not tolerance_m >= 0.0:
        raise ValueError(f"tolerance_m must be >= 0, got {tolerance_m}")
    est = np.asarray(estimates, dtype=float).reshape(-1, 2)
    if len(est) == 0:
        return np.zeros(0, dtype=bool)
    if not np.all(np.isfinite(est)):
        raise ValueError("estimates must be finite")
    median = np.median(est, axis=0)
    return np.hypot(*(est - median).T) <= tolerance_m


def fuse(estimates, tolerance_m: float) -> np.ndarray | None:
    """Mean of the consistent estimates, or ``None`` if no strict majority agrees (or none given)."""
    est = np.asarray(estimates, dtype=float).reshape(-1, 2)
    inliers = consistent(est, tolerance_m)
    if len(est) == 0 or 2 * int(inliers.sum()) <= len(est):
        return None
    return est[inliers].mean(axis=0)
