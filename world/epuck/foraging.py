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
   non-systematic error of seed 000 eq. 10 with the +-20 % uniform slip of seed 001 §4.1), or per
   physics sub-step (``OdometryConfig.substeps``); then
   collisions are resolved and the foraging metrics updated.

The world owns all physical randomness, one generator drawn in a fixed order (IR noise, ground
noise; loss, range noise, bearing noise, slip), so that a seeded run is the same whether the
agents are processes or the batch engine's arrays. Consecutive draws are merged into one
``random`` call where that gives the same numbers (see ``world/epuck/kernels.py``: ``uniform``). Each
of :meth:`ForagingWorld.observe` and :meth:`ForagingWorld.step` is one call of a compiled kernel
of ``world/epuck/kernels.py`` (``observe_tick``, ``step_tick``), which draws from the world's generator
itself, the same numbers in the same order. A dead robot (``alive`` false) stands still, sends
nothing and hears nothing; it stays an obstacle.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from swarmloc import numerics
from swarmloc.protocol.epuck import GROUND_SENSOR_OFFSETS_M, IR_SENSOR_ANGLES_RAD, EpuckBody
from swarmloc.protocol.messages import MAX_RAB_PAYLOAD_BYTES, MAX_RECEIVED
from swarmloc.world.epuck import kernels
from swarmloc.world.epuck.arena import (
    REFLECTANCE_BY_AREA,
    Arena,
    Disc,
    arena_discs,
    resolve_collisions,
)
from swarmloc.world.epuck.medium import Deliveries, RabMedium
from swarmloc.world.epuck.metrics import ForagingMetrics
from swarmloc.world.epuck.sensors import SensorParams

_COS_IR = np.cos(IR_SENSOR_ANGLES_RAD)
_SIN_IR = np.sin(IR_SENSOR_ANGLES_RAD)
_N_IR = IR_SENSOR_ANGLES_RAD.shape[0]
_N_GROUND = GROUND_SENSOR_OFFSETS_M.shape[0]
_C_CROSSED, _C_PAIRS = kernels.C_CROSSED, kernels.C_PAIRS
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
    #: 0: the arena above, whatever the number of robots. N > 0: a tiled arena that keeps a
    #: density of N robots per arena of the size above for any number of robots (the ``ES3-tiled``
    #: family): the arena above (its nest, prey and start disc) is one tile, repeated as many
    #: times as the robots need (:func:`tile_grid`) inside one set of outer walls; robot ``i``
    #: starts in the start disc of tile ``i * tiles // robots``.
    tile_robots: int = 0
    #: Where nest and prey are, as a reading (issue 42). Seed 000 gives no positions: "All
    #: setups are carried out in a similar arena (see Figure 7)", and the figure is not in the
    #: text. 0 (default): ``nest_centre_m`` and ``prey_centre_m`` as given (the shipped ES1-ES3
    #: put them 15 % of the long side from the short walls). ``f`` in (0, 0.5): both on the long
    #: axis, at ``f`` and ``1 - f`` of the long side from one short wall, replacing the centres.
    goal_fraction: float = 0.0

    def __post_init__(self):
        if not 0.0 <= self.goal_fraction < 0.5:
            raise ValueError(f"goal_fraction: must be in [0, 0.5) (0: the centres as given), got {self.goal_fraction}")
        if self.goal_fraction > 0.0:
            f = self.goal_fraction
            if self.height_m >= self.width_m:
                nest, prey = (self.width_m / 2, f * self.height_m), (self.width_m / 2, (1 - f) * self.height_m)
            else:
                nest, prey = (f * self.width_m, self.height_m / 2), ((1 - f) * self.width_m, self.height_m / 2)
            object.__setattr__(self, "nest_centre_m", nest)
            object.__setattr__(self, "prey_centre_m", prey)
        arena = self.arena()  # validates sizes and discs
        if isinstance(self.tile_robots, bool) or not isinstance(self.tile_robots, int) or self.tile_robots < 0:
            raise ValueError(f"tile_robots: must be an integer >= 0, got {self.tile_robots!r}")
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
        """One tile's arena (the whole arena unless ``tile_robots``: see WorldConfig.arena_model)."""
        return Arena(
            width_m=self.width_m,
            height_m=self.height_m,
            nest=Disc(tuple(self.nest_centre_m), self.nest_radius_m),
            prey=Disc(tuple(self.prey_centre_m), self.prey_radius_m),
        )


@dataclass(frozen=True)
class OdometryConfig:
    #: Per-wheel uniform slip as a fraction of the commanded travel of one physics step (seed
    #: 001 §4.1: "randomly chosen from a uniform distribution, being limited to +-20% of the
    #: maximum movement at each time step").
    slip_fraction: float = 0.2
    #: Physics sub-steps per controller tick, the slip drawn per sub-step (issue 18, reading 3).
    #: Seed 001 §4.1 draws the slip "at each time step" of a simulator "based on ODE", whose step
    #: it does not give; seed 000 §5 gives only the controller's 10 Hz clock. 1 (``v0-defaults``):
    #: the world moves once per 100 ms tick. ``S`` > 1: it moves ``S`` times, ``1/S`` of the
    #: commanded travel each, so the heading drift per metre shrinks about as ``1/sqrt(S)``
    #: (+-20 % per 10 ms sub-step, ``S`` = 10, drifts like +-6.3 % per tick). The encoders and
    #: the collisions stay per tick.
    #:
    #: Default 10 (100 Hz physics under the 10 Hz controller): seed 001's "time step" is the ODE
    #: simulator's, and a rigid-body simulator steps faster than the controller it hosts (ODE
    #: robot simulators of the time commonly at 100 Hz; the papers name no rate, so 10 is ours).
    #: With 1, a lone robot's lateral miss over ES3's 5.95 m is several area radii and the
    #: SGIKFs' chains of corrections cannot keep up (ablation docs/so-000-readings/, group
    #: substeps-10; seed 000 §6.2 quotes about 150 SGIKF round trips in simulated ES1).
    substeps: int = 10

    def __post_init__(self):
        if not 0.0 <= self.slip_fraction < 1.0:
            raise ValueError(f"slip_fraction: must be in [0, 1), got {self.slip_fraction}")
        if not 1 <= self.substeps <= 100:
            raise ValueError(f"substeps: must be in 1..100, got {self.substeps}")


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
        if not 1 <= self.robots <= MAX_ROBOTS:
            raise ValueError(f"robots: must be in 1..{MAX_ROBOTS}, got {self.robots}")
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
        cols, rows = self.tiles
        free = self.arena.width_m * self.arena.height_m * cols * rows
        if self.robots * np.pi * self.body.body_radius_m**2 > 0.5 * free:
            raise ValueError(f"robots: {self.robots} e-pucks do not fit in the arena")

    @property
    def n_ticks(self) -> int:
        return round(self.duration_s / self.tick_s)

    @property
    def tiles(self) -> tuple[int, int]:
        """Columns and rows of tiles of the arena (1, 1 unless ``arena.tile_robots``)."""
        if not self.arena.tile_robots:
            return 1, 1
        return tile_grid(-(-self.robots // self.arena.tile_robots), self.arena.width_m, self.arena.height_m)

    def arena_model(self) -> Arena:
        """The walled arena the robots move in: ``arena.arena()``, or its tiling."""
        one = self.arena.arena()
        cols, rows = self.tiles
        if cols * rows == 1:
            return one
        return replace(one, width_m=cols * one.width_m, height_m=rows * one.height_m,
                       tile_m=(one.width_m, one.height_m))


#: The most robots a world holds. The batch engine takes that many; a swarm of processes at most
#: 65,536 (robot ids cross the wire as 0..65535, protocol/messages.py), fewer if the machine's
#: memory cannot hold them (deploy/run.py: check_memory).
MAX_ROBOTS = 1 << 20


def tile_grid(tiles: int, tile_w_m: float, tile_h_m: float) -> tuple[int, int]:
    """``(columns, rows)`` for at least ``tiles`` tiles of ``tile_w_m`` x ``tile_h_m``: the fewest
    tiles left empty (none when ``tiles`` factors so), with the arena's sides at most 3:1, and
    of those the squarest arena (1000 ES3 tiles: 40 x 25, 240 x 212.5 m); robots are spread evenly
    over all tiles, so the density is ``robots / (columns * rows * tile area)``."""
    best = None
    for cols in range(1, tiles + 1):
        rows = -(-tiles // cols)
        aspect = max(cols * tile_w_m, rows * tile_h_m) / min(cols * tile_w_m, rows * tile_h_m)
        key = (aspect > 3.0, cols * rows - tiles, aspect)
        if best is None or key < best[0]:
            best = (key, cols, rows)
        if rows == 1:
            break
    return best[1], best[2]


@dataclass
class Observation:
    """What every robot perceives at one tick (arrays with a leading robot axis)."""

    tick: int
    encoder_steps: np.ndarray  # (N, 2) left, right steps counted during the last tick
    ir: np.ndarray  # (N, 8) in [0, 1]
    ground: np.ndarray  # (N, 3) reflectance
    deliveries: Deliveries  # messages sent at tick-1, as received now


def initial_poses(config: WorldConfig, rng: np.random.Generator) -> np.ndarray:
    """Random non-overlapping poses in the start disc, random headings (seed 000 §5, §6.2). In a
    tiled arena, the robots of each tile in order (robot ``i`` in tile ``i * tiles // robots``,
    so that neighbours are near in memory too) in that tile's start disc, then all headings."""
    n = config.robots
    cols, rows = config.tiles
    if cols * rows == 1:
        centre = np.array([config.arena.width_m / 2, config.arena.height_m / 2])
        pose = np.zeros((n, 3))
        _place_in_disc(pose, centre, config, rng, config.arena_model())
    else:
        pose = np.zeros((n, 3))
        tiles = cols * rows
        bounds = np.arange(tiles + 1) * n // tiles
        arena = config.arena_model()
        for t in range(tiles):  # row by row
            centre = np.array([(t % cols + 0.5) * config.arena.width_m, (t // cols + 0.5) * config.arena.height_m])
            _place_in_disc(pose[bounds[t]:bounds[t + 1]], centre, config, rng, arena)
    pose[:, 2] = rng.uniform(-np.pi, np.pi, n)
    return pose


def _place_in_disc(pose: np.ndarray, centre: np.ndarray, config: WorldConfig, rng: np.random.Generator,
                   arena: Arena) -> None:
    """Positions ``pose[:, :2]`` at random in the start disc around ``centre``, without overlap:
    batches of candidates drawn at once, each kept if it overlaps no body kept before
    (world/epuck/kernels.py: place_candidates)."""
    n, radius = pose.shape[0], config.body.body_radius_m
    if n == 0:
        return
    spread = config.arena.initial_radius_m
    placed = 0
    for _ in range(200):
        # Draw a whole batch of candidates at once; keep those that do not overlap.
        r = spread * np.sqrt(rng.random(n))
        a = rng.uniform(-np.pi, np.pi, n)
        cand = centre + np.stack((r * np.cos(a), r * np.sin(a)), axis=1)
        placed = kernels.place_candidates(pose, placed, cand, 2 * radius)
        if placed == n:
            break
    if placed < n:  # too dense to place without overlap: let collisions spread the rest
        extra = centre + rng.uniform(-spread, spread, (n - placed, 2))
        pose[placed:, :2] = extra
        pose[:, :2] = resolve_collisions(pose[:, :2], radius, arena, iterations=20)


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
    world = ForagingWorld(replace(config, robots=robots, arena=replace(config.arena, tile_robots=0)),
                          np.random.default_rng(0))
    world.observe()
    world.step(np.zeros((robots, 2)), np.ones(robots, bool), np.zeros(robots, bool))


class ForagingWorld:
    """The e-puck foraging world over a batch of robots."""

    def __init__(self, config: WorldConfig, rng: np.random.Generator | None = None):
        self.config = config
        self.rng = rng if rng is not None else np.random.default_rng([config.seed, WORLD_STREAM])
        self.arena = config.arena_model()
        n = self._n = config.robots
        self.pose = initial_poses(config, self.rng)
        self.alive = np.ones(n, bool)
        self.tick = 0
        self.encoder_steps = np.zeros((n, 2))
        self.metrics = ForagingMetrics(n, config.tick_s)
        self._n_ticks = config.n_ticks
        # The compiled tick (world/epuck/kernels.py: observe_tick, step_tick): constants, and buffers
        # that the two calls share. Pairs for the IR sensors, the medium and the collisions of the
        # step after are found when sensing, within the larger of the two reaches.
        body, medium = config.body, config.medium
        self._params = kernels.world_params(
            body_radius_m=body.body_radius_m, ir_range_m=config.sensors.ir_range_m,
            width_m=self.arena.width_m, height_m=self.arena.height_m,
            ir_noise=config.sensors.ir_noise_fraction, ground_noise=config.sensors.ground_noise_fraction,
            pair_cutoff_m=max(medium.range_m, 2.0 * body.body_radius_m + config.sensors.ir_range_m),
            rab_range_m=medium.range_m, range_noise_m=medium.range_noise_m,
            bearing_noise_rad=medium.bearing_noise_rad, near_m=medium.near_m, loss_near=medium.loss_near,
            loss_far=medium.loss_far, max_received=medium.max_received_per_tick,
            vmax=body.max_wheel_speed_steps_s, tick_s=config.tick_s, metres_per_step=body.metres_per_step,
            slip_fraction=config.odometry.slip_fraction, wheelbase_m=body.wheelbase_m,
            iterations=_COLLISION_ITERATIONS, ahead_m=GROUND_SENSOR_OFFSETS_M[1, 0],
            substeps=config.odometry.substeps,
        )
        self._discs = arena_discs(self.arena)
        self._counts = np.zeros(kernels.N_COUNTS, np.int64)
        self._counts[kernels.C_PAIRS] = -1  # no pairs found yet
        self._pair_buffers(8 * n + 16)
        self._noise_u = np.empty(n * (_N_IR + _N_GROUND))  # room for observe's uniforms
        self._per_robot = np.empty((2, n + 1), np.int64)
        self._snapshot = np.empty((n, 3))  # the poses the pairs were found at
        self._trig = np.empty((2, n))  # cosines and sines of the headings of the poses _trig_pose
        self._trig_pose = np.full((n, 3), np.nan)
        # Messages that crossed at the last step, heard at the next observe: (sender, receiver)
        # and the (range, bearing) measured; at most max_received_per_tick per receiver.
        k_max = n * medium.max_received_per_tick
        self._crossed_ij = np.empty((2, k_max), np.int64)
        self._crossed_f = np.empty((2, k_max))
        self._step_u = np.empty(2 * k_max + 2 * config.odometry.substeps * n)  # room for step's uniforms
        self._rng_address: tuple = (None, 0, 0)  # (generator, next_double, state)
        self._math = numerics.numpy_math()  # numpy's arctan2, bit for bit

    def _pair_buffers(self, capacity: int) -> None:
        """Room for ``capacity`` neighbour pairs (world/epuck/kernels.py: neighbour_pairs_into) and for
        the messages they may carry (step_tick's scratch)."""
        self._counts[_C_PAIRS] = -1  # the pairs found, if any, were in the old buffers
        self._pair_ij = np.empty((2, capacity), np.int64)
        self._pair_f = np.empty((3, capacity))
        self._pair_scratch = np.empty((2, capacity), np.int64)
        self._work_i = np.empty((5, 2 * capacity), np.int64)
        self._work_f = np.empty((7, 2 * capacity))

    @property
    def n_robots(self) -> int:
        return self.config.robots

    @property
    def done(self) -> bool:
        return self.tick >= self._n_ticks

    def _rng_addresses(self) -> tuple[int, int]:
        """Where the kernels draw from ``self.rng`` (swarmloc/numerics.py: generator_address)."""
        rng, fn, state = self._rng_address
        if rng is not self.rng:
            fn, state = numerics.generator_address(self.rng)
            self._rng_address = (self.rng, fn, state)
        return fn, state

    def observe(self) -> Observation:
        """Every robot's percepts at the current poses (one compiled call: see
        ``world/epuck/kernels.py: observe_tick``). Draws: IR noise ``(N, 8)`` then ground noise
        ``(N, 3)``, as one ``random(11 N)``: the numbers of ir_proximity's and ground_sensors'
        two ``uniform()`` calls (world/epuck/sensors.py)."""
        if self.tick == 0:
            _load_kernels(self.config)
        n, counts = self._n, self._counts
        ir = np.empty((n, _N_IR))
        ground = np.empty((n, _N_GROUND))
        k = int(counts[_C_CROSSED])
        sender, receiver = np.empty(k, np.int64), np.empty(k, np.int64)
        range_m, bearing_rad = np.empty(k), np.empty(k)
        while True:
            kept = kernels.observe_tick(*self._observe_args(self.pose, ir, ground, sender, receiver, range_m, bearing_rad))
            if kept >= 0:
                break
            self._grow_pairs()  # nothing drawn yet
        if kept < k:  # dead receivers hear nothing
            sender, receiver, range_m, bearing_rad = sender[:kept], receiver[:kept], range_m[:kept], bearing_rad[:kept]
        return Observation(self.tick, self.encoder_steps.copy(), ir, ground,
                           Deliveries(sender, receiver, range_m, bearing_rad))

    def step(self, wheel_speed_steps_s: np.ndarray, sending: np.ndarray, on_path: np.ndarray):
        """Apply one tick of wheel commands ``(N, 2)`` (steps/s, left and right); ``sending``
        ``(N,)``: who broadcasts (dead robots never do); ``on_path`` ``(N,)``: who forages on the
        path, for the metrics.

        In one compiled call (``world/epuck/kernels.py: step_tick``): the board measures range and
        bearing when the message crosses, at the poses the senders computed their content from;
        receivers hear it at the next tick. The medium's draws (world/epuck/medium.py: loss, then range
        and bearing noises) come first, then the slip of each wheel as U(-slip, slip), the
        non-systematic odometry error: one random() call for the noises and the slips gives the
        same numbers as three uniform() calls. Then the encoders (commanded steps) and the true
        motion ((1 + u) times that, eq. 3-7), collisions (world/epuck/arena.py: resolve_collisions)
        and the foraging metrics of the true area under each robot's middle ground sensor.
        """
        n = self._n
        cmd = np.asarray(wheel_speed_steps_s, float)
        if cmd.shape != (n, 2):
            raise ValueError(f"wheel_speed_steps_s: expected shape ({n}, 2), got {cmd.shape}")
        sending = np.asarray(sending, bool)
        if sending.shape != (n,):
            raise ValueError(f"sending must have shape ({n},), got {sending.shape}")
        on_path = np.asarray(on_path, bool)
        if on_path.shape != (n,):
            raise ValueError(f"on_path must have shape ({n},), got {on_path.shape}")
        pose = np.empty((n, 3))
        encoder = np.empty((n, 2))
        on_path_count = kernels.step_tick(*self._step_args(cmd, sending, on_path, pose, encoder))
        self._finish_step(pose, encoder, self.tick + 1, on_path_count, on_path)

    # The arguments of world/epuck/kernels.py: observe_tick and step_tick, in their order: also for the
    # batch engine's compiled tick (deploy/lab/epuck/batch.py), which calls them from there.

    def _observe_args(self, pose, ir, ground, sender, receiver, range_m, bearing_rad) -> tuple:
        """``observe_tick``'s arguments, sensing at ``pose`` into ``ir``, ``ground`` and the
        deliveries' arrays (room for every message that crossed)."""
        fn, state = self._rng_addresses()
        return (pose, self._params, _COS_IR, _SIN_IR, GROUND_SENSOR_OFFSETS_M, self._discs, REFLECTANCE_BY_AREA,
                fn, state, ir, ground, self._pair_ij, self._pair_f, self._pair_scratch, self._snapshot,
                self._counts, self._crossed_ij, self._crossed_f, self.alive, sender, receiver, range_m,
                bearing_rad, self._trig, self._trig_pose, self._noise_u)

    def _grow_pairs(self) -> None:
        """``observe_tick`` found more pairs than there is room for (and did nothing else)."""
        self._pair_buffers(-2 * int(self._counts[_C_PAIRS]))

    def _step_args(self, cmd, sending, on_path, pose, encoder) -> tuple:
        """``step_tick``'s arguments for validated commands, into ``pose`` and ``encoder``."""
        fn, state = self._rng_addresses()
        first_visit, round_trips, stage, codes = self.metrics.kernel_state()
        return (self.pose, cmd, self.alive, sending, on_path, self._params, self._discs, fn, state, self._math,
                self._pair_ij, self._pair_f, self._snapshot, self._counts, pose, encoder, self._crossed_ij,
                self._crossed_f, self.tick + 1, first_visit, round_trips, stage, codes, self._trig, self._trig_pose,
                self._per_robot, self._work_i, self._work_f, self._step_u)

    def _finish_step(self, pose, encoder, tick: int, on_path_count: int, on_path: np.ndarray) -> None:
        """After ``step_tick`` (here or in the batch engine's compiled tick, deploy/lab/epuck/batch.py):
        the new state; ``on_path_count`` < 0 means a crowd, whose collisions are resolved here."""
        self.pose = pose
        self.encoder_steps = encoder
        self.tick = tick
        if on_path_count >= 0:
            self.metrics.counted(tick, on_path_count)
        else:  # a crowd: resolve_collisions' own (KD-tree) path
            pose[:, :2] = resolve_collisions(
                pose[:, :2], self.config.body.body_radius_m, self.arena, iterations=_COLLISION_ITERATIONS
            )
            area = kernels.sensor_areas(pose, GROUND_SENSOR_OFFSETS_M[1, 0], self._discs)
            self.metrics.update(tick, area, on_path & self.alive)

    def kill(self, index: int) -> None:
        """The robot's agent is gone: it stands still from now on."""
        self.alive[index] = False

    def revive(self, index: int) -> None:
        self.alive[index] = True
