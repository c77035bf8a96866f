"""The sample-based landmark localizers of the replay family: the particle filter and CFS-GA.

Both keep a population of pose hypotheses, from the laser family's filters adapted to MRCLAM's
landmark range-and-bearing readings (contract, noise, measurement models and teammate reports in
:mod:`swarmloc.agents.replay.localizers`, whose registry builds them as ``pf`` and ``cfsga``):

- :class:`ParticleFilterLocalizer`: the AMCL-style filter of ``agents/laser/amcl.py``
  (:class:`~swarmloc.agents.laser.amcl.AugmentedMCL`: KLD sampling, recovery) with the landmark
  log-likelihood plugged in; cooperative: each particle is reweighted by the density of the
  teammate's broadcast belief at the place the particle and the relative measurement put it
  (:func:`teammate_log_density`), and optionally, where that belief contradicts the set, part
  of the set is drawn from it (``teammate_reset_fraction``, :func:`poses_from_teammate_reading`);
- :class:`CfsgaLocalizer`: CFS-GA of ``agents/laser/cfsga.py`` (seed 003) with the landmark
  fitness; cooperative: 003 §IV-B's virtual population and virtual niches.

:class:`ReadingWindow` (the landmark readings of the last seconds, brought to the present by the
odometry) and :func:`median_pose` are shared with MR-SSGA
(:mod:`swarmloc.agents.replay.ssga_landmarks`).
"""


from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, fields

import numpy as np

from swarmloc.agents.replay.fixes import ReadingBuffer
from swarmloc.agents.replay.localizers import (
    _NO_ROWS,
    MAX_REPORT_SAMPLES,
    TWO_PI,
    CameraNoise,
    LandmarkSetup,
    RelativeReading,
    TeammateReport,
    _between,
    _real,
    calibrated,
    check_observation,
    decode_received,
    landmark_fitness_terms,
    landmark_log_likelihood,
    polar_covariance,
    position_fix,
    relative_readings,
    spectral_norm_xy,
    unicycle,
    wrap_angle,
)
from swarmloc.world.replay.replay import LandmarkObservation

# --------------------------------------------------------------------------------------------
# Teammate evidence for particle sets and populations
# --------------------------------------------------------------------------------------------


def teammate_log_density(poses: np.ndarray, reading: RelativeReading, own_pose: np.ndarray,
                         own_cov: np.ndarray, camera: CameraNoise,
                         normalised: bool = True) -> np.ndarray:
    """``(P,)`` log-density of a teammate's broadcast belief (a Gaussian: its pose estimate and
    covariance) at the place each hypothesis ``(P, 3)`` and the relative reading put it:

    - observer (this robot measured the teammate at ``(r, b)``): the teammate is predicted at
      ``p + r (cos, sin)(theta + b)`` from each hypothesis; density ``N(mean_j, P_j + R)`` with
      ``R`` the reading's covariance in x/y (taken along the estimate's line of sight);
    - observed (the teammate measured this robot): density of the position fix
      (:func:`position_fix`) at each hypothesis's position.

    The collaborative particle filter of Fox, Burgard, Kruppa, Thrun (2000) with a Gaussian
    belief summary, for range-and-bearing readings (no relative heading)."""
    rep = reading.report
    if reading.observer:
        direction = poses[:, 2] + reading.bearing_rad
        points = poses[:, :2] + reading.range_m * np.column_stack([np.cos(direction),
                                                                   np.sin(direction)])
        mean = rep.pose[:2]
        cov = rep.covariance[:2, :2] + polar_covariance(
            reading.range_m, float(own_pose[2]) + reading.bearing_rad,
            float(camera.range_std(reading.range_m)), camera.bearing_std_rad)
    else:
        mean, cov = position_fix(reading, float(own_pose[2]), float(own_cov[2, 2]), camera)
        points = poses[:, :2]
    cov = cov + np.eye(2) * 1e-6
    inv = np.linalg.inv(cov)
    d = points - mean
    maha = np.einsum("pi,ij,pj->p", d, inv, d)
    if not normalised:
        return -0.5 * maha
    return -0.5 * maha - math.log(TWO_PI) - 0.5 * math.log(np.linalg.det(cov))


def _mixture(log_density: np.ndarray, outlier_probability: float, log_uniform: float):
    if outlier_probability <= 0.0:
        return log_density
    return np.logaddexp(math.log1p(-outlier_probability) + log_density,
                        math.log(outlier_probability) + log_uniform)


def _motion_growth(std_d: float, std_t: float) -> np.ndarray:
    """What one tick of motion noise adds to a pose covariance (the distance error split over
    x and y, the turn error on the heading): a cheap stand-in between two weighted-set
    covariances."""
    out = np.zeros((3, 3))
    out[0, 0] = out[1, 1] = 0.5 * std_d * std_d
    out[2, 2] = std_t * std_t
    return out


def _weighted_pose_covariance(poses: np.ndarray, weights: np.ndarray, mean: np.ndarray):
    d = poses - mean
    d[:, 2] = wrap_angle(d[:, 2])
    return (d * weights[:, None]).T @ d + np.eye(3) * 1e-9


class _Cooperation:
    """What PF and GA share: decoding teammates' reports, the readings to use, and the report
    to broadcast."""

    def __init__(self, setup: LandmarkSetup):
        self.setup = setup
        self.rejected: tuple[tuple[int, ValueError], ...] = ()
        self.out: bytes | None = None

    def readings(self, obs: LandmarkObservation) -> list[RelativeReading]:
        if not self.setup.cooperative:
            return []
        reports, rejected = decode_received(obs.received, self.setup.robot_id, obs.robot_ids)
        self.rejected = tuple(rejected)
        return relative_readings(obs, reports, self.setup.robot_id)

    def publish(self, obs: LandmarkObservation, pose, cov, samples=None) -> None:
        if self.setup.cooperative:
            self.out = TeammateReport.build(self.setup.robot_id, obs.tick, pose, cov, obs,
                                            samples).encode()


@dataclass(frozen=True)
class PfParams:
    """The landmark particle filter's own parameters; every other key goes to
    :class:`swarmloc.agents.laser.amcl.AMCLParams` (``min_particles``, ``recovery``, ...)."""

    #: Resample when the effective sample size falls below this fraction of the particles
    #: (``amcl`` resamples every ``resample_interval`` updates; with 0.02 s ticks and a few
    #: readings per second the ESS rule spares needless resampling noise).
    resample_ess_fraction: float = 0.5
    #: With ``recovery``: draw the injected particles from the poses that explain one of the
    #: tick's landmark readings (:func:`sensor_resetting_poses`) instead of uniformly over the
    #: area (when the tick had none: uniformly).
    sensor_resetting: bool = True
    #: Sensor resetting (with ``recovery`` and ``sensor_resetting``): the likelihood of each
    #: reading, averaged over the particles, relative to its peak (the likelihood of a reading
    #: that fits exactly), smoothed over readings with weight ``reset_smoothing``; while it is
    #: below ``reset_threshold`` a fraction ``1 - fit / reset_threshold`` of the particles is
    #: replaced by poses drawn from the tick's readings (Lenser and Veloso 2000). A pose that
    #: fits a reading within one std in range and bearing scores ``exp(-1) = 0.37``.
    reset_threshold: float = 0.02
    reset_smoothing: float = 0.3
    #: Sensor resetting draws from the pose fixed by the landmark readings of the last
    #: ``fix_window_s`` seconds when they hold two distinct landmarks
    #: (:class:`~swarmloc.agents.replay.fixes.ReadingBuffer`, mixture MCL's dual proposal),
    #: from one reading's circle otherwise (issue 19). Off: on Dataset 6 (unknown start, seeds
    #: 0-3, 180 s) it localized 5/20 robots within 60 s alone and 8/20 cooperative, against
    #: 6/20 and 10/20 without it: the first landmarks most robots see are close together and
    #: far away (robot 1: landmarks 14 and 15, 0.18 m apart, at 6.5 m), so the fix pins the
    #: pose no better than one reading (see ``deploy/lab/replay/feasibility.py``).
    fix_proposal: bool = False
    fix_window_s: float = 2.0
    #: With recovery and ``fix_proposal``: on every tick with readings whose fix lies more than
    #: ``fix_disagreement_m`` from the estimate, this share of the particles is drawn from the
    #: fix whatever the fit (mixture MCL's fixed mixing ratio): a set collapsed onto a wrong
    #: pose that fits the readings tolerably is otherwise never reset. Off (0): with 0.05, on
    #: the same runs, 1/20 alone and 0/20 cooperative within 60 s (fixes from far, close
    #: landmarks and odometry-carried readings throw a tracked estimate off).
    fix_mixing: float = 0.0
    fix_disagreement_m: float = 0.5
    #: Teammate resetting (the AMCL core's ``teammate_reset_fraction`` > 0; off by default, on
    #: in the hybrid's search, :data:`~swarmloc.agents.replay.hybrid.HYBRID_PF_DEFAULTS`): when
    #: a teammate's reading contradicts the set (see :meth:`ParticleFilterLocalizer._disagrees`)
    #: that fraction of the particles is drawn from the teammate
    #: (:func:`poses_from_teammate_reading`), but only from a teammate whose reported position
    #: std (the square root of the largest eigenvalue of its position covariance) is under
    #: ``teammate_reset_std_m`` [m]: a teammate still searching can report a set collapsed onto
    #: a wrong pose, and a robot drawn from it follows it there.
    teammate_reset_std_m: float = 0.15
    #: The position std [m] this filter reports to its teammates is at least this (0: the
    #: particles' own). A set that has collapsed reports a spread far under its error, and a
    #: set drawn from a teammate's reading reports that teammate's own estimate back to it: the
    #: teammate, fusing it as independent evidence, counts its own estimate twice.
    report_floor_std_m: float = 0.0

    def __post_init__(self):
        if not 0.0 < _real(self.resample_ess_fraction, "resample_ess_fraction") <= 1.0:
            raise ValueError(f"resample_ess_fraction must be in (0, 1], got {self.resample_ess_fraction}")
        if not isinstance(self.sensor_resetting, bool):
            raise TypeError(f"sensor_resetting must be true or false, got {self.sensor_resetting!r}")
        if not 0.0 <= _real(self.reset_threshold, "reset_threshold") < 1.0:
            raise ValueError(f"reset_threshold must be in [0, 1), got {self.reset_threshold}")
        if not 0.0 < _real(self.reset_smoothing, "reset_smoothing") <= 1.0:
            raise ValueError(f"reset_smoothing must be in (0, 1], got {self.reset_smoothing}")
        if not isinstance(self.fix_proposal, bool):
            raise TypeError(f"fix_proposal must be true or false, got {self.fix_proposal!r}")
        _real(self.fix_window_s, "fix_window_s", positive=True)
        _real(self.teammate_reset_std_m, "teammate_reset_std_m", positive=True)
        _real(self.report_floor_std_m, "report_floor_std_m")


def sensor_resetting_poses(n: int, rng: np.random.Generator, landmarks_xy: np.ndarray,
                           range_m: np.ndarray, bearing_rad: np.ndarray, camera: CameraNoise,
                           bounds_m: tuple[float, float, float, float] | None = None) -> np.ndarray:
    """``(n, 3)`` poses drawn from what one landmark reading says (sensor resetting, Lenser and
    Veloso 2000): for each pose a reading ``k`` chosen at random, the direction ``phi`` from the
    robot to the landmark uniform, the range and bearing drawn from the camera's noise; the
    robot then stands at ``l_k - r (cos, sin)(phi)`` with heading ``phi - b``.

    Our choice for the landmark PF's recovery: one known landmark's reading puts the robot on a
    circle with a known heading along it, a set of three dimensions cut to one; AMCL's uniform
    draw (seed 003 §II) would hit it once in about a thousand particles on Dataset 6's field.
    With ``bounds_m`` the poses outside are drawn again (up to four rounds; then kept)."""
    out = _reading_poses(n, rng, landmarks_xy, range_m, bearing_rad, camera)
    if bounds_m is not None:
        x0, y0, x1, y1 = bounds_m
        for _ in range(4):
            outside = (out[:, 0] < x0) | (out[:, 0] > x1) | (out[:, 1] < y0) | (out[:, 1] > y1)
            if not outside.any():
                break
            out[outside] = _reading_poses(int(outside.sum()), rng, landmarks_xy, range_m,
                                          bearing_rad, camera)
    return out


def poses_from_teammate_reading(n: int, rng: np.random.Generator, reading: RelativeReading,
                                robot_id: int, obs: LandmarkObservation,
                                camera: CameraNoise) -> np.ndarray:
    """``(n, 3)`` poses of this robot drawn from a teammate's broadcast belief (a Gaussian: its
    report's pose and covariance) through the readings between the two (sensor resetting with
    the teammate as the landmark; the laser family's :func:`~swarmloc.agents.laser.amcl_belief.
    poses_from_teammate` for range-and-bearing readings, which carry no relative heading). The
    teammate's pose ``s`` is drawn from its belief, each reading from the camera's noise:

    - the teammate measured this robot at ``(r', b')`` (its report's ``seen``): the robot stands at
      ``s_xy + r' (cos, sin)(theta_s + b')``; its heading, when this robot measured the teammate
      too at ``(r, b)``, is the direction to the teammate minus ``b``, otherwise uniform;
    - only this robot measured the teammate, at ``(r, b)``: a circle around the teammate, the
      direction ``phi`` from the robot to it uniform, the robot at ``s_xy - r (cos, sin)(phi)``
      with heading ``phi - b`` (as for a landmark, :func:`sensor_resetting_poses`).

    Draws: ``rng.normal`` of shape ``(n, 3)`` (the teammate), then of ``(n, 2)`` per reading
    used, then one ``rng.uniform`` of ``n`` where a heading or a direction is unknown."""
    rep = reading.report
    cov = rep.covariance + np.eye(3) * 1e-12
    teammate = rep.pose + rng.normal(size=(n, 3)) @ np.linalg.cholesky(cov).T
    seen = rep.seen[rep.seen[:, 0] == robot_id] if rep.seen.size else rep.seen
    own = np.flatnonzero(obs.robot_ids == reading.teammate_id)
    out = np.empty((n, 3))
    if seen.shape[0]:
        r_seen, b_seen = _noisy_reading(n, rng, float(seen[0, 1]), float(seen[0, 2]), camera)
        direction = teammate[:, 2] + b_seen
        out[:, 0] = teammate[:, 0] + r_seen * np.cos(direction)
        out[:, 1] = teammate[:, 1] + r_seen * np.sin(direction)
        if own.size:
            _, b_own = _noisy_reading(n, rng, float(obs.robot_range_m[own[0]]),
                                      float(obs.robot_bearing_rad[own[0]]), camera)
            out[:, 2] = np.arctan2(teammate[:, 1] - out[:, 1], teammate[:, 0] - out[:, 0]) - b_own
        else:
            out[:, 2] = rng.uniform(-math.pi, math.pi, size=n)
    else:
        r_own, b_own = _noisy_reading(n, rng, reading.range_m, reading.bearing_rad, camera)
        phi = rng.uniform(-math.pi, math.pi, size=n)
        out[:, 0] = teammate[:, 0] - r_own * np.cos(phi)
        out[:, 1] = teammate[:, 1] - r_own * np.sin(phi)
        out[:, 2] = phi - b_own
    out[:, 2] = wrap_angle(out[:, 2])
    return out


def _noisy_reading(n: int, rng: np.random.Generator, range_m: float, bearing_rad: float,
                   camera: CameraNoise) -> tuple[np.ndarray, np.ndarray]:
    noise = rng.normal(size=(n, 2))
    return (np.maximum(range_m + noise[:, 0] * float(camera.range_std(range_m)), 0.0),
            bearing_rad + noise[:, 1] * camera.bearing_std_rad)


def _reading_poses(n, rng, landmarks_xy, range_m, bearing_rad, camera) -> np.ndarray:
    k = rng.integers(0, range_m.size, size=n)
    phi = rng.uniform(-math.pi, math.pi, size=n)
    r = np.maximum(range_m[k] + rng.normal(size=n) * camera.range_std(range_m[k]), 0.0)
    b = bearing_rad[k] + rng.normal(size=n) * camera.bearing_std_rad
    out = np.empty((n, 3))
    out[:, 0] = landmarks_xy[k, 0] - r * np.cos(phi)
    out[:, 1] = landmarks_xy[k, 1] - r * np.sin(phi)
    out[:, 2] = wrap_angle(phi - b)
    return out


#: Defaults of the AMCL core for MRCLAM (others are ``AMCLParams``' own): a tracking filter
#: from a known pose needs far fewer particles than global localization in a laser map; and no
#: random-particle recovery: one range-and-bearing reading fits a whole circle of poses, so a
#: random particle on that circle outweighs the tracked set whenever the robot comes back from a
#: gap in its readings (on Dataset 6 recovery turns 0.1-0.2 m errors into 1-3 m ones). Turn it
#: on with ``recovery=true`` for a kidnapped-robot experiment.
PF_AMCL_DEFAULTS = {"min_particles": 300, "max_particles": 2000, "bin_size_m": 0.25,
                    "teammate_outlier_probability": 0.1, "recovery": False}


def pf_params(params: Mapping):
    """``(PfParams, AMCLParams)`` from one mapping: :class:`PfParams`' keys are the landmark
    filter's own, every other key goes to the AMCL core (over :data:`PF_AMCL_DEFAULTS`)."""
    from swarmloc.agents.laser.amcl import AMCLParams

    own = {k: v for k, v in params.items() if k in {f.name for f in fields(PfParams)}}
    amcl = {**PF_AMCL_DEFAULTS, **{k: v for k, v in params.items() if k not in own}}
    return PfParams(**own), AMCLParams.from_dict(amcl)


class ParticleFilterLocalizer:
    """The AMCL-style particle filter (``agents/laser/amcl.py``'s :class:`AugmentedMCL`) on landmark
    readings: each tick the particles move with the odometry (per-step noise: the motion model
    at MRCLAM's typical command, :attr:`MotionNoise.typical_v_mps`, since the AMCL core takes one
    fixed noise); on a tick with readings, the weights are multiplied by the landmark likelihood
    (:func:`landmark_log_likelihood`) and the teammates' evidence
    (:func:`teammate_log_density`), the estimate is AMCL's best-cluster mean, and the set is
    resampled (KLD-sized; recovery off by default, see :data:`PF_AMCL_DEFAULTS`) when its
    effective size drops below
    ``resample_ess_fraction``. In between, the estimate follows the odometry."""

    def __init__(self, setup: LandmarkSetup, params: Mapping, rng: np.random.Generator):
        from swarmloc.agents.laser.amcl import AugmentedMCL

        self.params, self.amcl_params = pf_params(params)
        self.setup = setup
        x0, y0, x1, y1 = setup.bounds_m
        self._log_uniform_xy = -math.log((x1 - x0) * (y1 - y0))
        # A misread: any range up to the area's diagonal, any bearing.
        self._log_uniform_reading = -math.log(math.hypot(x1 - x0, y1 - y0) * TWO_PI)
        low, high = np.array([x0, y0, -math.pi]), np.array([x1, y1, math.pi])

        def sample_area(n: int, generator: np.random.Generator) -> np.ndarray:
            if self.params.sensor_resetting and self._last_readings is not None:
                return self._reset_poses(n, generator, *self._last_readings)
            return generator.uniform(low, high, size=(n, 3))

        # Motion noise per second at the typical command; the per-tick std is this times
        # sqrt(dt) (MotionNoise.tick_std is linear in sqrt(dt)).
        self._per_second = setup.motion.tick_std(setup.motion.typical_v_mps,
                                                 setup.motion.typical_omega_rad_s, 1.0)
        n = self.amcl_params.max_particles
        initial = setup.initial_hypotheses(n, rng)
        self._make = lambda motion_std, particles: AugmentedMCL(
            self.amcl_params, rng, sample_area, motion_std, initial_particles=particles)
        self.filter = None
        self._dt = None
        self._initial = initial
        #: The landmark readings of the last tick that had some (the recovery's sampler).
        self._last_readings = None
        self._pose = setup.initial_pose.copy()
        self._cov = setup.initial_covariance()
        self.coop = _Cooperation(setup)
        self.updates = 0
        #: Sensor resetting: the smoothed fit of the readings (see :class:`PfParams`), and how
        #: many particles were replaced so far.
        self.fit = 1.0 if setup.initial_area_m is None else 0.0
        self.resets = 0
        #: Teammate resetting (see :meth:`_disagrees`): readings that contradicted the set, and
        #: particles replaced by poses drawn from the teammate.
        self.teammate_disagreements = 0
        self.teammate_resets = 0
        #: The readings of the last ``fix_window_s`` (only with ``fix_proposal``, its one user:
        #: carrying them through every tick's motion is a Python loop on the hot path).
        self._buffer = ReadingBuffer(self.params.fix_window_s) if self.params.fix_proposal else None
        self._rng = rng  # the core's generator too: one stream per robot

    def _disagrees(self, core, reading: RelativeReading, log_density: np.ndarray) -> bool:
        """Teammate resetting (``teammate_reset_fraction`` > 0, the laser family's rule,
        :class:`~swarmloc.agents.laser.amcl.AugmentedMCL`): the teammate is sure of itself
        (``teammate_reset_std_m``) and the weighted mean of its density over the particles is
        below a uniform belief's over the area, so reweighting could not move the set. Unlike
        the laser family, which resets after resampling, the particles are drawn before the
        reading reweights the set, so the reading weighs them at once: a robot seeing no
        landmark has no other evidence to weigh them by (robot 4 of Dataset 6, unknown start,
        seed 3: no landmark from 30 to 65 s, while from 41 to 62 s localized teammates measured
        it, or it them, 2 to 5 times a second; its particles stayed 1.9 m off)."""
        if self.amcl_params.teammate_reset_fraction <= 0.0 or spectral_norm_xy(
                reading.report.covariance) >= self.params.teammate_reset_std_m ** 2:
            return False
        weights = core.weights
        peak = float(log_density.max())
        agreement = peak + math.log(max(float(weights @ np.exp(log_density - peak)), 1e-300))
        if agreement >= self._log_uniform_xy:
            return False
        self.teammate_disagreements += 1
        return True

    def _mix_fix(self, core) -> None:
        """Mixture MCL's fixed share of particles from the fix, when it disagrees with the
        estimate (see :class:`PfParams`)."""
        probe = self._buffer.fix_poses(16, self._rng)
        if probe is None:
            return
        centre = np.median(probe[:, :2], axis=0)
        if float(np.hypot(*(centre - self._pose[:2]))) <= self.params.fix_disagreement_m:
            return
        n_mix = max(1, int(core.n_particles * self.params.fix_mixing))
        self.resets += core.replace_random(n_mix, lambda n, g: self._buffer.fix_poses(n, g))

    def _reset_poses(self, n: int, generator: np.random.Generator, landmarks_xy: np.ndarray,
                     range_m: np.ndarray, bearing_rad: np.ndarray) -> np.ndarray:
        """Sensor resetting's poses: from the buffered readings' fix when ``fix_proposal`` is on
        and they hold two distinct landmarks, else from the circles of the readings given."""
        fixed = None if self._buffer is None else self._buffer.fix_poses(n, generator)
        if fixed is not None:
            return fixed
        return sensor_resetting_poses(n, generator, landmarks_xy, range_m, bearing_rad,
                                      self.setup.camera, self.setup.bounds_m)

    def _core(self, dt_s: float):
        """The AMCL core; its per-step motion noise is fixed when it is built, so it is built
        for the replay's tick length at the first step."""
        if self.filter is None:
            scale = math.sqrt(dt_s)
            self.filter = self._make((self._per_second[0] * scale, self._per_second[1] * scale),
                                     self._initial)
            self._dt = dt_s
        elif abs(dt_s - self._dt) > 1e-9:
            raise ValueError(f"obs.odometry_dt_s: {dt_s} differs from the first tick's {self._dt}")
        return self.filter

    @property
    def rejected(self):
        return self.coop.rejected

    @property
    def covariance(self) -> np.ndarray:
        """The pose covariance broadcast to the teammates: the weighted particles' at the last
        update, grown by the motion noise since."""
        return self._cov.copy()

    def step(self, obs: LandmarkObservation) -> None:
        setup = self.setup
        check_observation(obs, setup.robot_id)
        obs = calibrated(obs, setup.camera)
        dt = obs.odometry_dt_s
        core = self._core(dt)
        distance, turn, std_d, std_t = tick_motion(obs, setup.motion)
        core.predict(distance, turn)
        if self._buffer is not None:
            self._buffer.move(distance, turn, dt)
        self._pose = unicycle(self._pose[None, :], distance, turn)[0]
        self._cov = self._cov + _motion_growth(std_d, std_t)
        readings = self.coop.readings(obs)
        xy, known = setup.landmark_positions(obs.landmark_ids)
        if known.any() or readings:
            camera = setup.camera
            if known.any():
                lm_xy, rng_m = xy[known], obs.landmark_range_m[known]
                bearing = obs.landmark_bearing_rad[known]
                self._last_readings = (lm_xy, rng_m, bearing)
                if self._buffer is not None:
                    self._buffer.add(obs.landmark_ids[known], lm_xy, rng_m, bearing, camera)
                # One correction per reading: the recovery averages (w_slow, w_fast) then
                # compare likelihoods of one reading each, not of frames with 1 or 4 readings.
                resetting = self.amcl_params.recovery and self.params.sensor_resetting
                for k in range(lm_xy.shape[0]):
                    log_w_avg = core.correct(lambda p, k=k: landmark_log_likelihood(
                        p, lm_xy[k:k + 1], rng_m[k:k + 1], bearing[k:k + 1], camera,
                        self._log_uniform_reading))
                    if resetting:
                        peak = -math.log(TWO_PI * float(camera.range_std(rng_m[k]))
                                         * camera.bearing_std_rad)
                        a = self.params.reset_smoothing
                        self.fit = (1 - a) * self.fit + a * math.exp(min(log_w_avg - peak, 0.0))
                if resetting and self.params.fix_proposal and self.params.fix_mixing > 0.0 and \
                        self.fit >= self.params.reset_threshold:
                    self._mix_fix(core)
                if resetting and self.fit < self.params.reset_threshold:
                    n_reset = int(core.n_particles * (1.0 - self.fit / self.params.reset_threshold))
                    self.resets += core.replace_random(n_reset, lambda n, g: self._reset_poses(
                        n, g, lm_xy, rng_m, bearing))
            for reading in readings:
                log_density = teammate_log_density(core.particles, reading, self._pose,
                                                   self._cov, camera)
                if self._disagrees(core, reading, log_density):
                    self.teammate_resets += core.replace_random(
                        round(self.amcl_params.teammate_reset_fraction * core.n_particles),
                        lambda n, g, reading=reading: poses_from_teammate_reading(
                            n, g, reading, setup.robot_id, obs, camera))
                    log_density = teammate_log_density(core.particles, reading, self._pose,
                                                       self._cov, camera)
                core.reweight(_mixture(log_density, self.amcl_params.teammate_outlier_probability,
                                       self._log_uniform_xy))
            estimate, _ = core.estimate_with_share()
            self._pose = estimate
            weights = core.weights
            self._cov = _weighted_pose_covariance(core.particles, weights, estimate)
            ess = 1.0 / float(np.sum(weights * weights))
            if ess < self.params.resample_ess_fraction * core.n_particles:
                core.resample()
            self.updates += 1
        cov = self._cov
        floor = self.params.report_floor_std_m
        if floor > 0.0 and (cov[0, 0] < floor * floor or cov[1, 1] < floor * floor):
            cov = cov.copy()
            cov[0, 0], cov[1, 1] = max(cov[0, 0], floor * floor), max(cov[1, 1], floor * floor)
        self.coop.publish(obs, self._pose, cov)

    def estimate(self) -> np.ndarray:
        return self._pose.copy()

    def outgoing(self) -> bytes | None:
        return self.coop.out


def tick_motion(obs: LandmarkObservation, motion) -> tuple[float, float, float, float]:
    """The tick's odometry increments and their noise: ``(distance [m], turn [rad], std of the
    distance, std of the turn)`` (:meth:`MotionNoise.tick_std`)."""
    dt = obs.odometry_dt_s
    std_d, std_t = motion.tick_std(obs.odometry_v_mps, obs.odometry_omega_rad_s, dt)
    return obs.odometry_v_mps * dt, obs.odometry_omega_rad_s * dt, std_d, std_t


class ReadingWindow:
    """The landmark readings of the last ``window_s`` seconds, for a raw fitness that covers them
    all (CFS-GA's and MR-SSGA's, :func:`landmark_fitness_terms`): with each reading, the robot's
    odometry pose (dead reckoning in its own frame) and the motion variances accumulated up to
    it, so that a hypothesis of the present pose can be moved back to the time of each reading
    and the reading's noise grown by the motion noise of that interval.

    Each tick: :meth:`move` (the tick's odometry and its noise stds, the tick's end time; drops
    the readings ``window_s`` or more seconds old), then :meth:`add` for the tick's readings of
    known landmarks; :meth:`fitness_terms` gives the summed terms as a function of the poses."""

    def __init__(self, window_s: float):
        self.window_s = window_s
        self.odometry_pose = np.zeros(3)
        self.odometry_var = np.zeros(2)  # accumulated distance and turn variances
        self.time_s = 0.0
        #: (odometry pose, accumulated variances, landmarks xy (K, 2), ranges (K,),
        #: bearings (K,), time) of each tick with readings in the window.
        self.entries: list[tuple] = []

    def move(self, distance_m: float, turn_rad: float, std_d: float, std_t: float,
             time_s: float) -> None:
        self.odometry_pose = unicycle(self.odometry_pose[None, :], distance_m, turn_rad)[0]
        self.odometry_var = self.odometry_var + np.array([std_d * std_d, std_t * std_t])
        self.time_s = time_s
        horizon = self.time_s - self.window_s
        self.entries = [e for e in self.entries if e[5] > horizon]

    def add(self, landmarks_xy: np.ndarray, range_m: np.ndarray, bearing_rad: np.ndarray) -> None:
        self.entries.append((self.odometry_pose.copy(), self.odometry_var.copy(), landmarks_xy,
                             range_m, bearing_rad, self.time_s))

    def record(self, obs: LandmarkObservation, setup: LandmarkSetup, distance_m: float,
               turn_rad: float, std_d: float, std_t: float) -> bool:
        """One tick: :meth:`move` by the tick's motion, then :meth:`add` the tick's readings of
        known landmarks (``obs`` already calibrated); True if there were any."""
        self.move(distance_m, turn_rad, std_d, std_t, obs.time_s)
        xy, known = setup.landmark_positions(obs.landmark_ids)
        if not known.any():
            return False
        self.add(xy[known], obs.landmark_range_m[known], obs.landmark_bearing_rad[known])
        return True

    def fitness_terms(self, camera: CameraNoise):
        """``(terms, K)``: ``terms(poses (P, 3)) -> (P,)`` the sum of the ``K`` readings' raw
        fitness terms as a function of the present poses (None and 0 for an empty window)."""
        entries = self.entries
        if not entries:
            return None, 0
        odo = np.array([e[0] for e in entries])
        var = np.array([e[1] for e in entries])
        lm_xy = np.concatenate([e[2] for e in entries])
        rng_m = np.concatenate([e[3] for e in entries])
        bearing = np.concatenate([e[4] for e in entries])
        counts = [e[2].shape[0] for e in entries]
        delta = np.repeat(_between(self.odometry_pose, odo), counts, axis=0)
        extra = np.repeat(self.odometry_var[None, :] - var, counts, axis=0)
        range_std = np.sqrt(camera.range_std(rng_m) ** 2 + extra[:, 0])
        bearing_std = np.sqrt(camera.bearing_std_rad**2 + extra[:, 1])

        def terms(poses: np.ndarray) -> np.ndarray:
            return landmark_fitness_terms(poses, delta, lm_xy, rng_m, bearing, range_std,
                                          bearing_std)

        return terms, rng_m.size


def median_pose(population: np.ndarray, radius_m: float) -> np.ndarray:
    """A population's coordinate-wise median position, with the circular mean heading of the
    individuals within ``radius_m`` of it (of all of them when none is)."""
    xy = np.median(population[:, :2], axis=0)
    near = np.hypot(population[:, 0] - xy[0], population[:, 1] - xy[1]) < radius_m
    headings = population[near, 2] if near.any() else population[:, 2]
    heading = math.atan2(np.sin(headings).mean(), np.cos(headings).mean())
    return np.array([xy[0], xy[1], heading])


@dataclass(frozen=True)
class CfsgaMrclamParams:
    """The landmark CFS-GA's own parameters; every other key goes to
    :class:`swarmloc.agents.laser.cfsga.CFSGAParams` (``population_size``, ...)."""

    #: How many of its above-average individuals a robot broadcasts (fittest first).
    shared_individuals: int = 64
    #: Also score each individual by the teammates' readings (a term of the raw fitness's mean,
    #: like one more landmark): ours; 003 §IV-B uses teammates only through the virtual niches.
    teammate_fitness: bool = True
    #: The raw fitness covers the landmark readings of the last ``window_s`` seconds, each
    #: brought to the present by the odometry since (see :class:`CfsgaLocalizer`).
    window_s: float = 1.0
    #: "best": 003's best individual; "median": the population's coordinate-wise median
    #: position, with the circular mean heading of the individuals within ``median_radius_m``.
    estimate: str = "median"
    median_radius_m: float = 0.5

    def __post_init__(self):
        if isinstance(self.shared_individuals, bool) or not isinstance(self.shared_individuals, int) \
                or not 0 <= self.shared_individuals <= MAX_REPORT_SAMPLES:
            raise ValueError(f"shared_individuals must be an integer in [0, {MAX_REPORT_SAMPLES}]")
        if not isinstance(self.teammate_fitness, bool):
            raise TypeError(f"teammate_fitness must be true or false, got {self.teammate_fitness!r}")
        _real(self.window_s, "window_s")
        _real(self.median_radius_m, "median_radius_m", positive=True)
        if self.estimate not in ("best", "median"):
            raise ValueError(f"estimate: expected 'best' or 'median', got {self.estimate!r}")


#: CFS-GA core parameters for MRCLAM: table I of 003 (the core's defaults) with
#: ``motion_diffusion`` on: each individual draws its own odometry noise, since the logged
#: commands are not the motion and without it the population cannot follow the true pose's
#: drift (first 300 s of Dataset 6: position RMSE 0.39 m without, 0.13 m with).
CFSGA_TRACKING_DEFAULTS = {"motion_diffusion": True}


class CfsgaLocalizer:
    """CFS-GA (``agents/laser/cfsga.py``'s :class:`FitnessSharingGA`, seed 003) on landmark readings.

    Each tick every individual moves with the odometry plus its own draw of the motion noise
    (:meth:`MotionNoise.tick_std`). On a tick with landmark readings (or, cooperative, a reading
    of or by a teammate) the GA runs one generation (003 §IV-A):

    - **raw fitness** (:func:`landmark_fitness_terms`, 003's mean over the measurements of a
      Gaussian of each residual): 003 scores a pose by a whole laser scan; one camera frame holds one to four
      landmark readings, which leave a pose undetermined (one reading fits a circle of poses), so
      the fitness covers the readings of the last ``window_s`` seconds. Each is predicted from
      the individual's pose at the time of the reading: its present pose moved back by the
      odometry since (dead reckoning over at most ``window_s``), with the reading's noise grown
      by the motion noise of that interval. With ``teammate_fitness`` the teammates' readings of
      this tick (:func:`teammate_log_density`) are further terms of the mean;
    - shared fitness, tournaments, elitism, aging: the core, unchanged;
    - **cooperative**: the virtual population of 003 §IV-B: the teammates' broadcast
      above-average individuals turned into hypotheses of this robot's position by the reading
      between the two robots (``R(P_b, Delta)``; MRCLAM measures no relative heading, so a
      virtual individual gets this robot's estimated heading, which the niche count, a distance
      between positions, does not use).

    The estimate is the best individual (raw fitness times the aging factor)."""

    def __init__(self, setup: LandmarkSetup, params: Mapping, rng: np.random.Generator):
        from swarmloc.agents.laser.cfsga import CFSGAParams, FitnessSharingGA, box_sampler

        own_names = {f.name for f in fields(CfsgaMrclamParams)}
        own = {k: v for k, v in params.items() if k in own_names}
        core = {**CFSGA_TRACKING_DEFAULTS,
                **{k: v for k, v in params.items() if k not in own_names}}
        self.params = CfsgaMrclamParams(**own)
        self.ga_params = CFSGAParams.from_dict(core)
        self.setup = setup
        x0, y0, x1, y1 = setup.bounds_m
        diagonal = math.hypot(x1 - x0, y1 - y0)
        m = self.ga_params.population_size
        initial = setup.initial_hypotheses(m, rng)
        self.ga = FitnessSharingGA(self.ga_params, self.ga_params.niche_radius_fraction * diagonal,
                                   box_sampler(setup.bounds_m), rng, initial_population=initial)
        self._pose = setup.initial_pose.copy()
        self._cov = setup.initial_covariance()
        self._shared = _NO_ROWS
        self.coop = _Cooperation(setup)
        self.generations = 0
        self.virtual_size = 0
        self.window = ReadingWindow(self.params.window_s)

    @property
    def rejected(self):
        return self.coop.rejected

    def _virtual(self, readings: Sequence[RelativeReading]) -> np.ndarray | None:
        parts = []
        heading = float(self._pose[2])
        for reading in readings:
            samples = reading.report.samples
            if not samples.shape[0]:
                continue
            if reading.observer:
                direction = heading + reading.bearing_rad
                xy = samples[:, :2] - reading.range_m * np.array([math.cos(direction),
                                                                  math.sin(direction)])
            else:
                direction = samples[:, 2] + reading.bearing_rad
                xy = samples[:, :2] + reading.range_m * np.column_stack([np.cos(direction),
                                                                         np.sin(direction)])
            parts.append(np.column_stack([xy, np.full(xy.shape[0], heading)]))
        return np.concatenate(parts) if parts else None

    def step(self, obs: LandmarkObservation) -> None:
        setup = self.setup
        check_observation(obs, setup.robot_id)
        obs = calibrated(obs, setup.camera)
        distance, turn, std_d, std_t = tick_motion(obs, setup.motion)
        diffusion = 1.0 if self.ga_params.motion_diffusion else 0.0
        self.ga.kinematic_update(distance, turn, std_d * diffusion, std_t * diffusion)
        if self._shared.shape[0]:
            self._shared = unicycle(self._shared, distance, turn)
        self._cov = self._cov + _motion_growth(std_d, std_t)
        seen = self.window.record(obs, setup, distance, turn, std_d, std_t)
        readings = self.coop.readings(obs)
        use_teammates = bool(readings) and self.params.teammate_fitness
        if seen or use_teammates:
            camera = setup.camera
            window_terms, n_window = self.window.fitness_terms(camera)
            pose, cov = self._pose, self._cov
            n_terms = n_window + (len(readings) if use_teammates else 0)

            def raw_fitness(poses: np.ndarray) -> np.ndarray:
                total = window_terms(poses) if n_window else np.zeros(poses.shape[0])
                if use_teammates:
                    for reading in readings:
                        total = total + np.exp(teammate_log_density(poses, reading, pose, cov,
                                                                    camera, normalised=False))
                return total / n_terms

            self.ga.evaluate(raw_fitness)
            if setup.cooperative and self.params.shared_individuals:
                self._shared = self.ga.above_average(self.params.shared_individuals)
            virtual = self._virtual(readings)
            self.virtual_size = 0 if virtual is None else int(virtual.shape[0])
            self.ga.evolve(virtual)
            self.generations += 1
            population = self.ga.population
            self._pose = self._population_estimate()
            self._cov = _weighted_pose_covariance(
                population, np.full(population.shape[0], 1.0 / population.shape[0]), self._pose)
        else:
            self._pose = unicycle(self._pose[None, :], distance, turn)[0]
        self.coop.publish(obs, self._pose, self._cov, self._shared)

    def _population_estimate(self) -> np.ndarray:
        if self.params.estimate == "best":
            return self.ga.best_pose
        return median_pose(self.ga.population, self.params.median_radius_m)

    def estimate(self) -> np.ndarray:
        return self._pose.copy()

    def outgoing(self) -> bytes | None:
        return self.coop.out
