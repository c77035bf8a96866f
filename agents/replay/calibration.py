"""Self-calibration of a robot's camera while it localizes: no ground truth (issue 19).

MRCLAM's camera ranges carry a bias that depends on the bearing, ``measured = r (1 + c0 +
c2 b^2)`` (:class:`~swarmloc.agents.replay.localizers.CameraNoise`). The Vicon fit of
:func:`swarmloc.deploy.lab.replay.mrclam.fit_camera` measures it against the ground truth of the
very run it scores; a user with real robots has no Vicon. Here each robot estimates it from its
own data while localizing:

- :class:`RangeBiasEstimator`: the bias model as a linear regression of the relative range
  residual ``rel = measured / predicted - 1`` on ``(1, min(b^2, 1))`` (the same model and the same
  misread gates as ``fit_camera``: ``|rel| < 0.25``, bearing residual under 0.1 rad), solved from
  accumulated normal equations with a ridge prior that pulls towards no bias (``prior_readings``
  pseudo-readings at ``c0 = c2 = 0``) and Huber weights (a reading more than ``huber_k`` residual
  stds from the current fit counts less). It also keeps the weighted residual spreads: the
  relative range noise (``range_fraction``) and the bearing noise (``bearing_std_rad``).
- :class:`SelfCalibratingLocalizer`: wraps any landmark localizer. Before each step it predicts
  the robot's pose at the readings (the localizer's estimate moved by the tick's odometry: the
  prior, not the posterior the readings themselves pull towards them), and feeds an estimator
  the landmark readings, corrected by the calibration so far, against that pose; when
  cooperative, a second one the readings of teammates against their broadcast positions (the
  robots' barcode tubes differ from the landmarks': the teammates' bias is the landmarks' plus
  a difference of its own, which starts at zero; there are four times fewer such readings).
  Every ``refresh_readings`` readings the bias left in the corrected readings is folded into the
  calibration with gain ``gain`` and the estimator starts afresh, and the wrapped localizer's
  camera is replaced by the calibrated one (its ``setup.camera``, which every localizer reads at
  each step). An EM in its online form: E, the poses from the filter; M, the bias from the
  readings. A fold that would leave an implausible camera (a range scale under 0.2 within 1 rad
  of the axis, which :class:`~swarmloc.agents.replay.localizers.CameraNoise` refuses: a fit on a
  narrow spread of bearings can swing ``c2`` that far) is refused and counted (``refused``); the
  calibration stays as it was and the next readings estimate afresh.

  Why gain 1 (the whole residual bias at each refresh): the filter absorbs part of the bias, so
  each fold falls short of the true bias and the iteration approaches it from one side; a gain
  under 1 only shortens steps that are already short. Robots 1 and 4 of Dataset 6 are trusted
  for 140-170 readings in their first 180 s, so with gain 0.5 their ``c2`` was -0.01 and -0.16
  at 180 s against the Vicon fit's -0.46 (gain 1: -0.03, poorly seen at robot 1's narrow
  bearings, and -0.33; robots 2, 3, 5 within 0.08 of it by 120 s). Measured with the hybrid,
  cooperative (position RMSE per robot): known start, 900 s, gain 0.5 0.075 / 0.087 / 0.099 /
  0.110 / 0.079 m, gain 1 0.069 / 0.086 / 0.097 / 0.099 / 0.080 m; unknown start, seeds 0-9,
  RMSE after localizing, gain 0.5 0.113 / 0.125 / 0.070 / 0.116 / 0.102 m, gain 1 0.098 /
  0.105 / 0.071 / 0.107 / 0.085 m; seeds 0-39, gain 1: 0.096 / 0.105 / 0.080 / 0.116 / 0.101 m
  (0.084 / 0.107 / 0.077 / 0.117 / 0.103 m with the hybrid's ``uncalibrated_folds`` 2, which
  the first fold's shortfall asked for until the team's calibration; 1 since, see
  :class:`~swarmloc.agents.replay.hybrid.HybridParams`).
  The price is noise: the calibration after a fold carries that fold's (100 readings); at the
  end of Dataset 6 ``c2`` is within 0.002-0.075 of the Vicon fit by robot, against 0-0.061 with
  gain 0.5, and on the synthetic runs of the tests up to 0.06 off (0.03 with gain 0.5). Also
  measured (known start, robot 4; unknown start, worst RMSE after): gain 0.75 0.103 m, 0.115 m;
  gain 1 for the first fold then 0.5, 0.109 m, 0.115 m; refreshing every 50 readings (gain 1)
  0.102 m, and fits noisy enough to swing ``c2`` to -0.8.

  Why the residual and not the raw bias: the filter's poses absorb part of any bias (with a
  forward camera a range scale error looks much like a position error along the heading), so a
  regression of the raw readings on the filter's poses underestimates it (Dataset 6: about half
  of ``c2``). Its fixed point, no bias left in the corrected readings as the filter sees them,
  is the true bias whatever share the filter absorbs.
- **The team's calibration** (``from_teammates``, cooperative only): a robot broadcasts its
  landmark calibration once it has folded it (``(c0, c2, folds)`` in its
  :class:`~swarmloc.agents.replay.localizers.TeammateReport`), and a robot whose own camera has
  not folded yet starts from the calibration of the teammate that folded most often (the
  lowest id among equals); its estimator then learns what that leaves in its own readings, and
  its own folds go on from there. An adopted calibration is never passed on (only a camera's
  own). Why: the team's cameras are one model, their biases alike (Dataset 6, the Vicon fit:
  ``c0`` 0.025-0.066, ``c2`` about -0.46 for every robot), and a robot learns only once it is
  localized, so from an unknown start no camera is corrected in the first 43 s (Dataset 6, seed
  42: robot 5 folds first, at 43 s; robot 2 at 84 s). Robot 2 reads landmark 18 eight times at
  0.51 rad just before its 46 s without landmarks, 7-8 % short, and the uncorrected readings
  leave it 0.15-0.17 m off (``docs/mrclam/README.md``). Measured with the hybrid, cooperative,
  unknown start, 180 s (every robot under 0.3 m within 60 s and staying, seeds; robot-seeds):
  seeds 0-39 (on which the hybrid's defaults were chosen) 39/40, 199/200 without it, 38/40,
  198/200 with it; seeds 40-79 35/40, 195/200 and **39/40, 199/200**; seeds 80-119 (never run
  before) 34/40, 193/200 and 36/40, 195/200: 108 and 113 of 120. Known start, position RMSE by
  robot: the hybrid 0.065 / 0.088 / 0.097 / 0.099 / 0.081 m without, 0.062 / 0.089 / 0.098 /
  0.097 / 0.080 m with; the EKF 0.079 / 0.092 / 0.108 / 0.109 / 0.088 and 0.068 / 0.085 / 0.108
  / 0.104 / 0.086 m; the particle filter 0.084 / 0.142 / 0.141 / 0.124 / 0.100 and 0.083 /
  0.100 / 0.127 / 0.116 / 0.100 m. ``swarmloc mrclam --calibration self-own`` is each robot on
  its own readings only (a team whose cameras differ).

A robot that is not localized (an unknown start, a kidnap) would teach the estimator nonsense,
so readings are only used while the localizer looks consistent with them: at least
``trust_fraction`` of the last ``trust_window`` landmark readings within the gates.

This is our choice; the seeds do not calibrate cameras (the MRCLAM literature calibrates against
Vicon, as ``fit_camera`` does). Pure: no clock, no randomness.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from swarmloc.agents.replay.localizers import (
    CameraNoise,
    LandmarkLocalizer,
    _real,
    decode_received,
    predicted_range_bearing,
    teammate_camera_biases,
    unicycle,
    with_camera_bias,
    wrap_angle,
)
from swarmloc.world.replay.replay import LandmarkObservation

#: The misread gates of ``fit_camera``: relative range error and bearing error.
MAX_RELATIVE_ERROR = 0.25
MAX_BEARING_ERROR_RAD = 0.1


@dataclass(frozen=True)
class SelfCalibrationParams:
    """Parameters of :class:`RangeBiasEstimator` and :class:`SelfCalibratingLocalizer`."""

    prior_readings: float = 20.0
    huber_k: float = 2.0
    #: The teammates' bias is refreshed once this many landmark readings are in.
    min_readings: int = 50
    #: Readings per refresh, and the share of the bias left in them folded in at each.
    refresh_readings: int = 100
    gain: float = 1.0
    trust_window: int = 40
    trust_fraction: float = 0.8
    #: Lower bounds of the noise handed to the localizer (the spread of the residuals also holds
    #: the pose error, but never let a lucky stretch make the filter overconfident).
    min_range_fraction: float = 0.02
    min_bearing_std_rad: float = 0.005
    #: Hand the localizer the spread of the bearing residuals too (they hold the filter's
    #: heading error as well as the camera's: an upper bound; on Dataset 6 it helps).
    learn_bearing_std: bool = True
    #: Cooperative: a robot whose camera has not folded yet starts from the calibration a
    #: teammate broadcasts (the team's cameras are one model; see the module docstring).
    from_teammates: bool = True

    def __post_init__(self):
        _real(self.prior_readings, "prior_readings", positive=True)
        _real(self.huber_k, "huber_k", positive=True)
        if not 0.0 < _real(self.gain, "gain") <= 1.0:
            raise ValueError(f"gain must be in (0, 1], got {self.gain}")
        if not isinstance(self.from_teammates, bool):
            raise TypeError(f"from_teammates must be true or false, got {self.from_teammates!r}")
        for name in ("min_readings", "refresh_readings", "trust_window"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")
        if not 0.0 <= _real(self.trust_fraction, "trust_fraction") <= 1.0:
            raise ValueError(f"trust_fraction must be in [0, 1], got {self.trust_fraction}")
        _real(self.min_range_fraction, "min_range_fraction", positive=True)
        _real(self.min_bearing_std_rad, "min_bearing_std_rad", positive=True)


def robust_std(values: np.ndarray) -> float:
    """1.4826 times the median absolute deviation (the std of a Gaussian, blind to outliers)."""
    return float(1.4826 * np.median(np.abs(values - np.median(values))))


class RangeBiasEstimator:
    """Online robust least squares of ``rel = c0 + c2 min(b^2, 1)`` (see the module docstring).
    The noise figures are robust stds (:func:`robust_std`) of the last ``NOISE_WINDOW``
    residuals."""

    NOISE_WINDOW = 500

    def __init__(self, params: SelfCalibrationParams | None = None,
                 initial_range_fraction: float = 0.04, initial_bearing_std_rad: float = 0.015):
        self.params = params or SelfCalibrationParams()
        # sum w x x^T + prior; the prior's weight on c2 is that of readings at b^2 = 0.1 (a
        # typical bearing of 0.3 rad), so it does not outweigh the data on the smaller feature.
        self._normal = np.diag([1.0, 0.01]) * self.params.prior_readings
        self._moment = np.zeros(2)  # sum w x rel
        self._coef = np.zeros(2)
        self._range_residuals = deque(maxlen=self.NOISE_WINDOW)
        self._bearing_errors = deque(maxlen=self.NOISE_WINDOW)
        self._range_fraction = float(initial_range_fraction)
        self._bearing_std = float(initial_bearing_std_rad)
        self.accepted = 0  #: readings used so far
        self.rejected = 0  #: readings outside the misread gates

    def add(self, relative_error, bearing_rad, bearing_error_rad) -> np.ndarray:
        """Feed readings (arrays of one length): ``measured / predicted - 1``, the bearing of
        each reading and its bearing residual. Returns which were used (within the gates)."""
        rel = np.atleast_1d(np.asarray(relative_error, dtype=np.float64))
        b_sq = np.minimum(np.square(np.atleast_1d(np.asarray(bearing_rad, dtype=np.float64))), 1.0)
        b_err = np.atleast_1d(np.asarray(bearing_error_rad, dtype=np.float64))
        good = (np.abs(rel) < MAX_RELATIVE_ERROR) & (np.abs(b_err) < MAX_BEARING_ERROR_RAD) \
            & np.isfinite(rel) & np.isfinite(b_err)
        self.rejected += int((~good).sum())
        k = self.params.huber_k
        for r, x2, e in zip(rel[good], b_sq[good], b_err[good]):
            x = np.array([1.0, x2])
            residual = r - float(x @ self._coef)
            scale = k * self._range_fraction
            w = 1.0 if abs(residual) <= scale else scale / abs(residual)
            self._normal += w * np.outer(x, x)
            self._moment += w * r * x
            self._coef = np.linalg.solve(self._normal, self._moment)
            self._range_residuals.append(residual)
            self._bearing_errors.append(e)
            self.accepted += 1
            if self.accepted % 50 == 0:  # the robust noise, now and then (a median)
                self._range_fraction = robust_std(np.array(self._range_residuals))
                self._bearing_std = robust_std(np.array(self._bearing_errors))
        return good

    @property
    def c0(self) -> float:
        return float(self._coef[0])

    @property
    def c2(self) -> float:
        return float(self._coef[1])

    @property
    def range_fraction(self) -> float:
        """The weighted spread of the relative range residuals after the bias."""
        return self._range_fraction

    @property
    def bearing_std_rad(self) -> float:
        return self._bearing_std


class _Bias:
    """One kind of reading's calibration: the total bias so far and the estimator of what is
    left of it in the corrected readings."""

    def __init__(self, params: SelfCalibrationParams, camera: CameraNoise):
        self.params = params
        self.c0 = self.c2 = 0.0
        self.estimator = RangeBiasEstimator(params, camera.range_fraction, camera.bearing_std_rad)
        self.used = 0  #: readings used since the last refresh
        self.total = 0  #: readings used so far
        self.refreshes = 0

    def correction(self, bearing_rad: np.ndarray, prior: _Bias | None = None) -> np.ndarray:
        """``1 + c0 + c2 min(b^2, 1)``; with ``prior``, its bias plus this one's."""
        c0, c2 = self.c0, self.c2
        if prior is not None:
            c0, c2 = c0 + prior.c0, c2 + prior.c2
        return 1.0 + c0 + c2 * np.minimum(np.square(bearing_rad), 1.0)

    def add(self, corrected_rel, bearing_rad, bearing_error_rad) -> int:
        n = int(self.estimator.add(corrected_rel, bearing_rad, bearing_error_rad).sum())
        self.used += n
        self.total += n
        return n

    def refresh(self) -> bool:
        """Fold what is left into the total (``(1 + c)(1 + d) ~ 1 + c + d``) with the gain,
        and start estimating afresh; the noise figures are kept. False: too few readings."""
        if self.used < self.params.refresh_readings:
            return False
        gain = self.params.gain
        self.c0 += gain * self.estimator.c0
        self.c2 += gain * self.estimator.c2
        self._restart()
        self.refreshes += 1
        return True

    def adopt(self, c0: float, c2: float) -> None:
        """Start from another camera's bias: the estimator starts afresh on the residual left by
        it; the refresh count stays this camera's own."""
        self.c0, self.c2 = float(c0), float(c2)
        self._restart()

    def _restart(self) -> None:
        """A fresh estimator of the bias left, with the noise figures kept."""
        old = self.estimator
        self.estimator = RangeBiasEstimator(self.params, old.range_fraction, old.bearing_std_rad)
        self.estimator._range_residuals, self.estimator._bearing_errors = \
            old._range_residuals, old._bearing_errors
        self.used = 0

    def state(self) -> tuple[float, float, int]:
        return self.c0, self.c2, self.refreshes

    def restore(self, state: tuple[float, float, int]) -> None:
        self.c0, self.c2, self.refreshes = state


class SelfCalibratingLocalizer:
    """A landmark localizer whose camera calibrates itself (see the module docstring). It is a
    :class:`~swarmloc.agents.replay.localizers.LandmarkLocalizer` itself."""

    def __init__(self, inner: LandmarkLocalizer, params: SelfCalibrationParams | None = None):
        if not hasattr(inner, "setup"):
            raise TypeError(f"{type(inner).__name__} has no setup to calibrate")
        self.inner = inner
        self.params = params or SelfCalibrationParams()
        base = inner.setup.camera
        if any((base.range_bias_c0, base.range_bias_c2, base.teammate_range_bias_c0,
                base.teammate_range_bias_c2)):
            raise ValueError("self-calibration starts from a camera without a range bias")
        self.base_camera = base
        self.landmarks = _Bias(self.params, base)
        self.teammates = _Bias(self.params, base)
        self._recent = deque(maxlen=self.params.trust_window)
        self.refused = 0  #: folds refused because they would leave an implausible camera
        #: The teammate whose broadcast calibration this camera started from (None: none).
        self.adopted_from: int | None = None
        self._sent: tuple[bytes | None, bytes | None] = (None, None)  # (inner's, with camera)

    @property
    def setup(self):
        return self.inner.setup

    def covariance_xy(self):
        """The wrapped localizer's position covariance, if it gives one."""
        inner = getattr(self.inner, "covariance_xy", None)
        return inner() if inner is not None else None

    def heading_variance(self):
        """The wrapped localizer's heading variance, if it gives one."""
        inner = getattr(self.inner, "heading_variance", None)
        return inner() if inner is not None else None

    @property
    def rejected(self):
        return getattr(self.inner, "rejected", ())

    @property
    def refreshes(self) -> int:
        return self.landmarks.refreshes + self.teammates.refreshes

    def trusted(self) -> bool:
        """Whether the localizer's pose agrees with enough recent readings to learn from."""
        recent = self._recent
        return len(recent) == recent.maxlen and \
            sum(recent) >= self.params.trust_fraction * recent.maxlen

    def step(self, obs: LandmarkObservation) -> None:
        if self.params.from_teammates and self.adopted_from is None and obs.received \
                and self.landmarks.refreshes == 0 and self.inner.setup.cooperative:
            self._adopt(obs)
        if obs.landmark_ids.size or obs.robot_ids.size:
            prior = unicycle(np.asarray(self.inner.estimate(), dtype=np.float64)[None, :],
                             obs.odometry_v_mps * obs.odometry_dt_s,
                             obs.odometry_omega_rad_s * obs.odometry_dt_s)
            self._learn(obs, prior)
        self.inner.step(obs)

    def _adopt(self, obs: LandmarkObservation) -> None:
        """Start from the calibration of the teammate that has folded its own the most times
        (the lowest id among equals), if any has."""
        biases = teammate_camera_biases(obs.received, self.inner.setup.robot_id)
        if not biases:
            return
        sender = min(biases, key=lambda rid: (-biases[rid][2], rid))
        c0, c2, _ = biases[sender]
        self.landmarks.adopt(c0, c2)
        self.adopted_from = sender
        self._count_folds()
        self.inner.setup = replace(self.inner.setup, camera=self.camera())

    def _count_folds(self) -> None:
        """Tell a localizer that wants to know (the hybrid) how far the calibration has come:
        its own folds, and an adopted calibration counts as one until the first of them."""
        if hasattr(self.inner, "calibration_folds"):
            self.inner.calibration_folds = max(self.landmarks.refreshes,
                                               int(self.adopted_from is not None))

    def _learn(self, obs: LandmarkObservation, prior: np.ndarray) -> None:
        setup = self.inner.setup
        if obs.landmark_ids.size:
            xy, known = setup.landmark_positions(obs.landmark_ids)
            if known.any():
                bearing = obs.landmark_bearing_rad[known]
                pred_r, pred_b = predicted_range_bearing(prior, xy[known])
                corrected = obs.landmark_range_m[known] / self.landmarks.correction(bearing)
                rel = corrected / np.maximum(pred_r[0], 1e-6) - 1.0
                b_err = wrap_angle(bearing - pred_b[0])
                # Readings closer than 0.1 m say nothing of a scale (as in fit_camera).
                rel[pred_r[0] < 0.1] = np.nan
                consistent = (np.abs(rel) < MAX_RELATIVE_ERROR) & \
                    (np.abs(b_err) < MAX_BEARING_ERROR_RAD)
                trusted = self.trusted()
                self._recent.extend(consistent.tolist())
                if trusted:
                    self.landmarks.add(rel, bearing, b_err)
        if obs.robot_ids.size and setup.cooperative and obs.received and self.trusted():
            reports, _ = decode_received(obs.received, setup.robot_id, obs.robot_ids)
            for rid, range_m, bearing in zip(obs.robot_ids, obs.robot_range_m,
                                             obs.robot_bearing_rad):
                rep = reports.get(int(rid))
                # Only teammates that are themselves well localized (position std < 0.1 m).
                if rep is None or np.trace(rep.covariance[:2, :2]) > 0.02:
                    continue
                pred_r, pred_b = predicted_range_bearing(prior, rep.pose[None, :2])
                if pred_r[0, 0] < 0.1:
                    continue
                corrected = range_m / float(self.teammates.correction(np.array(bearing),
                                                                       self.landmarks))
                self.teammates.add(corrected / pred_r[0, 0] - 1.0, bearing,
                                   wrap_angle(bearing - pred_b[0, 0]))
        before = self.landmarks.state(), self.teammates.state()
        refreshed = self.landmarks.refresh()
        if self.landmarks.total >= self.params.min_readings:
            refreshed |= self.teammates.refresh()
        if not refreshed:
            return
        try:
            camera = self.camera()
        except ValueError:  # an implausible fold (see the module docstring)
            self.landmarks.restore(before[0])
            self.teammates.restore(before[1])
            self.refused += 1
            return
        self._count_folds()
        self.inner.setup = replace(self.inner.setup, camera=camera)

    def camera(self) -> CameraNoise:
        """The camera as calibrated so far."""
        p, lm, tm = self.params, self.landmarks, self.teammates
        values = {"range_bias_c0": lm.c0, "range_bias_c2": lm.c2,
                  "range_fraction": max(lm.estimator.range_fraction, p.min_range_fraction),
                  "teammate_range_bias_c0": lm.c0 + tm.c0, "teammate_range_bias_c2": lm.c2 + tm.c2}
        if p.learn_bearing_std:
            values["bearing_std_rad"] = max(lm.estimator.bearing_std_rad, p.min_bearing_std_rad)
        return replace(self.base_camera, **values)

    def estimate(self) -> np.ndarray:
        return self.inner.estimate()

    def outgoing(self) -> bytes | None:
        """The localizer's report, with this camera's own calibration once it has folded it
        (an adopted one is not passed on)."""
        payload = self.inner.outgoing()
        lm = self.landmarks
        if payload is None or not lm.refreshes:
            return payload
        if self._sent[0] is not payload:
            self._sent = (payload, with_camera_bias(payload, (lm.c0, lm.c2, lm.refreshes)))
        return self._sent[1]
