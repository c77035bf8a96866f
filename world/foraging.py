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

The world owns all physical randomness, one generator drawn in a fixed order, so that a seeded
run is the same whether the agents are processes or the batch engine's arrays. A dead robot
(``alive`` false) stands still, sends nothing and hears nothing; it stays an obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from swarmloc.protocol.epuck import EpuckBody, ground_sensor_point, integrate_pose
from swarmloc.protocol.messages import MAX_RAB_PAYLOAD_BYTES, MAX_RECEIVED
from swarmloc.world.arena import Arena, Disc, area_at, resolve_collisions
from swarmloc.world.medium import Deliveries, RabMedium, deliver
from swarmloc.world.metrics import ForagingMetrics
from swarmloc.world.sensors import SensorParams, ground_sensors, ir_proximity

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

    @property
    def n_robots(self) -> int:
        return self.config.robots

    @property
    def done(self) -> bool:
        return self.tick >= self.config.n_ticks

    def observe(self) -> Observation:
        cfg = self.config
        ir = ir_proximity(self.pose, cfg.body.body_radius_m, self.arena, cfg.sensors, self.rng)
        ground = ground_sensors(self.pose, self.arena, cfg.sensors, self.rng)
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
        vmax = cfg.body.max_wheel_speed_steps_s
        cmd = np.clip(np.asarray(wheel_speed_steps_s, float), -vmax, vmax)
        cmd[~self.alive] = 0.0
        # The board measures range and bearing when the message crosses, at the poses the
        # senders computed their content from; receivers hear it at the next tick.
        sending = np.asarray(sending, bool) & self.alive
        self._deliveries = deliver(self.pose, sending, cfg.medium, self.rng)
        encoder = cmd * cfg.tick_s
        slip = cfg.odometry.slip_fraction
        factor = 1.0 + self.rng.uniform(-slip, slip, size=encoder.shape)
        travel_m = encoder * cfg.body.metres_per_step * factor
        pose = integrate_pose(self.pose, travel_m[:, 0], travel_m[:, 1], cfg.body.wheelbase_m)
        pose[:, :2] = resolve_collisions(pose[:, :2], cfg.body.body_radius_m, self.arena)
        self.pose = pose
        self.encoder_steps = encoder
        self.tick += 1
        # A robot is at an area when its (middle) ground sensor truly is over it.
        sensor = ground_sensor_point(pose)
        self.metrics.update(self.tick, area_at(sensor, self.arena), on_path & self.alive)

    def kill(self, index: int) -> None:
        """The robot's agent is gone: it stands still from now on."""
        self.alive[index] = False

    def revive(self, index: int) -> None:
        self.alive[index] = True
