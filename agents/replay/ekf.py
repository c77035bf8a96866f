"""EKF localization with known landmarks, alone and cooperative (the MRCLAM reference baseline).

State: the pose ``(x_m, y_m, theta_rad)`` and its covariance ``P`` (3 x 3).

- **Predict** (each tick): the unicycle of seed 000 eq. 7 driven by the tick's mean command
  ``(v, omega, dt)``; ``P <- A P A^T + W Q W^T`` (seed 000 eq. 9, with ``A`` the Jacobian of
  eq. 11 and ``W`` the one with respect to the travelled distance and turn; ``Q`` from
  :class:`~swarmloc.agents.replay.localizers.MotionNoise`), see
  :func:`~swarmloc.agents.replay.localizers.propagate`.
- **Landmark update** (:func:`range_bearing_update`): the readings of one tick stacked into one
  update, ``h(x) = (|l - p|, atan2(l_y - y, l_x - x) - theta)`` with ``H`` its Jacobian,
  ``S = H P H^T + R``, ``K = P H^T S^-1``, Joseph-form covariance update (Probabilistic Robotics
  table 7.2, EKF localization with known correspondences, all readings of a tick at once). A
  reading whose own Mahalanobis distance ``nu^T S_k^-1 nu`` exceeds ``gate_chi2`` (chi-square, 2
  degrees of freedom; default 99.9 %) is discarded as an outlier (MRCLAM has misread barcodes and
  about 2 % of ranges off by more than 0.5 m).
- **Odometry self-calibration** (``odometry_calibration``, off by default; issue 19): MRCLAM's
  odometry is the velocity *command*, and the robots do not do what they are told: on Dataset 6
  they turn about 0.75 (robot 5: 0.9) of the commanded turn and drive about 0.9 of the
  commanded distance, a systematic error that a white motion noise cannot model and that makes
  the pose drift in the 20-50 s gaps without landmark readings. The state is augmented with a
  speed scale ``k_v``, a turn scale ``k_w`` and a turn-rate offset ``b_w`` (the robot moves
  ``k_v v dt`` and turns ``(k_w omega + b_w) dt``), estimated by the same filter from the
  landmark readings (online odometry calibration, as in A. Martinelli, "The odometry error of
  a mobile robot with a synchronous drive system", IEEE T-RO 18(3), 2002, and "Simultaneous
  localization and odometry self-calibration for mobile robot", Autonomous Robots 22, 2007:
  the augmented EKF). Prior: no error (1, 1, 0) with stds ``odometry_prior_std``; a random
  walk of ``odometry_drift_std`` per square-root second keeps them able to follow a slow
  change. Ground truth is not used: only the readings. Our choice (the seeds do not calibrate
  odometry); the motion noise is unchanged. The teammates see the pose block only. Measured on
  Dataset 6 (cooperative, self-calibrated camera, seed 0): with these priors no gain (mean
  0.100 m against 0.099 m), and none either with the scales held at the Vicon regression's
  values (0.099 m): the ratio of true to commanded turn is not a constant (about 0.7 while
  driving at 0.07 m/s and turning, about 1.0 while creeping; see ``docs/mrclam/README.md``).
  The speed scale alone (``odometry_prior_std = (0.1, 0, 0)``: the turn scale and offset held)
  does help: mean 0.178 -> 0.158 m alone, 0.099 -> 0.092 m cooperative (worst robot 0.117 ->
  0.112 m). It is part of the hybrid's tracking default (:mod:`swarmloc.agents.replay.hybrid`); the
  ``ekf`` algorithm stays the literature's filter, commands as odometry, by default. The offset
  acts only while the command moves the robot: told to stand still, it stands still (Vicon).
- **Command classes and lag** (``odometry_turn_class_rad_s``, ``odometry_lag_s``; both off by
  default): against Vicon, Dataset 6's robots drive 1.00-1.03x the commanded speed straight
  ahead but 0.65-0.71x while turning, about 0.2 s after the command
  (``deploy/lab/replay/motion_bound.py``). With ``odometry_turn_class_rad_s > 0`` the state
  holds one ``(k_v, k_w, b_w)`` per command class (:func:`command_class`: turning slower than
  the threshold, left, right), each with the prior and random walk above; with
  ``odometry_lag_s`` a command moves the robot that long after it is given. Measured with the
  hybrid, cooperative, Dataset 6, before its teammate floor after a handover (known start,
  position RMSE robots 1-5; unknown start, seeds 0-19, 180 s: robot-seeds under 0.3 m within
  60 s and staying, and seeds with every robot):
  its default 0.075 / 0.087 / 0.099 / 0.110 / 0.079 m, 94/100, 14/20; lag 0.2 s 0.072 / 0.083 /
  0.085 / 0.116 / 0.079, 89, 14; lag and a speed scale per class (prior stds ``(0.2, 0, 0)``,
  threshold 0.1 rad/s) 0.070 / 0.077 / 0.069 / 0.134 / 0.071, 90, 13; lag and the whole set
  per class ``(0.2, 0.3, 0.03)`` 0.068 / 0.088 / 0.074 / 0.122 / 0.070, 82, 5. Better on four
  robots, worse on robot 4, whose 60 s without readings is the issue's binding case, and worse
  from an unknown start (a fresh handover has more to learn), so neither is a default. The
  class model fitted against Vicon on the 280 s before that gap leaves robot 4 at 0.118 m
  (``motion_bound --fit-s 280``): a better learner of this model would not do better.
- **Cooperative** (``setup.cooperative``): each robot broadcasts a
  :class:`~swarmloc.agents.replay.localizers.TeammateReport` (pose, covariance, the teammates it
  measured). With ``fusion="relative"`` a reading between this robot and teammate ``j``
  (:func:`~swarmloc.agents.replay.localizers.relative_readings`, at most one per teammate and
  tick) is an EKF update in which the teammate's position is an uncertain landmark:
  ``S = H P H^T + H_j P_j H_j^T + R`` (this robot measured ``j``), or, when ``j`` measured this
  robot, a position fix ``p_j + r (cos, sin)(theta_j + b)`` with covariance through ``P_j``
  (:func:`position_update`). This is the decentralised "pose and covariance exchange" scheme; it
  ignores the correlation between the two estimates (built up by earlier exchanges), so a
  teammate's covariance is inflated by ``teammate_inflation`` and, with ``only_from_better``, only
  teammates whose position is more certain than this robot's are used (the better-localised
  robot helps the worse, never the other way round, which keeps the exchange from feeding a
  robot's own information back to it). ``teammate_floor_std_m`` adds a floor to the teammate's
  position variance (0 by default): the tracking filters are overconfident on MRCLAM (the
  hybrid's EKF stage, seed 0 known start: mean position NEES 10-30 per robot where a consistent
  filter has 2; seed 6 unknown start: 6-73), most of all just after a handover, and a teammate
  0.15 m off with a 0.02 m std drags this robot along (robot 2, seed 6, 23-70 s: teammates 4
  and 5). A scale does not reach such stds (inflation 3: 93 robot-seeds of 100, unknown start);
  a floor does: with the hybrid, cooperative (before its own floor after a handover,
  :mod:`swarmloc.agents.replay.hybrid`), 0.05 / 0.1 / 0.15 / 0.2 m give 94 / 95 / 95 / 95
  robot-seeds and every robot in 15 / 17 / 16 / 17 of 20 seeds (default: 94, 14), but from the
  known start robot 4 rises from 0.110 to 0.130 / 0.139 m (0.05 / 0.1 m) and the RMSE after
  localizing grows (robot 2 0.119 -> 0.128 m at 0.1 m): not made default. With
  ``fusion="sgikf"`` the reading becomes a position fix
  fused by social odometry's SGIKF (seed 000 eq. 18-22,
  :func:`~swarmloc.agents.replay.localizers.sgikf_fuse`). With ``fusion="ci"`` (the algorithm
  ``ekf-ci``: a covariance-intersection version of this cooperative EKF, after CoLo-AT's
  local-state covariance intersection, issue 46; the paper's LS-CI itself is ``ls-ci``,
  :mod:`swarmloc.agents.replay.colo`) the teammate's
  estimate and the reading give a fix of this robot's position, fused by covariance
  intersection instead of a Kalman update: correct whatever the unknown correlation between the
  two estimates (S. J. Julier and J. K. Uhlmann, "A non-divergent estimation algorithm in the
  presence of unknown correlations", ACC 1997; for cooperative localization, L. C. Carrillo-Arce,
  E. D. Nerurkar, J. L. Gordillo and S. I. Roumeliotis, "Decentralized multi-robot cooperative
  localization using covariance intersection", IROS 2013). CI fuses the position block
  (:func:`ci_position_update`, ``w`` chosen to minimise the fused trace) and the rest of the
  state follows by conditioning: no inflation or "only from better" guard is needed, so
  ``teammate_inflation`` does not apply (the floor does). Ours: a position fix, as the EKF's
  other teammate updates are; the papers' LS-CI fuses the teammate's whole relative pose.
  Measured on Dataset 6, the first 600 s, seed 0, self-calibrated cameras (``swarmloc mrclam
  DATA --algorithm ekf-ci --cooperative --duration-s 600``): mean position RMSE 0.104 m
  (robots 0.084 / 0.092 / 0.097 / 0.130 / 0.116), against 0.085 m for ``ekf`` cooperative
  (relative updates, teammates inflated 2x) and 0.183 m alone: CI pays for its guarantee
  with part of the gain. It is the more consistent (first 120 s, position NEES mean per robot,
  2 if consistent, ``consistency`` in deploy/lab/replay/mrclam.py): ekf-ci 1.0 / 4.6 / 4.1 /
  9.0 / 52.5 against ekf's 3.3 / 6.6 / 14.3 / 33.1 / 117.9; robot 5's overconfidence is its own
  landmark updates', not the teammates'.

Pure: no clock, no randomness (the EKF draws nothing; the generator is accepted for the common
builder signature).
"""

from __future__ import annotations

import math
from collections import deque
from dataclasses import dataclass, replace

import numpy as np

from swarmloc.agents.replay.localizers import (
    LandmarkSetup,
    TeammateReport,
    _real,
    calibrated,
    check_observation,
    decode_received,
    position_fix,
    propagate,
    relative_readings,
    sgikf_fuse,
    spectral_norm_xy,
    wrap_angle,
)
from swarmloc.world.replay.replay import LandmarkObservation

#: chi-square quantile, 2 degrees of freedom, 99.9 %.
CHI2_2DOF_999 = 13.815510557964274

#: chi-square 95 % quantile, 2 degrees of freedom (a reading's NIS band).
CHI2_2DOF_95 = 5.991464547107979


@dataclass
class NisTally:
    """The normalized innovation squared ``nu^T S^-1 nu`` of a kind of update (2 degrees of
    freedom: 2 on average for a consistent filter, inside :data:`CHI2_2DOF_95` 95 % of the time;
    for a CI fusion, of the fix against ``P + R``, which assumes no correlation), every reading
    counted, gated out or not."""

    count: int = 0
    total: float = 0.0
    inside_95: int = 0

    def add(self, value: float) -> None:
        self.count += 1
        self.total += value
        self.inside_95 += int(value <= CHI2_2DOF_95)

    def scores(self, kind: str) -> dict[str, float]:
        n = self.count
        return {f"{kind}_nis_mean": self.total / n if n else math.nan,
                f"{kind}_nis_in_95": self.inside_95 / n if n else math.nan,
                f"{kind}_nis_count": float(n)}


FUSIONS = ("relative", "sgikf", "ci")


@dataclass(frozen=True)
class EkfParams:
    """EKF parameters (see the module docstring)."""

    gate_chi2: float = CHI2_2DOF_999
    fusion: str = "relative"
    teammate_inflation: float = 2.0
    #: Added to a teammate's position std before its reading is fused [m] (0: none; see the
    #: module docstring).
    teammate_floor_std_m: float = 0.0
    only_from_better: bool = False
    #: Broadcast the estimate after the teammate updates of the tick (True) or before them
    #: (False: a teammate never receives back, one tick later, what it just sent).
    share_fused: bool = False
    #: Estimate the odometry's speed scale, turn scale and turn offset in the state (see the
    #: module docstring).
    odometry_calibration: bool = False
    #: Prior stds of ``(k_v, k_w, b_w [rad/s])``, and their random walk per sqrt(second).
    odometry_prior_std: tuple[float, float, float] = (0.2, 0.3, 0.03)
    odometry_drift_std: tuple[float, float, float] = (1e-3, 1e-3, 1e-4)
    #: 0: one ``(k_v, k_w, b_w)`` for every command; above 0, one for each of three command
    #: classes: turning slower than this [rad/s] (driving straight, or standing), turning left,
    #: turning right (see the module docstring).
    odometry_turn_class_rad_s: float = 0.0
    #: The robot carries out a command this long after it is given [s] (0: at once; rounded to
    #: whole ticks).
    odometry_lag_s: float = 0.0

    def __post_init__(self):
        _real(self.gate_chi2, "gate_chi2", positive=True)
        _real(self.teammate_inflation, "teammate_inflation", positive=True)
        _real(self.odometry_turn_class_rad_s, "odometry_turn_class_rad_s")
        _real(self.teammate_floor_std_m, "teammate_floor_std_m")
        _real(self.odometry_lag_s, "odometry_lag_s")
        if self.fusion not in FUSIONS:
            raise ValueError(f"fusion: expected one of {FUSIONS}, got {self.fusion!r}")
        for name in ("odometry_prior_std", "odometry_drift_std"):
            value = getattr(self, name)
            if not isinstance(value, (tuple, list)) or len(value) != 3:
                raise ValueError(f"{name} must be 3 numbers (speed scale, turn scale, turn "
                                 f"offset), got {value!r}")
            for k, v in enumerate(value):
                _real(v, f"{name}[{k}]")
        for name in ("only_from_better", "share_fused", "odometry_calibration"):
            if not isinstance(getattr(self, name), bool):
                raise TypeError(f"{name} must be true or false, got {getattr(self, name)!r}")


def range_bearing_update(pose: np.ndarray, cov: np.ndarray, targets_xy: np.ndarray,
                         range_m: np.ndarray, bearing_rad: np.ndarray, range_std_m: np.ndarray,
                         bearing_std_rad: float, gate_chi2: float,
                         targets_cov: np.ndarray | None = None, nis: NisTally | None = None):
    """EKF update with ``K`` range-and-bearing readings of targets ``(K, 2)`` (landmarks, or
    teammates with position covariances ``targets_cov (K, 2, 2)``). Returns ``(pose, cov,
    accepted (K,) bool)``; readings beyond the gate are left out."""
    dx = targets_xy[:, 0] - pose[0]
    dy = targets_xy[:, 1] - pose[1]
    q = np.maximum(dx * dx + dy * dy, 1e-12)
    r = np.sqrt(q)
    k = targets_xy.shape[0]
    n_state = pose.shape[0]  # the pose first, then any further state (odometry calibration)
    h = np.zeros((k, 2, n_state))
    h[:, 0, 0], h[:, 0, 1] = -dx / r, -dy / r
    h[:, 1, 0], h[:, 1, 1], h[:, 1, 2] = dy / q, -dx / q, -1.0
    nu = np.column_stack([range_m - r, wrap_angle(bearing_rad - (np.arctan2(dy, dx) - pose[2]))])
    noise = np.zeros((k, 2, 2))
    noise[:, 0, 0] = np.square(range_std_m)
    noise[:, 1, 1] = bearing_std_rad**2
    if targets_cov is not None:
        ht = -h[:, :, :2]
        noise = noise + ht @ targets_cov @ ht.transpose(0, 2, 1)
    s_each = h @ cov @ h.transpose(0, 2, 1) + noise
    d2 = np.einsum("ki,kij,kj->k", nu, np.linalg.inv(s_each), nu)
    if nis is not None:  # every reading, gated out or not
        for value in d2.tolist():
            nis.add(value)
    accepted = d2 < gate_chi2
    if not accepted.any():
        return pose, cov, accepted
    hs = h[accepted].reshape(-1, n_state)
    n = hs.shape[0]
    r_big = np.zeros((n, n))
    blocks = noise[accepted]
    for i in range(0, n, 2):  # block diagonal: one 2 x 2 block per accepted reading
        r_big[i:i + 2, i:i + 2] = blocks[i // 2]
    s = hs @ cov @ hs.T + r_big
    gain = np.linalg.solve(s, hs @ cov).T  # P H^T S^-1 (S and P symmetric)
    new = pose + gain @ nu[accepted].reshape(-1)
    new[2] = wrap_angle(new[2])
    i_kh = np.eye(n_state) - gain @ hs
    new_cov = i_kh @ cov @ i_kh.T + gain @ r_big @ gain.T
    return new, 0.5 * (new_cov + new_cov.T), accepted


def command_class(omega_rad_s: float, turn_class_rad_s: float) -> int:
    """The odometry calibration's parameter set for a command: 0 with one set
    (``turn_class_rad_s == 0``) or a turn slower than ``turn_class_rad_s``, 1 turning left, 2
    turning right."""
    if turn_class_rad_s <= 0.0 or abs(omega_rad_s) < turn_class_rad_s:
        return 0
    return 1 if omega_rad_s > 0.0 else 2


def propagate_calibrated(state: np.ndarray, cov: np.ndarray, v_mps: float, omega_rad_s: float,
                         dt_s: float, motion, drift_std, turn_class_rad_s: float = 0.0
                         ) -> tuple[np.ndarray, np.ndarray]:
    """One tick of the unicycle for the augmented state ``(x, y, theta, k_v, k_w, b_w, ...)``
    (one ``(k_v, k_w, b_w)`` per command class, :func:`command_class`): the robot moves
    ``d = k_v v dt`` and turns ``phi = (k_w omega + b_w) dt`` with the command's class's set
    (seed 000 eq. 7 with the calibrated command), ``P <- A P A^T + W Q W^T + D`` with ``A`` the
    Jacobian in the whole state, ``Q`` the motion noise of the calibrated command and ``D`` the
    parameters' random walk (``drift_std`` per sqrt(second), every set)."""
    j = 3 + 3 * command_class(omega_rad_s, turn_class_rad_s)
    k_v, k_w, b_w = state[j], state[j + 1], state[j + 2]
    u_d, u_t = v_mps * dt_s, omega_rad_s * dt_s
    # A robot told to stand still stands still (Vicon, Dataset 6): the offset acts only while
    # the command moves it.
    u_b = dt_s if (v_mps != 0.0 or omega_rad_s != 0.0) else 0.0
    d, turn = k_v * u_d, k_w * u_t + b_w * u_b
    mid = state[2] + 0.5 * turn
    c, s = math.cos(mid), math.sin(mid)
    new = state.copy()
    new[0] += d * c
    new[1] += d * s
    new[2] = (state[2] + turn + math.pi) % (2.0 * math.pi) - math.pi
    n = state.shape[0]
    a = np.eye(n)
    a[0, 2], a[1, 2] = -d * s, d * c
    a[0, j], a[1, j] = u_d * c, u_d * s  # d/dk_v
    a[0, j + 1], a[1, j + 1], a[2, j + 1] = -0.5 * d * s * u_t, 0.5 * d * c * u_t, u_t  # d/dk_w
    a[0, j + 2], a[1, j + 2], a[2, j + 2] = -0.5 * d * s * u_b, 0.5 * d * c * u_b, u_b
    std_d, std_t = motion.tick_std(d / dt_s, turn / dt_s, dt_s)
    w = np.zeros((n, 2))
    w[:3] = [[c, -0.5 * d * s], [s, 0.5 * d * c], [0.0, 1.0]]
    q = np.array([std_d * std_d, std_t * std_t])
    out = a @ cov @ a.T + (w * q) @ w.T
    out[3:, 3:] += np.diag(np.tile(np.square(drift_std), (n - 3) // 3) * dt_s)
    return new, out


def position_update(pose: np.ndarray, cov: np.ndarray, fix_xy: np.ndarray, fix_cov: np.ndarray,
                    gate_chi2: float, nis: NisTally | None = None):
    """EKF update with a direct position measurement ``fix_xy`` of covariance ``fix_cov``.
    Returns ``(pose, cov, accepted)``."""
    nu = fix_xy - pose[:2]
    s = cov[:2, :2] + fix_cov
    d2 = float(nu @ np.linalg.solve(s, nu))
    if nis is not None:
        nis.add(d2)
    if d2 >= gate_chi2:
        return pose, cov, False
    gain = np.linalg.solve(s, cov[:2, :]).T  # (n, 2)
    new = pose + gain @ nu
    new[2] = wrap_angle(new[2])
    n_state = pose.shape[0]
    hs = np.zeros((2, n_state))
    hs[0, 0] = hs[1, 1] = 1.0
    i_kh = np.eye(n_state) - gain @ hs
    new_cov = i_kh @ cov @ i_kh.T + gain @ fix_cov @ gain.T
    return new, 0.5 * (new_cov + new_cov.T), True


def ci_position_update(pose: np.ndarray, cov: np.ndarray, fix_xy: np.ndarray, fix_cov: np.ndarray,
                       gate_chi2: float, nis: NisTally | None = None):
    """Covariance intersection of this robot's position with a position fix of unknown
    correlation to it (Julier and Uhlmann), then the rest of the state by conditioning.

    The position block: ``P+^-1 = w P^-1 + (1 - w) R^-1``, ``p+ = P+ (w P^-1 p + (1 - w) R^-1 z)``,
    ``w`` in (0, 1) the one that minimises ``trace(P+)`` (bounded scalar search); the estimate is
    kept as it is (``w = 1``) if no ``w`` does better. The rest of the state (heading, odometry
    calibration) follows the position as the joint Gaussian says, ``x_r += G (p+ - p)``,
    ``P_rr -= G (P - P+) G^T``, ``P_rp = G P+`` with ``G = P_rp P^-1``: the CI update's usual
    form on the whole state (``cov / w``) would inflate the unobserved heading's variance by
    ``1 / w`` (tens of times; the test holds this form to it). The gate is the EKF's, on
    ``P + R``. Returns ``(pose, cov, accepted, w)``."""
    from scipy.optimize import minimize_scalar

    p, p_cov = pose[:2], cov[:2, :2]
    nu = fix_xy - p
    d2 = float(nu @ np.linalg.solve(p_cov + fix_cov, nu))
    if nis is not None:  # against P + R: as if uncorrelated (NisTally)
        nis.add(d2)
    if d2 >= gate_chi2:
        return pose, cov, False, 1.0
    info_own, info_fix = np.linalg.inv(p_cov), np.linalg.inv(fix_cov)

    def fused_cov(w: float) -> np.ndarray:
        return np.linalg.inv(w * info_own + (1.0 - w) * info_fix)

    best = minimize_scalar(lambda w: float(np.trace(fused_cov(w))), bounds=(1e-3, 1.0 - 1e-3),
                           method="bounded", options={"xatol": 1e-4})
    w = float(best.x)
    new_p_cov = fused_cov(w)
    if float(np.trace(new_p_cov)) >= float(np.trace(p_cov)):
        return pose, cov, True, 1.0
    new_p = new_p_cov @ (w * info_own @ p + (1.0 - w) * info_fix @ fix_xy)
    gain = cov[2:, :2] @ info_own  # G = P_rp P^-1
    new = pose.copy()
    new[:2] = new_p
    new[2:] = pose[2:] + gain @ (new_p - p)
    new[2] = wrap_angle(new[2])
    new_cov = cov.copy()
    new_cov[:2, :2] = new_p_cov
    new_cov[2:, :2] = gain @ new_p_cov
    new_cov[:2, 2:] = new_cov[2:, :2].T
    new_cov[2:, 2:] = cov[2:, 2:] - gain @ (p_cov - new_p_cov) @ gain.T
    return new, 0.5 * (new_cov + new_cov.T), True, w


class EkfLocalizer:
    """EKF with known landmarks for one robot (a
    :class:`~swarmloc.agents.replay.localizers.LandmarkLocalizer`)."""

    def __init__(self, setup: LandmarkSetup, params: EkfParams | None = None,
                 rng: np.random.Generator | None = None):
        if not isinstance(setup, LandmarkSetup):
            raise TypeError(f"setup must be a LandmarkSetup, got {type(setup).__name__}")
        self.setup = setup
        self.params = EkfParams() if params is None else params
        self.pose = setup.initial_pose.copy()
        self.covariance = setup.initial_covariance()
        if self.params.odometry_calibration:  # the augmented state (see the module docstring)
            sets = 3 if self.params.odometry_turn_class_rad_s > 0.0 else 1
            self.pose = np.concatenate([self.pose, np.tile([1.0, 1.0, 0.0], sets)])
            cov = np.zeros((3 + 3 * sets, 3 + 3 * sets))
            cov[:3, :3] = self.covariance
            cov[3:, 3:] = np.diag(np.tile(np.square(self.params.odometry_prior_std), sets))
            self.covariance = cov
            self._drift_std = np.asarray(self.params.odometry_drift_std, dtype=np.float64)
        #: Payloads skipped at the last step: ``(sender_id, error)`` (the shell counts them).
        self.rejected: tuple[tuple[int, ValueError], ...] = ()
        self.landmark_updates = 0  #: readings accepted so far
        self.landmark_rejected = 0  #: readings gated out so far
        self.teammate_updates = 0
        #: The NIS of the landmark and teammate updates (issue 46; a hybrid shares its own).
        self.nis = {"landmark": NisTally(), "teammate": NisTally()}
        self._out: bytes | None = None
        self._commands: deque[tuple[float, float]] = deque()  # given, not yet carried out

    def step(self, obs: LandmarkObservation) -> None:
        setup, params = self.setup, self.params
        check_observation(obs, setup.robot_id)
        obs = calibrated(obs, setup.camera)
        v_mps, omega_rad_s = obs.odometry_v_mps, obs.odometry_omega_rad_s
        if params.odometry_lag_s > 0.0:
            self._commands.append((v_mps, omega_rad_s))
            if len(self._commands) > round(params.odometry_lag_s / obs.odometry_dt_s):
                v_mps, omega_rad_s = self._commands.popleft()
            else:
                v_mps, omega_rad_s = 0.0, 0.0
        if params.odometry_calibration:
            self.pose, self.covariance = propagate_calibrated(
                self.pose, self.covariance, v_mps, omega_rad_s, obs.odometry_dt_s, setup.motion,
                self._drift_std, params.odometry_turn_class_rad_s)
        else:
            self.pose, self.covariance = propagate(self.pose, self.covariance, v_mps,
                                                   omega_rad_s, obs.odometry_dt_s, setup.motion)
        if obs.landmark_ids.size:
            xy, known = setup.landmark_positions(obs.landmark_ids)
            if known.any():
                rng_m = obs.landmark_range_m[known]
                self.pose, self.covariance, ok = range_bearing_update(
                    self.pose, self.covariance, xy[known], rng_m, obs.landmark_bearing_rad[known],
                    setup.camera.range_std(rng_m), setup.camera.bearing_std_rad, params.gate_chi2,
                    nis=self.nis["landmark"])
                self.landmark_updates += int(ok.sum())
                self.landmark_rejected += int((~ok).sum())
        if not setup.cooperative:
            return
        reports, rejected = decode_received(obs.received, setup.robot_id, obs.robot_ids)
        self.rejected = tuple(rejected)
        shared_pose, shared_cov = self.pose[:3].copy(), self.covariance[:3, :3].copy()
        for reading in relative_readings(obs, reports, setup.robot_id):
            self._fuse(reading)
        if params.share_fused:
            shared_pose, shared_cov = self.pose[:3], self.covariance[:3, :3]
        self._out = TeammateReport.build(setup.robot_id, obs.tick, shared_pose, shared_cov,
                                         obs).encode()

    def _fuse(self, reading) -> None:
        params, camera = self.params, self.setup.camera
        rep = reading.report
        teammate_cov = rep.covariance * params.teammate_inflation
        if params.teammate_floor_std_m:
            teammate_cov = teammate_cov + np.diag([params.teammate_floor_std_m**2] * 2 + [0.0])
        if params.only_from_better and spectral_norm_xy(teammate_cov) >= \
                spectral_norm_xy(self.covariance):
            return
        if params.fusion == "ci":  # no inflation: CI is consistent for any correlation
            floored = rep.covariance
            if params.teammate_floor_std_m:
                floored = floored + np.diag([params.teammate_floor_std_m**2] * 2 + [0.0])
            xy, cov = position_fix(replace(reading, report=replace(rep, covariance=floored)), self.pose[2],
                                   self.covariance[2, 2], self.setup.camera)
            self.pose, self.covariance, accepted, _ = ci_position_update(
                self.pose, self.covariance, xy, cov, params.gate_chi2, nis=self.nis["teammate"])
            self.teammate_updates += int(accepted)
            return
        inflated = replace(reading, report=replace(rep, covariance=teammate_cov))
        if params.fusion == "sgikf":
            xy, cov = position_fix(inflated, self.pose[2], self.covariance[2, 2], camera)
            # SGIKF scales the pose block; the odometry calibration is left as it is.
            pose, pose_cov, _ = sgikf_fuse(self.pose[:3], self.covariance[:3, :3], xy, cov)
            self.pose = np.concatenate([pose, self.pose[3:]])
            self.covariance = self.covariance.copy()
            self.covariance[:3, :3] = pose_cov
            self.teammate_updates += 1
            return
        if reading.observer:
            self.pose, self.covariance, ok = range_bearing_update(
                self.pose, self.covariance, rep.pose[None, :2], np.array([reading.range_m]),
                np.array([reading.bearing_rad]), camera.range_std(np.array([reading.range_m])),
                camera.bearing_std_rad, params.gate_chi2, targets_cov=teammate_cov[None, :2, :2],
                nis=self.nis["teammate"])
            accepted = bool(ok[0])
        else:
            xy, cov = position_fix(inflated, self.pose[2], self.covariance[2, 2], camera)
            self.pose, self.covariance, accepted = position_update(
                self.pose, self.covariance, xy, cov, params.gate_chi2, nis=self.nis["teammate"])
        self.teammate_updates += int(accepted)

    def estimate(self) -> np.ndarray:
        return self.pose[:3].copy()

    def covariance_xy(self) -> np.ndarray:
        """The estimate's position covariance (2 x 2): what the consistency scores read."""
        return self.covariance[:2, :2].copy()

    def nis_scores(self) -> dict[str, float]:
        """Mean NIS, share inside the 95 % band and count, of landmark and teammate updates
        (SGIKF fusions, which have no innovation test, are not counted)."""
        return {**self.nis["landmark"].scores("landmark"), **self.nis["teammate"].scores("teammate")}

    def heading_variance(self) -> float:
        """The heading's variance [rad^2]: the heading NEES reads it (issue 46)."""
        return float(self.covariance[2, 2])

    @property
    def odometry_calibration(self) -> tuple[tuple[float, float, float], ...]:
        """The estimated ``(k_v, k_w, b_w)`` of each command class (``((1, 1, 0),)`` when not
        estimated)."""
        if self.pose.size == 3:
            return ((1.0, 1.0, 0.0),)
        return tuple(tuple(map(float, self.pose[j:j + 3])) for j in range(3, self.pose.size, 3))

    def outgoing(self) -> bytes | None:
        return self._out

