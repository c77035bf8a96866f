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
engine the whole swarm (an agent process steps its batch of one through ``agents/epuck/agent_tick.py``:
the same kernel, its state packed, one compiled call per tick, the payloads coded in it). The
layers run in compiled kernels (``agents/epuck/kernels.py``), the same for both, in one call per tick;
they evaluate the equations of :mod:`.social_odometry` (whose numpy functions remain the readable
reference, and the tests hold the kernels to them). Each robot owns its generator, derived from
the run seed and its id; the kernel draws a robot's random walk from it, the numbers numpy would
give.

Modelling choices the papers leave open are named in :class:`AgentConfig`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgpack
import numpy as np

from swarmloc import numerics
from swarmloc.agents.epuck import kernels
from swarmloc.agents.epuck.fusion import FUSION_RULES
from swarmloc.agents.epuck.social_odometry import STRATEGIES
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

#: ``AgentConfig.encounter_stop`` values, in the order of the kernels' STOP_* codes.
ENCOUNTER_STOPS = ("none", "wandering", "all")

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
    #: Unit of ``p`` in the Fermi rule (seed 000 eq. 24, ``g = 1 / (1 + exp(-beta Delta p))``),
    #: in metres: 1.0 means ``p`` counts metres travelled. The seeds state no unit. Seed 000
    #: §6.1.2: "A maximum retrieval process is achieved when beta = 10^-2 for the ES1 and ES2, and
    #: beta = 10^-3 for the ES3". Until issue 18's second look the default was centimetres
    #: (0.01; variants ``v0-defaults`` and ``v1-defaults``): our retrieval is flat over small
    #: betas and falls beyond an edge, and in centimetres the paper's betas lie past that edge
    #: (ES2 SSGIFF median 832 round trips at beta 1e-2 against 949 at 1e-4, 30 replications,
    #: docs/social-odometry-000/ as of 037e757). In metres the edge moves two decades up and the
    #: paper's betas sit on our plateau (ES2 SSGIFF 954 at 1e-2, the best of the 8 betas; ES3
    #: 672 at 1e-3 against the best 696; 5 replications, docs/so-000-untested/, group p-metres).
    #: So the default is the unit under which the paper's best betas are good ones here, and it
    #: is the SI unit of the distance ``p`` is (eq. 23). Neither unit reproduces the paper's
    #: peak (worse on both sides of 1e-2): small betas, a plain average, are as good as any here.
    confidence_unit_m: float = 1.0
    #: Wheel speed while driving to a goal or wandering. Seed 000 §2 gives only the top speed
    #: ("The maximum speed of the wheels is about 1,000 steps/s"), not the foraging one; ours is
    #: 800. Measured (docs/so-000-speed/, 10 replications, today's other defaults; 800 / 1,000):
    #: SSGIKF round trips ES1 124 / 147, ES2 898.5 / 1,083.5, ES3 660 / 794.5 (seed 000 §6.1.2:
    #: about 150, 1,400, 2,000), NC 58.5 / 72.5 in ES1, robots on the path with communication
    #: ES1 41-48 / 37-40 %, ES2 49-54 / 46-50 %, ES3 38-40 / 34-36 % (seed 000 §6.1.3: 50-70 %).
    #: The top speed meets ES2's retrieval within 1.5x and ES1's about 150, but fewer robots are
    #: on the path everywhere (a faster robot drifts farther per metre: the slip is drawn per
    #: sub-step on the commanded travel) and the SGIKF / NC ratio does not move; neither speed
    #: is the text's, so the default stays 800 and the top speed is the named variant
    #: ``top-speed`` (``swarmloc.deploy.scenario.VARIANTS``).
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
    #: world's +-20 % uniform slip per physics sub-step gives at cruise speed, s^2 |dU| / (3 S)
    #: with S = 10 sub-steps per tick (``OdometryConfig.substeps``); 1.37e-4 with S = 1 (v0).
    odometry_k_m: float = 1.37e-5
    #: How many neighbours' bearings a robot repeats in its messages (needed for eq. 27).
    heard_capacity: int = 3
    #: Two robots exchange once per encounter (seed 000 §4.1, §5): after an exchange the partner
    #: is ignored until it has been out of hearing for this long. Fusing every message of one
    #: encounter would make the SGIKF overconfident (p shrinks with each correlated copy).
    encounter_gap_s: float = 2.0
    #: How many recent partners a robot remembers. When all slots hold partners still within the
    #: gap, the one expiring first is evicted, and if it is still in range the pair can fuse again
    #: within one encounter (issue 18, reading 6). Default 16 slots (the most), so that the seeds'
    #: "When two robots encounter they exchange their estimates" (seed 000 §4.1) happens once per
    #: encounter, as the papers describe it: at the seeds' densities no partner still in range is
    #: then evicted. 4 was the default before issue 18 (``v0-defaults``).
    encounter_memory: int = 16

    # -- Readings of the seeds' text where it contradicts itself or is silent (issue 18). The
    # defaults are the readings the seeds' text supports, chosen on the ablation
    # docs/so-000-readings/ (deploy/experiments/so-000-readings.toml). The defaults before issue 18
    # (p "fused", sends "both", give_up_factor 0, encounter_memory 4, world.odometry.substeps 1,
    # odometry_k_m 1.37e-4, confidence_unit_m 0.01) remain selectable as the named variant
    # ``v0-defaults`` (``swarmloc.deploy.scenario.VARIANTS``; ``--variant v0-defaults``), with
    # which docs/social-odometry-000/ and -001/ were made before issue 18; issue 18's first
    # defaults (give_up_factor 2, p in centimetres) as ``v1-defaults``.

    #: What ``p`` is after a fusion (issue 18, reading 1). Seed 000 contradicts itself here:
    #:
    #: - ``"fused"`` (``v0-defaults``): table 1 and eq. 13, "p_{k|k-1} = p_{k-1|k-1} + Delta d_k":
    #:   the fused ``p`` of eq. 22 (SGIKF) / eq. 26 (SGIFF) is kept and grows with the distance
    #:   travelled, so every fusion leaves a robot more confident;
    #: - ``"distance"`` (default): eq. 23, "we define the inverse of the a priori confidence level
    #:   (p_{k|k-1}^i) of robot i as the distance travelled (d_k^i) since the robot left a
    #:   specific area. [...] p_{k|k-1}^i = d_k^i" (and §4.2.2 for the SGIFF: "also calculated as
    #:   the distance travelled since the robot left a specific area"); seed 001 §4.2: "the
    #:   robots use the inverse of the distance traveled as a confidence level". A fusion moves
    #:   the estimate (eq. 21 / 25) but leaves ``p`` at the distance travelled. A goal adopted
    #:   from a neighbour (eq. 14) takes the neighbour's ``p`` and grows from there, as it did.
    #:
    #: The SIKF strategies (``confidence = "covariance"``) ignore it: their prior, eq. 19, is
    #: propagated from the a posteriori covariance by definition.
    #:
    #: Default ``"distance"``: eq. 23 is the SGIKF's own definition of its prior, stated twice in
    #: seed 000 and again in seed 001; table 1's generic eq. 13 is the SIKF's. With "fused",
    #: every encounter leaves both robots more confident than either was, and a pair of wrong
    #: estimates then outweighs a right one (ablation, group p-distance).
    p_after_fusion: str = "distance"
    #: Which goal estimates a robot sends (issue 18, reading 2):
    #:
    #: - ``"both"`` (``v0-defaults``): every goal it knows (seed 000 §4.1: "When two robots encounter they
    #:   exchange their estimates about the goal areas");
    #: - ``"last-visited"`` (default): seed 001 §4.2, "While moving from one area to the other, if a robot
    #:   encounters another robot, it transmits its estimated location of the last visited
    #:   area"; seed 000 §6.1.2 explains single beating double by the same: "they have better
    #:   information on the goal they are coming from than the one they are aiming at". A robot
    #:   with a target sends only the other goal (the area it comes from), if it knows it; a
    #:   wandering robot (no target: it knows at most the one area it found) sends what it knows,
    #:   so that recruitment (seed 000 §6.1.1) still works.
    #:
    #: Default ``"last-visited"``: seed 001 says it in so many words, and seed 000 §6.1.2's
    #: explanation of its own result ("robot i improves its goal estimate with the more reliable
    #: information of robot j (the estimate on where it is coming from)") holds only if robot j
    #: sends that estimate; seed 000 §4.1's "exchange their estimates" does not say which.
    sends: str = "last-visited"
    #: Giving up on an estimate that cannot be reached (issue 18, reading 5). Seed 000 §5: "If
    #: the robot arrives at a place where the area was supposed to be but is not, it resets its
    #: Goal Locations memory"; an estimate beyond a wall is never arrived at. 0 (``v0-defaults``):
    #: the robot declares itself lost only within ``arrival_tolerance_m`` of the estimate plus the
    #: overshoot, and meanwhile counts as on the path. ``f > 0``: on setting out for a target (on
    #: leaving an area, or recruited to one) the robot allows itself ``f`` times the straight-line
    #: distance to the estimate; having travelled that (odometric distance, eq. 23's measure)
    #: without reaching the estimate it declares itself lost, as if it had arrived where the area
    #: should be and not found it. The papers give no such rule: the factor is ours.
    #:
    #: A limit is needed: a robot pressed against a wall by an estimate behind it never "arrives
    #: at a place where the area was supposed to be", so without one seed 000 §5's reset never
    #: happens to it, and it is counted on the path for the rest of the run (seed 000 §6.1.3
    #: counts it lost: "when robots get lost they are typically around the nest or prey area").
    #:
    #: Default 4, calibrated on seed 000 §6.1.3's own figures, "between 50 % and 70 % of the
    #: robots" on the path with communication and "no more than 20 %" with NC, since the text
    #: gives no factor (docs/so-000-untested/, 5 replications; robots on the path with
    #: communication in ES1 / ES2 / ES3, NC's in brackets): factor 2 (issue 18's first default,
    #: variant ``v1-defaults``) 32-34 / 41-44 / 34-35 % (13 / 3 / 2 %); 3: 38-40 / 47-49 / 35-39 %;
    #: 4: 38-43 / 49-52 / 38-40 % (11 / 5 / 3 %); never giving up: 36-44 / 50-56 / 41-43 %, but NC
    #: at 29 % in ES2, over the paper's 20 %. Round trips do not move beyond the replications'
    #: spread (SSGIKF ES2 870 / 882 / 901 / 911). 4 is the laxest factor tested that keeps NC
    #: under 20 %.
    give_up_factor: float = 4.0

    # -- The communication process of an encounter (issue 42). Seed 000 §6.2 (real robots): "the
    # time used in the communication is longer in the real robots scenario. This is because
    # errors in the communication makes the communication layer repeat some messages. Therefore,
    # robots wait a little more time (around 20-30%) in the communication process"; §6.1.1: "when
    # robots are looking for one of the areas and they find a neighbor, they stop and check if
    # the neighbor is transmitting information about the unknown area"; §5: the IR sensors
    # "are used to detect the presence of obstacles or neighbors with whom the robots can
    # communicate", and the controller has *Send Data* and *Receive Data* layers. So an encounter
    # is a process during which robots wait and messages are repeated; the text gives neither how
    # many messages nor how the receiver combines them. Each message crosses the board with fresh
    # range and bearing noise (+-2.5 cm, +-20 deg), so combining the messages of one encounter
    # shrinks the error eq. 27 makes of them. Before issue 42 an encounter was one message, fused
    # at once, and nobody waited (variant ``v2-defaults``).
    #
    # Defaults chosen on the ablation docs/so-000-comm/ (deploy/experiments/so-000-comm.toml, 10
    # replications, seeds 1-10; SSGIKF round trips ES1 / ES2 / ES3, robots on the path, and the
    # median error of the target estimate at departure in ES2; NC: 58.5 / 118.5 / 15.5):
    #
    # - one message (v2): 124 / 898.5 / 660, 42 / 52 / 40 %, 0.33 m;
    # - the mean of 5 messages, nobody waits: 139 / 1176.5 / 934.5, 53 / 70 / 54 %, 0.27 m
    #   (10 messages: 146 / 1175.5 / 955.5: no better than 5);
    # - 5 messages, robots looking for an area wait (the default): 137 / 1161.5 / 912, 53 / 70 /
    #   54 %, 0.27 m; all robots wait: 125 / 1023 / 843.5 (more on the path, 62 / 75 / 60 %, but
    #   a robot heading home that stops loses its time); each message fused as it comes: 115.5 /
    #   957.5 / 720 (correlated copies pull the estimate to the first);
    # - SSGIFF (beta 1e-2) alike: 132 / 996.5 / 721.5 with one message, 157 / 1242 / 969.5 with
    #   the default.
    #
    # The mean of 5 is the largest gain measured; whether wandering robots wait changes nothing
    # beyond the replications' spread (ES1 recruitment 227 s against 259 s with it), and seed 000
    # §6.1.1 says they stop and check, so they do. 5 messages (0.5 s at 10 Hz if none is lost) is
    # ours: the text gives no number.
    #: How many of a partner's messages one encounter combines (1: the first message is fused
    #: at once, as before issue 42). The encounter ends when that many have crossed, or when
    #: ``encounter_window_s`` has passed since the first (what was collected is then used).
    #: Default 5 (see above).
    encounter_messages: int = 5
    #: How the receiver combines them: ``"mean"`` fuses the mean of the estimates transformed
    #: with eq. 27 (and the mean ``p``) once, with the strategy's filter; ``"each"`` fuses every
    #: message as it comes (eq. 14 for the first if the goal is unknown, eq. 15-16 after).
    encounter_combine: str = "mean"
    #: The longest an encounter collects messages, from its first (s).
    encounter_window_s: float = 1.0
    #: Who waits, wheels still, while one of its encounters collects: ``"none"``, ``"wandering"``
    #: (robots looking for an area, seed 000 §6.1.1's "they stop and check"), ``"all"`` (seed 000
    #: §6.2's "robots wait [...] in the communication process"). The avoid layer still acts.
    #: Default ``"wandering"`` (see above).
    encounter_stop: str = "wandering"

    def __post_init__(self):
        try:
            STRATEGIES.get(self.strategy)
        except ValueError as exc:
            raise ValueError(f"strategy: {exc}") from None
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
        if self.p_after_fusion not in ("fused", "distance"):
            raise ValueError(f"p_after_fusion: expected 'fused' or 'distance', got {self.p_after_fusion!r}")
        if self.sends not in ("both", "last-visited"):
            raise ValueError(f"sends: expected 'both' or 'last-visited', got {self.sends!r}")
        if not 0.0 <= self.give_up_factor <= 100.0:
            raise ValueError(f"give_up_factor: must be in [0, 100] (0: never give up), got {self.give_up_factor}")
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
        if type(self.encounter_messages) is not int or not 1 <= self.encounter_messages <= 50:
            raise ValueError(f"encounter_messages: must be an integer in 1..50, got {self.encounter_messages!r}")
        if self.encounter_combine not in ("mean", "each"):
            raise ValueError(f"encounter_combine: expected 'mean' or 'each', got {self.encounter_combine!r}")
        if not 0.0 < self.encounter_window_s <= 60.0:
            raise ValueError(f"encounter_window_s: must be in (0, 60] s, got {self.encounter_window_s}")
        if self.encounter_stop not in ENCOUNTER_STOPS:
            raise ValueError(f"encounter_stop: expected one of {', '.join(map(repr, ENCOUNTER_STOPS))}, "
                             f"got {self.encounter_stop!r}")
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
        known = self.goal_known[row].tolist()
        distance, angle, p = (self.goal_distance_m[row].tolist(), self.goal_angle_rad[row].tolist(),
                              self.goal_p_m[row].tolist())
        heard = []
        for rid, bearing in zip(self.heard_ids[row].tolist(), self.heard_bearing_rad[row].tolist()):
            if rid >= 0:
                heard += [rid, bearing]
        body = [int(known[NEST]) | (int(known[PREY]) << 1),
                distance[NEST], angle[NEST], p[NEST], distance[PREY], angle[PREY], p[PREY], heard]
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
    #: ``protocol.epuck.on_path(state)``, computed with the state codes (None: not computed).
    on_path: np.ndarray | None = None


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
        # A tuple: the kernels draw from these very generators (see _rng_addresses).
        self.rngs = tuple(rngs)
        self._rng_address: tuple = (None, None, None)
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
        # Each partner slot's encounter: what it collected (agents/epuck/kernels.py: E_*).
        self.encounter_acc = np.zeros((n, config.encounter_memory, kernels.N_ENCOUNTER))
        self._no_cov = np.zeros((n, 2, 3, 3))  # stands in for goal_cov where there is none
        self._adopted = np.zeros((n, 2), bool)
        # Goal vectors of the motor and send layers, their angles, robots drawing a new walk.
        self._geometry = np.zeros((2, n, 3))
        self._atan = np.zeros((n, 3))
        self._need = np.zeros(n, np.int64)
        self._n_need = np.zeros(1, np.int64)
        self._silent = SocialMessages.empty(n, k)  # what a robot that never sends "sends"
        self._sending = np.full(n, self.strategy.communicates)
        spin_rad_s = 2.0 * config.turn_speed_steps_s * body.metres_per_step / body.wheelbase_m
        # Constants of the layers (agents/epuck/kernels.py: brain_tick). The random walk's
        # uniform((-pi, lo), (pi, hi)) as low + (high - low) * random(), how numpy computes it.
        lo, hi = config.wander_straight_s
        self._params = np.zeros(kernels.N_BRAIN_PARAMS)
        for slot, value in (
            (kernels.A_CRUISE, config.cruise_speed_steps_s), (kernels.A_SPIN, config.turn_speed_steps_s),
            (kernels.A_STEERING_GAIN, config.steering_gain), (kernels.A_TURN_IN_PLACE, config.turn_in_place_rad),
            (kernels.A_ARRIVAL_TOLERANCE, config.arrival_tolerance_m),
            (kernels.A_SEARCH_OVERSHOOT, config.search_overshoot_m),
            (kernels.A_AVOID_THRESHOLD, config.avoid_threshold), (kernels.A_VMAX, body.max_wheel_speed_steps_s),
            (kernels.A_TURN_LO, -math.pi), (kernels.A_TURN_SPAN, math.pi - -math.pi),
            (kernels.A_STRAIGHT_LO, lo), (kernels.A_STRAIGHT_SPAN, hi - lo),
            (kernels.A_SPIN_PER_TICK, spin_rad_s * tick_s), (kernels.A_TICK, tick_s),
            (kernels.U_METRES_PER_STEP, body.metres_per_step), (kernels.U_WHEELBASE, body.wheelbase_m),
            (kernels.U_BLACK_BELOW, GROUND_BLACK_BELOW), (kernels.U_GREY_BELOW, GROUND_GREY_BELOW),
            (kernels.U_GROUND_AHEAD, _GROUND_AHEAD_M), (kernels.U_BETA, config.beta),
            (kernels.U_CONFIDENCE_UNIT, config.confidence_unit_m), (kernels.U_GIVE_UP_FACTOR, config.give_up_factor),
        ):
            self._params[slot] = float(value)
        self._settings = np.zeros(kernels.N_SETTINGS, np.int64)
        gain = {"none": kernels.GAIN_NONE, "kalman": kernels.GAIN_KALMAN, "fermi": kernels.GAIN_FERMI}
        self._math = numerics.numpy_math()  # numpy's exp and arctan2, bit for bit
        if self.strategy.gain not in gain:  # a user's fusion rule (agents/epuck/fusion.py)
            rule = FUSION_RULES[self.strategy.gain]
            gain[rule.name] = kernels.GAIN_CUSTOM
            self._math[numerics.M_GAIN], self._math[numerics.M_CONFIDENCE] = rule.addresses()
        for slot, value in (
            (kernels.S_DO_ODOMETRY, not uses_cov), (kernels.S_USE_COV, uses_cov),
            (kernels.S_COMMUNICATES, self.strategy.communicates), (kernels.S_DOUBLE, self.strategy.double),
            (kernels.S_GAIN, gain[self.strategy.gain]), (kernels.S_GAP_TICKS, round(config.encounter_gap_s / tick_s)),
            (kernels.S_KNOWS_BOTH, KNOWS_BOTH), (kernels.S_MOTORS, 1),
            (kernels.S_P_IS_DISTANCE, config.p_after_fusion == "distance"),
            (kernels.S_SENDS_LAST, config.sends == "last-visited"),
            (kernels.S_ENCOUNTER_MESSAGES, config.encounter_messages),
            (kernels.S_COMBINE_EACH, config.encounter_combine == "each"),
            (kernels.S_WINDOW_TICKS, max(1, round(config.encounter_window_s / tick_s))),
            (kernels.S_STOP_MODE, ENCOUNTER_STOPS.index(config.encounter_stop)),
        ):
            self._settings[slot] = int(value)

    # -- layers ------------------------------------------------------------------------------
    # The work is done by the compiled kernels of agents/epuck/kernels.py, on the state arrays above,
    # in one call per tick (brain_tick), for a batch of one as for the whole swarm.
    #
    # *Odometry*: dead reckoning of the encoder counts (seed 000 eq. 7); ``p`` grows with the
    # distance travelled (eq. 23), or is the spectral norm of the odometry covariance propagated
    # with eq. 9-11 (eq. 19, SIKF strategies: that part is numpy, here, before the kernel).
    #
    # *Arrive*: store goal locations seen by the ground sensors; switch target on arrival. The
    # stored location is the mean, over the visit, of where the robot believes its ground sensor
    # was while it saw the area: a point inside the area, not the body centre beside it.
    #
    # *Receive*: fuse what neighbours sent (seed 000 eq. 14-16, 27). Eq. 27 needs the range and
    # both bearings of one crossing. A message sent at tick k-1 carries the sender's goals in its
    # body frame of tick k-2 and the bearing at which it heard us at tick k-2; we heard the sender
    # at that same crossing, so our own range and bearing from last tick's table, and our pose of
    # then, complete the transform with no timing error. One exchange per encounter: a recent
    # partner still in hearing is ignored.
    #
    # *Remember heard*: keep the nearest neighbours heard this tick, their ids, range and bearing
    # (measured at the previous tick's poses, when the messages crossed).
    #
    # *Forage* (steer to the target's estimate), *wander* (random walk: robots that start a new
    # segment draw a turn and a straight run from their own generator), *avoid* (seed 000 §5).
    #
    # *Send*: goals are sent in the body frame of the previous tick, the frame the heard bearings
    # were measured in: the receiver then combines measurements of one and the same crossing.

    #: The motor layers' stand-in: ``None`` runs forage, wander and avoid (in the compiled tick);
    #: a function ``f(ir) -> (N, 2) wheel speeds`` set on an instance drives the wheels instead
    #: (tests use it to steer robots along known paths), every other layer running as usual.
    _motors = None

    def _rng_addresses(self) -> tuple[np.ndarray, np.ndarray]:
        """Where the kernels draw each robot's numbers from (swarmloc/numerics.py:
        generator_address): the addresses of ``self.rngs``, found again if it was replaced."""
        rngs, fn, state = self._rng_address
        if rngs is not self.rngs:
            addresses = [numerics.generator_address(g) for g in self.rngs]
            fn = np.array([a[0] for a in addresses], np.int64)
            state = np.array([a[1] for a in addresses], np.int64)
            self._rng_address = (self.rngs, fn, state)
        return fn, state

    # The pieces of a call of agents/epuck/kernels.py: brain_tick, in its argument order: also for the
    # batch engine's compiled tick (deploy/lab/epuck/batch.py), which calls brain_tick from there.

    def _tick_state(self, new_pose: np.ndarray) -> tuple:
        """The state arguments of this tick: the pose before, ``new_pose`` (written), the pose of
        two ticks ago (the frame of the messages heard now), then the state arrays."""
        return (
            self.pose, new_pose, self.pose_history[1], self.robot_ids, self.known, self.goal_xy,
            self.goal_p_m, self.goal_cov if self.goal_cov is not None else self._no_cov, self.target,
            self.searching, self.search_left_m, self.lost_count, self.visit_ticks, self.turn_ticks,
            self.straight_ticks, self.turn_dir, self.heard_ids, self.heard_bearing_rad, self.heard_range_m,
            self.partner_ids, self.partner_until, self.encounter_acc, self._adopted,
        )

    def _tick_constants(self) -> tuple:
        """The constants, generators and scratch arguments."""
        fn, rng_state = self._rng_addresses()
        return (self._params, self._settings, self._math, fn, rng_state, _COS_IR, _SIN_IR,
                self._geometry, self._atan, self._need, self._n_need)

    #: Reuse one set of output arrays for every tick (an agent process, which encodes each
    #: answer before the next tick) instead of fresh ones (the default: callers may keep them).
    reuse_outputs = False
    _kept_outputs: tuple | None = None

    def _outputs(self) -> tuple:
        """Arrays for the answer: wheel speeds, the 6 message fields (no rows if the strategy
        does not communicate), state codes, pose estimates, on_path; fresh unless
        ``reuse_outputs``."""
        if self.reuse_outputs:
            if self._kept_outputs is None:
                self._kept_outputs = self._fresh_outputs()
            return self._kept_outputs
        return self._fresh_outputs()

    def _fresh_outputs(self) -> tuple:
        n, k = self.n, self.config.heard_capacity
        rows = n if self.strategy.communicates else 0
        return (np.empty((n, 2)), np.empty((rows, 2), bool), np.empty((rows, 2)), np.empty((rows, 2)),
                np.empty((rows, 2)), np.empty((rows, k), np.int64), np.empty((rows, k)), np.empty(n, np.int64),
                np.empty((n, 3)), np.empty(n, bool))

    def _commit_tick(self, new_pose: np.ndarray) -> None:
        """After the kernel: the tick is done, ``new_pose`` the pose."""
        self.tick += 1
        self.pose_history = (self.pose_history[1], self.pose)
        self.pose = new_pose

    def _covariance_odometry(self, encoder_steps: np.ndarray, previous: np.ndarray, pose: np.ndarray) -> None:
        """Odometry of the SIKF strategies: the pose (into ``pose``), then eq. 9-11 for each
        goal's covariance since the robot left it, then eq. 19."""
        kernels.odometry(
            previous, encoder_steps, self.body.metres_per_step, self.body.wheelbase_m,
            self.search_left_m, self.goal_p_m, False, pose,
        )
        du = encoder_steps * self.body.metres_per_step
        k = self.config.odometry_k_m
        cov = propagate_covariance(
            self.goal_cov.reshape(-1, 3, 3), np.repeat(previous, 2, axis=0),
            np.repeat(du[:, 0], 2), np.repeat(du[:, 1], 2), self.body.wheelbase_m, k, k,
        )
        self.goal_cov = cov.reshape(self.n, 2, 3, 3)
        self.goal_p_m = _spectral_norm_xy(self.goal_cov)

    def state_codes(self) -> np.ndarray:
        return kernels.state_codes(self.target, self.known, KNOWS_BOTH)

    # -- the contract ------------------------------------------------------------------------

    def step(
        self, encoder_steps: np.ndarray, ir: np.ndarray, ground: np.ndarray, inbox: Inbox
    ) -> BrainOutput:
        """One controller tick for every robot of the batch (10 Hz on the e-puck): the layers of
        the module docstring, in one compiled call (agents/epuck/kernels.py: brain_tick)."""
        encoder_steps = np.asarray(encoder_steps, float)
        new_pose = np.empty_like(self.pose)
        if self.goal_cov is not None:
            self._covariance_odometry(encoder_steps, self.pose, new_pose)
        cmd, *fields, state, pose, on_path_ = outputs = self._outputs()
        c = inbox.content
        motors = self._motors
        self._settings[kernels.S_MOTORS] = motors is None
        kernels.brain_tick(
            encoder_steps, np.asarray(ir, float), np.asarray(ground, float), self.tick + 1,
            *self._tick_state(new_pose),
            inbox.receiver, inbox.sender_id, inbox.range_m, inbox.bearing_rad, inbox.rows(),
            c.goal_known, c.goal_distance_m, c.goal_angle_rad, c.goal_p_m, c.heard_ids, c.heard_bearing_rad,
            *self._tick_constants(), *outputs,
        )
        self._commit_tick(new_pose)
        self._heard_clear = not inbox.receiver.shape[0]
        if motors is not None:
            cmd = np.asarray(motors(ir), float)
        messages = SocialMessages(*fields) if self.strategy.communicates else self._silent
        return BrainOutput(cmd, self._sending, messages, state, pose, on_path_)
