"""The e-puck foraging brain: subsumption controller with social odometry (seed 000 §4-5).

Layers, highest priority first (seed 000 §5, fig. 12):

- *avoid*: when an IR proximity reading is above a threshold, turn away from the obstacle vector;
- *receive data* / *send data*: every tick the robot broadcasts its goal estimates in its own body
  frame, and fuses what it hears with the strategy's filter (:mod:`.social_odometry`);
- *forage*: with a target goal, steer to its estimate by dead reckoning; on arriving in the area
  (ground sensors) store the estimate and head for the other area; arriving where the area should
  be and not finding it within ``search_overshoot_m`` means *lost*: both goal memories are reset;
- *wander*: random walk (straight for a random time, then turn in place by a random angle).

Dead reckoning integrates the encoder counts with seed 000 eq. 7. Goal estimates live in the
robot's odometric frame; ``p`` (inverse confidence, eq. 23) is the distance travelled since the
robot last left the area, in metres.

Everything is over a batch of robots, so one agent process runs a batch of one and the batch
engine the whole swarm. The only per-robot Python loop is over robots that need a random draw
this tick (each robot owns its generator, derived from the run seed and its id).

Modelling choices the papers leave open are named in :class:`AgentConfig`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgpack
import numpy as np

from swarmloc.agents.social_odometry import STRATEGIES, fuse, transform_received
from swarmloc.protocol.epuck import (  # noqa: F401 -- on_path is part of this module's API
    IR_SENSOR_ANGLES_RAD,
    STATE_KNOWS_BOTH,
    EpuckBody,
    ground_sensor_point,
    integrate_pose,
    on_path,
    propagate_covariance,
    wrap_angle,
)

NEST, PREY = 0, 1

#: Stream id that separates the agents' generators from the world's (``[seed, stream, id]``).
AGENT_STREAM = 1


def agent_rng(seed: int, robot_id: int) -> np.random.Generator:
    """Each agent's own generator, derived from the run seed and its robot id."""
    return np.random.default_rng([seed, AGENT_STREAM, robot_id])

#: Controller state codes reported in every Act (the contract is in protocol/epuck.py).
TARGET_NONE, TARGET_NEST, TARGET_PREY = 0, 1, 2
KNOWS_BOTH = STATE_KNOWS_BOTH

# Ground perception: reflectance bands of seed 000 §6.1 (black nest, grey prey, white floor,
# each with +-30 % noise) are disjoint; the thresholds sit between them.
GROUND_BLACK_BELOW = 0.25
GROUND_GREY_BELOW = 0.68

_XY_BLOCK = np.diag([1.0, 1.0, 0.0])

_COS_IR = np.cos(IR_SENSOR_ANGLES_RAD)
_SIN_IR = np.sin(IR_SENSOR_ANGLES_RAD)


def classify_ground(ground: np.ndarray) -> np.ndarray:
    """What each robot believes it stands on from its 3 ground readings ``(N, 3)``.

    Returns ``(N,)`` codes: -1 floor, ``NEST`` (any sensor black) or ``PREY`` (any sensor grey).
    """
    black = (ground < GROUND_BLACK_BELOW).any(axis=1)
    grey = ((ground >= GROUND_BLACK_BELOW) & (ground < GROUND_GREY_BELOW)).any(axis=1)
    return np.where(black, NEST, np.where(grey, PREY, -1))


@dataclass(frozen=True)
class AgentConfig:
    """Parameters of the foraging brain. The papers state the strategy names and beta range;
    speeds, thresholds and the random walk are ours (seed 000 does not give them)."""

    strategy: str = "SSGIKF"
    #: Fermi beta of the SGIFFs (seed 000 §6.1.2 sweeps 1e-5 .. 100).
    beta: float = 0.01
    #: Unit of ``p`` in the Fermi rule: the papers do not state it; centimetres make beta = 1e-2
    #: act on differences of about a metre, the scale of the ES1 path.
    confidence_unit_m: float = 0.01
    cruise_speed_steps_s: float = 800.0
    turn_speed_steps_s: float = 500.0
    #: Proportional steering: wheel speed difference per radian of heading error.
    steering_gain: float = 1.2
    #: Heading error above which the robot turns in place.
    turn_in_place_rad: float = 0.6
    avoid_threshold: float = 0.15
    wander_straight_s: tuple[float, float] = (2.0, 8.0)
    arrival_tolerance_m: float = 0.02
    #: How far past the estimated goal the robot keeps looking before it declares itself lost.
    search_overshoot_m: float = 0.10
    #: The odometry error constants k_r = k_l of seed 000 eq. 10 (m: variance per metre of wheel
    #: travel), known to SIKF robots ("covariance knowledge", seed 001 §5). Default: what the
    #: world's +-20 % uniform slip per tick gives at cruise speed, s^2 |dU| / 3.
    odometry_k_m: float = 1.37e-4
    #: How many neighbours' bearings a robot repeats in its messages (needed for eq. 27).
    heard_capacity: int = 3
    #: Two robots exchange once per encounter (seed 000 §4.1, §5): after an exchange the partner
    #: is ignored until it has been out of hearing for this long. Fusing every message of one
    #: encounter would make the SGIKF overconfident (p shrinks with each correlated copy).
    encounter_gap_s: float = 2.0
    encounter_memory: int = 4

    def __post_init__(self):
        if self.strategy not in STRATEGIES:
            import difflib

            close = difflib.get_close_matches(self.strategy, list(STRATEGIES), n=1, cutoff=0.3)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise ValueError(
                f"strategy: unknown strategy '{self.strategy}'{hint} "
                f"(known: {', '.join(STRATEGIES)})"
            )
        for name in (
            "confidence_unit_m",
            "cruise_speed_steps_s",
            "turn_speed_steps_s",
            "arrival_tolerance_m",
            "turn_in_place_rad",
            "odometry_k_m",
        ):
            if not getattr(self, name) > 0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)}")
        if not self.beta >= 0:
            raise ValueError(f"beta: must be >= 0, got {self.beta}")
        for name in ("cruise_speed_steps_s", "turn_speed_steps_s"):
            if getattr(self, name) > EpuckBody().max_wheel_speed_steps_s:
                raise ValueError(f"{name}: at most {EpuckBody().max_wheel_speed_steps_s} steps/s")
        lo, hi = self.wander_straight_s
        if not 0 < lo <= hi:
            raise ValueError(f"wander_straight_s: need 0 < min <= max, got {self.wander_straight_s}")
        if self.search_overshoot_m < 0 or self.avoid_threshold <= 0 or self.steering_gain <= 0:
            raise ValueError("search_overshoot_m, avoid_threshold and steering_gain must be positive")
        if self.encounter_gap_s < 0 or not 1 <= self.encounter_memory <= 16:
            raise ValueError("encounter_gap_s must be >= 0 and encounter_memory in 1..16")
        # 3 is the most that fits the board's 64-byte payload with any robot id.
        if not 0 <= self.heard_capacity <= 3:
            raise ValueError(f"heard_capacity: must be in 0..3, got {self.heard_capacity}")


# --------------------------------------------------------------------------------------------
# Messages robots send each other through the RAB medium.


@dataclass
class SocialMessages:
    """What robots broadcast, one row per message: each goal in the sender's body frame.

    ``goal_*`` are ``(M, 2)`` (nest, prey); ``heard_ids``/``heard_bearing_rad`` ``(M, K)``: the
    neighbours the sender heard last tick and the bearing it measured for each (-1 pads).
    Floats are rounded to float32, the precision they cross the wire with.
    """

    goal_known: np.ndarray
    goal_distance_m: np.ndarray
    goal_angle_rad: np.ndarray
    goal_p_m: np.ndarray
    heard_ids: np.ndarray
    heard_bearing_rad: np.ndarray

    @classmethod
    def empty(cls, m: int, capacity: int) -> SocialMessages:
        return cls(
            np.zeros((m, 2), bool),
            np.zeros((m, 2)),
            np.zeros((m, 2)),
            np.zeros((m, 2)),
            np.full((m, capacity), -1, np.int64),
            np.zeros((m, capacity)),
        )

    def take(self, index: np.ndarray) -> SocialMessages:
        return SocialMessages(*(getattr(self, f)[index] for f in self.__dataclass_fields__))

    def encode(self, row: int) -> bytes:
        """The payload bytes of one message (msgpack, float32): at most 64 bytes."""
        known = self.goal_known[row]
        heard = []
        for rid, bearing in zip(self.heard_ids[row], self.heard_bearing_rad[row]):
            if rid >= 0:
                heard += [int(rid), float(bearing)]
        body = [int(known[0]) | (int(known[1]) << 1)]
        for g in (NEST, PREY):
            body += [
                float(self.goal_distance_m[row, g]),
                float(self.goal_angle_rad[row, g]),
                float(self.goal_p_m[row, g]),
            ]
        body.append(heard)
        return msgpack.packb(body, use_single_float=True)

    @classmethod
    def decode(cls, payloads: list[bytes], capacity: int) -> SocialMessages:
        """Decode payloads; raise ``ValueError`` naming what is wrong in the first bad one."""
        out = cls.empty(len(payloads), capacity)
        for m, payload in enumerate(payloads):
            try:
                body = msgpack.unpackb(payload, max_array_len=16, max_bin_len=0, max_str_len=0)
            except Exception as exc:  # noqa: BLE001 -- msgpack raises many unrelated types
                raise ValueError(f"payload: not a social odometry message ({exc})") from None
            if not isinstance(body, list) or len(body) != 8:
                raise ValueError("payload: expected a list of 8 items")
            flags = body[0]
            if type(flags) is not int or not 0 <= flags <= 3:
                raise ValueError(f"payload.flags: expected 0..3, got {flags!r}")
            values = body[1:7]
            if not all(type(v) is float and math.isfinite(v) for v in values):
                raise ValueError("payload.goals: expected 6 finite floats")
            heard = body[7]
            if not isinstance(heard, list) or len(heard) % 2 or len(heard) > 2 * capacity:
                raise ValueError(f"payload.heard: expected at most {capacity} (id, bearing) pairs")
            for g in (NEST, PREY):
                d, a, p = values[3 * g : 3 * g + 3]
                if not (0.0 <= d <= 100.0 and abs(a) <= math.pi + 1e-5 and 0.0 <= p <= 1e7):
                    raise ValueError(f"payload.goals[{g}]: distance, angle or p out of range")
                out.goal_known[m, g] = bool(flags >> g & 1)
                out.goal_distance_m[m, g] = d
                out.goal_angle_rad[m, g] = a
                out.goal_p_m[m, g] = p
            for k in range(len(heard) // 2):
                rid, bearing = heard[2 * k], heard[2 * k + 1]
                if type(rid) is not int or not 0 <= rid <= 65535:
                    raise ValueError(f"payload.heard[{k}].id: expected 0..65535, got {rid!r}")
                if type(bearing) is not float or not abs(bearing) <= math.pi + 1e-5:
                    raise ValueError(f"payload.heard[{k}].bearing: out of range")
                out.heard_ids[m, k] = rid
                out.heard_bearing_rad[m, k] = bearing
        return out


def _spectral_norm_xy(cov: np.ndarray) -> np.ndarray:
    """Largest eigenvalue of the position block of covariances ``(..., 3, 3)`` (m^2)."""
    a, b, c = cov[..., 0, 0], cov[..., 0, 1], cov[..., 1, 1]
    return (a + c) / 2.0 + np.sqrt(((a - c) / 2.0) ** 2 + b * b)


def _f32(x: np.ndarray) -> np.ndarray:
    return np.asarray(x, np.float32).astype(np.float64)


@dataclass
class Inbox:
    """Messages received this tick by robots of a batch, sorted by (receiver, sender)."""

    receiver: np.ndarray  # (M,) index into the batch
    sender_id: np.ndarray  # (M,) robot id
    range_m: np.ndarray
    bearing_rad: np.ndarray
    content: SocialMessages

    @classmethod
    def empty(cls, capacity: int) -> Inbox:
        z = np.zeros(0)
        return cls(np.zeros(0, np.int64), np.zeros(0, np.int64), z, z, SocialMessages.empty(0, capacity))


@dataclass
class BrainOutput:
    wheel_speed_steps_s: np.ndarray  # (N, 2) left, right
    sending: np.ndarray  # (N,) bool
    messages: SocialMessages  # (N, ...) one row per robot (meaningful where sending)
    state: np.ndarray  # (N,) int state codes
    pose_estimate: np.ndarray  # (N, 3) dead-reckoned pose


def _rank_within(group: np.ndarray) -> np.ndarray:
    """Rank of each element within its run of equal values of a sorted ``group`` array."""
    n = group.shape[0]
    if n == 0:
        return np.zeros(0, np.int64)
    if n == 1:
        return np.zeros(1, np.int64)
    new_run = np.empty(n, bool)
    new_run[0] = True
    np.not_equal(group[1:], group[:-1], out=new_run[1:])
    starts = np.flatnonzero(new_run)
    run_start = np.repeat(starts, np.diff(np.append(starts, n)))
    return np.arange(n) - run_start


class ForagingBrain:
    """Brains of a batch of foraging e-pucks."""

    def __init__(
        self,
        config: AgentConfig,
        body: EpuckBody,
        robot_ids,
        rngs: list[np.random.Generator],
        tick_s: float,
    ):
        self.config = config
        self.body = body
        self.strategy = STRATEGIES[config.strategy]
        self.robot_ids = np.asarray(robot_ids, np.int64)
        n = self.robot_ids.shape[0]
        if len(rngs) != n:
            raise ValueError("one generator per robot")
        self.rngs = rngs
        self.tick_s = tick_s
        self.n = n
        k = config.heard_capacity
        self.pose = np.zeros((n, 3))  # odometric frame: every robot starts at its own origin
        # Poses of the two previous ticks: messages are read in the frame they were measured in.
        self.pose_history = (self.pose, self.pose)
        self.known = np.zeros((n, 2), bool)
        self.goal_xy = np.zeros((n, 2, 2))
        self.goal_p_m = np.zeros((n, 2))
        # Covariance of each goal estimate (SIKF strategies only): the pose covariance since the
        # robot left that area, seed 000 eq. 9 with P_0 = 0 at the area.
        uses_cov = STRATEGIES[config.strategy].confidence == "covariance"
        self.goal_cov = np.zeros((n, 2, 3, 3)) if uses_cov else None
        self.target = np.full(n, -1, np.int64)
        self.searching = np.zeros(n, bool)
        self.search_left_m = np.zeros(n)
        self.turn_ticks = np.zeros(n, np.int64)
        self.turn_dir = np.ones(n)
        self.straight_ticks = np.zeros(n, np.int64)
        self.heard_ids = np.full((n, k), -1, np.int64)
        self.heard_bearing_rad = np.zeros((n, k))
        self.heard_range_m = np.zeros((n, k))
        self._heard_clear = True
        self.lost_count = np.zeros(n, np.int64)
        self.visit_ticks = np.zeros((n, 2), np.int64)
        self.tick = 0
        self.partner_ids = np.full((n, config.encounter_memory), -1, np.int64)
        self.partner_until = np.zeros((n, config.encounter_memory), np.int64)
        self._gap_ticks = round(config.encounter_gap_s / tick_s)
        self._fuse = fuse(self.strategy, config.beta) if self.strategy.communicates else None
        self._rows = np.arange(n)
        self._silent = SocialMessages.empty(n, k)  # what a robot that never sends "sends"
        self._sending = np.full(n, self.strategy.communicates)
        spin_rad_s = 2.0 * config.turn_speed_steps_s * body.metres_per_step / body.wheelbase_m
        self._spin_rad_per_tick = spin_rad_s * tick_s

    # -- layers ------------------------------------------------------------------------------

    def _odometry(self, encoder_steps: np.ndarray) -> None:
        du = encoder_steps * self.body.metres_per_step
        self.pose_history = (self.pose_history[1], self.pose)
        self.pose = integrate_pose(self.pose, du[:, 0], du[:, 1], self.body.wheelbase_m)
        travelled = np.abs(du[:, 0] + du[:, 1]) / 2.0
        self.search_left_m -= travelled
        if self.goal_cov is None:
            self.goal_p_m += travelled[:, None]  # eq. 23: p is the distance travelled
            return
        # eq. 9-11 for each goal's covariance since the robot left it, then eq. 19.
        k = self.config.odometry_k_m
        before = np.repeat(self.pose_history[1], 2, axis=0)
        cov = propagate_covariance(
            self.goal_cov.reshape(-1, 3, 3), before, np.repeat(du[:, 0], 2), np.repeat(du[:, 1], 2),
            self.body.wheelbase_m, k, k,
        )
        self.goal_cov = cov.reshape(self.n, 2, 3, 3)
        self.goal_p_m = _spectral_norm_xy(self.goal_cov)

    def _arrive(self, area: np.ndarray) -> None:
        """Store goal locations seen by the ground sensors; switch target on arrival.

        The stored location is the mean, over the visit, of where the robot believes its ground
        sensor was while it saw the area: a point inside the area, not the body centre beside it.
        """
        if not (area >= 0).any():  # the common case: nobody stands on an area
            self.visit_ticks.fill(0)
            return
        sensor = ground_sensor_point(self.pose)
        for goal in (NEST, PREY):
            inside = area == goal
            entering = inside & (self.visit_ticks[:, goal] == 0)
            self.visit_ticks[~inside, goal] = 0
            if not inside.any():
                continue
            count = self.visit_ticks[inside, goal] + 1
            self.visit_ticks[inside, goal] = count
            prev = np.where(entering[inside, None], sensor[inside], self.goal_xy[inside, goal])
            self.goal_xy[inside, goal] = prev + (sensor[inside] - prev) / count[:, None]
            self.known[inside, goal] = True
            self.goal_p_m[inside, goal] = 0.0
            if self.goal_cov is not None:
                self.goal_cov[inside, goal] = 0.0
            other = 1 - goal
            arrived = inside & ((self.target == goal) | (self.target < 0))
            self.target[arrived] = np.where(self.known[arrived, other], other, -1)
            self.searching[arrived] = False

    def _lost(self, area: np.ndarray) -> None:
        if not self.searching.any():
            return
        lost = self.searching & (self.search_left_m <= 0.0) & (area != self.target)
        if lost.any():
            self.known[lost] = False
            self.goal_p_m[lost] = 0.0
            if self.goal_cov is not None:
                self.goal_cov[lost] = 0.0
            self.target[lost] = -1
            self.searching[lost] = False
            self.lost_count[lost] += 1

    def _receive(self, inbox: Inbox) -> None:
        """Fuse what neighbours sent (seed 000 eq. 14-16, 27).

        Eq. 27 needs the range and both bearings of one crossing. A message sent at tick k-1
        carries the sender's goals in its body frame of tick k-2 and the bearing at which it heard
        us at tick k-2; we heard the sender at that same crossing, so our own range and bearing
        from last tick's table, and our pose of then, complete the transform with no timing error.
        """
        m = inbox.receiver.shape[0]
        if m == 0 or not self.strategy.communicates:
            return
        content = inbox.content
        rank = _rank_within(inbox.receiver)
        adopted = np.zeros((self.n, 2), bool)
        for r in range(int(rank.max()) + 1):
            idx = np.flatnonzero(rank == r)
            rec = inbox.receiver[idx]
            theirs = content.heard_ids[idx] == self.robot_ids[rec][:, None]
            ours = self.heard_ids[rec] == inbox.sender_id[idx][:, None]
            has = theirs.any(axis=1) & ours.any(axis=1)
            if not has.any():
                continue
            idx, rec, theirs, ours = idx[has], rec[has], theirs[has], ours[has]
            # One exchange per encounter: a recent partner that is still around is ignored, and
            # stays ignored while we keep hearing it.
            sender = inbox.sender_id[idx]
            recent = (self.partner_ids[rec] == sender[:, None]) & (
                self.partner_until[rec] > self.tick
            )
            slot = np.where(
                recent.any(axis=1), recent.argmax(axis=1), self.partner_until[rec].argmin(axis=1)
            )
            self.partner_ids[rec, slot] = sender
            self.partner_until[rec, slot] = self.tick + self._gap_ticks
            fresh = ~recent.any(axis=1)
            if not fresh.any():
                continue
            idx, rec, theirs, ours = idx[fresh], rec[fresh], theirs[fresh], ours[fresh]
            gamma_sender = content.heard_bearing_rad[idx, theirs.argmax(axis=1)]
            slot = ours.argmax(axis=1)
            gamma_own = self.heard_bearing_rad[rec, slot]
            range_own = self.heard_range_m[rec, slot]
            frame = self.pose_history[0][rec]
            theta = frame[:, 2]
            cos_t, sin_t = np.cos(theta), np.sin(theta)
            for goal in (NEST, PREY):
                ok = content.goal_known[idx, goal]
                if not ok.any():
                    continue
                i, rr = idx[ok], rec[ok]
                local = transform_received(
                    range_own[ok],
                    gamma_own[ok],
                    gamma_sender[ok],
                    content.goal_distance_m[i, goal],
                    content.goal_angle_rad[i, goal],
                )
                x_other = frame[ok, :2] + np.stack(
                    (
                        cos_t[ok] * local[:, 0] - sin_t[ok] * local[:, 1],
                        sin_t[ok] * local[:, 0] + cos_t[ok] * local[:, 1],
                    ),
                    axis=1,
                )
                p_other = content.goal_p_m[i, goal]
                knew = self.known[rr, goal]
                # eq. 14: a robot that does not know the goal takes the neighbour's estimate.
                new = ~knew
                self.goal_xy[rr[new], goal] = x_other[new]
                self.goal_p_m[rr[new], goal] = p_other[new]
                if self.goal_cov is not None:  # only the norm crossed the air: isotropic
                    self.goal_cov[rr[new], goal] = p_other[new, None, None] * _XY_BLOCK
                self.known[rr[new], goal] = True
                adopted[rr[new], goal] = True
                # eq. 15-16: both know it; single strategies fuse only the goal they head to.
                fuse_mask = knew & (self.strategy.double | (self.target[rr] == goal))
                if fuse_mask.any():
                    rf = rr[fuse_mask]
                    unit = self.config.confidence_unit_m
                    x_new, p_new = self._fuse(
                        self.goal_xy[rf, goal],
                        self.goal_p_m[rf, goal] / unit,
                        x_other[fuse_mask],
                        p_other[fuse_mask] / unit,
                    )
                    if self.goal_cov is not None:  # eq. 22 on the whole matrix: P <- (1 - g) P
                        old = self.goal_p_m[rf, goal] / unit
                        scale = np.divide(p_new, old, out=np.zeros_like(p_new), where=old > 0)
                        self.goal_cov[rf, goal] *= scale[:, None, None]
                    self.goal_xy[rf, goal] = x_new
                    self.goal_p_m[rf, goal] = p_new * unit
        # A wandering robot recruited to a goal heads for it (seed 000 §6.1.1); of two, the nearer.
        recruited = (self.target < 0) & adopted.any(axis=1)
        if recruited.any():
            dist = np.linalg.norm(self.goal_xy[recruited] - self.pose[recruited, None, :2], axis=2)
            dist[~adopted[recruited]] = np.inf
            self.target[recruited] = dist.argmin(axis=1)
            self.searching[recruited] = False

    def _remember_heard(self, inbox: Inbox) -> None:
        """Keep the nearest neighbours heard this tick: their ids, range and bearing (measured at
        the previous tick's poses, when the messages crossed)."""
        k = self.config.heard_capacity
        empty = inbox.receiver.shape[0] == 0 or k == 0
        if empty and self._heard_clear:
            return
        self.heard_ids.fill(-1)
        self.heard_bearing_rad.fill(0.0)
        self.heard_range_m.fill(0.0)
        self._heard_clear = empty
        if empty:
            return
        order = np.lexsort((inbox.sender_id, inbox.range_m, inbox.receiver))
        rec = inbox.receiver[order]
        rank = _rank_within(rec)
        keep = rank < k
        rk, sk = rec[keep], rank[keep]
        self.heard_ids[rk, sk] = inbox.sender_id[order][keep]
        self.heard_bearing_rad[rk, sk] = _f32(inbox.bearing_rad[order][keep])
        self.heard_range_m[rk, sk] = inbox.range_m[order][keep]

    def _wander_draws(self, need: np.ndarray) -> None:
        """Start a new random-walk segment for robots in ``need``: a turn, then a straight run."""
        lo, hi = self.config.wander_straight_s
        for i in np.flatnonzero(need):
            angle, straight_s = self.rngs[i].uniform((-math.pi, lo), (math.pi, hi))
            self.turn_ticks[i] = round(abs(angle) / self._spin_rad_per_tick)
            self.turn_dir[i] = 1.0 if angle >= 0 else -1.0
            self.straight_ticks[i] = round(straight_s / self.tick_s)

    def _motors(self, ir: np.ndarray) -> np.ndarray:
        cfg = self.config
        cruise, spin = cfg.cruise_speed_steps_s, cfg.turn_speed_steps_s

        # forage: steer to the target's estimate (err stays 0 for robots without a target)
        going = self.target >= 0
        if going.any():
            g = self.goal_xy[self._rows, np.maximum(self.target, 0)]
            delta = g - self.pose[:, :2]
            dist = np.hypot(delta[:, 0], delta[:, 1])
            err = wrap_angle(np.arctan2(delta[:, 1], delta[:, 0]) - self.pose[:, 2])
            start = going & ~self.searching & (dist < cfg.arrival_tolerance_m)
            if start.any():
                self.searching[start] = True
                self.search_left_m[start] = cfg.search_overshoot_m
            err[self.searching | ~going] = 0.0
            in_place = going & (np.abs(err) > cfg.turn_in_place_rad)
            spin_dir = np.sign(err)
        else:
            err = np.zeros(self.n)
            in_place = np.zeros(self.n, bool)
            spin_dir = err
        # wander: random walk
        wandering = ~going
        if wandering.any():
            need = wandering & (self.turn_ticks <= 0) & (self.straight_ticks <= 0)
            if need.any():
                self._wander_draws(need)
            turning = wandering & (self.turn_ticks > 0)
            self.turn_ticks[turning] -= 1
            self.straight_ticks[wandering & ~turning] -= 1
            if turning.any():
                spin_dir = np.where(turning, self.turn_dir, spin_dir)
                in_place = in_place | turning

        steer = np.clip(cfg.steering_gain * err, -1.0, 1.0)
        cmd = np.empty((self.n, 2))
        cmd[:, 0] = cruise * (1.0 - steer)
        cmd[:, 1] = cruise * (1.0 + steer)
        if in_place.any():
            cmd[in_place, 0] = -spin * spin_dir[in_place]
            cmd[in_place, 1] = spin * spin_dir[in_place]

        # avoid: subsumes the layers below
        avoiding = (ir > cfg.avoid_threshold).any(axis=1)
        if avoiding.any():
            vx = ir[avoiding] @ _COS_IR
            vy = ir[avoiding] @ _SIN_IR
            obstacle = np.arctan2(vy, vx)
            ahead = np.abs(obstacle) < math.pi / 2
            away = np.where(obstacle > 0, -1.0, 1.0)  # obstacle on the left: turn right
            c = np.empty((avoiding.sum(), 2))
            c[:, 0] = np.where(ahead, -spin * away, cruise)
            c[:, 1] = np.where(ahead, spin * away, cruise)
            cmd[avoiding] = c
        vmax = self.body.max_wheel_speed_steps_s
        return np.clip(cmd, -vmax, vmax, out=cmd)

    def _outgoing(self) -> SocialMessages:
        if not self.strategy.communicates:
            return self._silent
        # Goals in the body frame of the previous tick, the frame the heard bearings were measured
        # in: the receiver then combines measurements of one and the same crossing.
        frame = self.pose_history[1]
        delta = self.goal_xy - frame[:, None, :2]
        distance = np.hypot(delta[..., 0], delta[..., 1])
        angle = wrap_angle(np.arctan2(delta[..., 1], delta[..., 0]) - frame[:, None, 2])
        return SocialMessages(
            goal_known=self.known.copy(),
            goal_distance_m=_f32(np.where(self.known, distance, 0.0)),
            goal_angle_rad=_f32(np.where(self.known, angle, 0.0)),
            goal_p_m=_f32(np.where(self.known, self.goal_p_m, 0.0)),
            heard_ids=self.heard_ids.copy(),
            heard_bearing_rad=self.heard_bearing_rad.copy(),
        )

    def state_codes(self) -> np.ndarray:
        target_code = np.where(self.target < 0, TARGET_NONE, self.target + 1)
        return target_code | np.where(self.known.all(axis=1), KNOWS_BOTH, 0)

    # -- the contract ------------------------------------------------------------------------

    def step(
        self, encoder_steps: np.ndarray, ir: np.ndarray, ground: np.ndarray, inbox: Inbox
    ) -> BrainOutput:
        """One controller tick for every robot of the batch (10 Hz on the e-puck)."""
        self.tick += 1
        self._odometry(encoder_steps)
        area = classify_ground(ground)
        self._arrive(area)
        self._lost(area)
        self._receive(inbox)
        self._remember_heard(inbox)
        cmd = self._motors(ir)
        return BrainOutput(
            wheel_speed_steps_s=cmd,
            sending=self._sending,
            messages=self._outgoing(),
            state=self.state_codes(),
            pose_estimate=self.pose.copy(),
        )
