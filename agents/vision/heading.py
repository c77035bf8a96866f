"""A teammate's pose from shared perception alone: one common object, and the ambiguity it leaves.

Seed 004 (``seeds/004_e71d8ee95e0baa56.txt``, Peula et al.) §II: "if a single landmark is detected
and no information at all on localization is available, the robot may know how far from the
landmark is, but not from which direction it is seeing it. [...] This uncertainty can be reduced
if two or more landmarks are detected, as triangulation allows correct positioning with respect
to them both. Besides, since robots are moving, statistical tools like Markov Fields can be used to
remove uncertainty as well. [...] Hoffmann [21], for example, uses negative information". §III:
"Localization can be still ambiguous after checking all distances associated to color events. In
this case, triangulation is used to reduce ambiguity." §IV-A: "The information that they are
sharing is the position of the ball respect to each AIBO, and the angle of the neck."

What one common object fixes. I see the object at ``O`` (my odometry frame); the teammate sees it
at ``o_t`` in its body frame (distance ``B = |o_t|``, bearing ``beta_t``: image position plus
"the angle of the neck"). The teammate's pose ``(T, phi)`` in my frame satisfies
``O = T + R(phi) o_t``: two equations, three unknowns. The solutions are the circle
``T(gamma) = O + B (cos gamma, sin gamma)`` with ``phi(gamma) = gamma + pi - beta_t``, where
``gamma`` is the direction from the object to the teammate (eq. 2's triangle with the angle at
the object unknown). Eq. 1 (stereo) resolves it only by assuming rectified, i.e. parallel,
cameras, which is the parallel-start prior this module does without.

:class:`DirectionGrid` is a Markov (histogram) filter over ``gamma``, one per teammate, anchored
on one common object. ``gamma``, unlike ``phi``, does not change when the teammate turns or walks
straight at (or away from) the object, so between measurements it only diffuses by the
teammate's sideways motion (:meth:`DirectionGrid.diffuse`). Each paired frame (mine and the
teammate's of the same time, §III's 2 s window) multiplies it by likelihoods
(:func:`object_likelihood`, :func:`sighting_likelihood`):

- a second common object (Fig. 2): the hypothesis predicts where the teammate should see it;
- a yellow blob I see (a direct sighting), or that the teammate sees (me);
- negative information (Hoffmann): a hypothesis that puts the teammate inside my field of view,
  within range and unhidden, while I see no yellow blob there, is down-weighted by
  ``miss_likelihood``; the same for me in the teammate's view.

Choices where the paper is silent (all parameters of ``VisionAgentConfig``): detections are
paired only within §III's window ("it checks for all previous distances ... associated to this
color object in last 2 seconds"), but what the grid has learnt from them persists beyond it
(the Markov filter of §II), blurred as the teammate may have moved; the grid has
``heading_bins`` bins; a sighting or object check is a Gaussian of spread ``match_sigma_m``
(plus 5 % of the distance); a miss costs ``miss_likelihood``; the grid never lets a bin fall below
``1e-4`` of the uniform weight (recovery from a wrong elimination, e.g. by an occlusion the
model does not know); when the anchor object changes the grid is shifted by the change of the
teammate's bearing, ``gamma' = gamma + beta_new - beta_old``.
"""

from __future__ import annotations

import math

import numpy as np

#: A bin never falls below this fraction of the uniform weight.
FLOOR_FRACTION = 1e-4
#: A hypothesis counts as "in view" only this far (rad) inside the field of view's edge, beyond
#: the teammate's own angular half-width (the agent drops blobs cut by the image edge).
VIEW_MARGIN_RAD = 0.03
#: Ranges (m) within which a teammate would be detected as a whole blob.
VIEW_MIN_M, VIEW_MAX_M = 0.25, 3.5


def rot(theta_rad) -> np.ndarray:
    """Rotation matrices ``(..., 2, 2)`` of the angles ``theta_rad``."""
    c, s = np.cos(theta_rad), np.sin(theta_rad)
    return np.stack([np.stack([c, -s], -1), np.stack([s, c], -1)], -2)


class DirectionGrid:
    """Histogram over ``gamma``, the direction (my odometry frame) from the anchor object to the
    teammate (module docstring). ``anchor``: colour of the anchor object or ``None``;
    ``anchor_bearing_rad``: the teammate's last bearing to it; ``time_s``: last update."""

    def __init__(self, bins: int):
        self.bins = int(bins)
        self.gamma_rad = -math.pi + (np.arange(self.bins) + 0.5) * (2.0 * math.pi / self.bins)
        self.weights = np.full(self.bins, 1.0 / self.bins)
        self.anchor: str | None = None
        self.anchor_bearing_rad = 0.0
        self.time_s: float | None = None

    def _normalise(self) -> None:
        self.weights = np.maximum(self.weights, FLOOR_FRACTION / self.bins * self.weights.sum())
        self.weights /= self.weights.sum()

    def diffuse(self, sigma_rad: float) -> None:
        """Blur by a wrapped Gaussian of ``sigma_rad`` (the teammate's sideways motion)."""
        step = 2.0 * math.pi / self.bins
        if sigma_rad < 0.25 * step:
            return
        half = min(self.bins // 2, math.ceil(3.0 * sigma_rad / step))
        offsets = np.arange(-half, half + 1)
        kernel = np.exp(-0.5 * (offsets * step / sigma_rad) ** 2)
        kernel /= kernel.sum()
        out = np.zeros_like(self.weights)
        for k, o in zip(kernel, offsets, strict=True):
            out += k * np.roll(self.weights, o)
        self.weights = out
        self._normalise()

    def shift(self, delta_rad: float) -> None:
        """``gamma -> gamma + delta_rad`` (a new anchor object), linear interpolation."""
        pos = delta_rad / (2.0 * math.pi / self.bins)
        lo = math.floor(pos)
        frac = pos - lo
        self.weights = (1.0 - frac) * np.roll(self.weights, lo) + frac * np.roll(self.weights, lo + 1)
        self._normalise()

    def update(self, likelihood: np.ndarray) -> None:
        """Bayes: multiply by ``likelihood`` (one value per bin) and normalise."""
        w = self.weights * np.asarray(likelihood, float)
        if not np.isfinite(w).all() or w.sum() <= 0.0:
            return  # every hypothesis excluded: the measurement, not the grid, is wrong
        self.weights = w
        self._normalise()

    def mode(self, window_rad: float = 0.3) -> tuple[float, float]:
        """The most probable direction (circular mean around the best bin, ``±window_rad``) and
        the probability mass within ``±window_rad`` of it."""
        best = self.gamma_rad[int(np.argmax(self.weights))]
        delta = (self.gamma_rad - best + math.pi) % (2.0 * math.pi) - math.pi
        near = np.abs(delta) <= window_rad
        w = self.weights[near]
        gamma = best + float(np.sum(w * delta[near]) / w.sum())
        return float((gamma + math.pi) % (2.0 * math.pi) - math.pi), float(w.sum())


def ring(anchor_xy, distance_m: float, gamma_rad: np.ndarray) -> np.ndarray:
    """Teammate positions ``(K, 2)`` of the hypotheses: ``O + B (cos gamma, sin gamma)``."""
    return np.asarray(anchor_xy, float) + distance_m * np.stack(
        [np.cos(gamma_rad), np.sin(gamma_rad)], -1
    )


def heading_of(gamma_rad, anchor_bearing_rad: float):
    """The teammate's heading (my odometry frame) of each hypothesis: ``gamma + pi - beta_t``."""
    return (np.asarray(gamma_rad) + math.pi - anchor_bearing_rad + math.pi) % (2 * math.pi) - math.pi


def to_frame(points_xy: np.ndarray, origin_xy, heading_rad) -> np.ndarray:
    """Points ``(K, 2)`` expressed in frames at ``origin_xy`` (``(2,)`` or ``(K, 2)``) with
    headings ``heading_rad`` (scalar or ``(K,)``)."""
    offset = np.asarray(points_xy, float) - np.asarray(origin_xy, float)
    r = rot(-np.asarray(heading_rad, float))
    if r.ndim == 2:
        return offset @ r.T
    return np.einsum("kij,kj->ki", r, offset)


def in_view(
    positions_body: np.ndarray,
    head_pan_rad: float,
    half_fov_rad: float,
    body_radius_m: float,
    occluders_body=(),
) -> np.ndarray:
    """Whether a robot at each position ``(K, 2)`` (observer's body frame) would show as a whole
    blob: within range, wholly inside the field of view, not behind a known nearer object
    (``occluders_body``: ``(position (2,), radius_m)`` pairs)."""
    p = np.asarray(positions_body, float)
    rng = np.hypot(p[:, 0], p[:, 1])
    bearing = np.arctan2(p[:, 1], p[:, 0])
    off = np.abs((bearing - head_pan_rad + math.pi) % (2 * math.pi) - math.pi)
    half_width = np.arctan2(body_radius_m, np.maximum(rng, 1e-6))
    ok = (rng >= VIEW_MIN_M) & (rng <= VIEW_MAX_M) & (off + half_width <= half_fov_rad - VIEW_MARGIN_RAD)
    for centre, radius in occluders_body:
        c = np.asarray(centre, float)
        c_rng = float(np.hypot(*c))
        if c_rng <= 1e-6:
            continue
        c_bearing = math.atan2(c[1], c[0])
        gap = np.abs((bearing - c_bearing + math.pi) % (2 * math.pi) - math.pi)
        hidden = (rng > c_rng) & (gap < math.atan2(radius, c_rng) + half_width)
        ok &= ~hidden
    return ok


def sighting_likelihood(
    predicted_body: np.ndarray,
    sightings_body,
    visible: np.ndarray,
    sigma_m: float,
    miss_likelihood: float,
    exclusive: bool,
) -> np.ndarray:
    """Likelihood of each hypothesis given the yellow blobs an observer saw.

    ``predicted_body``: where each hypothesis puts the robot in the observer's body frame;
    ``visible``: whether it would be seen there (:func:`in_view`). A hypothesis near a sighting
    scores up to 1; one in view with no sighting near it scores ``miss_likelihood`` (negative
    information); one out of view scores 1, unless ``exclusive`` (the observer has a single
    teammate, so any yellow blob is that robot) and a sighting exists, then at most 0.05.
    """
    p = np.asarray(predicted_body, float)
    s = np.asarray(sightings_body, float).reshape(-1, 2)
    if len(s):
        d2 = ((p[:, None, :] - s[None, :, :]) ** 2).sum(-1)
        spread = sigma_m + 0.05 * np.hypot(s[:, 0], s[:, 1])[None, :]
        match = np.exp(-0.5 * d2 / spread**2).max(axis=1)
    else:
        match = np.zeros(len(p))
    out_of_view = 0.05 if (exclusive and len(s)) else 1.0
    floor = np.where(visible, miss_likelihood, out_of_view)
    return np.maximum(match, floor)


def object_likelihood(predicted_body: np.ndarray, measured_body, sigma_m: float) -> np.ndarray:
    """Likelihood of each hypothesis from a second common object: where the hypothesis says
    the teammate sees it against where it does (Gaussian, spread ``sigma_m`` + 5 % of the
    distance; at least 1e-3, a wrong size-based distance must not exclude the truth)."""
    m = np.asarray(measured_body, float)
    spread = sigma_m + 0.05 * float(np.hypot(*m))
    d2 = ((np.asarray(predicted_body, float) - m) ** 2).sum(-1)
    return np.maximum(np.exp(-0.5 * d2 / spread**2), 1e-3)
