"""Replaying a real-data set (MRCLAM's layout) with a landmark localizer per robot, and scoring
the estimates against the ground truth: the configuration of a replay (:class:`ReplayConfig`), the
world and each robot's localizer built from it (:func:`replay_world`, :func:`replay_localizer`), the
in-process run (:func:`run_replay`) and its scores (:func:`score`, :func:`consistency`, the trajectory
errors, TUM files). Below the shells: the world-server and the agent processes build exactly what
the in-process evaluation builds (``deploy/lab/replay/mrclam.py``, the ``swarmloc mrclam`` command,
describes the data set and the settings).
"""

from __future__ import annotations

import math
import time
from collections.abc import Mapping
from dataclasses import dataclass, field, replace
from pathlib import Path

import numpy as np

from swarmloc.agents.replay.calibration import (
    SelfCalibratingLocalizer,
    SelfCalibrationParams,
    robust_std,
)
from swarmloc.agents.replay.colo import COLO_ALGORITHMS
from swarmloc.agents.replay.ekf import CHI2_2DOF_95
from swarmloc.agents.replay.localizers import (
    ALGORITHMS,
    CameraNoise,
    LandmarkSetup,
    MotionNoise,
    build_localizer,
    wrap_angle,
)
from swarmloc.world.replay.mrclam import MrclamDataset
from swarmloc.world.replay.replay import DEFAULT_DT_S, ReplayWorld

#: Stream id separating the MRCLAM localizers' generators (``[seed, stream, robot_id]``).
MRCLAM_STREAM = 7
#: The report's line-up, in table order.
REPORT_ALGORITHMS = ("dr", "ekf", "pf", "cfsga", "ssga", "hybrid")
#: ``ReplayConfig.calibration``: self (no ground truth), the Vicon fit (reference), none.
CALIBRATIONS = ("self", "self-own", "vicon", "none")
#: ``ReplayConfig.start``.
STARTS = ("known", "unknown")
#: ``ReplayConfig.heading``: estimated by the localizer, or the ground truth's given to it
#: (CoLo-AT's setting; read by CoLo's estimators, ``agents/replay/colo.py``).
HEADINGS = ("estimate", "truth")
#: The localizers that can start from an unknown pose (a population over the whole field).
GLOBAL_ALGORITHMS = ("pf", "cfsga", "ssga", "hybrid")
#: A kidnap's jump told by the odometry: (distance m along the mid-turn heading, turn rad).
KIDNAP_JUMP = (2.0, math.pi / 2)
#: Error below which a robot counts as localized (issue 19: 0.3 m, and it must stay there).
LOCALIZED_M = 0.3


@dataclass(frozen=True)
class ReplayConfig:
    """One configuration: algorithm, cooperation, seed, tick, and parameters."""

    algorithm: str = "ekf"
    cooperative: bool = False
    seed: int = 0
    dt_s: float = DEFAULT_DT_S
    params: Mapping = field(default_factory=dict)
    motion: MotionNoise = field(default_factory=MotionNoise)
    camera: CameraNoise = field(default_factory=CameraNoise)
    initial_std: tuple[float, float, float] = (0.05, 0.05, 0.05)
    #: Replay only this many seconds from the start (None: the whole data set).
    duration_s: float | None = None
    #: How each robot's camera range bias is found (:data:`CALIBRATIONS`): ``self``, estimated
    #: while localizing from the robot's own data
    #: (:class:`~swarmloc.agents.replay.calibration.SelfCalibratingLocalizer`, no ground truth;
    #: cooperative, a robot whose camera has not folded yet starts from a teammate's broadcast
    #: calibration); ``self-own``, the same from the robot's own data only;
    #: ``vicon``, fitted (:func:`fit_camera`) on the first ``calibration_s`` seconds of readings
    #: against the Vicon ground truth (a reference: ground truth in the loop); ``none``: ``camera``
    #: as it is.
    calibration: str = "self"
    #: The Vicon fit's window (``calibration="vicon"`` only; None or 0: no fit).
    calibration_s: float | None = 120.0
    #: ``known``: every localizer starts at the robot's first Vicon pose with ``initial_std``;
    #: ``unknown``: no knowledge of the pose (uniform over the landmarks' bounding box, every
    #: heading), for the global localizers only (:data:`GLOBAL_ALGORITHMS`).
    start: str = "known"
    #: Kidnap: ``kidnap_s`` seconds after the start, robot ``kidnap_robot`` (a data set id; None:
    #: the first) is told by its odometry that it jumped ``KIDNAP_JUMP`` (its estimate is
    #: teleported; the robot did not move). None: no kidnap.
    kidnap_s: float | None = None
    kidnap_robot: int | None = None
    #: ``estimate`` (the localizer estimates it) or ``truth``: every observation carries the
    #: robot's true heading (CoLo-AT's setting, issue 46), which CoLo's estimators use in
    #: propagation and measurement models (the other localizers cannot: an error).
    heading: str = "estimate"
    #: The robots given their landmark readings (None: every robot; CoLo-AT's setting: 1, 2, 3).
    landmark_robots: tuple[int, ...] | None = None
    #: Who hears whom: receiver id -> the ids it hears (None: everyone hears everyone;
    #: CoLo-AT's setting: ``{1: (2,), 2: (3,)}``, robots 3-5 hear nobody).
    links: Mapping | None = None

    def __post_init__(self):
        if self.heading not in HEADINGS:
            raise ValueError(f"heading: unknown {self.heading!r} (known: {', '.join(HEADINGS)})")
        if self.heading == "truth" and self.algorithm not in COLO_ALGORITHMS:
            raise ValueError(f"heading: 'truth' is read by CoLo's estimators only "
                             f"({', '.join(COLO_ALGORITHMS)}), not {self.algorithm!r}")
        if self.landmark_robots is not None:
            ids = self.landmark_robots
            if isinstance(ids, (str, bytes)) or not isinstance(ids, (list, tuple)) or \
                    not all(isinstance(r, int) and not isinstance(r, bool) for r in ids):
                raise ValueError(f"landmark_robots: expected a list of robot ids, got {ids!r}")
            object.__setattr__(self, "landmark_robots", tuple(ids))
        if self.links is not None:
            object.__setattr__(self, "links", parse_links(self.links))
        if self.algorithm not in ALGORITHMS:
            try:
                ALGORITHMS.get(self.algorithm)  # the registry's message: closest name, plugins
            except ValueError as exc:
                raise ValueError(f"algorithm: {exc}") from None
        if isinstance(self.seed, bool) or not isinstance(self.seed, int) or self.seed < 0:
            raise ValueError(f"seed must be an integer >= 0, got {self.seed!r}")
        if not isinstance(self.cooperative, bool):
            raise TypeError(f"cooperative must be true or false, got {self.cooperative!r}")
        if self.duration_s is not None and not (math.isfinite(self.duration_s) and self.duration_s > 0):
            raise ValueError(f"duration_s must be > 0, got {self.duration_s!r}")
        if self.calibration not in CALIBRATIONS:
            raise ValueError(f"calibration: unknown {self.calibration!r} (known: "
                             f"{', '.join(CALIBRATIONS)})")
        if self.calibration_s is not None and not (math.isfinite(self.calibration_s)
                                                   and self.calibration_s >= 0):
            raise ValueError(f"calibration_s must be >= 0, got {self.calibration_s!r}")
        if self.start not in STARTS:
            raise ValueError(f"start: unknown {self.start!r} (known: {', '.join(STARTS)})")
        if self.start == "unknown" and self.algorithm not in GLOBAL_ALGORITHMS:
            raise ValueError(f"start: 'unknown' needs a global localizer ({', '.join(GLOBAL_ALGORITHMS)}"
                             f"), not {self.algorithm!r} (a single Gaussian cannot start from nowhere)")
        if self.kidnap_s is not None and not (math.isfinite(self.kidnap_s) and self.kidnap_s > 0):
            raise ValueError(f"kidnap_s must be > 0, got {self.kidnap_s!r}")
        if self.kidnap_s is not None and self.duration_s is not None and \
                self.kidnap_s >= self.duration_s:
            raise ValueError(f"kidnap_s ({self.kidnap_s}) must be before the end of the replay "
                             f"(duration_s {self.duration_s})")
        if self.kidnap_robot is not None and (isinstance(self.kidnap_robot, bool)
                                              or not isinstance(self.kidnap_robot, int)):
            raise ValueError(f"kidnap_robot must be a robot id, got {self.kidnap_robot!r}")

    @property
    def label(self) -> str:
        """``algorithm[+coop]``, then what differs from the default tracking run."""
        tags = [f"{self.algorithm}{'+coop' if self.cooperative else ''}"]
        if self.calibration != "self":
            tags.append(f"{self.calibration}-cal")
        if self.start != "known":
            tags.append(f"{self.start}-start")
        if self.kidnap_s is not None:
            tags.append("kidnap")
        if self.heading != "estimate":
            tags.append(f"{self.heading}-heading")
        return " ".join(tags)


@dataclass(frozen=True)
class ReplayResult:
    config: ReplayConfig
    robot_ids: tuple[int, ...]
    times_s: np.ndarray  #: (T,) tick end times since the data set's epoch
    estimates: np.ndarray  #: (T, N, 3)
    truth: np.ndarray  #: (T, N, 3), NaN where unknown
    cpu_s: float  #: process CPU time of the replay loop
    rejected_payloads: int = 0
    #: ``(robot id, tick)`` of the kidnap, or None.
    kidnap: tuple[int, int] | None = None
    #: (T, N, 2, 2) each estimate's position covariance, NaN where the localizer gives none
    #: (``covariance_xy()``: the EKFs; issue 46's consistency).
    covariance_xy: np.ndarray | None = None
    #: Per robot, the NIS of its landmark and teammate updates, for localizers that count it
    #: (``nis_scores()``: CoLo's estimators, ``agents/replay/colo.py``); empty otherwise.
    nis: Mapping[int, Mapping[str, float]] = field(default_factory=dict)
    #: (T, N) each estimate's heading variance [rad^2], NaN where the localizer gives none
    #: (``heading_variance()``; issue 46's heading NEES).
    heading_variance: np.ndarray | None = None

    def position_error_m(self) -> np.ndarray:
        """(T, N) distance between estimate and truth (NaN where no truth)."""
        return np.linalg.norm(self.estimates[..., :2] - self.truth[..., :2], axis=2)


def _reading_errors(dataset: MrclamDataset, robot_id: int, kind: str, start_s: float,
                    end_s: float):
    """True range, measured range, measured bearing and bearing error of one robot's readings
    of landmarks or robots in ``[start_s, end_s)``, against the Vicon ground truth."""
    rec = dataset.robots[robot_id]
    meas = rec.landmark_measurements if kind == "landmark" else rec.robot_measurements
    sel = (meas.time_s >= start_s) & (meas.time_s < end_s)
    t, subject = meas.time_s[sel], meas.subject[sel]
    pose = rec.pose_at(t)
    if kind == "landmark":
        target = np.full((t.size, 2), np.nan)
        rows = dataset.landmarks.index_of(subject)
        target[rows >= 0] = dataset.landmarks.xy_m[rows[rows >= 0]]
    else:
        target = np.full((t.size, 2), np.nan)
        for rid in np.unique(subject):
            mine = subject == rid
            target[mine] = dataset.robots[int(rid)].pose_at(t[mine])[:, :2]
    d = target - pose[:, :2]
    true_range = np.hypot(d[:, 0], d[:, 1])
    bearing_err = wrap_angle(meas.bearing_rad[sel] - (np.arctan2(d[:, 1], d[:, 0]) - pose[:, 2]))
    ok = np.isfinite(true_range) & np.isfinite(bearing_err) & (true_range > 0.1)
    return true_range[ok], meas.range_m[sel][ok], meas.bearing_rad[sel][ok], bearing_err[ok]


def fit_camera(dataset: MrclamDataset, robot_id: int, start_s: float, end_s: float,
               base: CameraNoise | None = None) -> CameraNoise:
    """Calibrate one robot's camera on its readings in ``[start_s, end_s)`` against the Vicon
    ground truth: the range bias ``measured / true - 1 = c0 + c2 b^2`` (least squares, landmark
    and robot readings separately), then the noise left: ``range_fraction`` (robust std of the
    relative range residual) and ``bearing_std_rad`` (robust std of the bearing error).
    Readings with a bearing error above 0.1 rad or a relative range error above 25 % (misreads)
    are left out of the fit. Fewer than 20 usable readings of a kind: that kind is not
    corrected."""
    base = base or CameraNoise()
    values = {}
    residuals, bearing_errors = [], []
    for kind, prefix in (("landmark", ""), ("robot", "teammate_")):
        true_range, measured, bearing, bearing_err = _reading_errors(dataset, robot_id, kind,
                                                                     start_s, end_s)
        rel = measured / true_range - 1.0
        good = (np.abs(bearing_err) < 0.1) & (np.abs(rel) < 0.25)
        if good.sum() < 20:
            continue
        design = np.column_stack([np.ones(good.sum()), bearing[good] ** 2])
        (c0, c2), *_ = np.linalg.lstsq(design, rel[good], rcond=None)
        values[f"{prefix}range_bias_c0"] = float(c0)
        values[f"{prefix}range_bias_c2"] = float(c2)
        residuals.append(rel[good] - design @ np.array([c0, c2]))
        bearing_errors.append(bearing_err[good])
    if residuals:
        values["range_fraction"] = robust_std(np.concatenate(residuals))
        values["bearing_std_rad"] = max(robust_std(np.concatenate(bearing_errors)), 1e-3)
    return replace(base, **values)


def robot_rng(seed: int, robot_id: int) -> np.random.Generator:
    return np.random.default_rng([seed, MRCLAM_STREAM, robot_id])


def replay_world(dataset: MrclamDataset, config: ReplayConfig) -> ReplayWorld:
    """The replay world of ``config`` (its tick and duration)."""
    end = None
    if config.duration_s is not None:
        end = dataset.time_span_s()[0] + config.duration_s
    kidnap = None
    if config.kidnap_s is not None:
        rid = dataset.robot_ids[0] if config.kidnap_robot is None else config.kidnap_robot
        if rid not in dataset.robot_ids:
            raise ValueError(f"kidnap_robot: {rid} is not a robot of {dataset.name} "
                             f"({', '.join(map(str, dataset.robot_ids))})")
        kidnap = (rid, dataset.time_span_s()[0] + config.kidnap_s, KIDNAP_JUMP)
    return ReplayWorld(dataset, config.dt_s, end_s=end, kidnap=kidnap,
                       true_heading=config.heading == "truth",
                       landmark_robots=config.landmark_robots, links=config.links)


def parse_links(links) -> dict[int, tuple[int, ...]]:
    """``links`` as ``{receiver: (senders...)}`` from a mapping (keys may be strings, as TOML
    writes them) or a string ``"1:2 2:3"`` (receiver:sender,sender ...); ``ValueError`` naming
    the key."""
    if isinstance(links, str):
        pairs = {}
        for item in links.split():
            receiver, sep, senders = item.partition(":")
            if not sep:
                raise ValueError(f"links: expected RECEIVER:SENDER[,SENDER] items, got {item!r}")
            pairs[receiver] = senders.split(",") if senders else []
        links = pairs
    if not isinstance(links, Mapping):
        raise ValueError(f"links: expected a mapping receiver -> list of senders, got {links!r}")  # noqa: TRY004
    out = {}
    for receiver, senders in links.items():
        try:
            key = int(receiver)
            values = tuple(int(v) for v in (senders if isinstance(senders, (list, tuple)) else [senders]))
        except (TypeError, ValueError):
            raise ValueError(f"links: robot ids must be integers, got {receiver!r}: {senders!r}") from None
        if isinstance(receiver, bool) or any(isinstance(v, bool) for v in values):
            raise ValueError(f"links: robot ids must be integers, got {receiver!r}: {senders!r}")
        out[key] = values
    return out


def replay_localizer(dataset: MrclamDataset, world: ReplayWorld, config: ReplayConfig, rid: int,
                     initial_pose: np.ndarray | None = None):
    """Robot ``rid``'s localizer, built as every runner builds it (in-process or an agent
    process): its camera calibrated if asked, its known initial pose, its generator."""
    if initial_pose is None:
        initial_pose = world.initial_poses()[world.robot_ids.index(rid)]
    camera = config.camera
    if config.calibration == "vicon" and config.calibration_s:
        camera = fit_camera(dataset, rid, world.start_s, world.start_s + config.calibration_s,
                            camera)
    unknown = config.start == "unknown"
    lm = dataset.landmarks.xy_m
    setup = LandmarkSetup(robot_id=rid, landmark_ids=dataset.landmarks.ids,
                          landmark_xy_m=lm,
                          initial_pose=lm.mean(axis=0).tolist() + [0.0] if unknown else initial_pose,
                          initial_std=config.initial_std, motion=config.motion,
                          camera=camera, cooperative=config.cooperative,
                          initial_area_m=((*lm.min(axis=0), *lm.max(axis=0)) if unknown else None))
    brain = build_localizer(config.algorithm, setup, robot_rng(config.seed, rid), config.params)
    if config.calibration in ("self", "self-own"):
        brain = SelfCalibratingLocalizer(
            brain, SelfCalibrationParams(from_teammates=config.calibration == "self"))
    return brain


def run_replay(dataset: MrclamDataset, config: ReplayConfig) -> ReplayResult:
    """Replay ``dataset`` through one localizer per robot (see the module docstring)."""
    world = replay_world(dataset, config)
    initial = world.initial_poses()
    brains = {rid: replay_localizer(dataset, world, config, rid, initial[i])
              for i, rid in enumerate(world.robot_ids)}
    n = len(world.robot_ids)
    estimates = np.empty((world.n_ticks, n, 3))
    covariance = np.full((world.n_ticks, n, 2, 2), np.nan)
    heading_var = np.full((world.n_ticks, n), np.nan)
    rejected = 0
    t0 = time.process_time()
    while not world.done:
        k = world.tick
        outgoing = {}
        for i, obs in enumerate(world.observe()):
            brain = brains[obs.robot_id]
            brain.step(obs)
            estimates[k, i] = brain.estimate()
            cov_xy = getattr(brain, "covariance_xy", None)
            if cov_xy is not None and (c := cov_xy()) is not None:
                covariance[k, i] = c
            var_h = getattr(brain, "heading_variance", None)
            if var_h is not None and (v := var_h()) is not None:
                heading_var[k, i] = v
            outgoing[obs.robot_id] = brain.outgoing()
            rejected += len(getattr(brain, "rejected", ()))
        world.step(outgoing)
    cpu = time.process_time() - t0
    nis = {}
    for rid, brain in brains.items():
        nis_scores = getattr(getattr(brain, "inner", brain), "nis_scores", None)
        if nis_scores is not None:
            nis[rid] = nis_scores()
    return ReplayResult(config, world.robot_ids, world.tick_end_times_s.copy(), estimates,
                        world.ground_truth(), cpu, rejected, world.kidnap_tick, covariance, nis,
                        heading_var)


def rmse_at_truth_stamps(result: ReplayResult, dataset: MrclamDataset) -> dict[int, float]:
    """Per robot, the position RMSE at every ground-truth stamp inside the replay (CoLo-AT's
    metric, issue 46): the estimate at a stamp interpolated linearly between the ends of the
    ticks around it (stamps before the first tick's end are left out)."""
    out = {}
    t = result.times_s
    for i, rid in enumerate(result.robot_ids):
        rec = dataset.robots[rid]
        stamps = rec.groundtruth_time_s
        sel = (stamps >= t[0]) & (stamps <= t[-1])
        if not sel.any():
            out[rid] = math.nan
            continue
        gt = rec.groundtruth_pose[sel]
        ex = np.interp(stamps[sel], t, result.estimates[:, i, 0])
        ey = np.interp(stamps[sel], t, result.estimates[:, i, 1])
        out[rid] = float(np.sqrt(np.mean((ex - gt[:, 0]) ** 2 + (ey - gt[:, 1]) ** 2)))
    return out


def write_tum(result: ReplayResult, out_dir: Path) -> list[Path]:
    """The estimated and the true trajectory of every robot in the TUM format that evo and
    others read (``t x y z qx qy qz qw`` a line, ``z = 0``, the heading as a rotation about z):
    ``estimate_R<id>.tum`` (every tick) and ``groundtruth_R<id>.tum`` (the ticks with ground
    truth). Returns the paths."""
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    paths = []
    for i, rid in enumerate(result.robot_ids):
        for name, poses in (("estimate", result.estimates[:, i]), ("groundtruth", result.truth[:, i])):
            ok = np.isfinite(poses).all(axis=1)
            half = 0.5 * poses[ok, 2]
            rows = np.column_stack([result.times_s[ok], poses[ok, 0], poses[ok, 1],
                                    np.zeros(ok.sum()), np.zeros(ok.sum()), np.zeros(ok.sum()),
                                    np.sin(half), np.cos(half)])
            path = out / f"{name}_R{rid}.tum"
            np.savetxt(path, rows, fmt="%.6f")
            paths.append(path)
    return paths


def trajectory_errors(result: ReplayResult, rpe_delta_m: float = 1.0) -> dict[int, dict[str, float]]:
    """Per robot, evo's absolute and relative trajectory error (translation part, no alignment:
    the estimates are in the landmarks' frame): ``ape_rmse_m``, and ``rpe_rmse_m`` over pose
    pairs ``rpe_delta_m`` of travel apart (evo's ``Unit.meters``), on the ticks with ground truth
    (issue 46)."""
    from evo.core import metrics
    from evo.core.trajectory import PoseTrajectory3D

    out = {}
    for i, rid in enumerate(result.robot_ids):
        ok = np.isfinite(result.truth[:, i]).all(axis=1)
        if ok.sum() < 2:
            out[rid] = {"ape_rmse_m": math.nan, "rpe_rmse_m": math.nan}
            continue
        trajectories = []
        for poses in (result.truth[ok, i], result.estimates[ok, i]):
            half = 0.5 * poses[:, 2]
            quat = np.column_stack([np.cos(half), np.zeros(half.size), np.zeros(half.size),
                                    np.sin(half)])
            xyz = np.column_stack([poses[:, :2], np.zeros(half.size)])
            trajectories.append(PoseTrajectory3D(positions_xyz=xyz, orientations_quat_wxyz=quat,
                                                 timestamps=result.times_s[ok]))
        ape = metrics.APE(metrics.PoseRelation.translation_part)
        ape.process_data(tuple(trajectories))
        rpe = metrics.RPE(metrics.PoseRelation.translation_part, delta=rpe_delta_m,
                          delta_unit=metrics.Unit.meters, all_pairs=False)
        try:
            rpe.process_data(tuple(trajectories))
            rpe_rmse = float(rpe.get_statistic(metrics.StatisticsType.rmse))
        except Exception:  # noqa: BLE001 -- evo raises its own types when too short a path
            rpe_rmse = math.nan
        out[rid] = {"ape_rmse_m": float(ape.get_statistic(metrics.StatisticsType.rmse)),
                    "rpe_rmse_m": rpe_rmse}
    return out


def localized_from(error_m: np.ndarray, threshold_m: float = LOCALIZED_M) -> int | None:
    """The first tick from which the error (``(T,)``, NaN where unscored) is under
    ``threshold_m`` at every scored tick to the end; None if the last scored tick is not."""
    scored = np.flatnonzero(np.isfinite(error_m))
    if not scored.size:
        return None
    bad = scored[error_m[scored] >= threshold_m]
    if not bad.size:
        return 0
    if bad[-1] == scored[-1]:
        return None
    return int(bad[-1]) + 1


def score(result: ReplayResult) -> dict[int, dict[str, float]]:
    """Per robot: position RMSE [m], heading RMSE [rad], final position error [m], the number
    of ticks scored; ``localized_s``, the time from the start until the error falls under
    :data:`LOCALIZED_M` and stays there to the end (NaN: never), and ``rmse_localized_m``, the
    position RMSE from then on; for the kidnapped robot ``recovery_s``, the same time counted
    from the kidnap (NaN for the others, or if it never recovers). Consistency is
    :func:`consistency`'s."""
    out = {}
    err = result.position_error_m()
    heading = wrap_angle(result.estimates[..., 2] - result.truth[..., 2])
    dt = result.config.dt_s
    start = result.times_s[0] - dt
    for i, rid in enumerate(result.robot_ids):
        ok = np.isfinite(err[:, i])
        last = np.flatnonzero(ok)[-1] if ok.any() else None
        k = localized_from(err[:, i])
        after = err[k:, i][np.isfinite(err[k:, i])] if k is not None else np.zeros(0)
        recovery = math.nan
        if result.kidnap is not None and result.kidnap[0] == rid:
            kk = result.kidnap[1]
            back = localized_from(err[kk:, i])
            if back is not None:
                recovery = float(result.times_s[kk + back] - result.times_s[kk])
        out[rid] = {
            "position_rmse_m": float(np.sqrt(np.mean(err[ok, i] ** 2))) if ok.any() else math.nan,
            "heading_rmse_rad": float(np.sqrt(np.mean(heading[ok, i] ** 2))) if ok.any() else math.nan,
            "final_error_m": float(err[last, i]) if last is not None else math.nan,
            "scored_ticks": int(ok.sum()),
            "localized_s": float(result.times_s[k] - dt - start) if k is not None else math.nan,
            "rmse_localized_m": float(np.sqrt(np.mean(after**2))) if after.size else math.nan,
            "recovery_s": recovery,
        }
    return out


def consistency(result: ReplayResult) -> dict[int, dict[str, float]]:
    """Per robot, for localizers that give a covariance (issue 46): ``position_nees_mean``, the
    mean over scored ticks of the position's normalized estimation error squared ``e^T P^-1 e``
    (2 for a consistent filter; larger: overconfident), and ``position_nees_in_95``, the share of
    those ticks within the chi-square 95 % quantile for 2 degrees of freedom (0.95 if
    consistent), and ``position_cov_trace_m2``, the mean trace of the position covariance (what
    CoLo-AT plots); NaN without a covariance. Apart from :func:`score`, whose figures the process
    path reproduces (an agent process reports its estimate, not its covariance)."""
    nees = position_nees(result)
    nees_h = heading_nees(result)
    out = {}
    for i, rid in enumerate(result.robot_ids):
        ok = np.isfinite(nees[:, i])
        v = nees[ok, i]
        h = nees_h[np.isfinite(nees_h[:, i]), i]
        trace = (np.trace(result.covariance_xy[ok, i], axis1=-2, axis2=-1)
                 if v.size and result.covariance_xy is not None else np.zeros(0))
        out[rid] = {"position_nees_mean": float(np.mean(v)) if v.size else math.nan,
                    "position_nees_in_95": float(np.mean(v <= CHI2_2DOF_95)) if v.size else math.nan,
                    "position_cov_trace_m2": float(np.mean(trace)) if trace.size else math.nan,
                    "heading_nees_mean": float(np.mean(h)) if h.size else math.nan,
                    "heading_nees_in_95": float(np.mean(h <= CHI2_1DOF_95)) if h.size else math.nan}
    return out


#: chi-square 95 % quantile, 1 degree of freedom (the heading alone).
CHI2_1DOF_95 = 3.841458820694124


def heading_nees(result: ReplayResult) -> np.ndarray:
    """(T, N) each tick's heading NEES ``e^2 / var`` with ``e`` the wrapped heading error (NaN
    without a heading variance or truth)."""
    out = np.full(result.estimates.shape[:2], np.nan)
    if result.heading_variance is None:
        return out
    e = np.angle(np.exp(1j * (result.estimates[..., 2] - result.truth[..., 2])))
    var = result.heading_variance
    have = np.isfinite(e) & np.isfinite(var) & (var > 0)
    out[have] = e[have] ** 2 / var[have]
    return out


def position_nees(result: ReplayResult) -> np.ndarray:
    """(T, N) each tick's position NEES ``e^T P^-1 e`` (NaN without a covariance or truth)."""
    out = np.full(result.estimates.shape[:2], np.nan)
    if result.covariance_xy is None:
        return out
    e = result.estimates[..., :2] - result.truth[..., :2]
    c = result.covariance_xy
    have = np.isfinite(e).all(axis=-1) & np.isfinite(c).all(axis=(-2, -1))
    if have.any():
        sol = np.linalg.solve(c[have], e[have][..., None])[..., 0]
        out[have] = np.einsum("ij,ij->i", e[have], sol)
    return out
