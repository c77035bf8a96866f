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
engine the whole swarm. The layers run in compiled kernels (``agents/kernels.py``), the same for
both; they evaluate the equations of :mod:`.social_odometry` (whose numpy functions remain the
readable reference, and the tests hold the kernels to them). The only per-robot Python loop is
over robots that need a random draw this tick (each robot owns its generator, derived from the
run seed and its id).

Modelling choices the papers leave open are named in :class:`AgentConfig`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgpack
import numpy as np

from swarmloc.agents import kernels
from swarmloc.agents.social_odometry import STRATEGIES
from swarmloc.protocol.epuck import (  # noqa: F401 -- on_path is part of this module's API
    GROUND_SENSOR_OFFSETS_M,
    IR_SENSOR_ANGLES_RAD,
    STATE_KNOWS_BOTH,
    EpuckBody,
    on_path,
    propagate_covariance,
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

#: How far ahead of the body centre the middle ground sensor is: where "on an area" is.
_GROUND_AHEAD_M = float(GROUND_SENSOR_OFFSETS_M[1, 0])

_COS_IR = np.cos(IR_SENSOR_ANGLES_RAD)
_SIN_IR = np.sin(IR_SENSOR_ANGLES_RAD)


def classify_ground(ground: np.ndarray) -> np.ndarray:
    """What each robot believes it stands on from its 3 ground readings ``(N, 3)``.

    Returns ``(N,)`` codes: -1 floor, ``NEST`` (any sensor black) or ``PREY`` (any sensor grey).
    """
    return kernels.classify_ground(np.asarray(ground, float), GROUND_BLACK_BELOW, GROUND_GREY_BELOW)


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


@dataclass
class Inbox:
    """Messages received this tick by robots of a batch, sorted by (receiver, sender)."""

    receiver: np.ndarray  # (M,) index into the batch
    sender_id: np.ndarray  # (M,) robot id
    range_m: np.ndarray
    bearing_rad: np.ndarray
    content: SocialMessages
    #: Row of ``content`` that each message carries (None: row m for message m). The batch
    #: engine passes every robot's outgoing messages once and the senders' rows here.
    content_row: np.ndarray | None = None

    def rows(self) -> np.ndarray:
        if self.content_row is None:
            return np.arange(self.receiver.shape[0])
        return self.content_row

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


_kernels_loaded = False


def _load_kernels(config: AgentConfig, body: EpuckBody, tick_s: float) -> None:
    """Load (or, the first time on a machine, compile) the brain's kernels now, once per process,
    by stepping a throwaway brain of one robot with its own generator: an agent in a real-time
    run must not spend its first ticks loading them."""
    global _kernels_loaded
    if _kernels_loaded:
        return
    _kernels_loaded = True
    brain = ForagingBrain(config, body, [0], [np.random.default_rng(0)], tick_s)
    brain.step(np.zeros((1, 2)), np.zeros((1, 8)), np.ones((1, 3)), Inbox.empty(config.heard_capacity))


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
        _load_kernels(config, body, tick_s)
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
        self._gain = {"none": kernels.GAIN_NONE, "kalman": kernels.GAIN_KALMAN, "fermi": kernels.GAIN_FERMI}[
            self.strategy.gain
        ]
        self._no_cov = np.zeros((n, 2, 3, 3))  # stands in for goal_cov where there is none
        self._z = np.zeros(1)  # the exponent of a Fermi gain, handed out by the kernel
        self._adopted = np.zeros((n, 2), bool)
        # Goal vectors of the motor and send layers, their angles, robots drawing a new walk.
        self._geometry = np.zeros((2, n, 3))
        self._atan = np.zeros((n, 3))
        self._need = np.zeros(n, np.int64)
        self._n_need = np.zeros(1, np.int64)
        self._reported: tuple | None = None  # _report()'s answer when _motors computed it
        self._wander_low = (-math.pi, config.wander_straight_s[0])
        self._wander_span = (math.pi - -math.pi, config.wander_straight_s[1] - config.wander_straight_s[0])
        self._silent = SocialMessages.empty(n, k)  # what a robot that never sends "sends"
        self._sending = np.full(n, self.strategy.communicates)
        spin_rad_s = 2.0 * config.turn_speed_steps_s * body.metres_per_step / body.wheelbase_m
        self._spin_rad_per_tick = spin_rad_s * tick_s

    # -- layers ------------------------------------------------------------------------------
    # The work is done by the compiled kernels of agents/kernels.py, on the state arrays below.

    def _update(self, encoder_steps: np.ndarray, ground: np.ndarray, inbox: Inbox) -> None:
        """Odometry, arrive, lost, receive and remember-heard layers (see :mod:`.kernels`).

        *Odometry*: dead reckoning of the encoder counts (seed 000 eq. 7); ``p`` grows with the
        distance travelled (eq. 23), or is the spectral norm of the odometry covariance
        propagated with eq. 9-11 (eq. 19, SIKF strategies).

        *Arrive*: store goal locations seen by the ground sensors; switch target on arrival. The
        stored location is the mean, over the visit, of where the robot believes its ground
        sensor was while it saw the area: a point inside the area, not the body centre beside it.

        *Receive*: fuse what neighbours sent (seed 000 eq. 14-16, 27). Eq. 27 needs the range
        and both bearings of one crossing. A message sent at tick k-1 carries the sender's goals
        in its body frame of tick k-2 and the bearing at which it heard us at tick k-2; we heard
        the sender at that same crossing, so our own range and bearing from last tick's table,
        and our pose of then, complete the transform with no timing error. One exchange per
        encounter: a recent partner still in hearing is ignored.

        *Remember heard*: keep the nearest neighbours heard this tick, their ids, range and
        bearing (measured at the previous tick's poses, when the messages crossed).
        """
        encoder_steps = np.asarray(encoder_steps, float)
        previous = self.pose
        self.pose_history = (self.pose_history[1], previous)
        self.pose = np.empty_like(previous)
        in_kernel = self.goal_cov is None
        if not in_kernel:
            kernels.odometry(
                previous, encoder_steps, self.body.metres_per_step, self.body.wheelbase_m,
                self.search_left_m, self.goal_p_m, False, self.pose,
            )
            # eq. 9-11 for each goal's covariance since the robot left it, then eq. 19.
            du = encoder_steps * self.body.metres_per_step
            k = self.config.odometry_k_m
            cov = propagate_covariance(
                self.goal_cov.reshape(-1, 3, 3), np.repeat(previous, 2, axis=0),
                np.repeat(du[:, 0], 2), np.repeat(du[:, 1], 2), self.body.wheelbase_m, k, k,
            )
            self.goal_cov = cov.reshape(self.n, 2, 3, 3)
            self.goal_p_m = _spectral_norm_xy(self.goal_cov)
        c = inbox.content
        cov = self.goal_cov if self.goal_cov is not None else self._no_cov
        strategy, body, cfg = self.strategy, self.body, self.config
        adopted = self._adopted
        resume, exp_z = kernels.DONE, 0.0
        while True:
            resume = kernels.brain_update(
                in_kernel, encoder_steps, previous, body.metres_per_step, body.wheelbase_m,
                self.pose, self.pose_history[0], self.robot_ids, self.known, self.goal_xy,
                self.goal_p_m, cov, not in_kernel, self.target, self.searching,
                self.search_left_m, self.lost_count, self.visit_ticks, self.turn_ticks,
                self.straight_ticks, self.heard_ids, self.heard_bearing_rad, self.heard_range_m,
                self.partner_ids, self.partner_until, adopted,
                np.asarray(ground, float), GROUND_BLACK_BELOW, GROUND_GREY_BELOW, _GROUND_AHEAD_M,
                self.tick,
                inbox.receiver, inbox.sender_id, inbox.range_m, inbox.bearing_rad, inbox.rows(),
                c.goal_known, c.goal_distance_m, c.goal_angle_rad, c.goal_p_m, c.heard_ids,
                c.heard_bearing_rad,
                strategy.communicates, strategy.double, self._gain, float(cfg.beta),
                cfg.confidence_unit_m, self._gap_ticks, resume, exp_z, self._z,
                self._geometry, self._need, self._n_need,
            )
            if resume == kernels.DONE:
                break
            exp_z = float(np.exp(self._z)[0])  # the Fermi gain's exp, numpy's (eq. 24)
        self._heard_clear = not inbox.receiver.shape[0]
        # Angles of the goal vectors, numpy's arctan2 (see agents/kernels.py).
        self._atan = np.arctan2(self._geometry[1], self._geometry[0])

    def _wander_draws(self, need: np.ndarray) -> None:
        """Start a new random-walk segment for robots in ``need``: a turn, then a straight run.

        ``uniform((-pi, lo), (pi, hi))`` of each robot's own generator, written as ``low +
        (high - low) * random()``, which is how numpy computes it (same numbers, less overhead).
        """
        low, span = self._wander_low, self._wander_span
        for i in need.tolist():
            u = self.rngs[i].random(2)
            angle = low[0] + span[0] * u[0]
            straight_s = low[1] + span[1] * u[1]
            self.turn_ticks[i] = round(abs(angle) / self._spin_rad_per_tick)
            self.turn_dir[i] = 1.0 if angle >= 0 else -1.0
            self.straight_ticks[i] = round(straight_s / self.tick_s)

    def _motors(self, ir: np.ndarray) -> np.ndarray:
        """Forage (steer to the target's estimate), wander (random walk), avoid (seed 000 §5)."""
        cfg = self.config
        n_need = int(self._n_need[0])
        if n_need:
            self._wander_draws(self._need[:n_need])
        # The send layer needs the same angles: its report (see _report) comes in the same call.
        communicates = self.strategy.communicates
        cmd, *fields, state, pose = kernels.act(
            self.pose, self.target, self.searching, self.search_left_m, self.turn_ticks,
            self.straight_ticks, self.turn_dir, self._geometry, self._atan,
            np.asarray(ir, float), _COS_IR, _SIN_IR, cfg.cruise_speed_steps_s,
            cfg.turn_speed_steps_s, cfg.steering_gain, cfg.turn_in_place_rad,
            cfg.arrival_tolerance_m, cfg.search_overshoot_m, cfg.avoid_threshold,
            self.body.max_wheel_speed_steps_s, self.pose_history[1], self.known, self.goal_p_m,
            self.heard_ids, self.heard_bearing_rad, communicates, KNOWS_BOTH,
        )
        self._reported = (SocialMessages(*fields) if communicates else self._silent), state, pose
        return cmd

    def _report(self) -> tuple[SocialMessages, np.ndarray, np.ndarray]:
        """The messages the robots send, their state codes and dead-reckoned poses.

        Goals are sent in the body frame of the previous tick, the frame the heard bearings were
        measured in: the receiver then combines measurements of one and the same crossing.
        """
        communicates = self.strategy.communicates
        *fields, state, pose = kernels.report(
            self.pose_history[1], self._geometry, self._atan, self.known, self.goal_p_m,
            self.heard_ids, self.heard_bearing_rad, communicates, self.target, KNOWS_BOTH, self.pose,
        )
        return (SocialMessages(*fields) if communicates else self._silent), state, pose

    def state_codes(self) -> np.ndarray:
        return kernels.state_codes(self.target, self.known, KNOWS_BOTH)

    # -- the contract ------------------------------------------------------------------------

    def step(
        self, encoder_steps: np.ndarray, ir: np.ndarray, ground: np.ndarray, inbox: Inbox
    ) -> BrainOutput:
        """One controller tick for every robot of the batch (10 Hz on the e-puck)."""
        self.tick += 1
        self._reported = None
        self._update(encoder_steps, ground, inbox)
        cmd = self._motors(ir)
        messages, state, pose_estimate = self._reported or self._report()
        return BrainOutput(
            wheel_speed_steps_s=cmd,
            sending=self._sending,
            messages=messages,
            state=state,
            pose_estimate=pose_estimate,
        )
