"""The replay world: an MRCLAM data set fed to the robots' localizers tick by tick, in lockstep.

Instead of simulating, this world replays what the real robots recorded (see
:mod:`swarmloc.world.replay.mrclam`). It has the world's per-tick shape, so the same localizer objects
run here in-process and, behind a world-server shell, over Zenoh:

    world = ReplayWorld(dataset, dt_s=0.02)
    while not world.done:
        observations = world.observe()          # one LandmarkObservation per robot
        world.step({o.robot_id: brains[o.robot_id].step(o) or brains[o.robot_id].outgoing()
                    for o in observations})     # payloads broadcast, delivered next tick

Tick ``k`` covers ``(t_k, t_k + dt]`` with ``t_k = start + k dt``. Its observation holds, for each
robot:

- **odometry** ``(v, omega, dt)``: the mean of the logged velocity commands over the tick, each
  held from its time stamp until the next one (zero-order hold; at most ``odometry_hold_s``, so
  a robot whose log ends stops). Dataset 6 has gaps of up to 1.03 s in the odometry log during
  which the Vicon ground truth shows the robots kept moving at about the held command, hence
  the hold. Integrating the unicycle over a tick with the mean command differs from integrating
  the 67 Hz samples by terms of order ``v omega dt^2`` (below 0.1 mm at 0.02 s);
- **landmark measurements** (subject id, range, bearing) and **robot measurements** (robot id,
  range, bearing) whose time stamp is nearest to the tick's end ``t_k + dt`` (so a measurement
  is applied at most ``dt / 2`` from when it was taken). Several per tick are common: one camera
  frame reads several barcodes;
- **received**: the payloads every other robot returned to :meth:`ReplayWorld.step` at the
  previous tick (a broadcast medium with no loss: the MRCLAM robots shared a WiFi network; the
  data set records no communication, so any robot can hear any other).

Why ``dt = 0.02 s`` by default: measurements are applied at the tick's end, so a tick of ``dt``
shifts a bearing by up to ``omega dt / 2`` (the robots turn at up to 0.57 rad/s). At 0.02 s
that is at most 0.006 rad, below the camera's bearing noise (0.012-0.016 rad, SOURCE.md); at
0.1 s it would be up to 0.029 rad, twice the noise, i.e. 0.09 m across at a 3 m range. The
odometry is logged at 67 Hz (15 ms), so 0.02 s ticks also keep one tick close to one sample.
``dt`` is a parameter; 0.1 s runs five times fewer ticks.

Pure: no Zenoh, no clock, no randomness (the data set is the randomness).
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass

import numpy as np

from swarmloc.agents.laser.localizer import RadioMessage
from swarmloc.protocol.messages import MAX_RADIO_PAYLOAD_BYTES
from swarmloc.world.replay.mrclam import MrclamDataset, RobotRecord

#: Default tick length, see the module docstring.
DEFAULT_DT_S = 0.02
#: A logged velocity command holds until the next one, for at most this long (longest gap in
#: Dataset 6's odometry logs: 1.03 s, during which the ground truth shows motion).
DEFAULT_ODOMETRY_HOLD_S = 1.5
#: Upper bound on one robot's outgoing payload (a pose, a covariance and a few measurements need
#: about 200 bytes; a particle filter that shares a sample of particles needs a few KiB): the
#: protocol's radio bound, as for the laser robots.
MAX_PAYLOAD_BYTES = MAX_RADIO_PAYLOAD_BYTES
#: A payload teammate ``sender_id`` broadcast at the previous tick: the laser robots' radio
#: message, one type for every family's radio.
Message = RadioMessage


@dataclass(frozen=True)
class LandmarkObservation:
    """What one robot gets at one tick of the replay (see the module docstring)."""

    robot_id: int
    tick: int
    time_s: float  #: end of the tick, seconds since the data set's epoch
    odometry_v_mps: float  #: mean forward velocity command over the tick
    odometry_omega_rad_s: float  #: mean angular velocity command over the tick
    odometry_dt_s: float
    landmark_ids: np.ndarray  #: (K,) landmark subject ids
    landmark_range_m: np.ndarray  #: (K,)
    landmark_bearing_rad: np.ndarray  #: (K,) in the body frame, counter-clockwise
    robot_ids: np.ndarray  #: (M,) ids of the teammates seen
    robot_range_m: np.ndarray  #: (M,)
    robot_bearing_rad: np.ndarray  #: (M,)
    received: tuple[Message, ...] = ()
    #: The robot's true heading at the tick's end from the ground truth, given only when the
    #: replay is told to (``ReplayWorld(true_heading=True)``: CoLo-AT's setting, issue 46);
    #: None otherwise. Where the ground truth has a gap or has ended, the last known heading.
    true_heading_rad: float | None = None
    #: ``sum dt_i^2`` over the odometry messages recorded in this tick, ``dt_i`` each one's gap
    #: to the message before (a gap in the log counts whole in the tick that ends it): what
    #: CoLo-AT's per-message propagation adds its noise with (issue 46); None: not given.
    odometry_gap2_s2: float | None = None


def _check_positive(value, name: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not math.isfinite(value) \
            or value <= 0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")
    return float(value)


def mean_commands(record: RobotRecord, boundaries_s: np.ndarray,
                  hold_s: float = DEFAULT_ODOMETRY_HOLD_S) -> tuple[np.ndarray, np.ndarray]:
    """Mean ``(v, omega)`` of the held commands over each interval between consecutive
    ``boundaries_s`` (``(T+1,)`` -> two ``(T,)`` arrays)."""
    t = record.odometry_time_s
    if t.size == 0:
        zeros = np.zeros(boundaries_s.size - 1)
        return zeros, zeros.copy()
    ends = np.minimum(np.append(t[1:], np.inf), t + hold_s)
    means = []
    for command in (record.odometry_v_mps, record.odometry_omega_rad_s):
        # The integral of the held command is piecewise linear with knots at every sample time
        # and every hold end: F(t_i) accumulates, F(end_i) = F(t_i) + c_i (end_i - t_i).
        held = command * (ends - t)
        at_start = np.concatenate([[0.0], np.cumsum(held)[:-1]])
        knots_t = np.column_stack([t, ends]).ravel()
        knots_f = np.column_stack([at_start, at_start + held]).ravel()
        integral = np.interp(boundaries_s, knots_t, knots_f)
        means.append(np.diff(integral) / np.diff(boundaries_s))
    return means[0], means[1]


class _Schedule:
    """One kind of measurement of one robot, grouped by tick: rows ``bounds[k]:bounds[k+1]``."""

    def __init__(self, time_s, subject, range_m, bearing_rad, start_s, dt_s, n_ticks):
        boundary = np.rint((time_s - start_s) / dt_s).astype(np.int64)  # nearest tick end
        tick = boundary - 1
        keep = (tick >= 0) & (tick < n_ticks)
        order = np.argsort(tick[keep], kind="stable")
        self.subject = subject[keep][order].astype(np.int64)
        self.range_m = range_m[keep][order].astype(np.float64)
        self.bearing_rad = bearing_rad[keep][order].astype(np.float64)
        self.bounds = np.searchsorted(tick[keep][order], np.arange(n_ticks + 1))

    def at(self, k: int):
        a, b = self.bounds[k], self.bounds[k + 1]
        return self.subject[a:b], self.range_m[a:b], self.bearing_rad[a:b]


class ReplayWorld:
    """Lockstep replay of one data set (see the module docstring).

    ``start_s``/``end_s`` (relative to the data set's epoch) default to its full span
    (:meth:`MrclamDataset.time_span_s`); ``n_ticks = floor((end - start) / dt)``.
    """

    def __init__(self, dataset: MrclamDataset, dt_s: float = DEFAULT_DT_S, *,
                 start_s: float | None = None, end_s: float | None = None,
                 odometry_hold_s: float = DEFAULT_ODOMETRY_HOLD_S,
                 kidnap: tuple[int, float, tuple[float, float]] | None = None,
                 true_heading: bool = False,
                 landmark_robots: tuple[int, ...] | None = None,
                 links: Mapping[int, tuple[int, ...]] | None = None):
        """``true_heading``: every observation carries the robot's true heading (CoLo-AT's
        setting); ``landmark_robots``: only these robots get their landmark readings (None:
        every robot); ``links``: receiver id -> the sender ids it hears (None: everyone hears
        everyone; a robot not listed hears nobody)."""
        self.dataset = dataset
        self.dt_s = _check_positive(dt_s, "dt_s")
        hold = _check_positive(odometry_hold_s, "odometry_hold_s")
        span_start, span_end = dataset.time_span_s()
        self.start_s = span_start if start_s is None else float(start_s)
        end = span_end if end_s is None else float(end_s)
        if not (math.isfinite(self.start_s) and math.isfinite(end)) or end <= self.start_s:
            raise ValueError(f"end_s ({end}) must be after start_s ({self.start_s})")
        self.n_ticks = math.floor((end - self.start_s) / self.dt_s + 1e-9)
        if self.n_ticks < 1:
            raise ValueError(f"dt_s={self.dt_s} is longer than the replayed span {end - self.start_s} s")
        self.robot_ids: tuple[int, ...] = dataset.robot_ids
        #: Tick boundaries ``(n_ticks + 1,)``: tick k ends at ``boundaries_s[k + 1]``.
        self.boundaries_s = self.start_s + self.dt_s * np.arange(self.n_ticks + 1)
        self._v, self._omega, self._landmarks, self._robots = [], [], [], []
        for rid in self.robot_ids:
            rec = dataset.robots[rid]
            v, omega = mean_commands(rec, self.boundaries_s, hold)
            self._v.append(v.tolist())
            self._omega.append(omega.tolist())
            for store, meas in ((self._landmarks, rec.landmark_measurements),
                                (self._robots, rec.robot_measurements)):
                store.append(_Schedule(meas.time_s, meas.subject, meas.range_m, meas.bearing_rad,
                                       self.start_s, self.dt_s, self.n_ticks))
        #: ``(robot id, tick)`` of the kidnap, or None.
        self.kidnap_tick: tuple[int, int] | None = None
        if kidnap is not None:
            self._kidnap(*kidnap)
        for name, ids in (("landmark_robots", landmark_robots or ()),
                          ("links", [*(links or {}), *(j for v in (links or {}).values() for j in v)])):
            for rid in ids:
                if rid not in self.robot_ids:
                    raise ValueError(f"{name}: no robot {rid!r} in {dataset.name} "
                                     f"(robots {', '.join(map(str, self.robot_ids))})")
        self.landmark_robots = None if landmark_robots is None else tuple(landmark_robots)
        self.links = None if links is None else {int(k): tuple(v) for k, v in links.items()}
        self._true_heading: list[list[float]] | None = None
        if true_heading:
            self._true_heading = []
            for rid in self.robot_ids:
                theta = dataset.robots[rid].pose_at(self.boundaries_s[1:], max_gap_s=np.inf)[:, 2]
                known = np.flatnonzero(np.isfinite(theta))
                if not known.size:
                    raise ValueError(f"true_heading: robot {rid} has no ground truth in the replay")
                # the last known heading across a gap or after the log's end (the first known
                # one before it starts)
                fill = known[np.clip(np.searchsorted(known, np.arange(theta.size), "right") - 1,
                                     0, None)]
                self._true_heading.append(theta[fill].tolist())
        self._gap2 = []
        for rid in self.robot_ids:  # each odometry message's squared gap, in the tick it ends
            t = dataset.robots[rid].odometry_time_s
            k = np.searchsorted(self.boundaries_s[1:], t[1:], side="left")
            inside = (t[1:] > self.boundaries_s[0]) & (k < self.n_ticks)
            gap2 = np.zeros(self.n_ticks)
            np.add.at(gap2, k[inside], np.square(np.diff(t))[inside])
            self._gap2.append(gap2.tolist())
        self.tick = 0
        self._inbox: dict[int, tuple[Message, ...]] = {rid: () for rid in self.robot_ids}

    def _kidnap(self, robot_id: int, time_s: float, jump: tuple[float, float]) -> None:
        """Kidnap the estimate of ``robot_id`` at the tick that ends at or after ``time_s``: its
        odometry of that tick also says it drove ``jump = (distance_m, turn_rad)`` (the robot
        did not move; every localizer applies it as motion, so its estimate is teleported)."""
        if robot_id not in self.robot_ids:
            raise ValueError(f"kidnap: no robot {robot_id!r} in this replay (robots {self.robot_ids})")
        k = int(np.searchsorted(self.boundaries_s[1:], time_s - 1e-9))
        if k >= self.n_ticks:
            raise ValueError(f"kidnap: time {time_s} s is after the replay's end "
                             f"({self.boundaries_s[-1]} s)")
        i = self.robot_ids.index(robot_id)
        distance_m, turn_rad = jump
        self._v[i][k] += distance_m / self.dt_s
        self._omega[i][k] += turn_rad / self.dt_s
        self.kidnap_tick = (robot_id, k)

    @property
    def done(self) -> bool:
        return self.tick >= self.n_ticks

    @property
    def tick_end_times_s(self) -> np.ndarray:
        """``(n_ticks,)``: the time each tick's estimates refer to."""
        return self.boundaries_s[1:]

    def initial_poses(self) -> np.ndarray:
        """``(N, 3)`` ground-truth poses at the start (the filters' known initial poses)."""
        out = np.empty((len(self.robot_ids), 3))
        for i, rid in enumerate(self.robot_ids):
            out[i] = self.dataset.robots[rid].pose_at([self.start_s], max_gap_s=np.inf)[0]
        return out

    def ground_truth(self) -> np.ndarray:
        """``(n_ticks, N, 3)`` ground truth at each tick's end, NaN where it is unknown (after
        its log ends or inside a long gap). Evaluation only: never shown to the robots."""
        times = self.tick_end_times_s
        return np.stack([self.dataset.robots[rid].pose_at(times) for rid in self.robot_ids],
                        axis=1)

    def observe(self) -> list[LandmarkObservation]:
        """The current tick's observation for every robot, in :attr:`robot_ids` order."""
        if self.done:
            raise RuntimeError(f"the replay has ended after {self.n_ticks} ticks")
        k = self.tick
        time_s = float(self.boundaries_s[k + 1])
        out = []
        for i, rid in enumerate(self.robot_ids):
            lm_ids, lm_range, lm_bearing = self._landmarks[i].at(k)
            if self.landmark_robots is not None and rid not in self.landmark_robots:
                lm_ids, lm_range, lm_bearing = lm_ids[:0], lm_range[:0], lm_bearing[:0]
            r_ids, r_range, r_bearing = self._robots[i].at(k)
            out.append(LandmarkObservation(
                robot_id=rid, tick=k, time_s=time_s, odometry_v_mps=self._v[i][k],
                odometry_omega_rad_s=self._omega[i][k], odometry_dt_s=self.dt_s,
                landmark_ids=lm_ids, landmark_range_m=lm_range, landmark_bearing_rad=lm_bearing,
                robot_ids=r_ids, robot_range_m=r_range, robot_bearing_rad=r_bearing,
                received=self._inbox[rid],
                true_heading_rad=None if self._true_heading is None else self._true_heading[i][k],
                odometry_gap2_s2=self._gap2[i][k]))
        return out

    def step(self, outgoing: Mapping[int, bytes | None]) -> None:
        """End the tick: each robot's payload (or None) is delivered to every other robot at
        the next tick. A robot missing from ``outgoing`` sends nothing."""
        if self.done:
            raise RuntimeError(f"the replay has ended after {self.n_ticks} ticks")
        messages = []
        for rid, payload in outgoing.items():
            if rid not in self._inbox:
                raise ValueError(f"outgoing: no robot {rid!r} in this replay (robots {self.robot_ids})")
            if payload is None:
                continue
            if not isinstance(payload, (bytes, bytearray)):
                raise TypeError(f"outgoing[{rid}]: payload must be bytes or None, "
                                f"got {type(payload).__name__}")
            if len(payload) > MAX_PAYLOAD_BYTES:
                raise ValueError(f"outgoing[{rid}]: payload of {len(payload)} bytes exceeds "
                                 f"{MAX_PAYLOAD_BYTES}")
            messages.append(Message(int(rid), bytes(payload)))
        messages.sort(key=lambda m: m.sender_id)
        self._inbox = {rid: tuple(m for m in messages if m.sender_id != rid and
                                  (self.links is None or m.sender_id in self.links.get(rid, ())))
                       for rid in self.robot_ids}
        self.tick += 1
