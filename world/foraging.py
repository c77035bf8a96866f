"""The e-puck foraging world: one pure model stepped by the world-server and the batch engine.

Per tick ``k`` (lockstep, seed 000 §5 controller clock of 10 Hz):

1. :meth:`ForagingWorld.observe` gives every robot its percepts at the current poses: the encoder
   increments of the last move, 8 IR proximity readings, 3 ground readings, and the messages sent
   at ``k-1`` that the range-and-bearing medium delivers now, tagged with the range and bearing
   the receiver measured when they crossed (at the poses of tick ``k-1``, which are the poses the
   senders computed their content from).
2. The agents answer with wheel speeds, an outgoing message, and their controller state.
3. :meth:`ForagingWorld.step` moves the robots: the encoders count the commanded steps, the
   wheels really travel ``(1 + u)`` times that, ``u ~ U(-slip, slip)`` per wheel and tick (the
   non-systematic error of seed 000 eq. 10 with the +-20 % uniform slip of seed 001 §4.1); then
   collisions are resolved and the foraging metrics updated.

The world owns all physical randomness, one generator drawn in a fixed order (IR noise, ground
noise; loss, range noise, bearing noise, slip), so that a seeded run is the same whether the
agents are processes or the batch engine's arrays. Consecutive draws are merged into one
``rng.random`` call where that gives the same numbers (see ``world/kernels.py``: ``uniform``), and
the per-robot loops run in the compiled kernels of ``world/kernels.py``. A dead robot
(``alive`` false) stands still, sends nothing and hears nothing; it stays an obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from swarmloc.protocol.epuck import GROUND_SENSOR_OFFSETS_M, IR_SENSOR_ANGLES_RAD, EpuckBody
from swarmloc.protocol.messages import MAX_RAB_PAYLOAD_BYTES, MAX_RECEIVED
from swarmloc.world import kernels
from swarmloc.world.arena import (
    REFLECTANCE_BY_AREA,
    Arena,
    Disc,
    arena_discs,
    resolve_collisions,
)
from swarmloc.world.medium import Deliveries, RabMedium, crossing, deliver
from swarmloc.world.metrics import ForagingMetrics
from swarmloc.world.sensors import SensorParams

_COS_IR = np.cos(IR_SENSOR_ANGLES_RAD)
_SIN_IR = np.sin(IR_SENSOR_ANGLES_RAD)
_N_IR = IR_SENSOR_ANGLES_RAD.shape[0]
_N_GROUND = GROUND_SENSOR_OFFSETS_M.shape[0]
_NO_PAIRS = np.empty(0, np.int64)
#: Collision-resolution iterations per tick (resolve_collisions' default).
_COLLISION_ITERATIONS = 2

#: Stream id of the world's generator (``[seed, stream]``); agents use stream 1 with their id.
WORLD_STREAM = 0


@dataclass(frozen=True)
class ArenaConfig:
    """A rectangular arena with a black nest and a grey prey disc (seed 000 fig. 7, table 2)."""

    width_m: float = 1.2
    height_m: float = 1.7
    nest_centre_m: tuple[float, float] = (0.6, 0.255)
    nest_radius_m: float = 0.1
    prey_centre_m: tuple[float, float] = (0.6, 1.445)
    prey_radius_m: float = 0.1
    #: Robots start at random in a disc at the centre of the arena (seed 000 §5).
    initial_radius_m: float = 0.2

    def __post_init__(self):
        arena = self.arena()  # validates sizes and discs
        centre = np.array([self.width_m / 2, self.height_m / 2])
        if not self.initial_radius_m > 0:
            raise ValueError(f"initial_radius_m: must be > 0, got {self.initial_radius_m}")
        if self.initial_radius_m > min(self.width_m, self.height_m) / 2:
            raise ValueError("initial_radius_m: the start disc does not fit in the arena")
        for name, disc in (("nest", arena.nest), ("prey", arena.prey)):
            gap = np.hypot(*(np.array(disc.centre_m) - centre))
            if gap < disc.radius_m + self.initial_radius_m:
                raise ValueError(f"{name}_centre_m: the {name} overlaps the start disc")

    def arena(self) -> Arena:
        return Arena(
            width_m=self.width_m,
            height_m=self.height_m,
            nest=Disc(tuple(self.nest_centre_m), self.nest_radius_m),
            prey=Disc(tuple(self.prey_centre_m), self.prey_radius_m),
        )


@dataclass(frozen=True)
class OdometryConfig:
    #: Per-wheel, per-tick uniform slip as a fraction of the commanded travel (seed 001 §4.1).
    slip_fraction: float = 0.2

    def __post_init__(self):
        if not 0.0 <= self.slip_fraction < 1.0:
            raise ValueError(f"slip_fraction: must be in [0, 1), got {self.slip_fraction}")


@dataclass(frozen=True)
class WorldConfig:
    """Everything the world needs to simulate one foraging run."""

    robots: int = 10
    duration_s: float = 1800.0
    tick_s: float = 0.1
    seed: int = 1
    arena: ArenaConfig = field(default_factory=ArenaConfig)
    body: EpuckBody = field(default_factory=EpuckBody)
    odometry: OdometryConfig = field(default_factory=OdometryConfig)
    sensors: SensorParams = field(default_factory=SensorParams)
    medium: RabMedium = field(default_factory=RabMedium)

    def __post_init__(self):
        if not 1 <= self.robots <= 65536:
            raise ValueError(f"robots: must be in 1..65536, got {self.robots}")
        if not self.tick_s > 0:
            raise ValueError(f"tick_s: must be > 0, got {self.tick_s}")
        if not self.duration_s >= self.tick_s:
            raise ValueError(f"duration_s: must be at least one tick, got {self.duration_s}")
        if not 0 <= self.seed < 2**63:
            raise ValueError(f"seed: must be in 0..2**63-1, got {self.seed}")
        if self.medium.max_received_per_tick > MAX_RECEIVED:
            raise ValueError(f"medium.max_received_per_tick: a Sense carries at most {MAX_RECEIVED} messages")
        if self.medium.max_payload_bytes > MAX_RAB_PAYLOAD_BYTES:
            raise ValueError(f"medium.max_payload_bytes: the protocol carries at most {MAX_RAB_PAYLOAD_BYTES} bytes")
        free = self.arena.width_m * self.arena.height_m
        if self.robots * np.pi * self.body.body_radius_m**2 > 0.5 * free:
            raise ValueError(f"robots: {self.robots} e-pucks do not fit in the arena")

    @property
    def n_ticks(self) -> int:
        return round(self.duration_s / self.tick_s)


@dataclass
class Observation:
    """What every robot perceives at one tick (arrays with a leading robot axis)."""

    tick: int
    encoder_steps: np.ndarray  # (N, 2) left, right steps counted during the last tick
    ir: np.ndarray  # (N, 8) in [0, 1]
    ground: np.ndarray  # (N, 3) reflectance
    deliveries: Deliveries  # messages sent at tick-1, as received now


def initial_poses(config: WorldConfig, rng: np.random.Generator) -> np.ndarray:
    """Random non-overlapping poses in the start disc, random headings (seed 000 §5, §6.2)."""
    n, radius = config.robots, config.body.body_radius_m
    centre = np.array([config.arena.width_m / 2, config.arena.height_m / 2])
    spread = config.arena.initial_radius_m
    pose = np.zeros((n, 3))
    placed = 0
    for _ in range(200):
        # Draw a whole batch of candidates at once; keep those that do not overlap.
        r = spread * np.sqrt(rng.random(n))
        a = rng.uniform(-np.pi, np.pi, n)
        cand = centre + np.stack((r * np.cos(a), r * np.sin(a)), axis=1)
        for c in cand:
            if placed == n:
                break
            if placed == 0 or np.min(np.hypot(*(pose[:placed, :2] - c).T)) >= 2 * radius:
                pose[placed, :2] = c
                placed += 1
        if placed == n:
            break
    if placed < n:  # too dense to place without overlap: let collisions spread the rest
        extra = centre + rng.uniform(-spread, spread, (n - placed, 2))
        pose[placed:, :2] = extra
        pose[:, :2] = resolve_collisions(pose[:, :2], radius, config.arena.arena(), iterations=20)
    pose[:, 2] = rng.uniform(-np.pi, np.pi, n)
    return pose


_kernels_loaded = False


def _load_kernels(config: WorldConfig) -> None:
    """Load (or, the first time on a machine, compile) the world's kernels now, once per process,
    by stepping a throwaway two-robot world of the same configuration with its own generator: at
    the first observe(), so that a world-server answers joins at once and, in real time, pays
    the loading on one tick instead of spreading it over the first few."""
    global _kernels_loaded
    if _kernels_loaded:
        return
    _kernels_loaded = True
    robots = 2 if 2 * np.pi * config.body.body_radius_m**2 <= 0.5 * config.arena.width_m * config.arena.height_m else 1
    world = ForagingWorld(replace(config, robots=robots), np.random.default_rng(0))
    world.observe()
    world.step(np.zeros((robots, 2)), np.ones(robots, bool), np.zeros(robots, bool))


class ForagingWorld:
    """The e-puck foraging world over a batch of robots."""

    def __init__(self, config: WorldConfig, rng: np.random.Generator | None = None):
        self.config = config
        self.rng = rng if rng is not None else np.random.default_rng([config.seed, WORLD_STREAM])
        self.arena = config.arena.arena()
        n = config.robots
        self.pose = initial_poses(config, self.rng)
        self.alive = np.ones(n, bool)
        self.tick = 0
        self.encoder_steps = np.zeros((n, 2))
        self._deliveries = deliver(self.pose, np.zeros(n, bool), config.medium, self.rng)
        self.metrics = ForagingMetrics(n, config.tick_s)
        self._n_ticks = config.n_ticks
        self._pairs: tuple = (None, None)  # (poses, neighbour pairs found at them by observe())
        # Pairs for the IR sensors, the medium and the collisions of the step after.
        self._pair_cutoff_m = max(
            config.medium.range_m, 2.0 * config.body.body_radius_m + config.sensors.ir_range_m
        )

    @property
    def n_robots(self) -> int:
        return self.config.robots

    @property
    def done(self) -> bool:
        return self.tick >= self._n_ticks

    def observe(self) -> Observation:
        if self.tick == 0:
            _load_kernels(self.config)
        cfg = self.config
        # ir_proximity and ground_sensors (world/sensors.py) in one kernel call, with one
        # random() call for both noises: the same numbers, in the same order, as their two
        # uniform() calls. The robot pairs it finds are those that the medium and the collisions
        # of step() need at these same poses: kept.
        n = self.n_robots
        f, g = cfg.sensors.ir_noise_fraction, cfg.sensors.ground_noise_fraction
        ir, ground, pairs = kernels.sense(
            self.pose, cfg.body.body_radius_m, cfg.sensors.ir_range_m, self.arena.width_m,
            self.arena.height_m, _COS_IR, _SIN_IR, -f, f - -f, GROUND_SENSOR_OFFSETS_M,
            arena_discs(self.arena), REFLECTANCE_BY_AREA, -g, g - -g,
            self.rng.random(n * (_N_IR + _N_GROUND)), self._pair_cutoff_m,
        )
        self._pairs = (self.pose, pairs)
        deliveries = self._deliveries
        if not self.alive.all() and deliveries.receiver.shape[0]:
            keep = self.alive[deliveries.receiver]
            deliveries = Deliveries(
                deliveries.sender[keep],
                deliveries.receiver[keep],
                deliveries.range_m[keep],
                deliveries.bearing_rad[keep],
            )
        return Observation(self.tick, self.encoder_steps.copy(), ir, ground, deliveries)

    def step(self, wheel_speed_steps_s: np.ndarray, sending: np.ndarray, on_path: np.ndarray):
        """Apply one tick of wheel commands ``(N, 2)`` (steps/s, left and right)."""
        cfg = self.config
        cmd = np.asarray(wheel_speed_steps_s, float)
        if cmd.shape != (self.n_robots, 2):
            raise ValueError(f"wheel_speed_steps_s: expected shape ({self.n_robots}, 2), got {cmd.shape}")
        # The board measures range and bearing when the message crosses, at the poses the
        # senders computed their content from; receivers hear it at the next tick. The medium's
        # draws (world/medium.py: deliver) come first, then the slip of each wheel, as
        # U(-slip, slip), the non-systematic odometry error: one random() call for the range and
        # bearing noises and the slips gives the same numbers as three uniform() calls.
        sending = np.asarray(sending, bool) & self.alive
        pairs = self._pairs[1] if self._pairs[0] is self.pose else None
        crossed = crossing(self.pose, sending, cfg.medium, self.rng, pairs)
        k, n = crossed.sender.shape[0], self.n_robots
        u = self.rng.random(2 * k + 2 * n)
        rn, bn = cfg.medium.range_noise_m, cfg.medium.bearing_noise_rad
        slip = cfg.odometry.slip_fraction
        # Then, in one kernel call: the boards' measurements, the encoders (commanded steps) and
        # the true motion ((1 + u) times that, eq. 3-7), collisions (world/arena.py:
        # resolve_collisions) and, for the metrics, the true area under each robot's (middle)
        # ground sensor.
        discs = arena_discs(self.arena)
        ahead_m = GROUND_SENSOR_OFFSETS_M[1, 0]
        pose, encoder, area, ok, range_m, bearing_rad = kernels.advance(
            self.pose, cmd, self.alive, cfg.body.max_wheel_speed_steps_s, cfg.tick_s,
            cfg.body.metres_per_step, -slip, slip - -slip, cfg.body.wheelbase_m, cfg.body.body_radius_m,
            self.arena.width_m, self.arena.height_m, _COLLISION_ITERATIONS, ahead_m, discs,
            crossed.dist_m, crossed.bearing_atan(), crossed.receiver_theta, -rn, rn - -rn, -bn, bn - -bn, u,
            *((pairs[0], pairs[1], self._pair_cutoff_m) if pairs is not None else (_NO_PAIRS, _NO_PAIRS, 0.0)),
        )
        self._deliveries = Deliveries(crossed.sender, crossed.receiver, range_m, bearing_rad)
        if not ok:  # a crowd: resolve_collisions' own (KD-tree) path
            pose[:, :2] = resolve_collisions(
                pose[:, :2], cfg.body.body_radius_m, self.arena, iterations=_COLLISION_ITERATIONS
            )
            area = kernels.sensor_areas(pose, ahead_m, discs)
        self.pose = pose
        self.encoder_steps = encoder
        self.tick += 1
        self.metrics.update(self.tick, area, on_path & self.alive)

    def kill(self, index: int) -> None:
        """The robot's agent is gone: it stands still from now on."""
        self.alive[index] = False

    def revive(self, index: int) -> None:
        self.alive[index] = True
