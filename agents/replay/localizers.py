"""Localizers for landmark range-and-bearing robots (the MRCLAM replay), and their contract.

This mirrors the laser family's contract (``agents/laser/localizer.py``) for the observations of
:class:`swarmloc.world.replay.replay.LandmarkObservation`: one localizer object is one robot's brain, a
pure model with its own ``numpy.random.Generator``, that the replay world feeds in-process or a
world-server shell feeds over Zenoh:

- :meth:`LandmarkLocalizer.step` applies the tick's odometry ``(v, omega, dt)``, then its landmark
  measurements (landmark id, range, bearing), then, when cooperative, its teammates' data;
- :meth:`LandmarkLocalizer.estimate` is the best pose ``(x_m, y_m, theta_rad)``;
- :meth:`LandmarkLocalizer.outgoing` is the payload broadcast to the teammates (delivered at the
  next tick), a :class:`TeammateReport`: the sender's pose estimate, its covariance, the
  teammates it measured this tick (id, range, bearing) and optionally a few pose samples.

Algorithms (registry :data:`ALGORITHMS`, built by :func:`build_localizer`):

- ``dr``: dead reckoning (unicycle integration of the commands, covariance propagated as in
  eq. 9 of seed 000 with the noise model of :class:`MotionNoise`); cooperative: **social
  odometry**, the SGIKF of seed 000 eq. 18-22 applied to pose estimates (see
  :func:`sgikf_fuse`), with the SIKF's covariance-norm confidence of eq. 19;
- ``ekf``: the EKF with known landmarks (``agents/replay/ekf.py``), the reference baseline of the MRCLAM
  literature; cooperative: relative range-and-bearing updates against the teammates' broadcast
  estimates (or the SGIKF fusion, ``fusion="sgikf"``);
- ``pf``: the AMCL-style particle filter of ``agents/laser/amcl.py`` (:class:`AugmentedMCL`: KLD
  sampling, recovery) with the landmark log-likelihood :func:`landmark_log_likelihood` plugged
  in; cooperative: each particle is reweighted by the density of the teammate's broadcast
  belief (a Gaussian) at the place the particle and the relative measurement put it (Fox, Burgard,
  Kruppa, Thrun 2000, as in ``amcl_belief.teammate_log_factor`` but without a relative heading, which
  MRCLAM's cameras do not measure);
- ``cfsga``: CFS-GA of ``agents/laser/cfsga.py`` (:class:`FitnessSharingGA`, seed 003) with the raw
  fitness :func:`landmark_fitness_terms` (003 §IV-A's mean of Gaussians of the measurement
  residuals, over the landmark readings of the last second); cooperative: 003 §IV-B's virtual
  population and virtual niches, the teammates' above-average individuals turned into
  hypotheses of this robot's position by the range-and-bearing reading between the two robots,
  and the teammates' readings as further fitness terms;
- ``hybrid``: the particle filter searches, the EKF tracks once the particles agree with each
  other and with the readings, and the search starts again when the EKF counts itself lost
  (:mod:`swarmloc.agents.replay.hybrid`).
- ``ssga``: MR-SSGA of seed 002 (the laser family's ``agents/laser/ssga.py``: population on a
  small-world network, table 1's mating rules) with eq. 1 as the mean of CFS-GA's landmark
  fitness terms over the readings of the last two seconds; cooperative: eq. 2, the teammates'
  relative readings against their broadcast beliefs added to the fitness
  (:mod:`swarmloc.agents.replay.ssga_landmarks`).
- ``ls-cen``, ``ls-bda``, ``ls-ci``, ``gs-ci``, ``gs-sci``: CoLo-AT's cooperative-localization
  estimators (centralized EKF as a replica in every robot, block-diagonal approximation,
  local-state and global-state covariance intersection, split CI), each from its paper
  (:mod:`swarmloc.agents.replay.colo`, issue 46).

Particle filter and GA run their measurement step (correction/generation) on the ticks that
bring a landmark or teammate measurement and only move their hypotheses with the odometry in
between (as ``amcl`` only updates after the robot moved, ``update_min_d``): a 900 s replay at
0.02 s has 45,000 ticks but about 2,000 camera frames per robot.

The particle filter and CFS-GA are :mod:`swarmloc.agents.replay.populations`, the EKF
:mod:`swarmloc.agents.replay.ekf`; this module holds the contract, the noise models, the
measurement models, the teammate reports, dead reckoning and the registry.

Every localizer starts from the known initial pose (the data sets' convention for tracking; the
MRCLAM literature initialises from the first ground-truth pose) with ``initial_std``; or, for
the population localizers (``pf``, ``cfsga``, ``ssga``, and ``hybrid``, which searches with the
``pf``), from an unknown one: ``LandmarkSetup.initial_area_m``
(uniform over that area and every heading, issue 19).

Noise parameters. :class:`CameraNoise`'s defaults are the raw camera of
``../shared/data/mrclam/SOURCE.md`` (bearing std 0.012-0.016 rad; range error std about 0.18 m
overall, modelled as 0.02 m + 4 % of the range); most of that range error is a bias that
depends on the bearing, which each robot estimates while it localizes
(:class:`swarmloc.agents.replay.calibration.SelfCalibratingLocalizer`, no ground truth; or, as a
reference, :func:`swarmloc.deploy.lab.replay.mrclam.fit_camera` against the Vicon ground truth)
and :meth:`CameraNoise.corrected_range` removes. :class:`MotionNoise`'s defaults follow the
commanded-vs-true velocity errors of Dataset 6 (speed error std 0.015-0.02 m/s, turn-rate error
std 0.08-0.12 rad/s over 0.2 s windows); the filters are insensitive to them within a factor
of two. The motion noise is thus calibrated on the data the report evaluates on; the report says
so.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field, fields, replace
from typing import Protocol, runtime_checkable

import msgpack
import numpy as np

from swarmloc.agents.epuck.social_odometry import sgikf_update
from swarmloc.config import did_you_mean
from swarmloc.registry import Registry
from swarmloc.world.replay.replay import MAX_PAYLOAD_BYTES, LandmarkObservation, Message

TWO_PI = 2.0 * math.pi


def wrap_angle(angle_rad):
    """Angles wrapped to ``[-pi, pi)``."""
    return (np.asarray(angle_rad, dtype=np.float64) + math.pi) % TWO_PI - math.pi


def _real(value, name: str, *, positive: bool = False, minimum: float | None = 0.0) -> float:
    if isinstance(value, (bool, str)) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name} must be a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if minimum is not None and number < minimum:
        raise ValueError(f"{name} must be >= {minimum}, got {value!r}")
    if positive and number <= 0.0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    return number


def reject_unknown_keys(config: Mapping, known, what: str) -> None:
    """A ValueError for the first key of ``config`` not in ``known``, naming the closest valid
    one."""
    known = list(known)
    for key in config:
        if key not in known:
            hint = did_you_mean(str(key), known, 0.5)
            raise ValueError(f"{key}: unknown {what} parameter{hint}")


def params_from_dict(cls, config: Mapping, what: str):
    """Build a parameter dataclass from a mapping; an unknown key names the closest valid one."""
    if not isinstance(config, Mapping):
        raise TypeError(f"{what} parameters must be a mapping, got {type(config).__name__}")
    reject_unknown_keys(config, [f.name for f in fields(cls)], what)
    return cls(**dict(config))


# --------------------------------------------------------------------------------------------
# Noise models and setup
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class MotionNoise:
    """How far the true motion strays from the logged commands ``(v, omega)``.

    The command errors are treated as white noise with correlation time ``correlation_s``: over
    a tick of ``dt`` the travelled distance gets a variance ``sigma_v^2 tau dt`` and the turn
    ``sigma_omega^2 tau dt``, with ``sigma_v = speed_fraction |v| + speed_std_mps`` and
    ``sigma_omega = turn_fraction |omega| + turn_std_rad_s + turn_per_speed |v|``.
    """

    speed_fraction: float = 0.15
    speed_std_mps: float = 0.005
    turn_fraction: float = 0.35
    turn_std_rad_s: float = 0.02
    turn_per_speed_rad_m: float = 0.5
    correlation_s: float = 1.0
    #: Typical command, for filters whose motion noise cannot follow the command (the AMCL core
    #: takes one per-step noise): MRCLAM's usual cruising command.
    typical_v_mps: float = 0.07
    typical_omega_rad_s: float = 0.2

    def __post_init__(self):
        for f in fields(self):
            _real(getattr(self, f.name), f.name, positive=f.name == "correlation_s")

    def tick_std(self, v_mps, omega_rad_s, dt_s: float) -> tuple[float, float]:
        """``(std of the distance [m], std of the turn [rad])`` over one tick."""
        scale = math.sqrt(self.correlation_s * dt_s)
        sigma_v = self.speed_fraction * abs(v_mps) + self.speed_std_mps
        sigma_w = (self.turn_fraction * abs(omega_rad_s) + self.turn_std_rad_s
                   + self.turn_per_speed_rad_m * abs(v_mps))
        return sigma_v * scale, sigma_w * scale


@dataclass(frozen=True)
class CameraNoise:
    """The camera's range-and-bearing model.

    MRCLAM's ranges carry a systematic error that depends on the bearing: the measured range is
    about ``r (1 + c0 + c2 b^2)`` of the true range ``r`` at bearing ``b`` (Dataset 6: ``c0``
    between 0.025 and 0.066 depending on the robot, ``c2`` about -0.46: +3 % straight ahead, -9 %
    at the edge of the field of view). :meth:`corrected_range` divides it out; the calibration
    comes from :func:`swarmloc.deploy.lab.replay.mrclam.fit_camera` (defaults: no correction). ``teammate_*``
    are the same coefficients for readings of robots (their barcode tubes differ from the
    landmarks').

    Noise after correction: range std ``range_std_m + range_fraction * range``, bearing std
    ``bearing_std_rad``; a reading is an outlier (a misread, a reflection) with probability
    ``outlier_probability`` (the robust likelihoods of PF and GA; the EKF gates instead).
    """

    range_std_m: float = 0.02
    range_fraction: float = 0.04
    bearing_std_rad: float = 0.015
    outlier_probability: float = 0.02
    range_bias_c0: float = 0.0
    range_bias_c2: float = 0.0
    teammate_range_bias_c0: float = 0.0
    teammate_range_bias_c2: float = 0.0

    def __post_init__(self):
        for f in fields(self):
            _real(getattr(self, f.name), f.name, minimum=None if "bias" in f.name else 0.0)
        if self.range_std_m == 0.0 and self.range_fraction == 0.0:
            raise ValueError("range_std_m and range_fraction cannot both be 0")
        if self.bearing_std_rad <= 0.0:
            raise ValueError(f"bearing_std_rad must be > 0, got {self.bearing_std_rad}")
        if not self.outlier_probability < 1.0:
            raise ValueError(f"outlier_probability must be < 1, got {self.outlier_probability}")
        for c0, c2 in ((self.range_bias_c0, self.range_bias_c2),
                       (self.teammate_range_bias_c0, self.teammate_range_bias_c2)):
            if not (1.0 + c0 > 0.2 and 1.0 + c0 + c2 > 0.2):
                raise ValueError(f"range bias (c0={c0}, c2={c2}) would scale ranges below 0.2 "
                                 "within 1 rad of the optical axis")

    def range_std(self, range_m) -> np.ndarray:
        return self.range_std_m + self.range_fraction * np.asarray(range_m, dtype=np.float64)

    def corrected_range(self, range_m, bearing_rad, teammate: bool = False) -> np.ndarray:
        """Measured ranges with the bearing-dependent bias divided out (the correction is the
        one at 1 rad for readings further off axis: MRCLAM's cameras see about +-0.6 rad)."""
        c0, c2 = ((self.teammate_range_bias_c0, self.teammate_range_bias_c2) if teammate
                  else (self.range_bias_c0, self.range_bias_c2))
        b_sq = np.minimum(np.square(np.asarray(bearing_rad, dtype=np.float64)), 1.0)
        return np.asarray(range_m, dtype=np.float64) / (1.0 + c0 + c2 * b_sq)


@dataclass(frozen=True)
class LandmarkSetup:
    """What every landmark localizer is built from. Algorithm parameters come separately."""

    robot_id: int
    landmark_ids: np.ndarray  #: (L,) subject ids
    landmark_xy_m: np.ndarray  #: (L, 2)
    initial_pose: np.ndarray  #: (3,) known initial pose (x_m, y_m, theta_rad)
    initial_std: tuple[float, float, float] = (0.05, 0.05, 0.05)
    motion: MotionNoise = field(default_factory=MotionNoise)
    camera: CameraNoise = field(default_factory=CameraNoise)
    cooperative: bool = False
    #: Where hypotheses may be drawn (random particles/individuals): x_min, y_min, x_max, y_max.
    #: Default: the landmarks' bounding box grown by 2 m.
    bounds_m: tuple[float, float, float, float] | None = None
    #: Unknown start: the initial hypotheses are drawn uniformly over this area (x_min, y_min,
    #: x_max, y_max) and every heading, and ``initial_pose``/``initial_std`` are not used (only
    #: the population localizers can; None: the known start).
    initial_area_m: tuple[float, float, float, float] | None = None

    def __post_init__(self):
        if isinstance(self.robot_id, bool) or not isinstance(self.robot_id, (int, np.integer)):
            raise TypeError(f"robot_id must be an integer, got {self.robot_id!r}")
        ids = np.asarray(self.landmark_ids, dtype=np.int64)
        xy = np.asarray(self.landmark_xy_m, dtype=np.float64)
        if ids.ndim != 1 or xy.shape != (ids.size, 2) or not np.all(np.isfinite(xy)):
            raise ValueError(f"landmark_xy_m must be finite with shape ({ids.size}, 2)")
        pose = np.asarray(self.initial_pose, dtype=np.float64)
        if pose.shape != (3,) or not np.all(np.isfinite(pose)):
            raise ValueError(f"initial_pose must be 3 finite numbers, got {self.initial_pose!r}")
        if len(self.initial_std) != 3:
            raise ValueError(f"initial_std must be 3 numbers, got {self.initial_std!r}")
        for k, s in enumerate(self.initial_std):
            _real(s, f"initial_std[{k}]")
        if not isinstance(self.cooperative, bool):
            raise TypeError(f"cooperative must be true or false, got {self.cooperative!r}")
        if not isinstance(self.motion, MotionNoise) or not isinstance(self.camera, CameraNoise):
            raise TypeError("motion must be a MotionNoise and camera a CameraNoise")
        if self.bounds_m is None:
            lo = xy.min(axis=0) - 2.0 if xy.size else pose[:2] - 5.0
            hi = xy.max(axis=0) + 2.0 if xy.size else pose[:2] + 5.0
            object.__setattr__(self, "bounds_m", (float(lo[0]), float(lo[1]), float(hi[0]),
                                                  float(hi[1])))
        elif len(self.bounds_m) != 4 or not (self.bounds_m[2] > self.bounds_m[0]
                                             and self.bounds_m[3] > self.bounds_m[1]):
            raise ValueError(f"bounds_m must be (x_min, y_min, x_max, y_max), got {self.bounds_m!r}")
        if self.initial_area_m is not None:
            area = tuple(float(v) for v in self.initial_area_m)
            if len(area) != 4 or not all(map(math.isfinite, area)) or \
                    not (area[2] > area[0] and area[3] > area[1]):
                raise ValueError(f"initial_area_m must be (x_min, y_min, x_max, y_max), got "
                                 f"{self.initial_area_m!r}")
            object.__setattr__(self, "initial_area_m", area)
        object.__setattr__(self, "landmark_ids", ids)
        object.__setattr__(self, "landmark_xy_m", xy)
        object.__setattr__(self, "initial_pose", pose)

    def landmark_positions(self, ids: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(xy (K, 2), known (K,) bool)`` of the given landmark ids (unknown ids: NaN rows)."""
        ids = np.asarray(ids, dtype=np.int64)
        if not ids.size:
            return np.zeros((0, 2)), np.zeros(0, dtype=bool)
        match = ids[:, None] == self.landmark_ids[None, :]
        known = match.any(axis=1)
        xy = np.full((ids.size, 2), np.nan)
        xy[known] = self.landmark_xy_m[match.argmax(axis=1)[known]]
        return xy, known

    def initial_covariance(self) -> np.ndarray:
        if self.initial_area_m is not None:  # the uniform's covariance
            x0, y0, x1, y1 = self.initial_area_m
            return np.diag([(x1 - x0) ** 2 / 12.0, (y1 - y0) ** 2 / 12.0, math.pi**2 / 3.0])
        return np.diag(np.square(np.asarray(self.initial_std, dtype=np.float64)))

    def initial_hypotheses(self, n: int, rng: np.random.Generator) -> np.ndarray:
        """``(n, 3)`` initial poses: around the known pose with ``initial_std``, or, for an
        unknown start, uniform over ``initial_area_m`` and every heading."""
        if self.initial_area_m is not None:
            x0, y0, x1, y1 = self.initial_area_m
            return rng.uniform([x0, y0, -math.pi], [x1, y1, math.pi], size=(n, 3))
        out = self.initial_pose + rng.normal(size=(n, 3)) * np.asarray(self.initial_std)
        out[:, 2] = wrap_angle(out[:, 2])
        return out


@runtime_checkable
class LandmarkLocalizer(Protocol):
    """One robot's localizer on landmark range-and-bearing observations."""

    def step(self, obs: LandmarkObservation) -> None:
        """Apply the odometry, then the landmark measurements, then the teammates' data."""

    def estimate(self) -> np.ndarray:
        """The best pose estimate ``(x_m, y_m, theta_rad)``, shape (3,)."""

    def outgoing(self) -> bytes | None:
        """What to broadcast to teammates after this step (None: nothing)."""


def check_observation(obs: LandmarkObservation, robot_id: int) -> None:
    """Reject an observation that is not for this robot or holds impossible values (the arrays
    must be numpy arrays, as the replay world makes them)."""
    if not isinstance(obs, LandmarkObservation):
        raise TypeError(f"obs must be a LandmarkObservation, got {type(obs).__name__}")
    if obs.robot_id != robot_id:
        raise ValueError(f"obs.robot_id: {obs.robot_id} is not this robot ({robot_id})")
    for name in ("odometry_v_mps", "odometry_omega_rad_s", "odometry_dt_s"):
        value = getattr(obs, name)
        if type(value) is not float or not math.isfinite(value):
            _real(value, f"obs.{name}", minimum=None)
    if not obs.odometry_dt_s > 0.0:
        raise ValueError(f"obs.odometry_dt_s must be > 0, got {obs.odometry_dt_s!r}")
    for prefix in ("landmark", "robot"):
        arrays = [getattr(obs, f"{prefix}_{n}") for n in ("ids", "range_m", "bearing_rad")]
        if not all(isinstance(a, np.ndarray) and a.ndim == 1 for a in arrays) or \
                not arrays[0].shape == arrays[1].shape == arrays[2].shape:
            raise ValueError(f"obs.{prefix}_*: ids, ranges and bearings must be 1-D numpy "
                             "arrays of one length")
        if arrays[0].size:
            rng_m, bearing = arrays[1], arrays[2]
            if not (np.isfinite(rng_m).all() and np.isfinite(bearing).all()) or (rng_m < 0).any():
                raise ValueError(f"obs.{prefix}_range_m/bearing_rad: must be finite, ranges >= 0")


def calibrated(obs: LandmarkObservation, camera: CameraNoise) -> LandmarkObservation:
    """The observation with its ranges corrected by :meth:`CameraNoise.corrected_range` (what
    every localizer works on, and what it reports of its teammate readings)."""
    if not obs.landmark_ids.size and not obs.robot_ids.size:
        return obs
    return replace(
        obs,
        landmark_range_m=camera.corrected_range(obs.landmark_range_m, obs.landmark_bearing_rad),
        robot_range_m=camera.corrected_range(obs.robot_range_m, obs.robot_bearing_rad, True))


# --------------------------------------------------------------------------------------------
# Motion and measurement models (batched over poses)
# --------------------------------------------------------------------------------------------


def unicycle(poses: np.ndarray, distance_m, turn_rad) -> np.ndarray:
    """Poses ``(P, 3)`` moved by ``distance`` along the mid-turn heading, then turned (eq. 7 of
    seed 000, eq. 3 of 002); ``distance``/``turn`` scalars or ``(P,)``."""
    out = np.empty_like(poses)
    mid = poses[:, 2] + 0.5 * np.asarray(turn_rad)
    out[:, 0] = poses[:, 0] + distance_m * np.cos(mid)
    out[:, 1] = poses[:, 1] + distance_m * np.sin(mid)
    out[:, 2] = wrap_angle(poses[:, 2] + turn_rad)
    return out


def predicted_range_bearing(poses: np.ndarray, targets_xy: np.ndarray):
    """Range and bearing ``(P, K)`` of targets ``(K, 2)`` seen from poses ``(P, 3)``."""
    dx = targets_xy[None, :, 0] - poses[:, 0:1]
    dy = targets_xy[None, :, 1] - poses[:, 1:2]
    return np.hypot(dx, dy), wrap_angle(np.arctan2(dy, dx) - poses[:, 2:3])


def landmark_log_likelihood(poses: np.ndarray, landmarks_xy: np.ndarray, range_m: np.ndarray,
                            bearing_rad: np.ndarray, camera: CameraNoise,
                            outlier_density: float) -> np.ndarray:
    """``(P,)`` log-likelihood of ``K`` landmark readings for each pose ``(P, 3)``: the product
    over readings of ``(1 - e) N(range) N(bearing) + e u`` (Probabilistic Robotics §6.6, with
    the camera's outlier probability ``e`` and the uniform density ``u`` of a misread)."""
    pred_range, pred_bearing = predicted_range_bearing(poses, landmarks_xy)
    range_std = camera.range_std(range_m)[None, :]
    z_r = (range_m[None, :] - pred_range) / range_std
    z_b = wrap_angle(bearing_rad[None, :] - pred_bearing) / camera.bearing_std_rad
    log_gauss = (-0.5 * (z_r * z_r + z_b * z_b) - np.log(TWO_PI * range_std * camera.bearing_std_rad))
    e = camera.outlier_probability
    if e <= 0.0:
        return log_gauss.sum(axis=1)
    return np.logaddexp(math.log1p(-e) + log_gauss, math.log(e) + outlier_density).sum(axis=1)


def landmark_fitness_terms(poses: np.ndarray, displacement: np.ndarray, landmarks_xy: np.ndarray,
                           range_m: np.ndarray, bearing_rad: np.ndarray, range_std_m: np.ndarray,
                           bearing_std_rad: np.ndarray) -> np.ndarray:
    """CFS-GA's raw fitness terms (003 §IV-A: a Gaussian of each measurement residual) for ``K``
    landmark readings, summed: ``(P,)``. Reading ``k`` was taken at the pose ``poses``
    composed with ``displacement[k]`` (body-frame ``(dx, dy, dtheta)``, zero for a reading of
    this tick); each term is ``exp(-(z_r^2 + z_b^2) / 2)`` with the residuals in units of the
    reading's std, in ``[0, 1]`` whatever the std (003's beams all share one sigma; a near and a
    far landmark should weigh alike)."""
    then = _compose(poses, displacement)  # (P, K, 3)
    dx = landmarks_xy[None, :, 0] - then[..., 0]
    dy = landmarks_xy[None, :, 1] - then[..., 1]
    z_r = (range_m[None, :] - np.hypot(dx, dy)) / range_std_m
    z_b = wrap_angle(bearing_rad[None, :] - np.arctan2(dy, dx) + then[..., 2]) / bearing_std_rad
    return np.exp(-0.5 * (z_r * z_r + z_b * z_b)).sum(axis=1)


def _compose(pose: np.ndarray, delta: np.ndarray) -> np.ndarray:
    """Poses ``(P, 3)`` composed with body-frame displacements ``(K, 3)``: ``(P, K, 3)``."""
    c, s = np.cos(pose[:, 2:3]), np.sin(pose[:, 2:3])
    out = np.empty((pose.shape[0], delta.shape[0], 3))
    out[..., 0] = pose[:, 0:1] + c * delta[None, :, 0] - s * delta[None, :, 1]
    out[..., 1] = pose[:, 1:2] + s * delta[None, :, 0] + c * delta[None, :, 1]
    out[..., 2] = pose[:, 2:3] + delta[None, :, 2]
    return out


def _between(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Displacements ``(K, 3)`` from pose ``a (3,)`` to poses ``b (K, 3)`` in ``a``'s frame."""
    c, s = math.cos(a[2]), math.sin(a[2])
    dx, dy = b[:, 0] - a[0], b[:, 1] - a[1]
    return np.column_stack([c * dx + s * dy, -s * dx + c * dy, wrap_angle(b[:, 2] - a[2])])


def polar_covariance(range_m: float, direction_rad: float, range_std_m: float,
                     bearing_std_rad: float) -> np.ndarray:
    """Covariance ``(2, 2)`` in x/y of the point ``range * (cos, sin)(direction)`` when range and
    direction have the given stds (along the line: range; across: range times direction)."""
    c, s = math.cos(direction_rad), math.sin(direction_rad)
    along, across = range_std_m**2, (range_m * bearing_std_rad) ** 2
    return np.array([[along * c * c + across * s * s, (along - across) * c * s],
                     [(along - across) * c * s, along * s * s + across * c * c]])


# --------------------------------------------------------------------------------------------
# Teammate reports (the payload every landmark localizer broadcasts)
# --------------------------------------------------------------------------------------------

REPORT_TYPE = "mrclam"
REPORT_VERSION = 2
#: At most this many teammate measurements and pose samples in one report.
MAX_REPORT_SIGHTINGS = 32
MAX_REPORT_SAMPLES = 1024
_REPORT_KEYS = frozenset({"v", "t", "id", "tick", "state", "seen", "samples", "camera"})
_MAX_COORDINATE_M = 1e5
_COV_INDEX = np.array([0, 1, 2, 1, 3, 4, 2, 4, 5])
_UPPER = (np.array([0, 0, 0, 1, 1, 2]), np.array([0, 1, 2, 1, 2, 2]))


@dataclass(frozen=True, eq=False)
class TeammateReport:
    """What a robot broadcasts after a tick: its pose estimate and covariance, the teammates it
    measured at that tick (``seen`` rows ``(robot_id, range_m, bearing_rad)``, ranges already
    corrected by its camera calibration) and optionally pose samples ``(Q, 3)`` of its belief
    (CFS-GA's above-average individuals), and optionally the camera's range bias as its own
    self-calibration has folded it (``camera_bias``: ``(c0, c2, folds)``, folds >= 1; see
    :class:`~swarmloc.agents.replay.calibration.SelfCalibratingLocalizer`).

    Wire format (msgpack map): ``{"v": 2, "t": "mrclam", "id": int, "tick": int,
    "state": <bin: 9 little-endian float64: x, y, theta, cov xx, xy, x-theta, yy, y-theta,
    theta-theta>, "seen": <bin: M x 3 float64>, "samples": <bin: Q x 3 float32>,
    "camera": <bin: empty, or 3 float64: c0, c2, folds>}`` (version 2 added ``camera``).
    """

    robot_id: int
    tick: int
    pose: np.ndarray  #: (3,)
    covariance: np.ndarray  #: (3, 3)
    seen: np.ndarray  #: (M, 3)
    samples: np.ndarray  #: (Q, 3), Q may be 0
    camera_bias: tuple[float, float, int] | None = None
    #: An algorithm's own further data (CoLo's estimators, :mod:`swarmloc.agents.replay.colo`:
    #: the tick's odometry and readings, a global state); on the wire only when not empty, under
    #: the optional key ``extra`` (bin), decoded by the algorithm that reads it.
    extra: bytes = b""

    def encode(self) -> bytes:
        state = np.concatenate([self.pose, self.covariance[_UPPER]]).astype("<f8")
        wire = {
            "v": REPORT_VERSION, "t": REPORT_TYPE, "id": int(self.robot_id), "tick": int(self.tick),
            "state": state.tobytes(),
            "seen": np.ascontiguousarray(self.seen, dtype="<f8").tobytes(),
            "samples": np.ascontiguousarray(self.samples, dtype="<f4").tobytes(),
            "camera": encode_camera_bias(self.camera_bias),
        }
        if self.extra:
            wire["extra"] = bytes(self.extra)
        data = msgpack.packb(wire, use_bin_type=True)
        if len(data) > MAX_PAYLOAD_BYTES:
            raise ValueError(f"report of {len(data)} bytes exceeds {MAX_PAYLOAD_BYTES}")
        return data

    @classmethod
    def build(cls, robot_id: int, tick: int, pose, covariance, obs: LandmarkObservation | None,
              samples: np.ndarray | None = None, extra: bytes = b"") -> TeammateReport:
        if obs is not None and obs.robot_ids.size:
            seen = np.column_stack([obs.robot_ids, obs.robot_range_m, obs.robot_bearing_rad])
            seen = seen[:MAX_REPORT_SIGHTINGS]
        else:
            seen = _NO_ROWS
        samples = _NO_ROWS if samples is None else np.asarray(samples)[:MAX_REPORT_SAMPLES]
        return cls(int(robot_id), int(tick), pose, covariance, seen, samples, extra=extra)


_NO_ROWS = np.zeros((0, 3))


def encode_camera_bias(bias: tuple[float, float, int] | None) -> bytes:
    """The wire form of a report's ``camera_bias`` (empty: none)."""
    if bias is None:
        return b""
    return np.array(bias, dtype="<f8").tobytes()


def with_camera_bias(payload: bytes, bias: tuple[float, float, int]) -> bytes:
    """A report's payload with its ``camera`` field set to ``bias`` (a self-calibrating
    wrapper adds its calibration to the report its localizer built)."""
    wire = msgpack.unpackb(payload, raw=False)
    wire["camera"] = encode_camera_bias(bias)
    return msgpack.packb(wire, use_bin_type=True)


def _camera_bias(raw) -> tuple[float, float, int] | None:
    """A report's ``camera`` field: ``(c0, c2, folds)`` or None; ``ValueError`` naming what is
    wrong (a bias :class:`CameraNoise` refuses is refused)."""
    if not isinstance(raw, bytes):
        raise ValueError(f"payload.camera: expected bytes, got {type(raw).__name__}")  # noqa: TRY004
    if not raw:
        return None
    if len(raw) != 24:
        raise ValueError(f"payload.camera: expected 3 float64 (c0, c2, folds), got {len(raw)} bytes")
    c0, c2, folds = np.frombuffer(raw, dtype="<f8").tolist()
    if not all(map(math.isfinite, (c0, c2, folds))):
        raise ValueError("payload.camera: must be finite")
    if abs(c0) > 1.0 or abs(c2) > 1.0:
        raise ValueError(f"payload.camera: implausible range bias c0={c0}, c2={c2}")
    try:
        CameraNoise(range_bias_c0=c0, range_bias_c2=c2)  # the camera's own plausibility rule
    except ValueError as exc:
        raise ValueError(f"payload.camera: implausible {exc}") from None
    if folds != round(folds) or not 1 <= folds <= 2**31:
        raise ValueError(f"payload.camera: folds must be an integer >= 1, got {folds}")
    return c0, c2, int(folds)


def _rows(raw, name: str, dtype: str, limit: int) -> np.ndarray:
    if not isinstance(raw, bytes):
        # A malformed payload is a ValueError (the shell counts those and goes on).
        raise ValueError(f"payload.{name}: expected bytes, got {type(raw).__name__}")  # noqa: TRY004
    size = 3 * np.dtype(dtype).itemsize
    if len(raw) % size or len(raw) // size > limit:
        raise ValueError(f"payload.{name}: expected at most {limit} rows of 3 {dtype} numbers, "
                         f"got {len(raw)} bytes")
    rows = np.frombuffer(raw, dtype=dtype).reshape(-1, 3).astype(np.float64)
    if not np.isfinite(rows).all():
        raise ValueError(f"payload.{name}: must be finite")
    return rows


def decode_report(payload: bytes) -> TeammateReport:
    """A :class:`TeammateReport` from its payload; ``ValueError`` naming what is wrong."""
    return _report_from_wire(_unpack_report(payload))


def _unpack_report(payload: bytes) -> dict:
    """The payload's msgpack map, with its keys, type and version checked."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise ValueError(f"payload: must be bytes, got {type(payload).__name__}")  # noqa: TRY004
    if len(payload) > MAX_PAYLOAD_BYTES:
        raise ValueError(f"payload: {len(payload)} bytes exceeds {MAX_PAYLOAD_BYTES}")
    try:
        wire = msgpack.unpackb(payload, raw=False, strict_map_key=True, max_str_len=16,
                               max_bin_len=MAX_PAYLOAD_BYTES, max_array_len=0, max_map_len=16,
                               max_ext_len=0)
    except Exception as exc:  # noqa: BLE001 -- msgpack raises many unrelated types
        raise ValueError(f"payload: not a teammate report ({type(exc).__name__})") from None
    if not isinstance(wire, dict):
        raise ValueError(f"payload: expected a map, got {type(wire).__name__}")  # noqa: TRY004
    if wire.keys() != _REPORT_KEYS and wire.keys() != _REPORT_KEYS | {"extra"}:
        missing, extra = _REPORT_KEYS - wire.keys(), wire.keys() - _REPORT_KEYS - {"extra"}
        raise ValueError(f"payload: missing field(s) {sorted(missing)}, "
                         f"unknown field(s) {sorted(map(str, extra))}")
    if wire["t"] != REPORT_TYPE:
        raise ValueError(f"payload.t: expected {REPORT_TYPE!r}, got {wire['t']!r}")
    if type(wire["v"]) is not int or wire["v"] != REPORT_VERSION:
        raise ValueError(f"payload.v: expected {REPORT_VERSION}, got {wire['v']!r}")
    wire["camera"] = _camera_bias(wire["camera"])  # small: checked for every payload
    extra = wire.setdefault("extra", b"")
    if not isinstance(extra, bytes):
        raise ValueError(f"payload.extra: expected bytes, got {type(extra).__name__}")  # noqa: TRY004
    return wire


def _report_from_wire(wire: dict) -> TeammateReport:
    for name in ("id", "tick"):
        if type(wire[name]) is not int or not -(2**62) < wire[name] < 2**62:
            raise ValueError(f"payload.{name}: expected an integer, got {wire[name]!r}")
    state = wire["state"]
    if not isinstance(state, bytes) or len(state) != 72:
        raise ValueError("payload.state: expected 9 float64 (pose and covariance), 72 bytes")
    state = np.frombuffer(state, dtype="<f8")
    if not np.isfinite(state).all():
        raise ValueError("payload.state: must be finite")
    pose = state[:3].copy()
    if abs(pose[0]) > _MAX_COORDINATE_M or abs(pose[1]) > _MAX_COORDINATE_M \
            or abs(pose[2]) > math.pi + 1e-6:
        raise ValueError("payload.state: position beyond 1e5 m or heading outside [-pi, pi]")
    cov = state[3:][_COV_INDEX].reshape(3, 3)
    variances = state[[3, 6, 8]]
    if (variances < 0.0).any() or (variances > 1e10).any():
        raise ValueError("payload.state: covariance variances must lie in [0, 1e10]")
    seen = _rows(wire["seen"], "seen", "<f8", MAX_REPORT_SIGHTINGS)
    if seen.shape[0]:
        if (seen[:, 0] != np.round(seen[:, 0])).any():
            raise ValueError("payload.seen: robot ids must be integers")
        if (seen[:, 1] < 0.0).any() or (seen[:, 1] > _MAX_COORDINATE_M).any() \
                or (np.abs(seen[:, 2]) > TWO_PI).any():
            raise ValueError("payload.seen: ranges must lie in [0, 1e5] m, bearings within 2 pi")
    samples = _rows(wire["samples"], "samples", "<f4", MAX_REPORT_SAMPLES)
    if samples.shape[0] and (np.abs(samples[:, :2]) > _MAX_COORDINATE_M).any():
        raise ValueError("payload.samples: positions must lie within 1e5 m")
    return TeammateReport(wire["id"], wire["tick"], pose, cov, seen, samples, wire["camera"],
                          wire["extra"])


def decode_received(received: Sequence[Message], robot_id: int,
                    observed: Sequence[int] | np.ndarray = ()):
    """Reports from the teammates (by sender id; the latest wins) and the rejected payloads
    ``(sender_id, error)``; a payload whose ``id`` is not its sender's is rejected.

    Every payload is unpacked and its envelope checked; the full decode (arrays, ranges) is
    done for the reports that can be used this tick: from a teammate in ``observed`` (the
    robots this robot measured now), or carrying readings of teammates (``seen``). A report of
    a robot that is neither measured nor measuring is not needed, and at 50 ticks per second
    decoding four of them per robot and tick is most of a cooperative replay's cost."""
    reports: dict[int, TeammateReport] = {}
    rejected: list[tuple[int, ValueError]] = []
    wanted = set(np.asarray(observed).tolist())
    for msg in received:
        if msg.sender_id == robot_id:
            continue
        try:
            wire = _unpack_report(msg.payload)
            if msg.sender_id not in wanted and wire["seen"] == b"":
                continue
            report = _report_from_wire(wire)
            if report.robot_id != msg.sender_id:
                raise ValueError(f"payload.id: {report.robot_id} is not the sender {msg.sender_id}")
        except ValueError as exc:
            rejected.append((msg.sender_id, exc))
            continue
        reports[msg.sender_id] = report
    return reports, rejected


def teammate_camera_biases(received: Sequence[Message], robot_id: int
                           ) -> dict[int, tuple[float, float, int]]:
    """The camera biases ``(c0, c2, folds)`` the teammates broadcast, by sender id (the latest
    wins). A malformed payload is left out here: the localizer's own :func:`decode_received`
    counts it."""
    out: dict[int, tuple[float, float, int]] = {}
    for msg in received:
        if msg.sender_id == robot_id:
            continue
        try:
            bias = _unpack_report(msg.payload)["camera"]
        except ValueError:
            continue
        if bias is not None:
            out[msg.sender_id] = bias
    return out


@dataclass(frozen=True)
class RelativeReading:
    """One range-and-bearing reading between this robot and teammate ``teammate_id``:
    ``observer`` True when this robot measured the teammate (bearing in this robot's frame),
    False when the teammate measured this robot (bearing in the teammate's frame)."""

    teammate_id: int
    observer: bool
    range_m: float
    bearing_rad: float
    report: TeammateReport


def relative_readings(obs: LandmarkObservation, reports: Mapping[int, TeammateReport],
                      robot_id: int) -> list[RelativeReading]:
    """The readings to fuse this tick, at most one per teammate (its broadcast estimate enters
    once, so the same teammate estimate is not counted twice): this robot's own reading of the
    teammate if it has one, else the teammate's reading of this robot from its last report."""
    out: dict[int, RelativeReading] = {}
    for j, r, b in zip(obs.robot_ids.tolist(), obs.robot_range_m.tolist(),
                       obs.robot_bearing_rad.tolist()):
        if j in reports and j not in out:
            out[j] = RelativeReading(j, True, r, b, reports[j])
    for j, report in reports.items():
        if j in out:
            continue
        mine = report.seen[report.seen[:, 0] == robot_id] if report.seen.size else report.seen
        if mine.shape[0]:
            out[j] = RelativeReading(j, False, float(mine[0, 1]), float(mine[0, 2]), report)
    return [out[j] for j in sorted(out)]


def position_fix(reading: RelativeReading, own_heading_rad: float, own_heading_var: float,
                 camera: CameraNoise) -> tuple[np.ndarray, np.ndarray]:
    """This robot's position ``(2,)`` and its covariance ``(2, 2)`` implied by a relative reading
    and the teammate's reported estimate:

    - observer: ``p_j - r (cos, sin)(theta_i + b)``, uncertain through ``P_j``, the reading and
      this robot's own heading variance;
    - observed: ``p_j + r (cos, sin)(theta_j + b)``, uncertain through ``P_j`` (heading
      included) and the reading.
    """
    rep, r, b = reading.report, reading.range_m, reading.bearing_rad
    range_std = float(camera.range_std(r))
    if reading.observer:
        direction = own_heading_rad + b
        xy = rep.pose[:2] - r * np.array([math.cos(direction), math.sin(direction)])
        cov = rep.covariance[:2, :2] + polar_covariance(
            r, direction, range_std, math.hypot(camera.bearing_std_rad, math.sqrt(own_heading_var)))
    else:
        direction = rep.pose[2] + b
        xy = rep.pose[:2] + r * np.array([math.cos(direction), math.sin(direction)])
        g = np.array([[1.0, 0.0, -r * math.sin(direction)], [0.0, 1.0, r * math.cos(direction)]])
        cov = g @ rep.covariance @ g.T + polar_covariance(r, direction, range_std,
                                                          camera.bearing_std_rad)
    return xy, cov


def spectral_norm_xy(cov: np.ndarray) -> float:
    """Largest eigenvalue of the position block (seed 000 eq. 19's ``||P||_2``), m^2."""
    a, b, c = cov[0, 0], cov[0, 1], cov[1, 1]
    return float((a + c) / 2.0 + math.sqrt(((a - c) / 2.0) ** 2 + b * b))


def sgikf_fuse(pose: np.ndarray, cov: np.ndarray, fix_xy: np.ndarray, fix_cov: np.ndarray):
    """Social odometry's SGIKF correction (seed 000 eq. 20-22) of a pose estimate by a position
    fix ``x^j + x^ij`` from a teammate: ``p = ||P_xy||_2`` (eq. 19) for both,
    ``g = p_i / (p_i + p_j)`` (eq. 20), ``x_i <- (1 - g) x_i + g (x_j + x_ij)`` (eq. 21) on the
    position, ``p_i <- (1 - g) p_i`` (eq. 22): the position block of ``P`` is scaled by
    ``1 - g`` (its cross terms with the heading by ``sqrt(1 - g)``, so ``P`` stays a covariance).
    Uses :func:`swarmloc.agents.epuck.social_odometry.sgikf_update`. Returns ``(pose, cov, g)``."""
    p_own = np.array([spectral_norm_xy(cov)])
    p_other = np.array([spectral_norm_xy(fix_cov)])
    new_xy, _ = sgikf_update(pose[None, :2], p_own, fix_xy[None, :], p_other)
    g = float(p_own[0] / (p_own[0] + p_other[0])) if p_own[0] + p_other[0] > 0 else 0.5
    out = pose.copy()
    out[:2] = new_xy[0]
    scale = np.array([math.sqrt(1.0 - g), math.sqrt(1.0 - g), 1.0])
    return out, cov * scale[:, None] * scale[None, :], g


# --------------------------------------------------------------------------------------------
# Dead reckoning (+ social odometry)
# --------------------------------------------------------------------------------------------


def propagate(pose: np.ndarray, cov: np.ndarray, v_mps: float, omega_rad_s: float, dt_s: float,
              motion: MotionNoise) -> tuple[np.ndarray, np.ndarray]:
    """One tick of the unicycle (eq. 7 of seed 000) and its covariance (eq. 9: ``A P A^T + W Q
    W^T``, with ``Q`` the distance and turn variances of :meth:`MotionNoise.tick_std`)."""
    d, turn = v_mps * dt_s, omega_rad_s * dt_s
    mid = pose[2] + 0.5 * turn
    c, s = math.cos(mid), math.sin(mid)
    new = np.array([pose[0] + d * c, pose[1] + d * s,
                    (pose[2] + turn + math.pi) % TWO_PI - math.pi])
    std_d, std_t = motion.tick_std(v_mps, omega_rad_s, dt_s)
    a = np.array([[1.0, 0.0, -d * s], [0.0, 1.0, d * c], [0.0, 0.0, 1.0]])
    w = np.array([[c, -0.5 * d * s], [s, 0.5 * d * c], [0.0, 1.0]])
    q = np.array([std_d * std_d, std_t * std_t])
    return new, a @ cov @ a.T + (w * q) @ w.T


@dataclass(frozen=True)
class DrParams:
    """Dead reckoning's cooperative (social odometry) option: with ``only_from_better`` a
    teammate's position fix is fused only when its confidence is better (``p_j < p_i``, eq. 19's
    norms). Default: every reading, as eq. 20-22 read (on Dataset 6 the stricter rule fuses
    little: a fix carries the teammate's covariance plus the reading's)."""

    only_from_better: bool = False

    def __post_init__(self):
        if not isinstance(self.only_from_better, bool):
            raise TypeError(f"only_from_better must be true or false, got {self.only_from_better!r}")


class DeadReckoning:
    """Dead reckoning; cooperative: social odometry (SGIKF, seed 000 eq. 18-22) on the pose
    estimate with the relative readings (:func:`relative_readings`, :func:`sgikf_fuse`)."""

    def __init__(self, setup: LandmarkSetup, rng: np.random.Generator | None = None,
                 params: DrParams | None = None):
        self.params = params or DrParams()
        self.setup = setup
        self.pose = setup.initial_pose.copy()
        self.covariance = setup.initial_covariance()
        self.rejected: tuple[tuple[int, ValueError], ...] = ()
        self.fusions = 0
        self._out: bytes | None = None

    def step(self, obs: LandmarkObservation) -> None:
        check_observation(obs, self.setup.robot_id)
        obs = calibrated(obs, self.setup.camera)
        self.pose, self.covariance = propagate(self.pose, self.covariance, obs.odometry_v_mps,
                                               obs.odometry_omega_rad_s, obs.odometry_dt_s,
                                               self.setup.motion)
        if self.setup.cooperative:
            reports, rejected = decode_received(obs.received, self.setup.robot_id, obs.robot_ids)
            self.rejected = tuple(rejected)
            for reading in relative_readings(obs, reports, self.setup.robot_id):
                xy, cov = position_fix(reading, self.pose[2], self.covariance[2, 2],
                                       self.setup.camera)
                if self.params.only_from_better and \
                        spectral_norm_xy(cov) >= spectral_norm_xy(self.covariance):
                    continue
                self.pose, self.covariance, _ = sgikf_fuse(self.pose, self.covariance, xy, cov)
                self.fusions += 1
            self._out = TeammateReport.build(self.setup.robot_id, obs.tick, self.pose,
                                             self.covariance, obs).encode()

    def estimate(self) -> np.ndarray:
        return self.pose.copy()

    def outgoing(self) -> bytes | None:
        return self._out


# --------------------------------------------------------------------------------------------
# Registry
# --------------------------------------------------------------------------------------------

Builder = Callable[[LandmarkSetup, np.random.Generator, Mapping], LandmarkLocalizer]


@dataclass(frozen=True)
class Algorithm:
    name: str
    description: str
    build: Builder


#: The landmark localizers by name (:class:`swarmloc.registry.Registry`); a plugin adds one with
#: :func:`register`.
ALGORITHMS: Registry[Algorithm] = Registry("algorithm")


#: Add an algorithm to :data:`ALGORITHMS`; a second one with the same name is an error. The
#: registry's own method, so that the origin it records is the caller's file and line.
register = ALGORITHMS.register


def build_localizer(name: str, setup: LandmarkSetup, rng: np.random.Generator,
                    params: Mapping | None = None) -> LandmarkLocalizer:
    """The localizer of algorithm ``name`` (``dr``, ``ekf``, ``pf``, ``cfsga``, ``hybrid``,
    ``ssga``) for one robot; ``params`` are the algorithm's parameters by name (unknown names
    are rejected)."""
    if name not in ALGORITHMS:
        hint = did_you_mean(str(name), ALGORITHMS.names(), 0.3)
        raise ValueError(f"algorithm: unknown {name!r} (known: {', '.join(ALGORITHMS)}){hint}")
    algorithm = ALGORITHMS.get(name)
    if not isinstance(rng, np.random.Generator):
        raise TypeError(f"rng must be a numpy.random.Generator, got {type(rng).__name__}")
    return algorithm.build(setup, rng, dict(params or {}))


def _build_dr(setup, rng, params):
    return DeadReckoning(setup, rng, params_from_dict(DrParams, params, "dr"))


def _build_ekf(setup, rng, params):
    from swarmloc.agents.replay.ekf import EkfLocalizer, EkfParams

    return EkfLocalizer(setup, params_from_dict(EkfParams, params, "ekf"), rng)


def _build_pf(setup, rng, params):
    from swarmloc.agents.replay.populations import ParticleFilterLocalizer

    return ParticleFilterLocalizer(setup, params, rng)


def _build_cfsga(setup, rng, params):
    from swarmloc.agents.replay.populations import CfsgaLocalizer

    return CfsgaLocalizer(setup, params, rng)


register(Algorithm("dr", "dead reckoning; cooperative: social odometry (SGIKF)", _build_dr))
register(Algorithm("ekf", "EKF with known landmarks; cooperative: relative updates", _build_ekf))


def _build_ekf_ci(setup, rng, params):
    from swarmloc.agents.replay.ekf import EkfLocalizer, EkfParams

    return EkfLocalizer(setup, params_from_dict(EkfParams, {"fusion": "ci", **params}, "ekf-ci"), rng)


register(Algorithm("ekf-ci", "EKF with known landmarks; cooperative: covariance intersection of position fixes (after CoLo's LS-CI; the paper's is ls-ci)",
                   _build_ekf_ci))
register(Algorithm("pf", "AMCL-style particle filter; cooperative: teammates' beliefs", _build_pf))
register(Algorithm("cfsga", "CFS-GA; cooperative: virtual population", _build_cfsga))


def _build_hybrid(setup, rng, params):
    from swarmloc.agents.replay.hybrid import HybridLocalizer

    return HybridLocalizer(setup, params, rng)


register(Algorithm("hybrid", "particle filter search, EKF tracking; cooperative: the active stage's",
                   _build_hybrid))


def _build_ssga(setup, rng, params):
    from swarmloc.agents.replay.ssga_landmarks import SsgaLocalizer

    return SsgaLocalizer(setup, params, rng)


register(Algorithm("ssga", "MR-SSGA (seed 002) on a small-world network; cooperative: teammates' "
                   "readings in the fitness", _build_ssga))


def _build_colo(name: str) -> Builder:
    def build(setup, rng, params):
        from swarmloc.agents.replay import colo

        return getattr(colo, "build_" + name.replace("-", "_"))(setup, rng, params)

    return build


for _name, _description in (
        ("ls-cen", "CoLo's LS-Cen: centralized EKF (Roumeliotis and Bekey 2002), a replica in every robot"),
        ("ls-bda", "CoLo's LS-BDA: block-diagonal approximation (Luft et al. 2018), a replica in every robot"),
        ("ls-ci", "CoLo's LS-CI: local-state covariance intersection (Carrillo-Arce et al. 2013)"),
        ("gs-ci", "CoLo's GS-CI: global-state covariance intersection (Chang, Chen and Mehta 2017)"),
        ("gs-sci", "CoLo's GS-SCI: global-state split covariance intersection (Li and Nashashibi 2013)")):
    register(Algorithm(_name, _description, _build_colo(_name)))
