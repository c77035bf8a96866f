"""The laser world: N unicycle robots with lasers and a radio on a segment map (seeds 002 and 003).

Seeds: ``/work/shared/seeds/002_fe2ac635ba0eab3e.txt`` (MR-SSGA: eq. 3-4, table 2, §6 fig. 8) and
``/work/shared/seeds/003_5278cbbbf8cc61de.txt`` (CFS-GA: §IV-B, table I, §V figs. 1-4).

One pure model serves the in-process runner (``deploy/lab/laser/runner.py``) and, unchanged, a
world-server: it never touches a transport, a clock or global random state.

Per step ``k`` (lockstep):

1. :meth:`LaserWorld.observe` gives every robot its :class:`~swarmloc.agents.laser.localizer.LaserObservation`
   at the current true poses: the odometry of the last move (the *commanded* increments, eq. 3
   of 002: the true robot moved by noisy ones), its laser scan (eq. 4 of 002 + Gaussian noise,
   :func:`~swarmloc.world.laser.laser.scan`), the teammates it sees (noisy distance, bearing and
   relative heading of robots within the relative-sensor range and in line of sight: 002 §3.2,
   table 2 "V"; 003 §IV-B, table I "Q_rd", "Q_ro"), and the radio messages teammates sent at
   ``k-1`` that the radio medium delivered.
2. The robots' localizers answer with an outgoing payload each (bytes or None).
3. :meth:`LaserWorld.step` hands those payloads to the radio (delivered at ``k+1`` to robots
   within ``radio.range_m`` of the sender and in line of sight, each copy lost with probability
   ``radio.loss_probability``: 003 §IV-B "both in their range of communication (c_r) and in line
   of sight"), moves every robot by the driver's command with :func:`unicycle_step` (true motion
   noisy, table 2 of 002 "sigma_s", table I of 003 "Q_m"), applies scheduled kidnaps, and
   computes the observation of step ``k+1``.

The radio message a robot receives at ``k`` was built from its sender's state at ``k-1``, while
its sighting of that sender is measured at ``k`` (one step of motion apart); localizers that
combine the two (CFS-GA's virtual population, 003 §IV-B) live with that lag, as a real robot does.

**Driver.** The papers drive robots along paths (002 fig. 8; 003 figs. 1-2: start S, kidnap point
K, restart R, goal G) or between random start and goal points (003 §V, robustness). The driver
plans on ground truth: a shortest path on an 8-connected grid of cells at least
``driver.clearance_m`` from every wall (Dijkstra, ``scipy.sparse.csgraph``), followed by pure
pursuit (heading-proportional turn rate, speed reduced by the cosine of the heading error). In
``"waypoints"`` mode each robot visits its scenario waypoints in order and stops at the last; in
``"random_goals"`` mode it drives to random reachable free cells, one after another. A move that
would bring a robot within ``driver.robot_radius_m`` of a wall (or through one, or out of the
map's bounds) is cancelled (the robot bumps and only turns) and the driver replans; so robots
always stay in free space. Robots do not collide with each other. A robot the driver holds still
does not move at all (no motion noise while standing).

**Kidnapping** (003 §V, fig. 1): :meth:`LaserWorld.kidnap` moves a robot's true pose without
telling it (its odometry of that step is unchanged); scheduled kidnaps (:class:`Kidnap`) are
applied by :meth:`LaserWorld.step`. A kidnap may send the robot on from a later waypoint
(``resume_waypoint``); until the kidnap happens the robot then waits at the waypoint before it.

**Randomness.** The world's generator is split (``Generator.spawn``) into four independent
streams, drawn in a fixed order: motion (one :func:`unicycle_step` draw per step), sensing (one
:func:`scan` and one :func:`relative_observation` draw per observation), radio (one uniform per
candidate delivery, candidates sorted by (sender, receiver)) and driver (random starts, goals and
kidnap poses). So the same seed gives the same trajectories whatever the robots send: a
collaborative and an autonomous run of one seed see the same paths and sensor noise.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass, field

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components, dijkstra
from scipy.spatial import cKDTree

from swarmloc.agents.laser.localizer import (
    MAX_RADIO_PAYLOAD_BYTES,
    LaserObservation,
    LocalizerSetup,
    RadioMessage,
    Sighting,
)
from swarmloc.config import did_you_mean
from swarmloc.world.laser.laser import (
    LaserParams,
    MotionNoise,
    RelativeNoise,
    relative_observation,
    scan,
    unicycle_step,
    visible_pairs,
    wrap_angle,
)
from swarmloc.world.laser.maps import MAPS, SegmentMap, distance_to_walls, line_of_sight

#: Stream id of the world's generator (``[seed, stream]``); agents use stream 1 with their id.
WORLD_STREAM = 0
#: At most this many robots in one laser world.
MAX_ROBOTS = 4096
DRIVER_MODES = ("waypoints", "random_goals")


def _finite(value, name: str, *, positive: bool = False, nonneg: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise TypeError(f"{name}: expected a number, got {value!r}")
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name}: must be finite, got {value!r}")
    if positive and not number > 0.0:
        raise ValueError(f"{name}: must be > 0, got {value!r}")
    if nonneg and number < 0.0:
        raise ValueError(f"{name}: must be >= 0, got {value!r}")
    return number


def _integer(value, name: str, lo: int, hi: int | None = None) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name}: expected an integer, got {value!r}")
    if value < lo or (hi is not None and value > hi):
        bound = f"in {lo}..{hi}" if hi is not None else f">= {lo}"
        raise ValueError(f"{name}: must be {bound}, got {value}")
    return int(value)


def _point(value, name: str, size: int) -> tuple[float, ...]:
    if not isinstance(value, (list, tuple, np.ndarray)) or len(value) != size:
        raise ValueError(f"{name}: expected {size} numbers, got {value!r}")
    return tuple(_finite(v, f"{name}[{i}]") for i, v in enumerate(value))


# --------------------------------------------------------------------------------------------
# Configuration
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True)
class RadioConfig:
    """The robots' radio: a broadcast reaches teammates within ``range_m`` (and, when
    ``line_of_sight``, with no wall in between), each copy lost with ``loss_probability``.
    Default: 4 m, table I of 003 (c_r)."""

    range_m: float = 4.0
    loss_probability: float = 0.0
    line_of_sight: bool = True

    def __post_init__(self) -> None:
        _finite(self.range_m, "range_m", positive=True)
        p = _finite(self.loss_probability, "loss_probability")
        if not 0.0 <= p <= 1.0:
            raise ValueError(f"loss_probability: must be in [0, 1], got {self.loss_probability}")
        if not isinstance(self.line_of_sight, bool):
            raise TypeError(f"line_of_sight: expected true or false, got {self.line_of_sight!r}")


@dataclass(frozen=True)
class DriverConfig:
    """How the world drives the robots (see the module docstring)."""

    mode: str = "random_goals"
    #: Cruise speed and the largest commanded turn rate.
    speed_mps: float = 0.2
    max_turn_rate_rad_s: float = 1.0
    #: Turn rate per radian of heading error (pure pursuit).
    heading_gain_per_s: float = 2.0
    #: Pure-pursuit look-ahead distance along the planned path.
    lookahead_m: float = 0.5
    #: A waypoint or goal counts as reached within this distance.
    goal_tolerance_m: float = 0.2
    #: Planned paths keep at least this far from walls; waypoints must too.
    clearance_m: float = 0.35
    #: Cell size of the planning grid (must be below ``clearance_m``).
    grid_cell_m: float = 0.1
    #: A move that would end closer than this to a wall is cancelled.
    robot_radius_m: float = 0.15

    def __post_init__(self) -> None:
        if self.mode not in DRIVER_MODES:
            hint = did_you_mean(str(self.mode), DRIVER_MODES, 0.6)
            raise ValueError(f"mode: unknown driver mode {self.mode!r}{hint} "
                             f"(known: {', '.join(DRIVER_MODES)})")
        _finite(self.speed_mps, "speed_mps", positive=True)
        _finite(self.max_turn_rate_rad_s, "max_turn_rate_rad_s", positive=True)
        _finite(self.heading_gain_per_s, "heading_gain_per_s", positive=True)
        _finite(self.lookahead_m, "lookahead_m", positive=True)
        _finite(self.goal_tolerance_m, "goal_tolerance_m", positive=True)
        _finite(self.clearance_m, "clearance_m", positive=True)
        _finite(self.grid_cell_m, "grid_cell_m", positive=True)
        _finite(self.robot_radius_m, "robot_radius_m", positive=True)
        if not self.grid_cell_m < self.clearance_m:
            raise ValueError(f"grid_cell_m: must be below clearance_m ({self.clearance_m}), "
                             f"got {self.grid_cell_m}")
        if not self.robot_radius_m < self.clearance_m:
            raise ValueError(f"robot_radius_m: must be below clearance_m ({self.clearance_m}), "
                             f"got {self.robot_radius_m}")


@dataclass(frozen=True)
class RobotPath:
    """One robot's start pose ``(x_m, y_m, theta_rad)`` (None: a random free pose) and, in
    ``"waypoints"`` mode, the points ``(x_m, y_m)`` it visits in order."""

    start: tuple[float, float, float] | None = None
    waypoints: tuple[tuple[float, float], ...] = ()

    def __post_init__(self) -> None:
        if self.start is not None:
            object.__setattr__(self, "start", _point(self.start, "start", 3))
        if not isinstance(self.waypoints, (list, tuple)):
            raise TypeError(f"waypoints: expected a list of [x, y], got {self.waypoints!r}")
        object.__setattr__(self, "waypoints", tuple(
            _point(w, f"waypoints[{i}]", 2) for i, w in enumerate(self.waypoints)))


@dataclass(frozen=True)
class Kidnap:
    """At step ``step`` robot ``robot`` is found at ``pose`` (None: a random free pose) without
    being told. With ``resume_waypoint`` i it then drives on from its waypoint i, and waits at
    waypoint i-1 if it gets there before the kidnap."""

    robot: int = 0
    step: int = 1
    pose: tuple[float, float, float] | None = None
    resume_waypoint: int | None = None

    def __post_init__(self) -> None:
        _integer(self.robot, "robot", 0)
        _integer(self.step, "step", 1)
        if self.pose is not None:
            object.__setattr__(self, "pose", _point(self.pose, "pose", 3))
        if self.resume_waypoint is not None:
            _integer(self.resume_waypoint, "resume_waypoint", 1)


@dataclass(frozen=True)
class LaserWorldConfig:
    """Everything the laser world needs for one run. Defaults: table I of 003 (18 beams of
    8 m, laser noise 0.1 m, odometry noise [0.05 m/s, 0.1 rad/s], relative noise 0.2 m / 0.1 rad
    within 4 m, radio range c_r = 4 m). ``paths``: one per robot, or none (random starts; only
    in ``"random_goals"`` mode)."""

    map: str = "office"
    robots: int = 1
    steps: int = 400
    dt_s: float = 0.5
    seed: int = 1
    laser: LaserParams = field(default_factory=LaserParams.cfs_ga)
    motion: MotionNoise = field(default_factory=MotionNoise.cfs_ga)
    relative: RelativeNoise = field(default_factory=RelativeNoise.cfs_ga)
    radio: RadioConfig = field(default_factory=RadioConfig)
    driver: DriverConfig = field(default_factory=DriverConfig)
    paths: tuple[RobotPath, ...] = ()
    kidnaps: tuple[Kidnap, ...] = ()

    def __post_init__(self) -> None:
        if not isinstance(self.map, str) or self.map not in MAPS.names():
            hint = did_you_mean(str(self.map), MAPS.names(), 0.6)
            raise ValueError(f"map: unknown map {self.map!r}{hint} (known: {', '.join(MAPS.names())})")
        _integer(self.robots, "robots", 1, MAX_ROBOTS)
        _integer(self.steps, "steps", 1)
        _finite(self.dt_s, "dt_s", positive=True)
        _integer(self.seed, "seed", 0, 2**63 - 1)
        for name, kind in (("laser", LaserParams), ("motion", MotionNoise),
                           ("relative", RelativeNoise), ("radio", RadioConfig),
                           ("driver", DriverConfig)):
            if not isinstance(getattr(self, name), kind):
                raise TypeError(f"{name}: expected a {kind.__name__}, got {getattr(self, name)!r}")
        object.__setattr__(self, "paths", tuple(self.paths))
        object.__setattr__(self, "kidnaps", tuple(self.kidnaps))
        world_map = self.segment_map()
        self._check_paths(world_map)
        self._check_kidnaps(world_map)

    def segment_map(self) -> SegmentMap:
        return MAPS.build(self.map)

    def _check_free(self, world_map: SegmentMap, xy, where: str, margin_m: float) -> None:
        x_min, y_min, x_max, y_max = world_map.bounds_m
        x, y = xy[0], xy[1]
        if not (x_min + margin_m <= x <= x_max - margin_m and y_min + margin_m <= y <= y_max - margin_m):
            raise ValueError(f"{where}: ({x}, {y}) is not inside map {self.map!r} "
                             f"bounds {world_map.bounds_m} with {margin_m} m to spare")
        gap = float(distance_to_walls(world_map, np.array([[x, y]]))[0])
        if gap < margin_m:
            raise ValueError(f"{where}: ({x}, {y}) is {gap:.3f} m from a wall of map {self.map!r}; "
                             f"it must be at least {margin_m} m (driver clearance) away")
        drv = self.driver
        if not shared_planner(self.map, drv.grid_cell_m, drv.clearance_m).reachable((x, y)):
            raise ValueError(f"{where}: ({x}, {y}) is enclosed (not reachable from the main free "
                             f"space of map {self.map!r})")

    def _check_paths(self, world_map: SegmentMap) -> None:
        if self.paths and len(self.paths) != self.robots:
            raise ValueError(f"paths: give one path per robot ({self.robots}), got {len(self.paths)}")
        if self.driver.mode == "waypoints" and not self.paths:
            raise ValueError("paths: driver mode 'waypoints' needs one path per robot")
        clearance = self.driver.clearance_m
        for r, path in enumerate(self.paths):
            if not isinstance(path, RobotPath):
                raise TypeError(f"paths[{r}]: expected a RobotPath, got {path!r}")
            if path.start is not None:
                self._check_free(world_map, path.start, f"paths[{r}].start", clearance)
            if self.driver.mode == "waypoints" and not path.waypoints:
                raise ValueError(f"paths[{r}].waypoints: driver mode 'waypoints' needs at least one")
            for i, w in enumerate(path.waypoints):
                self._check_free(world_map, w, f"paths[{r}].waypoints[{i}]", clearance)

    def _check_kidnaps(self, world_map: SegmentMap) -> None:
        seen = set()
        for i, k in enumerate(self.kidnaps):
            where = f"kidnaps[{i}]"
            if not isinstance(k, Kidnap):
                raise TypeError(f"{where}: expected a Kidnap, got {k!r}")
            if k.robot >= self.robots:
                raise ValueError(f"{where}.robot: must be < robots ({self.robots}), got {k.robot}")
            if k.step >= self.steps:
                raise ValueError(f"{where}.step: must be < steps ({self.steps}), got {k.step}")
            if (k.robot, k.step) in seen:
                raise ValueError(f"{where}: robot {k.robot} is kidnapped twice at step {k.step}")
            seen.add((k.robot, k.step))
            if k.pose is not None:
                self._check_free(world_map, k.pose, f"{where}.pose", self.driver.clearance_m)
            if k.resume_waypoint is not None:
                n_way = len(self.paths[k.robot].waypoints) if self.paths else 0
                if self.driver.mode != "waypoints" or k.resume_waypoint >= n_way:
                    raise ValueError(f"{where}.resume_waypoint: robot {k.robot} has no waypoint "
                                     f"{k.resume_waypoint} (it has {n_way}, mode "
                                     f"{self.driver.mode!r})")


# --------------------------------------------------------------------------------------------
# Path planning on ground truth
# --------------------------------------------------------------------------------------------


class GridPlanner:
    """Shortest paths between free cells of a grid over the map (cells at least
    ``clearance_m`` from every wall and from the bounds), 8-connected. A step's cost is its
    length times ``1 + WALL_PENALTY * max(0, 1 - d / WALL_PENALTY_RANGE_M)`` (``d``: the cells'
    mean distance to the nearest wall), so routes keep to the middle of doors and corridors."""

    WALL_PENALTY = 4.0
    WALL_PENALTY_RANGE_M = 1.0

    def __init__(self, world_map: SegmentMap, cell_m: float, clearance_m: float):
        x_min, y_min, x_max, y_max = world_map.bounds_m
        xs = np.arange(x_min + cell_m / 2.0, x_max, cell_m)
        ys = np.arange(y_min + cell_m / 2.0, y_max, cell_m)
        gx, gy = np.meshgrid(xs, ys, indexing="ij")
        centres = np.column_stack([gx.ravel(), gy.ravel()])
        inside = ((centres[:, 0] >= x_min + clearance_m) & (centres[:, 0] <= x_max - clearance_m)
                  & (centres[:, 1] >= y_min + clearance_m) & (centres[:, 1] <= y_max - clearance_m))
        gap = np.zeros(centres.shape[0])
        gap[inside] = distance_to_walls(world_map, centres[inside])
        free = inside & (gap >= clearance_m)
        penalty = self.WALL_PENALTY * np.clip(1.0 - gap / self.WALL_PENALTY_RANGE_M, 0.0, None)
        if not free.any():
            raise ValueError(f"clearance_m {clearance_m} leaves no free cell in map {world_map.name!r}")
        shape = gx.shape
        index = -np.ones(shape, dtype=np.int64)
        free_2d = free.reshape(shape)
        index[free_2d] = np.arange(int(free.sum()))
        cell_penalty = penalty[free]
        rows, cols, weights = [], [], []
        s0, s1 = shape
        for di, dj in ((1, 0), (0, 1), (1, 1), (1, -1)):
            # Cell (i, j) and its neighbour (i + di, j + dj), over every (i, j) where both exist.
            j0, j1 = max(0, -dj), s1 - max(0, dj)
            a = index[0 : s0 - di, j0:j1]
            b = index[di:s0, j0 + dj : j1 + dj]
            both = (a >= 0) & (b >= 0)
            rows.append(a[both])
            cols.append(b[both])
            a, b = a[both], b[both]
            weights.append(cell_m * math.hypot(di, dj)
                           * (1.0 + 0.5 * (cell_penalty[a] + cell_penalty[b])))
        r, c, w = np.concatenate(rows), np.concatenate(cols), np.concatenate(weights)
        n = int(free.sum())
        self.graph = coo_matrix((np.concatenate([w, w]), (np.concatenate([r, c]),
                                                          np.concatenate([c, r]))), shape=(n, n)).tocsr()
        self.cells_m = centres[free]
        self.cell_m = cell_m
        self._tree = cKDTree(self.cells_m)
        _, self.component = connected_components(self.graph, directed=False)
        #: The largest connected region: random starts and kidnap poses are drawn from it (a
        #: solid pillar's inside, e.g., is free space to the grid but unreachable).
        self.main_component = int(np.bincount(self.component).argmax())
        self._main_cells = np.flatnonzero(self.component == self.main_component)
        for array in (self.cells_m, self.component, self._main_cells):
            array.flags.writeable = False

    def reachable(self, xy) -> bool:
        """Whether the free cell nearest ``xy`` lies in the largest connected region."""
        return bool(self.component[self.nearest_cell(np.asarray(xy)[None, :2])[0]]
                    == self.main_component)

    def random_pose(self, rng: np.random.Generator) -> np.ndarray:
        """A random pose: a free cell of the largest region (uniform), a uniform heading."""
        xy = self.cells_m[self._main_cells[rng.integers(self._main_cells.size)]]
        return np.array([xy[0], xy[1], rng.uniform(-math.pi, math.pi)])

    def nearest_cell(self, xy: np.ndarray) -> np.ndarray:
        """Index of the free cell nearest to each point ``(K, 2)``."""
        return self._tree.query(np.atleast_2d(xy))[1]

    def plan(self, start_xy, goal_xy) -> np.ndarray | None:
        """Points ``(M, 2)`` from the cell nearest ``start_xy`` to ``goal_xy`` (the goal itself
        last), or None when the goal's cell is not reachable."""
        start, goal = self.nearest_cell(np.array([start_xy, goal_xy]))
        if self.component[start] != self.component[goal]:
            return None
        _, predecessors = dijkstra(self.graph, indices=int(start), return_predecessors=True)
        cells = [int(goal)]
        while cells[-1] != start:
            cells.append(int(predecessors[cells[-1]]))
        points = self.cells_m[cells[::-1]]
        return np.vstack([points, np.asarray(goal_xy, dtype=np.float64)[None, :2]])

    def random_goal(self, from_xy, rng: np.random.Generator) -> np.ndarray:
        """A random free cell reachable from ``from_xy`` (uniform over those cells)."""
        start = int(self.nearest_cell(np.asarray(from_xy)[None, :2])[0])
        reachable = np.flatnonzero(self.component == self.component[start])
        return self.cells_m[reachable[rng.integers(reachable.size)]].copy()


@functools.lru_cache(maxsize=8)
def shared_planner(map_name: str, cell_m: float, clearance_m: float) -> GridPlanner:
    """The planner of a built-in map, built once per process (it is never mutated)."""
    return GridPlanner(MAPS.build(map_name), cell_m, clearance_m)


# --------------------------------------------------------------------------------------------
# The world
# --------------------------------------------------------------------------------------------


class LaserWorld:
    """N laser robots on a segment map: true poses, driver, sensors, radio, kidnapping.

    ``observe()`` returns the current step's observations (the same objects until the next
    ``step``); ``step(outgoing)`` sends, moves and senses. ``true_poses`` is ground truth, never
    given to the robots.
    """

    def __init__(self, config: LaserWorldConfig, rng: np.random.Generator | None = None):
        if not isinstance(config, LaserWorldConfig):
            raise TypeError(f"config: expected a LaserWorldConfig, got {type(config).__name__}")
        self.config = config
        rng = rng if rng is not None else np.random.default_rng([config.seed, WORLD_STREAM])
        self._motion_rng, self._sense_rng, self._radio_rng, self._driver_rng = rng.spawn(4)
        self.map = config.segment_map()
        drv = config.driver
        self.planner = shared_planner(config.map, drv.grid_cell_m, drv.clearance_m)
        n = config.robots
        self.step_index = 0
        self._pose = self._initial_poses()
        # Driver state: a planned route per robot (padded), progress along it, what to do next.
        self._route = np.zeros((n, 1, 2))
        self._route_len = np.ones(n, dtype=np.int64)
        self._progress = np.zeros(n, dtype=np.int64)
        self._moving = np.zeros(n, dtype=bool)
        self._next_waypoint = np.zeros(n, dtype=np.int64)
        self._hold_before = np.full(n, np.iinfo(np.int64).max)
        self._pending = sorted(config.kidnaps, key=lambda k: (k.step, k.robot))
        for k in self._pending:
            if k.resume_waypoint is not None:
                self._hold_before[k.robot] = min(self._hold_before[k.robot], k.resume_waypoint)
        self.bumps = np.zeros(n, dtype=np.int64)
        self._wall_gap = distance_to_walls(self.map, self._pose)
        for r in range(n):
            self._next_route(r)
        self._inbox: list[list[RadioMessage]] = [[] for _ in range(n)]
        self._odometry = (np.zeros(n), np.zeros(n))
        self._observations = self._sense()

    # -- public surface ---------------------------------------------------------------------

    @property
    def n_robots(self) -> int:
        return self.config.robots

    @property
    def done(self) -> bool:
        return self.step_index >= self.config.steps

    @property
    def true_poses(self) -> np.ndarray:
        """Ground-truth poses ``(N, 3)`` (a copy)."""
        return self._pose.copy()

    def localizer_setup(self, robot_id: int, cooperative: bool = True,
                        extra: dict | None = None) -> LocalizerSetup:
        """What robot ``robot_id``'s localizer is built from (the world's sensor parameters)."""
        _integer(robot_id, "robot_id", 0, self.n_robots - 1)
        # The one derivation an agent process uses too, so both build the same localizer.
        return LocalizerSetup.from_world_config(self.config, robot_id, cooperative, extra)

    def observe(self) -> list[LaserObservation]:
        """Every robot's observation at the current step (robot id = list index)."""
        return list(self._observations)

    def step(self, outgoing: list[bytes | None]) -> None:
        """Send ``outgoing[r]`` (robot r's broadcast, or None), move every robot one step, apply
        the kidnaps scheduled for the new step, and sense."""
        if self.done:
            raise RuntimeError(f"the run is over ({self.config.steps} steps)")
        payloads = self._check_outgoing(outgoing)
        self._inbox = self._radio(payloads)
        self._move()
        self.step_index += 1
        while self._pending and self._pending[0].step == self.step_index:
            k = self._pending.pop(0)
            self._kidnap(k.robot, k.pose, k.resume_waypoint)
        self._observations = self._sense()

    def kidnap(self, robot: int, pose=None) -> None:
        """Move robot ``robot`` to ``pose`` ``(x_m, y_m, theta_rad)`` (None: a random free pose)
        without telling it; its current observation is sensed again at the new pose (odometry
        and received messages unchanged)."""
        _integer(robot, "robot", 0, self.n_robots - 1)
        if pose is not None:
            pose = _point(pose, "pose", 3)
            self.config._check_free(self.map, pose, "pose", self.config.driver.robot_radius_m)
        self._kidnap(int(robot), pose, None)
        self._observations = self._sense()

    # -- sensing ----------------------------------------------------------------------------

    def _sense(self) -> list[LaserObservation]:
        cfg = self.config
        poses = self._pose
        ranges = scan(self.map, poses, cfg.laser, self._sense_rng)
        ranges.flags.writeable = False  # shared by the observations: nobody edits a reading
        pairs = visible_pairs(self.map, poses, cfg.relative.range_m)
        seen: list[list[Sighting]] = [[] for _ in range(self.n_robots)]
        if pairs.shape[0]:
            rel = relative_observation(poses, pairs[:, 0], pairs[:, 1], self.map,
                                       cfg.relative.range_m, cfg.relative, self._sense_rng)
            for k in np.flatnonzero(rel.visible):
                i, j = int(pairs[k, 0]), int(pairs[k, 1])
                seen[i].append(Sighting(j, float(rel.distance_m[k]), float(rel.bearing_rad[k]),
                                        float(rel.relative_heading_rad[k])))
        delta_s, delta_phi = self._odometry
        return [
            LaserObservation(
                step=self.step_index,
                odometry_delta_s_m=float(delta_s[r]),
                odometry_delta_phi_rad=float(delta_phi[r]),
                ranges_m=ranges[r],
                sightings=tuple(seen[r]),
                received=tuple(self._inbox[r]),
            )
            for r in range(self.n_robots)
        ]

    # -- radio ------------------------------------------------------------------------------

    def _check_outgoing(self, outgoing) -> list[bytes | None]:
        if not isinstance(outgoing, (list, tuple)) or len(outgoing) != self.n_robots:
            raise ValueError(f"outgoing: expected a list of {self.n_robots} payloads (bytes or None), "
                             f"got {type(outgoing).__name__} of length "
                             f"{len(outgoing) if hasattr(outgoing, '__len__') else '?'}")
        payloads: list[bytes | None] = []
        for r, payload in enumerate(outgoing):
            if payload is None:
                payloads.append(None)
                continue
            if not isinstance(payload, (bytes, bytearray)):
                raise TypeError(f"outgoing[{r}]: expected bytes or None, got {type(payload).__name__}")
            if len(payload) > MAX_RADIO_PAYLOAD_BYTES:
                raise ValueError(f"outgoing[{r}]: payload of {len(payload)} bytes exceeds "
                                 f"{MAX_RADIO_PAYLOAD_BYTES}")
            payloads.append(bytes(payload))
        return payloads

    def _radio(self, payloads: list[bytes | None]) -> list[list[RadioMessage]]:
        """Deliveries of this step's broadcasts, at the senders' and receivers' current poses."""
        inbox: list[list[RadioMessage]] = [[] for _ in range(self.n_robots)]
        senders = np.array([p is not None for p in payloads])
        if not senders.any() or self.n_robots < 2:
            return inbox
        radio = self.config.radio
        if radio.line_of_sight:
            pairs = visible_pairs(self.map, self._pose, radio.range_m)
        else:
            half = cKDTree(self._pose[:, :2]).query_pairs(radio.range_m, output_type="ndarray")
            both = np.concatenate([half, half[:, ::-1]]).astype(np.int64).reshape(-1, 2)
            pairs = both[np.lexsort((both[:, 1], both[:, 0]))]
        pairs = pairs[senders[pairs[:, 0]]]  # (sender, receiver), sorted
        if pairs.shape[0] == 0:
            return inbox
        kept = self._radio_rng.random(pairs.shape[0]) >= radio.loss_probability
        for sender, receiver in pairs[kept]:
            inbox[int(receiver)].append(RadioMessage(int(sender), payloads[int(sender)]))
        return inbox

    # -- driver and motion ------------------------------------------------------------------

    def _initial_poses(self) -> np.ndarray:
        cfg = self.config
        poses = np.zeros((cfg.robots, 3))
        for r in range(cfg.robots):
            start = cfg.paths[r].start if cfg.paths else None
            if start is None:
                poses[r] = self.planner.random_pose(self._driver_rng)
            else:
                poses[r] = start
        poses[:, 2] = wrap_angle(poses[:, 2])
        return poses

    def _set_route(self, r: int, points: np.ndarray | None) -> None:
        if points is None:
            self._moving[r] = False
            return
        length = points.shape[0]
        if length > self._route.shape[1]:
            grown = np.zeros((self.n_robots, length, 2))
            grown[:, : self._route.shape[1]] = self._route
            self._route = grown
        self._route[r, :length] = points
        self._route_len[r] = length
        self._progress[r] = 0
        self._moving[r] = True

    def _next_route(self, r: int) -> None:
        """Plan robot ``r``'s route to its next goal (or stop it)."""
        xy = self._pose[r, :2]
        if self.config.driver.mode == "random_goals":
            goal = self.planner.random_goal(xy, self._driver_rng)
            self._set_route(r, self.planner.plan(xy, goal))
            return
        waypoints = self.config.paths[r].waypoints
        i = int(self._next_waypoint[r])
        if i >= len(waypoints) or i >= self._hold_before[r]:
            self._set_route(r, None)  # done, or waiting for a kidnap
            return
        self._set_route(r, self.planner.plan(xy, np.array(waypoints[i])))

    def _replan(self, r: int) -> None:
        """Plan again to the current goal (after a bump or a kidnap)."""
        if not self._moving[r]:
            return
        goal = self._route[r, self._route_len[r] - 1].copy()
        self._set_route(r, self.planner.plan(self._pose[r, :2], goal))

    def _kidnap(self, r: int, pose, resume_waypoint: int | None) -> None:
        if pose is None:
            pose = self.planner.random_pose(self._driver_rng)
        self._pose[r] = (pose[0], pose[1], float(wrap_angle(pose[2])))
        self._wall_gap[r] = distance_to_walls(self.map, self._pose[r : r + 1])[0]
        if resume_waypoint is not None:
            self._next_waypoint[r] = resume_waypoint
            later = [k.resume_waypoint for k in self._pending
                     if k.robot == r and k.resume_waypoint is not None]
            self._hold_before[r] = min(later) if later else np.iinfo(np.int64).max
            self._next_route(r)
        else:
            self._replan(r)

    def _command(self) -> tuple[np.ndarray, np.ndarray]:
        """Pure pursuit along every robot's route: ``(v_mps, omega_rad_s)``, each ``(N,)``."""
        drv, dt = self.config.driver, self.config.dt_s
        n = self.n_robots
        rows = np.arange(n)
        pos, heading = self._pose[:, :2], self._pose[:, 2]
        window = math.ceil(2.0 * drv.lookahead_m / drv.grid_cell_m) + 2
        last = self._route_len - 1
        idx = np.minimum(self._progress[:, None] + np.arange(window), last[:, None])
        points = self._route[rows[:, None], idx]
        dist = np.hypot(points[..., 0] - pos[:, None, 0], points[..., 1] - pos[:, None, 1])
        self._progress = idx[rows, np.argmin(dist, axis=1)]
        # Close to a wall (a corner cut short), look just one cell ahead: follow the route itself.
        lookahead = np.where(self._wall_gap < drv.clearance_m, 1.5 * drv.grid_cell_m,
                             drv.lookahead_m)
        ahead = (idx >= self._progress[:, None]) & (dist >= lookahead[:, None])
        target_idx = np.where(ahead.any(axis=1), idx[rows, np.argmax(ahead, axis=1)], idx[:, -1])
        target = self._route[rows, target_idx]
        goal = self._route[rows, last]
        to_goal = np.hypot(goal[:, 0] - pos[:, 0], goal[:, 1] - pos[:, 1])
        error = wrap_angle(np.arctan2(target[:, 1] - pos[:, 1], target[:, 0] - pos[:, 0]) - heading)
        omega = np.clip(drv.heading_gain_per_s * error, -drv.max_turn_rate_rad_s,
                        drv.max_turn_rate_rad_s)
        v = drv.speed_mps * np.clip(np.cos(error), 0.0, 1.0)
        v = np.minimum(v, to_goal / dt)
        return np.where(self._moving, v, 0.0), np.where(self._moving, omega, 0.0)

    def _arrivals(self) -> None:
        """Robots within the goal tolerance of their route's end go on to their next goal (a few
        rounds, in case a new goal is already reached)."""
        drv = self.config.driver
        rows = np.arange(self.n_robots)
        for _ in range(4):
            goal = self._route[rows, self._route_len - 1]
            to_goal = np.hypot(goal[:, 0] - self._pose[:, 0], goal[:, 1] - self._pose[:, 1])
            arrived = np.flatnonzero(self._moving & (to_goal < drv.goal_tolerance_m))
            if arrived.size == 0:
                return
            for r in arrived:
                if drv.mode == "waypoints":
                    self._next_waypoint[r] += 1
                self._next_route(int(r))

    def _move(self) -> None:
        cfg, drv = self.config, self.config.driver
        self._arrivals()
        v, omega = self._command()
        motion = unicycle_step(self._pose, v, omega, cfg.dt_s, cfg.motion, self._motion_rng)
        new = motion.poses_m
        standing = (v == 0.0) & (omega == 0.0)
        new[standing] = self._pose[standing]
        x_min, y_min, x_max, y_max = self.map.bounds_m
        rad = drv.robot_radius_m
        inside = ((new[:, 0] >= x_min + rad) & (new[:, 0] <= x_max - rad)
                  & (new[:, 1] >= y_min + rad) & (new[:, 1] <= y_max - rad))
        ok = inside.copy()
        ok[inside] = distance_to_walls(self.map, new[inside]) >= rad
        ok &= line_of_sight(self.map, self._pose[:, :2], new[:, :2]) | standing
        blocked = ~ok
        new[blocked, :2] = self._pose[blocked, :2]
        self._pose = new
        self._wall_gap = distance_to_walls(self.map, new)
        self.bumps += blocked
        self._odometry = (motion.odometry_delta_s_m, motion.odometry_delta_phi_rad)
        for r in np.flatnonzero(blocked):
            self._replan(int(r))


__all__ = [
    "DRIVER_MODES",
    "WORLD_STREAM",
    "DriverConfig",
    "GridPlanner",
    "Kidnap",
    "LaserWorld",
    "LaserWorldConfig",
    "RadioConfig",
    "RobotPath",
    "shared_planner",
]
