"""The vision family's scenario (seed 004 §IV): the setup its layouts are drawn from
(:class:`SetupConfig`), the scenario (:class:`VisionScenario`: setup, world, agents), the layout of
one seeded run (:func:`layout`) and the world a world-server serves for it (:func:`world_config`).
Beside the world model, below the shells: the in-process runner (``deploy/lab/vision/runner.py``,
whose docstring describes the experiments), the world-server and the agent processes build from
it alike.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import numpy as np

from swarmloc.agents.vision.brain import VisionAgentConfig, detections_from_blobs
from swarmloc.agents.vision.detection import detect_blobs
from swarmloc.config import from_dict, to_dict
from swarmloc.world.vision.camera import OBJECT_KINDS, CameraParams, make_object, render
from swarmloc.world.vision.world import (
    FieldObject,
    RobotStart,
    VisionWorldConfig,
)

EXPERIMENTS = ("vision-exp1", "vision-exp2", "vision-exp3")
#: Generator streams ``[seed, stream, ...]``: world 0 (``world/vision/world.py``), agents 1, layout 2,
#: fault injection 3.
AGENT_STREAM, LAYOUT_STREAM, FAULT_STREAM = 1, 2, 3
TEAM = "A"


# -- scenarios ----------------------------------------------------------------------------------


def _range(name: str, value: tuple[float, float], lo: float | None = None) -> None:
    a, b = value
    if not (math.isfinite(a) and math.isfinite(b) and a <= b):
        raise ValueError(f"{name}: expected [low, high] with low <= high, got {list(value)}")
    if lo is not None and a < lo:
        raise ValueError(f"{name}: values must be >= {lo}, got {list(value)}")


@dataclass(frozen=True)
class SetupConfig:
    """Which experiment of seed 004 §IV, and the ranges its layouts are drawn from.

    Robots start side by side, facing +x, ``spacing_m`` apart (plus ``position_jitter_m`` and
    ``heading_jitter_rad``, uniform). Experiment 1: the ball ``ball_distance_m`` ahead of their
    midpoint, ``ball_lateral_m`` to the side. Experiment 2: the obstacle ``obstacle_distance_m``
    ahead, ``obstacle_lateral_m`` to one side (drawn), the ball ``ball_distance_m`` ahead and
    ``ball_lateral_m`` to the other side. Experiment 3: the obstacle ``obstacle_distance_m`` ahead
    at a fraction ``obstacle_between`` of the way from the white robot to the black one; the
    ball ``ball_behind_m`` farther on the white robot's line of sight through the obstacle,
    within ``hidden_angle_rad`` of it. Layouts where the two robots' distances to the obstacle
    differ by less than ``min_assignment_gap_m`` are redrawn (the right goal would be a toss-up).
    """

    experiment: int = 1
    duration_s: float = 40.0
    reach_margin_m: float = 0.10
    spacing_m: tuple[float, float] = (0.5, 0.7)
    position_jitter_m: float = 0.03
    heading_jitter_rad: float = 0.03
    ball_distance_m: tuple[float, float] = (1.4, 2.0)
    ball_lateral_m: tuple[float, float] = (-0.1, 0.1)
    obstacle_distance_m: tuple[float, float] = (0.9, 1.2)
    obstacle_lateral_m: tuple[float, float] = (0.1, 0.35)
    obstacle_between: tuple[float, float] = (0.15, 0.85)
    ball_behind_m: tuple[float, float] = (0.6, 0.9)
    hidden_angle_rad: float = 0.03
    min_assignment_gap_m: float = 0.08
    #: Robots in the row (experiments 1 and 2; experiment 3 has two, as in §IV-C).
    robots: int = 2
    #: Robot 1's true start heading is turned by this much: the error of the parallel-start
    #: prior (``agent.initial_relative_heading_rad = 0``), an addition beyond the paper.
    start_heading_error_rad: float = 0.0

    def __post_init__(self) -> None:
        if self.experiment not in (1, 2, 3):
            raise ValueError(
                f"experiment: must be 1, 2 or 3 (seed 004 §IV), got {self.experiment!r}"
            )
        if not self.duration_s > 0:
            raise ValueError(f"duration_s: must be > 0, got {self.duration_s}")
        for name in (
            "reach_margin_m",
            "position_jitter_m",
            "heading_jitter_rad",
            "hidden_angle_rad",
            "min_assignment_gap_m",
        ):
            if not getattr(self, name) >= 0:
                raise ValueError(f"{name}: must be >= 0, got {getattr(self, name)}")
        for name in ("spacing_m", "ball_distance_m", "obstacle_distance_m", "ball_behind_m"):
            _range(name, getattr(self, name), lo=0.0)
        for name in ("ball_lateral_m", "obstacle_lateral_m"):
            _range(name, getattr(self, name))
        _range("obstacle_between", self.obstacle_between, lo=0.0)
        if self.obstacle_between[1] > 1.0:
            raise ValueError("obstacle_between: fractions must lie in [0, 1]")
        if isinstance(self.robots, bool) or not isinstance(self.robots, int) or not (
            2 <= self.robots <= 8
        ):
            raise ValueError(f"robots: an integer in 2..8, got {self.robots!r}")
        if self.robots > 2 and self.experiment == 3:
            raise ValueError("robots: experiment 3 (§IV-C) has two robots, one of them blind")
        if not (math.isfinite(self.start_heading_error_rad)
                and abs(self.start_heading_error_rad) <= 1.0):
            raise ValueError("start_heading_error_rad: must lie in [-1, 1] rad")
        if self.spacing_m[0] < 2 * OBJECT_KINDS["teammate"].radius_m + 2 * self.position_jitter_m:
            raise ValueError("spacing_m: robots could start overlapping")


@dataclass(frozen=True)
class VisionScenario:
    """A vision scenario (family ``"vision"``): the setup its layouts are drawn from, the world
    without placements, the brains' configuration. :func:`world_config` makes a run's world."""

    name: str = "custom"
    description: str = ""
    family: str = "vision"
    setup: SetupConfig = field(default_factory=SetupConfig)
    world: VisionWorldConfig = field(default_factory=VisionWorldConfig)
    agent: VisionAgentConfig = field(default_factory=VisionAgentConfig)

    @property
    def n_ticks(self) -> int:
        """Ticks of a run (``swarmloc.families.Family``'s scenario contract)."""
        return round(self.setup.duration_s / self.world.tick_s)

    @property
    def label(self) -> str:
        """What tells runs of this scenario apart: whether the robots share detections."""
        return "sharing" if self.agent.sharing else "no-sharing"

    def __post_init__(self) -> None:
        if self.family != "vision":
            raise ValueError(f"family: {self.family!r} is not a vision scenario")

    def to_dict(self) -> dict:
        return to_dict(self)

    @classmethod
    def from_dict(cls, data: dict) -> VisionScenario:
        return from_dict(cls, data)


# -- layouts ------------------------------------------------------------------------------------


@dataclass(frozen=True)
class Layout:
    """One drawn layout: the world's placements and the ground truth the metrics need.

    ``goals[i]``: robot i's correct goal by seed 004's rule on the true start positions;
    ``blind``: index of the robot that cannot see the ball at the start (experiment 3) or -1;
    ``variant``: "a" when robot 1 takes the obstacle, "b" when robot 0 does, "" in experiment 1.
    """

    robots: tuple[RobotStart, ...]
    objects: tuple[FieldObject, ...]
    goals: tuple[str, ...]
    blind: int
    variant: str


def _visible(pose, pan_rad: float, objects, camera: CameraParams) -> set[str]:
    """Colours the agent would use in a noise-free frame from ``pose`` (its own detections)."""
    clean = dataclasses.replace(camera, noise_sigma=0.0, gain_min=1.0, gain_max=1.0)
    image = render(pose, pan_rad, objects, clean, np.random.default_rng(0))
    blobs = detect_blobs(image, clean)
    return {d.colour for d in detections_from_blobs(blobs, 0, 0.0, pan_rad, clean)}


def _any_pixel(pose, pan_rad: float, objects, kind: str, camera: CameraParams) -> bool:
    """Whether any pixel of the ``kind`` object shows in a noise-free frame."""
    clean = dataclasses.replace(camera, noise_sigma=0.0, gain_min=1.0, gain_max=1.0)
    with_it = render(pose, pan_rad, objects, clean, np.random.default_rng(0))
    without = render(
        pose, pan_rad, [o for o in objects if o.kind != kind], clean, np.random.default_rng(0)
    )
    return bool(np.any(with_it != without))


def _aim(pose, points) -> float:
    """Head pan centring the bearings of ``points`` seen from ``pose``."""
    bearings = [math.atan2(py - pose[1], px - pose[0]) - pose[2] for px, py in points]
    bearings = [(b + math.pi) % (2 * math.pi) - math.pi for b in bearings]
    return 0.5 * (min(bearings) + max(bearings))


def layout(scenario: VisionScenario, seed: int, max_tries: int = 2000) -> Layout:
    """Draw the layout of run ``seed`` (module docstring); ``RuntimeError`` if none fits."""
    s = scenario.setup
    camera = scenario.world.camera
    rng = np.random.default_rng([seed, LAYOUT_STREAM])
    body_r = scenario.world.body_radius_m
    for _ in range(max_tries):
        side = rng.choice([-1.0, 1.0])  # mirror image of the layout (which robot is on the left)
        spacing = rng.uniform(*s.spacing_m)
        n = s.robots
        jitter = rng.uniform(-s.position_jitter_m, s.position_jitter_m, (n, 2))
        heading = rng.uniform(-s.heading_jitter_rad, s.heading_jitter_rad, n)
        heading[1] += s.start_heading_error_rad
        row = side * spacing * ((n - 1) / 2.0 - np.arange(n))
        starts = np.stack([np.zeros(n), row], -1) + jitter
        mid_y = float(starts[:, 1].mean())
        if s.experiment == 1:
            ball = (rng.uniform(*s.ball_distance_m), mid_y + rng.uniform(*s.ball_lateral_m))
            objects = [make_object("ball", *ball)]
            goals = ("ball",) * n
            blind, variant = -1, ""
        elif s.experiment == 2:
            obstacle_side = rng.choice([-1.0, 1.0])
            obstacle = (
                rng.uniform(*s.obstacle_distance_m),
                obstacle_side * rng.uniform(*s.obstacle_lateral_m),
            )
            ball = (
                rng.uniform(*s.ball_distance_m),
                -obstacle_side * rng.uniform(*s.ball_lateral_m),
            )
            if math.hypot(ball[0] - obstacle[0], ball[1] - obstacle[1]) < 0.4:
                continue
            objects = [make_object("ball", *ball), make_object("obstacle", *obstacle)]
            blind = -1
        else:
            white, black = starts[0], starts[1]
            frac = rng.uniform(*s.obstacle_between)
            obstacle = (
                rng.uniform(*s.obstacle_distance_m),
                white[1] + frac * (black[1] - white[1]),
            )
            ray = np.array(obstacle) - white
            ray_len = float(np.hypot(*ray))
            angle = math.atan2(ray[1], ray[0]) + rng.uniform(
                -s.hidden_angle_rad, s.hidden_angle_rad
            )
            reach = ray_len + rng.uniform(*s.ball_behind_m)
            ball = (white[0] + reach * math.cos(angle), white[1] + reach * math.sin(angle))
            objects = [make_object("ball", *ball), make_object("obstacle", *obstacle)]
            blind = 0
        if s.experiment in (2, 3):
            d = sorted((math.hypot(obstacle[0] - p[0], obstacle[1] - p[1]), i)
                       for i, p in enumerate(starts))
            if d[1][0] - d[0][0] < s.min_assignment_gap_m:
                continue
            nearest = d[0][1]
            goals = tuple("obstacle" if i == nearest else "ball" for i in range(n))
            variant = "a" if nearest == 1 else "b"
        # Start poses and head pans: each robot looks at the middle of the objects.
        robots, ok = [], True
        points = [o.centre_m for o in objects]
        for i in range(n):
            pose = (float(starts[i, 0]), float(starts[i, 1]), float(heading[i]))
            if blind == i:
                pan = _aim(pose, [o.centre_m for o in objects if o.kind == "obstacle"])
            else:
                pan = _aim(pose, points)
            if abs(pan) > camera.pan_limit_rad:
                ok = False
                break
            others = [make_object("teammate", *starts[j]) for j in range(n) if j != i]
            seen = _visible(pose, pan, objects + others, camera)
            wanted = {"pink"} | ({"orange"} if s.experiment in (2, 3) else set())
            if blind == i:
                wanted = {"orange"}
                if _any_pixel(pose, pan, objects + others, "ball", camera):
                    ok = False
                    break
            if not wanted <= seen:
                ok = False
                break
            robots.append(RobotStart(pose[0], pose[1], pose[2], TEAM, float(pan)))
        if not ok:
            continue
        solid = [(o.centre_m, o.radius_m) for o in objects if o.kind != "ball"]
        if any(
            math.hypot(c[0] - p[0], c[1] - p[1]) < r + body_r + 0.05
            for c, r in solid
            for p in starts
        ):
            continue
        field_objects = tuple(FieldObject(o.kind, *o.centre_m) for o in objects)
        return Layout(tuple(robots), field_objects, goals, blind, variant)
    raise RuntimeError(
        f"{scenario.name}: no layout satisfies the setup in {max_tries} draws "
        f"(seed {seed}); widen the [setup] ranges"
    )


def world_config(scenario: VisionScenario, seed: int) -> tuple[VisionWorldConfig, Layout]:
    """The world of run ``seed``: the scenario's world with the drawn layout and the seed (what
    a world-server shell serves; the agents need only ``scenario.agent`` and their team)."""
    lay = layout(scenario, seed)
    world = dataclasses.replace(scenario.world, robots=lay.robots, objects=lay.objects, seed=seed)
    return world, lay
