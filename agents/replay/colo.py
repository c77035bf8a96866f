"""CoLo-AT's cooperative-localization estimators as landmark localizers (issue 46).

CoLo-AT (UCLA LEMUR, ``William-SKC/LEMUR-CoLo-Copy``, folder ``CoLo-AT/``) compares five
estimators on MRCLAM. Each is implemented here from its paper (CoLo-AT's code was read for its
setting and noise model, not copied), on one set of pure functions over a stacked state
(:class:`Joint`), and registered in the replay family's registry:

- ``ls-cen``: the centralized EKF over every robot's pose, the optimal reference. S. I.
  Roumeliotis and G. A. Bekey, "Distributed multirobot localization", IEEE T-RA 18(5), 2002:
  propagation eq. (5)-(8) (each robot's block moves with its own odometry, the cross-covariances
  ``P_ij <- Phi_i P_ij``), relative position measurement ``z = C(theta_i)^T (p_j - p_i) + n``
  (their eq. (18)-(20)) and the stacked EKF update (eq. (21)-(24)); landmark readings are the
  same measurement with a known ``p_j``.
- ``ls-bda``: the same filter with the block-diagonal approximation of the cross-covariances
  of L. Luft, T. Schubert, S. I. Roumeliotis and W. Burgard, "Recursive decentralized
  localization for multi-robot systems with asynchronous pairwise communication", IJRR 37(10),
  2018: a private (landmark) update changes only robot ``i``'s block and multiplies its
  cross-covariances by ``Sigma_ii^+ (Sigma_ii^-)^-1`` (= ``I - K H``); a relative update between
  ``i`` and ``j`` is the exact EKF on the pair's joint block, then every ``Sigma_ik`` and
  ``Sigma_jk`` (``k`` a third robot) is multiplied by the same factor of ``i`` (``j``) (Luft et al.
  §4, the approximation of the unknown cross-correlation update; the other robots' estimates are
  not corrected). CoLo-AT runs it as one centralized process too.
- ``ls-ci``: local-state covariance intersection, L. C. Carrillo-Arce, E. D. Nerurkar, J. L.
  Gordillo and S. I. Roumeliotis, "Decentralized multi-robot cooperative localization using
  covariance intersection", IROS 2013: each robot keeps its own pose only; when robot ``i``
  measures robot ``j``, ``j`` receives ``i``'s estimate and the reading, forms the estimate of
  its own position ``p_i + C(theta_i) z`` (covariance ``J P_i J^T + C R C^T``) and fuses it with
  its own by covariance intersection (S. J. Julier and J. K. Uhlmann, ACC 1997: ``P^-1 = w P_1^-1
  + (1 - w) P_2^-1``, ``w`` minimising the trace). Only the observed robot fuses (the paper's
  reading); the heading, when estimated, follows the position by conditioning
  (:func:`ci_fuse`). CoLo-AT's LS-CI leaves the reading ``z`` in the observer's frame (no
  ``C(theta_i)``) and drops the reading's and the observer's covariance for a fixed ``w = 0.5``
  of ``P_i``: here the reading is rotated into the world frame.
- ``gs-ci``: global-state covariance intersection, T.-K. Chang, S. Chen and A. Mehta,
  "Multirobot cooperative localization algorithm with explicit communication and its topology
  analysis", ISRR 2017: each robot keeps the whole team's state; its own readings (landmark and
  relative) are EKF updates of that global state, the teammates' blocks it cannot see move as a
  random walk (``teammate_speed_std_mps``, ``teammate_turn_std_rad_s``: the paper leaves the
  teammates' motion model open; CoLo-AT moves them at 0.25 m/s along their true heading), and a
  teammate's global state received over a link is fused by CI over the whole state (a robot the
  teammate does not hold enters the fusion with a std of :data:`UNKNOWN_STD_M`, so it is all but
  left as it is; a robot only the teammate holds joins first). As in CoLo-AT, a robot fuses what
  it hears when it takes a measurement (its camera frames), not at every tick; here just before
  the measurement is applied, so that a relative reading meets fresh teammate blocks. One weight
  for the whole state (the paper's) cannot take each teammate's best block: consistent, but the
  robot without landmarks gains little (tests/test_colo.py).
- ``gs-sci``: the same with split covariance intersection (H. Li and F. Nashashibi,
  "Cooperative multi-vehicle localization using split covariance intersection filter", IEEE ITS
  Magazine 5(2), 2013; for CL, T. R. Wanasinghe, G. K. I. Mann and R. G. Gosine, "Decentralized
  cooperative localization for heterogeneous multi-robot system using split covariance
  intersection filter", CRV 2014): the covariance is split into an independent part ``P_i`` (the
  process and measurement noise a robot adds itself) and a dependent part ``P_d = P - P_i``;
  EKF updates keep ``P_i <- (I - K H) P_i (I - K H)^T + K R K^T``; a fusion uses ``P_1 = P_d1 / w +
  P_i1``, ``P_2 = P_d2 / (1 - w) + P_i2``, ``K = P_1 (P_1 + P_2)^-1``, ``P = (I - K) P_1``,
  ``P_i = (I - K) P_i1 (I - K)^T + K P_i2 K^T``. CoLo-AT's GS-SCI relative update ignores the reading
  (it moves ``p_i`` towards ``p_j``'s estimate) and writes ``-K P_1`` (a negative block) into the
  covariance; here the reading is the EKF update of the global state and no block is negated.
  What counts as independent is the choice the papers leave open in a team: Li and Nashashibi's
  recursion (``sci_independent = "paper"``) keeps the teammate's independent part as
  independent after a fusion, and in a team that broadcasts its state every tick this counts the
  same noise again and again (position NEES 22-90 on the synthetic team of the tests, 2 if
  consistent). The default (``"since-broadcast"``) counts as independent only what a robot added
  since its last broadcast (the part is zeroed at each): consistent, and with a broadcast every
  tick almost nothing is independent, so GS-SCI comes out as GS-CI.

**One process per robot.** The centralized filter (``ls-cen``, and ``ls-bda`` which CoLo-AT
also runs centrally) is run as **replicas**: every robot broadcasts, each tick, its odometry (and
its true heading when the setting gives it) and its readings (landmarks in the report's
``extra``, teammates in its ``seen``), and every robot runs the same joint filter over the
team's events of the previous tick (the medium delivers a tick's payloads at the next), in the
same order (all propagations, then landmark readings by robot id, then relative readings by
robot id), so that every replica holds the same joint estimate one tick behind; its own block is
then brought to the present with its own events of this tick on a copy (a look-ahead) and
reported. A teammate joins a replica with the estimate of its first report (uncorrelated), and
its events count from then on; a tick whose payload is missing moves the teammate as a random
walk (``teammate_speed_std_mps``). Replicas stay identical as long as the medium loses nothing
(the replay world's does not); the price is that every robot runs the whole team's filter.

**State.** CoLo-AT's state is ``(x, y)`` per robot with the heading taken from the ground truth
(``heading = "truth"`` in the replay's settings: the observation carries
``true_heading_rad``, used in propagation at the mid-tick heading and in the measurement model).
Otherwise (``heading = "estimate"``, swarmloc's own setting) the state is ``(x, y, theta)`` per
robot, propagated by the unicycle of seed 000 eq. 7 with the Jacobians of
:func:`swarmloc.agents.replay.localizers.propagate`, and the measurement Jacobian has the
observer's heading column (``d C^T / d theta (p_j - p_i)``).

**Noise models** (``noise_model``): ``swarmloc`` (the replay family's :class:`MotionNoise` and
:class:`CameraNoise`, self-calibrated or not), ``colo`` (CoLo-AT's numbers,
``robots/robot_system.py``: odometry variances 0.01 along and 0.1 across the heading, the latter
times ``v^2`` as its LS-BDA, GS-CI and GS-SCI have it; camera range variance 0.015 m^2 and
bearing variance 0.01 rad^2, times ``r^2`` across), and ``colo-unscaled`` (its LS-Cen: neither
``v^2`` nor ``r^2``, so 0.1 and 0.01 act as m^2/s^2 and m^2). CoLo-AT adds ``var dt^2`` per
odometry message of ``dt``; MRCLAM's odometry comes at 67 Hz, so here a tick of ``dt`` adds ``var
dt 0.015 s`` (:data:`COLO_ODOMETRY_PERIOD_S`): the same growth per second whatever the tick.
Measurements are the relative position in the observer's frame, ``R = Rot(b) diag(var_r,
var_across) Rot(b)^T`` (CoLo-AT's form; the first-order form of the range-bearing noise).

Readings are gated by the innovation's Mahalanobis distance (``gate_chi2``, chi-square 2 d.o.f.
99.9 %, as the ``ekf``; CoLo-AT has no gate: ``gate_chi2 = 1e9`` turns it off). Every estimator
counts the NIS of its robot's own landmark and teammate updates (:class:`NisTally`,
``nis_scores()``), and ``motion_noise_scale`` / ``reading_noise_scale`` multiply the noise
models' covariances: on MRCLAM, whose odometry is the command and whose errors are systematic,
every filter here is overconfident as it stands (``docs/mrclam/colo.md``: LS-Cen is consistent
with both times 6 and the gate divided by 6).

Pure: no clock, no randomness (the generator is accepted for the common builder signature).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgpack
import numpy as np

from swarmloc.agents.replay.ekf import CHI2_2DOF_999, NisTally
from swarmloc.agents.replay.localizers import (
    MAX_REPORT_SIGHTINGS,
    LandmarkSetup,
    TeammateReport,
    _real,
    calibrated,
    check_observation,
    decode_received,
    wrap_angle,
)
from swarmloc.world.replay.replay import LandmarkObservation

NOISE_MODELS = ("swarmloc", "colo", "colo-unscaled")
ODOMETRY_NOISE = ("per-tick", "per-message")
SCI_INDEPENDENT = ("since-broadcast", "paper")
#: CoLo-AT's odometry variances along and across the heading (``robots/robot_system.py``).
COLO_ODOMETRY_VAR = (0.01, 0.1)
#: CoLo-AT's camera variances: range [m^2], bearing [rad^2] (across: times ``r^2``).
COLO_CAMERA_VAR = (0.015, 0.01)
#: MRCLAM's odometry period (67 Hz), to which CoLo-AT's per-message ``var dt^2`` refers.
COLO_ODOMETRY_PERIOD_S = 0.015
#: The algorithms of this module.
COLO_ALGORITHMS = ("ls-cen", "ls-bda", "ls-ci", "gs-ci", "gs-sci")
_MAX_TEAM = 32


@dataclass(frozen=True)
class ColoParams:
    """Parameters of CoLo's estimators (see the module docstring)."""

    noise_model: str = "swarmloc"
    #: Covariance intersection weight: 0 chooses it to minimise the fused trace (Julier and
    #: Uhlmann); a value in (0, 1) fixes it (CoLo-AT: 0.5 for LS-CI, 0.8 for GS-CI and GS-SCI).
    ci_weight: float = 0.0
    #: A teammate's motion where its odometry is not known (GS's teammates, a replica's missing
    #: payload): a random walk whose variance grows by ``std^2 * 1 s`` per second
    #: (:func:`random_walk`), position and heading.
    teammate_speed_std_mps: float = 0.1
    teammate_turn_std_rad_s: float = 0.3
    gate_chi2: float = CHI2_2DOF_999
    #: GS-SCI's independent part: ``since-broadcast`` (only the noise a robot added since it
    #: last broadcast its state counts as independent: the part is zeroed at each broadcast) or
    #: ``paper`` (Li and Nashashibi's recursion, never zeroed; see the module docstring).
    sci_independent: str = "since-broadcast"
    #: Multipliers of the motion noise's and the readings' covariances (1: the noise model as it
    #: is): what a filter needs to be consistent on data whose errors are not its model's
    #: (MRCLAM's odometry is the command, its errors systematic; see docs/mrclam/colo.md).
    motion_noise_scale: float = 1.0
    reading_noise_scale: float = 1.0
    #: How a CoLo noise model's odometry covariance grows: ``per-tick`` (``var dt 0.015 s`` per
    #: tick of ``dt``: the same growth per second whatever the log's rhythm) or ``per-message``
    #: (CoLo-AT's: ``var dt_i^2`` for each odometry message ``i``, ``dt_i`` the time since the
    #: one before, so a gap in the log adds its square at once; the replay gives each tick's
    #: ``sum dt_i^2``). See the module docstring.
    odometry_noise: str = "per-tick"

    def __post_init__(self):
        _real(self.motion_noise_scale, "motion_noise_scale", positive=True)
        _real(self.reading_noise_scale, "reading_noise_scale", positive=True)
        if self.sci_independent not in SCI_INDEPENDENT:
            raise ValueError(f"sci_independent: expected one of {SCI_INDEPENDENT}, got "
                             f"{self.sci_independent!r}")
        if self.noise_model not in NOISE_MODELS:
            raise ValueError(f"noise_model: expected one of {NOISE_MODELS}, got {self.noise_model!r}")
        if self.odometry_noise not in ODOMETRY_NOISE:
            raise ValueError(f"odometry_noise: expected one of {ODOMETRY_NOISE}, got {self.odometry_noise!r}")
        if self.odometry_noise == "per-message" and self.noise_model == "swarmloc":
            raise ValueError("odometry_noise: 'per-message' is CoLo-AT's growth of its own noise "
                             "models ('colo', 'colo-unscaled'), not of 'swarmloc'")
        w = _real(self.ci_weight, "ci_weight")
        if not w < 1.0:
            raise ValueError(f"ci_weight must be 0 (chosen) or in (0, 1), got {self.ci_weight!r}")
        _real(self.teammate_speed_std_mps, "teammate_speed_std_mps")
        _real(self.teammate_turn_std_rad_s, "teammate_turn_std_rad_s")
        _real(self.gate_chi2, "gate_chi2", positive=True)


def rot(angle_rad: float) -> np.ndarray:
    c, s = math.cos(angle_rad), math.sin(angle_rad)
    return np.array([[c, -s], [s, c]])


# --------------------------------------------------------------------------------------------
# Noise
# --------------------------------------------------------------------------------------------


def motion_noise(setup: LandmarkSetup, model: str, v_mps: float, omega_rad_s: float, dt_s: float,
                 heading_mid_rad: float, d: int, gap2_s2: float | None = None) -> np.ndarray:
    """The covariance ``(d, d)`` one tick of odometry adds to a robot's block, in the world frame
    (position, then heading when ``d == 3``); a CoLo model's position part grows by ``var dt
    0.015 s``, or with ``gap2_s2`` (the tick's ``sum dt_i^2`` of odometry messages) by ``var
    gap2_s2`` as CoLo-AT's per-message propagation."""
    dist = v_mps * dt_s
    c, s = math.cos(heading_mid_rad), math.sin(heading_mid_rad)
    std_d, std_t = setup.motion.tick_std(v_mps, omega_rad_s, dt_s)
    if model == "swarmloc":
        w = np.array([[c, -0.5 * dist * s], [s, 0.5 * dist * c], [0.0, 1.0]])
        q = (w * np.array([std_d**2, std_t**2])) @ w.T
        return q[:d, :d]
    along, across = COLO_ODOMETRY_VAR
    if model == "colo":
        across = across * v_mps * v_mps
    g = rot(heading_mid_rad)
    out = np.zeros((d, d))
    growth = dt_s * COLO_ODOMETRY_PERIOD_S if gap2_s2 is None else gap2_s2
    out[:2, :2] = g @ np.diag([along, across]) @ g.T * growth
    if d == 3:
        out[2, 2] = std_t**2
    return out


def reading_noise(setup: LandmarkSetup, model: str, range_m: float, bearing_rad: float) -> np.ndarray:
    """``R`` (2 x 2) of a relative position reading ``r (cos b, sin b)`` in the observer's frame."""
    if model == "swarmloc":
        var_r = float(setup.camera.range_std(range_m)) ** 2
        var_a = (range_m * setup.camera.bearing_std_rad) ** 2
    else:
        var_r, var_a = COLO_CAMERA_VAR
        if model == "colo":
            var_a = var_a * range_m * range_m
    g = rot(bearing_rad)
    return g @ np.diag([var_r, var_a]) @ g.T


# --------------------------------------------------------------------------------------------
# The stacked state and its updates
# --------------------------------------------------------------------------------------------


class Joint:
    """Robots' stacked states: ``ids`` (N), per robot ``d`` numbers (``(x, y)`` with the
    heading given, or ``(x, y, theta)``), ``x`` (N d,), ``P`` (N d, N d); ``heading`` (N,) the
    given headings when ``d == 2``; ``Pi`` the independent part of ``P`` (split CI) or None."""

    def __init__(self, d: int, split: bool = False):
        self.d = d
        self.ids: list[int] = []
        self.x = np.zeros(0)
        self.P = np.zeros((0, 0))
        self.heading = np.zeros(0)
        self.Pi = np.zeros((0, 0)) if split else None

    def copy(self) -> Joint:
        out = Joint.__new__(Joint)
        out.d, out.ids, out.x, out.P = self.d, list(self.ids), self.x.copy(), self.P.copy()
        out.heading = self.heading.copy()
        out.Pi = None if self.Pi is None else self.Pi.copy()
        return out

    def index(self, rid: int) -> int | None:
        try:
            return self.ids.index(rid)
        except ValueError:
            return None

    def block(self, k: int) -> slice:
        return slice(k * self.d, (k + 1) * self.d)

    def add(self, rid: int, pose: np.ndarray, cov3: np.ndarray, cov_i: np.ndarray | None = None) -> None:
        """Append robot ``rid`` with pose ``(3,)`` and covariance ``(3, 3)``, uncorrelated."""
        d, n = self.d, self.x.size
        self.ids.append(int(rid))
        self.x = np.concatenate([self.x, pose[:d]])
        self.heading = np.append(self.heading, pose[2])
        self.P = _grow(self.P, cov3[:d, :d])
        if self.Pi is not None:
            self.Pi = _grow(self.Pi, (cov3 if cov_i is None else cov_i)[:d, :d])
        assert self.x.size == n + d

    def pose(self, k: int) -> np.ndarray:
        b = self.x[self.block(k)]
        return np.array([b[0], b[1], b[2] if self.d == 3 else self.heading[k]])

    def cov3(self, k: int) -> np.ndarray:
        out = np.zeros((3, 3))
        out[:self.d, :self.d] = self.P[self.block(k), self.block(k)]
        return out

    def theta(self, k: int) -> float:
        return float(self.x[k * 3 + 2]) if self.d == 3 else float(self.heading[k])


def _grow(m: np.ndarray, block: np.ndarray) -> np.ndarray:
    n, d = m.shape[0], block.shape[0]
    out = np.zeros((n + d, n + d))
    out[:n, :n] = m
    out[n:, n:] = block
    return out


def propagate_robot(joint: Joint, k: int, setup: LandmarkSetup, params: ColoParams,
                    ev: TickEvents) -> None:
    """Robot ``k``'s block moved by one tick of odometry ``ev`` (Roumeliotis and Bekey eq.
    (5)-(8): its cross-covariances follow ``Phi_k``); with the heading given, along the mid-tick
    true heading. The noise is ``params``' model, times its ``motion_noise_scale``."""
    model, scale = params.noise_model, params.motion_noise_scale
    v_mps, omega_rad_s, dt_s, true_heading_rad = ev.v_mps, ev.omega_rad_s, ev.dt_s, ev.true_heading_rad
    gap2 = None
    if params.odometry_noise == "per-message":
        gap2 = ev.gap2_s2
        if gap2 is None:
            raise ValueError("odometry_noise: 'per-message' needs the gaps of the odometry messages, "
                             "which this observation does not carry")
    d, sl = joint.d, joint.block(k)
    if d == 2:
        prev = joint.heading[k]
        end = prev if true_heading_rad is None else true_heading_rad
        mid = prev + 0.5 * float(wrap_angle(end - prev))
        joint.heading[k] = end
        dist = v_mps * dt_s
        joint.x[sl] += dist * np.array([math.cos(mid), math.sin(mid)])
        q = motion_noise(setup, model, v_mps, omega_rad_s, dt_s, mid, 2, gap2) * scale
        joint.P[sl, sl] += q
        if joint.Pi is not None:
            joint.Pi[sl, sl] += q
        return
    x, y, th = joint.x[sl]
    dist, turn = v_mps * dt_s, omega_rad_s * dt_s
    mid = th + 0.5 * turn
    c, s = math.cos(mid), math.sin(mid)
    joint.x[sl] = [x + dist * c, y + dist * s, float(wrap_angle(th + turn))]
    a = np.array([[1.0, 0.0, -dist * s], [0.0, 1.0, dist * c], [0.0, 0.0, 1.0]])
    q = motion_noise(setup, model, v_mps, omega_rad_s, dt_s, mid, 3, gap2) * scale
    for m in (joint.P, joint.Pi):
        if m is None:
            continue
        m[sl, :] = a @ m[sl, :]
        m[:, sl] = m[:, sl] @ a.T
        m[sl, sl] += q


def random_walk(joint: Joint, k: int, speed_std: float, turn_std: float, dt_s: float) -> None:
    """A teammate whose motion is not known: its block stays, its covariance grows as a random
    walk, ``speed_std^2 * 1 s`` per second (m^2/s: after ``T`` seconds the std is ``speed_std
    sqrt(T * 1 s)``, the distance a robot at that speed covers in a second or so, as
    :class:`MotionNoise`'s correlation time of 1 s has it), and the heading's likewise."""
    sl = joint.block(k)
    q = np.diag([speed_std**2 * dt_s] * 2 + ([turn_std**2 * dt_s] if joint.d == 3 else []))
    joint.P[sl, sl] += q
    if joint.Pi is not None:
        joint.Pi[sl, sl] += q


def relative_model(joint: Joint, i: int, j: int | None, target_xy: np.ndarray | None):
    """``(z_hat (2,), H (2, n))`` of the relative position ``C(theta_i)^T (p_t - p_i)`` of
    robot ``j``'s position (``j`` not None) or a known point ``target_xy``, seen by robot ``i``."""
    d = joint.d
    th = joint.theta(i)
    c, s = math.cos(th), math.sin(th)
    ct = np.array([[c, s], [-s, c]])
    si = i * d
    p_i = joint.x[si:si + 2]
    p_t = joint.x[j * d:j * d + 2] if j is not None else target_xy
    delta = p_t - p_i
    h = np.zeros((2, joint.x.size))
    h[:, si:si + 2] = -ct
    if j is not None:
        h[:, j * d:j * d + 2] += ct
    if d == 3:
        h[:, si + 2] = np.array([[-s, c], [-c, -s]]) @ delta
    return ct @ delta, h


def _wrap_headings(joint: Joint) -> None:
    if joint.d == 3:
        joint.x[2::3] = wrap_angle(joint.x[2::3])


def _gated(d2: float, gate_chi2: float, nis: NisTally | None) -> bool:
    if nis is not None:
        nis.add(d2)
    return d2 >= gate_chi2


def ekf_update(joint: Joint, h: np.ndarray, nu: np.ndarray, r: np.ndarray, gate_chi2: float,
               nis: NisTally | None = None) -> bool:
    """The EKF update of the whole stacked state (Joseph form; ``Pi`` too, for split CI).
    Returns whether the reading passed the gate."""
    pht = joint.P @ h.T
    s = h @ pht + r
    if _gated(float(nu @ np.linalg.solve(s, nu)), gate_chi2, nis):
        return False
    k = np.linalg.solve(s, pht.T).T
    joint.x += k @ nu
    _wrap_headings(joint)
    ikh = np.eye(joint.x.size) - k @ h
    krk = k @ r @ k.T
    new = ikh @ joint.P @ ikh.T + krk
    joint.P = 0.5 * (new + new.T)
    if joint.Pi is not None:
        new_i = ikh @ joint.Pi @ ikh.T + krk
        joint.Pi = 0.5 * (new_i + new_i.T)
    return True


def bda_update(joint: Joint, robots: list[int], h: np.ndarray, nu: np.ndarray, r: np.ndarray,
               gate_chi2: float, nis: NisTally | None = None) -> bool:
    """Luft et al.'s block-diagonal approximation: the EKF on the joint block of ``robots`` (one
    for a landmark reading, two for a relative one); every cross-covariance of an updated robot
    ``a`` with a robot ``k`` outside is multiplied by ``Sigma_aa^+ (Sigma_aa^-)^-1``; the robots
    outside are not corrected."""
    d = joint.d
    idx = np.concatenate([np.arange(a * d, (a + 1) * d) for a in robots])
    hs = h[:, idx]
    ps = joint.P[np.ix_(idx, idx)]
    s = hs @ ps @ hs.T + r
    if _gated(float(nu @ np.linalg.solve(s, nu)), gate_chi2, nis):
        return False
    k = np.linalg.solve(s, hs @ ps).T
    joint.x[idx] += k @ nu
    _wrap_headings(joint)
    ikh = np.eye(idx.size) - k @ hs
    new = ikh @ ps @ ikh.T + k @ r @ k.T
    new = 0.5 * (new + new.T)
    others = np.setdiff1d(np.arange(joint.x.size), idx)
    for m, a in enumerate(robots):
        sl = joint.block(a)
        local = slice(m * d, (m + 1) * d)
        factor = np.linalg.solve(ps[local, local].T, new[local, local].T).T  # new inv(old)
        if others.size:
            joint.P[sl, others] = factor @ joint.P[sl, others]
            joint.P[others, sl] = joint.P[sl, others].T
    joint.P[np.ix_(idx, idx)] = new
    return True


def _psd(m: np.ndarray) -> np.ndarray:
    """The symmetric part of ``m`` with its negative eigenvalues (rounding) set to 0."""
    vals, vecs = np.linalg.eigh(0.5 * (m + m.T))
    return (vecs * np.maximum(vals, 0.0)) @ vecs.T


def ci_weight_for(trace_of, fixed: float) -> float:
    """The CI weight: ``fixed`` if set, else the one in (0, 1) minimising ``trace_of(w)``."""
    if fixed > 0.0:
        return fixed
    from scipy.optimize import minimize_scalar

    best = minimize_scalar(trace_of, bounds=(1e-3, 1.0 - 1e-3), method="bounded",
                           options={"xatol": 1e-3})
    return float(best.x)


def ci_fuse(joint: Joint, idx: np.ndarray, z: np.ndarray, z_cov: np.ndarray, weight: float,
            gate_chi2: float = math.inf, z_cov_i: np.ndarray | None = None,
            nis: NisTally | None = None) -> float | None:
    """Fuse an estimate ``z`` (covariance ``z_cov``) of the state entries ``idx``, of unknown
    correlation with them, by covariance intersection (Julier and Uhlmann; split CI of Li and
    Nashashibi when the joint keeps ``Pi`` and ``z_cov_i`` is the estimate's independent part).
    The entries outside ``idx`` follow by conditioning on the fused ones (``G = P_ro P_oo^-1``).
    Returns the weight used, or None when gated out or when no weight lowers the trace."""
    p_oo = joint.P[np.ix_(idx, idx)]
    x_o = joint.x[idx]
    nu = z - x_o
    if joint.d == 3:  # headings among the entries: the innovation's angles wrapped
        heads = (idx % 3) == 2
        nu[heads] = wrap_angle(nu[heads])
    if _gated(float(nu @ np.linalg.solve(p_oo + z_cov, nu)), gate_chi2, nis):
        return None
    split = joint.Pi is not None and z_cov_i is not None
    if split:
        pi_oo = joint.Pi[np.ix_(idx, idx)]
        pd_own, pd_z = _psd(p_oo - pi_oo), _psd(z_cov - z_cov_i)

        def fused(w):
            p1 = pd_own / w + pi_oo
            p2 = pd_z / (1.0 - w) + z_cov_i
            k = np.linalg.solve((p1 + p2).T, p1.T).T
            return k, (np.eye(idx.size) - k) @ p1
    else:
        info_own, info_z = np.linalg.inv(p_oo), np.linalg.inv(z_cov)

        def fused(w):
            cov = np.linalg.inv(w * info_own + (1.0 - w) * info_z)
            return (1.0 - w) * cov @ info_z, cov  # gain on the innovation, fused covariance

    w = ci_weight_for(lambda w: float(np.trace(fused(w)[1])), weight)
    gain, new_oo = fused(w)
    if split:  # the same P, summed from its two parts in Joseph form: P - P_i stays PSD
        ik = np.eye(idx.size) - gain
        new_i = ik @ pi_oo @ ik.T + gain @ z_cov_i @ gain.T
        new_oo = new_i + ik @ (pd_own / w) @ ik.T + gain @ (pd_z / (1.0 - w)) @ gain.T
    new_oo = 0.5 * (new_oo + new_oo.T)
    if weight == 0.0 and float(np.trace(new_oo)) >= float(np.trace(p_oo)):
        return None
    delta = gain @ nu
    n = joint.x.size
    rest = np.setdiff1d(np.arange(n), idx)
    g = joint.P[np.ix_(rest, idx)] @ np.linalg.inv(p_oo) if rest.size else np.zeros((0, idx.size))
    old_p = joint.P
    joint.x[idx] += delta
    if rest.size:
        joint.x[rest] += g @ delta
    _wrap_headings(joint)
    new_p = old_p.copy()
    new_p[np.ix_(idx, idx)] = new_oo
    if rest.size:
        new_p[np.ix_(rest, idx)] = g @ new_oo
        new_p[np.ix_(idx, rest)] = new_p[np.ix_(rest, idx)].T
        new_p[np.ix_(rest, rest)] = old_p[np.ix_(rest, rest)] - g @ (p_oo - new_oo) @ g.T
    joint.P = 0.5 * (new_p + new_p.T)
    if split:
        pi = joint.Pi.copy()
        pi[np.ix_(idx, idx)] = 0.5 * (new_i + new_i.T)
        # the entries outside keep their independent part, bounded by their total
        joint.Pi = pi
    return w


# --------------------------------------------------------------------------------------------
# What a robot broadcasts (in its TeammateReport's ``extra``)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class TickEvents:
    """One robot's odometry and readings of one tick (calibrated ranges)."""

    v_mps: float
    omega_rad_s: float
    dt_s: float
    true_heading_rad: float | None
    landmarks: np.ndarray  #: (K, 3) id, range, bearing
    robots: np.ndarray  #: (M, 3) id, range, bearing
    #: ``sum dt_i^2`` of the tick's odometry messages (ColoParams.odometry_noise), None: unknown
    gap2_s2: float | None = None

    @classmethod
    def of(cls, obs: LandmarkObservation) -> TickEvents:
        return cls(obs.odometry_v_mps, obs.odometry_omega_rad_s, obs.odometry_dt_s,
                   obs.true_heading_rad,
                   np.column_stack([obs.landmark_ids, obs.landmark_range_m, obs.landmark_bearing_rad]),
                   np.column_stack([obs.robot_ids, obs.robot_range_m, obs.robot_bearing_rad]),
                   obs.odometry_gap2_s2)


def encode_extra(events: TickEvents | None = None, joint: Joint | None = None) -> bytes:
    wire = {}
    if events is not None:
        wire["o"] = np.array([events.v_mps, events.omega_rad_s, events.dt_s,
                              math.nan if events.true_heading_rad is None else events.true_heading_rad,
                              math.nan if events.gap2_s2 is None else events.gap2_s2],
                             dtype="<f8").tobytes()
        wire["l"] = np.ascontiguousarray(events.landmarks[:MAX_REPORT_SIGHTINGS], dtype="<f8").tobytes()
    if joint is not None:
        wire["i"] = np.array(joint.ids, dtype="<i8").tobytes()
        wire["h"] = joint.heading.astype("<f8").tobytes()
        wire["x"] = joint.x.astype("<f8").tobytes()
        wire["p"] = joint.P.astype("<f8").tobytes()
        if joint.Pi is not None:
            wire["q"] = joint.Pi.astype("<f8").tobytes()
    return msgpack.packb(wire, use_bin_type=True)


def decode_extra(report: TeammateReport, d: int):
    """``(events or None, (ids, heading, x, P, Pi) or None)`` from a report; ``ValueError``
    naming what is wrong."""
    try:
        wire = msgpack.unpackb(report.extra, raw=False, strict_map_key=True, max_map_len=8,
                               max_array_len=0, max_str_len=4, max_ext_len=0)
    except Exception as exc:  # noqa: BLE001 -- msgpack raises many unrelated types
        raise ValueError(f"payload.extra: not CoLo data ({type(exc).__name__})") from None
    if not isinstance(wire, dict) or not set(wire) <= {"o", "l", "i", "h", "x", "p", "q"} \
            or not all(isinstance(v, bytes) for v in wire.values()):
        raise ValueError("payload.extra: expected a map of o, l, i, h, x, p, q to bytes")
    events = state = None
    if "o" in wire:
        o = _array(wire["o"], "o", 5, allow_nan=True)
        if not np.isfinite(o[:3]).all() or not o[2] > 0 or o[4] < 0:
            raise ValueError("payload.extra.o: odometry must be finite with dt > 0 and gaps >= 0")
        lm = _array(wire.get("l", b""), "l", None).reshape(-1, 3)
        events = TickEvents(float(o[0]), float(o[1]), float(o[2]),
                            None if math.isnan(o[3]) else float(o[3]), lm, report.seen,
                            None if math.isnan(o[4]) else float(o[4]))
    if "i" in wire:
        ids = np.frombuffer(wire["i"], dtype="<i8") if len(wire["i"]) % 8 == 0 else None
        if ids is None or not 0 < ids.size <= _MAX_TEAM or len(set(ids.tolist())) != ids.size:
            raise ValueError("payload.extra.i: expected 1 to 32 distinct robot ids")
        n = ids.size * d
        heading = _array(wire.get("h", b""), "h", ids.size)
        x = _array(wire.get("x", b""), "x", n)
        p = _array(wire.get("p", b""), "p", n * n).reshape(n, n)
        pi = _array(wire["q"], "q", n * n).reshape(n, n) if "q" in wire else None
        if (np.diag(p) < 0).any():
            raise ValueError("payload.extra.p: negative variances")
        state = (ids.tolist(), heading, x, p, pi)
    return events, state


def _array(raw: bytes, name: str, size: int | None, allow_nan: bool = False) -> np.ndarray:
    if len(raw) % 8 or (size is not None and len(raw) != 8 * size):
        raise ValueError(f"payload.extra.{name}: expected {size if size is not None else 'a multiple of 3'} float64")
    a = np.frombuffer(raw, dtype="<f8")
    if size is None and a.size % 3:
        raise ValueError(f"payload.extra.{name}: expected rows of 3 float64")
    if not (np.isfinite(a) | (allow_nan & np.isnan(a))).all():
        raise ValueError(f"payload.extra.{name}: must be finite")
    return a


# --------------------------------------------------------------------------------------------
# The localizers
# --------------------------------------------------------------------------------------------


class _ColoBase:
    """What every CoLo estimator shares: its own block in a :class:`Joint`, the readings of a
    tick applied to a joint (its own landmark readings, its relative readings), the report."""

    split = False

    def _begin(self, obs: LandmarkObservation):
        """The start of every step: the observation checked and calibrated, the joint state
        started from the first one; returns ``(obs, joint, params)``."""
        check_observation(obs, self.setup.robot_id)
        obs = calibrated(obs, self.setup.camera)
        if self.joint is None:
            self.joint = self._start(obs)
        return obs, self.joint, self.params

    def __init__(self, setup: LandmarkSetup, params: ColoParams, rng: np.random.Generator | None = None):
        if not isinstance(setup, LandmarkSetup):
            raise TypeError(f"setup must be a LandmarkSetup, got {type(setup).__name__}")
        self.setup, self.params = setup, params
        self.joint: Joint | None = None  # made at the first step, when the heading mode is known
        self.rejected: tuple[tuple[int, ValueError], ...] = ()
        self.landmark_updates = self.teammate_updates = self.fusions = 0
        #: NIS of this robot's own landmark readings and of its teammate updates (relative
        #: readings, CI fixes), see :class:`NisTally` and :meth:`nis_scores`.
        self.nis = {"landmark": NisTally(), "teammate": NisTally()}
        self._out: bytes | None = None
        self._view: Joint | None = None

    def _start(self, obs: LandmarkObservation) -> Joint:
        d = 3 if obs.true_heading_rad is None else 2
        joint = Joint(d, split=self.split)
        # the known start's heading (the first ground-truth pose) until the first tick's truth
        joint.add(self.setup.robot_id, self.setup.initial_pose.copy(), self.setup.initial_covariance())
        return joint

    def nis_scores(self) -> dict[str, float]:
        """Mean NIS, share inside the 95 % band and count, of landmark and teammate updates."""
        return {**self.nis["landmark"].scores("landmark"), **self.nis["teammate"].scores("teammate")}

    def _landmarks(self, joint: Joint, k: int, lm: np.ndarray, bda: bool = False,
                   tally: bool = True) -> None:
        if not lm.shape[0]:
            return
        nis = self.nis["landmark"] if tally else None
        xy, known = self.setup.landmark_positions(lm[:, 0].astype(np.int64))
        for (_, r, b), p, ok in zip(lm, xy, known):
            if not ok:
                continue
            z_hat, h = relative_model(joint, k, None, p)
            nu = r * np.array([math.cos(b), math.sin(b)]) - z_hat
            noise = reading_noise(self.setup, self.params.noise_model, r, b) * self.params.reading_noise_scale
            if bda:
                accepted = bda_update(joint, [k], h, nu, noise, self.params.gate_chi2, nis)
            else:
                accepted = ekf_update(joint, h, nu, noise, self.params.gate_chi2, nis)
            self.landmark_updates += int(accepted)

    def _relative(self, joint: Joint, k: int, rows: np.ndarray, bda: bool = False,
                  tally: bool = True) -> None:
        nis = self.nis["teammate"] if tally else None
        for rid, r, b in rows:
            j = joint.index(int(rid))
            if j is None or j == k:
                continue
            z_hat, h = relative_model(joint, k, j, None)
            nu = r * np.array([math.cos(b), math.sin(b)]) - z_hat
            noise = reading_noise(self.setup, self.params.noise_model, r, b) * self.params.reading_noise_scale
            if bda:
                accepted = bda_update(joint, [k, j], h, nu, noise, self.params.gate_chi2, nis)
            else:
                accepted = ekf_update(joint, h, nu, noise, self.params.gate_chi2, nis)
            self.teammate_updates += int(accepted)

    def _own(self) -> int:
        return self._view.index(self.setup.robot_id)

    def estimate(self) -> np.ndarray:
        if self._view is None:
            return self.setup.initial_pose.copy()
        return self._view.pose(self._own())

    def covariance_xy(self) -> np.ndarray | None:
        if self._view is None:
            return None
        return self._view.cov3(self._own())[:2, :2]

    def heading_variance(self) -> float | None:
        """The heading's variance when the heading is estimated (None in CoLo-AT's setting,
        where the true heading is given and the state is x, y)."""
        if self._view is None or self._view.d != 3:
            return None
        return float(self._view.cov3(self._own())[2, 2])

    def outgoing(self) -> bytes | None:
        return self._out

    def _report(self, obs: LandmarkObservation, extra: bytes) -> None:
        k = self._own()
        pose = self._view.pose(k)
        pose[2] = float(wrap_angle(pose[2]))
        self._out = TeammateReport.build(self.setup.robot_id, obs.tick, pose, self._view.cov3(k),
                                         obs, extra=extra).encode()

    def _decode(self, obs: LandmarkObservation) -> dict[int, TeammateReport]:
        senders = np.array(sorted({m.sender_id for m in obs.received}), dtype=np.int64)
        reports, rejected = decode_received(obs.received, self.setup.robot_id, senders)
        self.rejected = tuple(rejected)
        return reports


class ReplicaLocalizer(_ColoBase):
    """``ls-cen`` (exact) and ``ls-bda`` (Luft et al.'s approximation): a replica of the
    centralized filter in every robot (see the module docstring)."""

    def __init__(self, setup, params, rng=None, bda: bool = False):
        super().__init__(setup, params, rng)
        self.bda = bda
        self._pending: TickEvents | None = None

    def step(self, obs: LandmarkObservation) -> None:
        obs, joint, p = self._begin(obs)
        own = TickEvents.of(obs)
        if self.setup.cooperative:
            events: dict[int, TickEvents] = {}
            for rid, rep in self._decode(obs).items():
                try:
                    ev, _ = decode_extra(rep, joint.d)
                except ValueError as exc:
                    self.rejected = (*self.rejected, (rid, exc))
                    continue
                if ev is None:
                    continue
                if joint.index(rid) is None:  # joins with the estimate its report gives
                    if len(joint.ids) >= _MAX_TEAM:
                        continue
                    joint.add(rid, rep.pose, rep.covariance)
                    continue  # its events count from the next tick on
                events[rid] = ev
            if self._pending is not None:
                events[self.setup.robot_id] = self._pending
            self._commit(joint, events)
            self._pending = own
            view = joint.copy()
        else:
            view = joint  # alone: nothing to wait for
        k = view.index(self.setup.robot_id)
        propagate_robot(view, k, self.setup, p, own)
        # Cooperative, this robot's readings are counted in the NIS when they are committed
        # (next tick); alone, the view is the filter.
        alone = not self.setup.cooperative
        self._landmarks(view, k, own.landmarks, self.bda, tally=alone)
        if self.setup.cooperative:
            self._relative(view, k, own.robots, self.bda, tally=False)
        self._view = view
        if self.setup.cooperative:
            self._report(obs, encode_extra(events=own))

    def _commit(self, joint: Joint, events: dict[int, TickEvents]) -> None:
        """The team's events of one tick, in the order every replica applies them."""
        p = self.params
        for k, rid in enumerate(joint.ids):
            ev = events.get(rid)
            if ev is None:  # no payload (or just joined): a random walk of the tick's length
                dt = next(iter(events.values())).dt_s if events else 0.0
                random_walk(joint, k, p.teammate_speed_std_mps, p.teammate_turn_std_rad_s, dt)
                continue
            propagate_robot(joint, k, self.setup, p, ev)
        for rid in sorted(events):
            self._landmarks(joint, joint.index(rid), events[rid].landmarks, self.bda,
                            tally=rid == self.setup.robot_id)
        for rid in sorted(events):
            rows = events[rid].robots
            rows = rows[[r in events for r in rows[:, 0].astype(int).tolist()]] if rows.size else rows
            self._relative(joint, joint.index(rid), rows, self.bda, tally=rid == self.setup.robot_id)


class LsCiLocalizer(_ColoBase):
    """``ls-ci``: Carrillo-Arce et al. 2013 (see the module docstring)."""

    def step(self, obs: LandmarkObservation) -> None:
        obs, joint, p = self._begin(obs)
        ev = TickEvents.of(obs)
        propagate_robot(joint, 0, self.setup, p, ev)
        self._landmarks(joint, 0, ev.landmarks)
        self._view = joint
        if not self.setup.cooperative:
            return
        me = self.setup.robot_id
        for rid, rep in sorted(self._decode(obs).items()):
            mine = rep.seen[rep.seen[:, 0] == me] if rep.seen.size else rep.seen
            if not mine.shape[0]:
                continue
            _, r, b = mine[0]
            fix, fix_cov = observed_fix(rep.pose, rep.covariance, r, b,
                                        reading_noise(self.setup, p.noise_model, r, b) * p.reading_noise_scale, joint.d)
            w = ci_fuse(joint, np.arange(2), fix, fix_cov, p.ci_weight, p.gate_chi2,
                        nis=self.nis["teammate"])
            self.fusions += int(w is not None)
        self._report(obs, b"")


def observed_fix(observer_pose: np.ndarray, observer_cov: np.ndarray, range_m: float,
                 bearing_rad: float, reading_cov: np.ndarray, d: int) -> tuple[np.ndarray, np.ndarray]:
    """The observed robot's position ``p_i + C(theta_i) z`` from the observer's estimate and its
    reading ``z = r (cos b, sin b)`` (noise ``reading_cov`` in the observer's frame), and its
    covariance ``J P_i J^T + C R C^T`` (``J`` with the heading column when it is estimated)."""
    th = float(observer_pose[2])
    c = rot(th)
    z = range_m * np.array([math.cos(bearing_rad), math.sin(bearing_rad)])
    fix = observer_pose[:2] + c @ z
    j = np.zeros((2, 3))
    j[:, :2] = np.eye(2)
    if d == 3:
        j[:, 2] = np.array([[-math.sin(th), -math.cos(th)], [math.cos(th), -math.sin(th)]]) @ z
    return fix, j @ observer_cov @ j.T + c @ reading_cov @ c.T


class GlobalStateLocalizer(_ColoBase):
    """``gs-ci`` and ``gs-sci`` (``split``): the team's state in every robot, fused by
    (split) covariance intersection over the links (see the module docstring)."""

    def __init__(self, setup, params, rng=None, split: bool = False):
        self.split = split
        super().__init__(setup, params, rng)

    def step(self, obs: LandmarkObservation) -> None:
        obs, joint, p = self._begin(obs)
        reports = self._decode(obs) if self.setup.cooperative else {}
        states = {}
        for rid, rep in reports.items():
            try:
                _, state = decode_extra(rep, joint.d)
            except ValueError as exc:
                self.rejected = (*self.rejected, (rid, exc))
                continue
            if state is not None:
                states[rid] = state
            if joint.index(rid) is None and len(joint.ids) < _MAX_TEAM:
                joint.add(rid, rep.pose, rep.covariance)
        for k, rid in enumerate(joint.ids):
            if rid == self.setup.robot_id:
                propagate_robot(joint, k, self.setup, p, TickEvents.of(obs))
            else:
                random_walk(joint, k, p.teammate_speed_std_mps, p.teammate_turn_std_rad_s,
                            obs.odometry_dt_s)
                if joint.d == 2 and rid in reports:  # a teammate's heading is its own business
                    joint.heading[k] = reports[rid].pose[2]
        k = joint.index(self.setup.robot_id)
        ev = TickEvents.of(obs)
        if ev.landmarks.shape[0] or ev.robots.shape[0]:
            # CoLo-AT fuses what a robot hears when it has taken a measurement; here just before
            # the measurement is applied, so that a relative reading meets fresh teammate blocks
            for rid in sorted(states):
                self._fuse(joint, states[rid])
            k = joint.index(self.setup.robot_id)
        self._landmarks(joint, k, ev.landmarks)
        if self.setup.cooperative:
            self._relative(joint, k, ev.robots)
        self._view = joint
        if self.setup.cooperative:
            self._report(obs, encode_extra(joint=joint))
            if joint.Pi is not None and p.sci_independent == "since-broadcast":
                joint.Pi = np.zeros_like(joint.Pi)  # broadcast: any teammate may hold it now

    def _fuse(self, joint: Joint, state) -> None:
        """A teammate's global state fused into this one: robots it holds that this one does
        not join (with its estimate, all of it counted as dependent); robots this one holds
        that it does not are given to the fusion as known to it with a std of
        :data:`UNKNOWN_STD_M` (so that (split) CI runs over the whole state and leaves them
        all but unchanged)."""
        ids, heading, x, p_other, pi_other = state
        d = joint.d
        for m, rid in enumerate(ids):
            if joint.index(rid) is None and len(joint.ids) < _MAX_TEAM:
                sl = slice(m * d, (m + 1) * d)
                cov3 = np.zeros((3, 3))
                cov3[:d, :d] = p_other[sl, sl]
                joint.add(rid, np.array([*x[sl][:2], x[sl][2] if d == 3 else heading[m]]), cov3,
                          np.zeros((3, 3)))
        n = joint.x.size
        z = joint.x.copy()
        z_cov = np.eye(n) * UNKNOWN_STD_M**2
        z_cov_i = None if pi_other is None else z_cov.copy()
        theirs = [(joint.index(r), m) for m, r in enumerate(ids) if joint.index(r) is not None]
        mine = np.concatenate([np.arange(a * d, (a + 1) * d) for a, _ in theirs])
        other = np.concatenate([np.arange(m * d, (m + 1) * d) for _, m in theirs])
        z[mine] = x[other]
        z_cov[np.ix_(mine, mine)] = p_other[np.ix_(other, other)]
        if z_cov_i is not None:
            z_cov_i[np.ix_(mine, mine)] = pi_other[np.ix_(other, other)]
        w = ci_fuse(joint, np.arange(n), z, z_cov, self.params.ci_weight, math.inf, z_cov_i)
        self.fusions += int(w is not None)


#: The std given, in a fusion, to a robot the teammate does not hold [m, rad].
UNKNOWN_STD_M = 100.0


def _params(params) -> ColoParams:
    from swarmloc.agents.replay.localizers import params_from_dict

    return params_from_dict(ColoParams, params, "colo")


def build_ls_cen(setup, rng, params):
    return ReplicaLocalizer(setup, _params(params), rng)


def build_ls_bda(setup, rng, params):
    return ReplicaLocalizer(setup, _params(params), rng, bda=True)


def build_ls_ci(setup, rng, params):
    return LsCiLocalizer(setup, _params(params), rng)


def build_gs_ci(setup, rng, params):
    return GlobalStateLocalizer(setup, _params(params), rng)


def build_gs_sci(setup, rng, params):
    return GlobalStateLocalizer(setup, _params(params), rng, split=True)


__all__ = [
    "COLO_ALGORITHMS",
    "NOISE_MODELS",
    "ColoParams",
    "Joint",
    "bda_update",
    "ci_fuse",
    "ekf_update",
    "observed_fix",
    "propagate_robot",
    "relative_model",
]
