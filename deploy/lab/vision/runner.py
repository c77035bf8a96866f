"""Seed 004's experiments with the vision robots, in one process: world + one brain per robot.

Seed 004 §IV (``seeds/004_e71d8ee95e0baa56.txt``, Peula et al.) tests cooperative localization from shared colour detections with two
Aibo ERS-7 robots:

- **Experiment 1** (§IV-A): two robots side by side, "close to each other on purpose", a ball in
  front; both must catch it. Without sharing they "crash in the middle of the experiment, and
  they go on crashing till they catch the ball"; sharing the ball's position and the neck angle,
  they estimate each other's position by stereo and avoid each other.
- **Experiment 2** (§IV-B): a ball and an orange obstacle, both seen by both robots; the robot
  nearest the obstacle must catch it and the other the ball (Fig. 7a/7b: both assignments).
- **Experiment 3** (§IV-C): the obstacle hides the ball from one robot ("white"); the other
  ("black") sends it, and the goals are assigned as in experiment 2 (Fig. 8a/8b).

The scenarios are ``deploy/scenarios/vision/vision-exp{1,2,3}.toml``: a ``[setup]`` table
(:class:`SetupConfig`: the experiment and the ranges its layout is drawn from), ``[world]``
(``VisionWorldConfig`` without placements) and ``[agent]`` (``VisionAgentConfig``). Each seeded
run draws its own layout (:func:`layout`, generator ``[seed, 2]``), checked by rendering: each
robot sees what the paper says it sees at the start (a noise-free frame, the agent's own
detection). Left/right and variant a/b of the paper's figures are drawn at random.

:func:`run_vision` runs one seed: :class:`~swarmloc.world.vision.world.VisionWorld` and one
:class:`~swarmloc.agents.vision.brain.VisionBrain` per robot (generator ``[seed, 1, id]``), in
lockstep; shared detections travel as the same bytes payloads an agent process would publish on
``swarmloc/<run>/team/<team>/blobs/<id>``, through :class:`TeamChannel` (emitted at tick k,
delivered at k+1). An image or a payload that a brain rejects (``ValueError``) is counted and the
run goes on (the robot keeps its previous command for that tick). Measured per run, against the
world's ground truth: robot-robot collisions (events) and contact time, robot-obstacle
collisions, whether every robot chose the goal the rule gives on the true start positions, the
time until each robot reaches its (correct) goal (centre within ``body + goal radius +
reach_margin_m``), and the error of each robot's estimate of its teammate and of the ball.

:func:`run_experiments` repeats runs over seeds and both sharing modes in a pool of spawned
processes and writes a CSV; :func:`write_report` writes ``docs/vision/README.md`` with the
table next to the paper's claims, figures, and the detection accuracy of
:func:`detection_accuracy` (also printed by ``benchmarks/bench_vision_detection.py``).
Command line: ``swarmloc vision-experiment NAME|all --runs 30 [--no-sharing | --both]
[--report docs/vision]``.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from swarmloc.agents.vision.brain import (
    VisionAgentConfig,
    VisionBrain,
    decode_image,
    detections_from_blobs,
)
from swarmloc.agents.vision.detection import detect_blobs
from swarmloc.config import ConfigError, apply_overrides, from_dict, load_toml, to_dict
from swarmloc.protocol.keys import Keys
from swarmloc.world.vision.camera import OBJECT_KINDS, CameraParams, make_object, project, render
from swarmloc.world.vision.world import (
    STOP,
    FieldObject,
    RobotStart,
    VisionWorld,
    VisionWorldConfig,
    encode_image,
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

    def __post_init__(self) -> None:
        if self.family != "vision":
            raise ValueError(f"family: {self.family!r} is not a vision scenario")

    def to_dict(self) -> dict:
        return to_dict(self)

    @classmethod
    def from_dict(cls, data: dict) -> VisionScenario:
        return from_dict(cls, data)


def _scenario_folder() -> Path:
    return Path(str(resources.files("swarmloc.deploy") / "scenarios" / "vision"))


def scenario_names() -> list[str]:
    """The shipped vision scenarios."""
    return sorted(p.stem for p in _scenario_folder().glob("vision-*.toml"))


def load_vision_scenario(name_or_path: str, overrides: list[str] = ()) -> VisionScenario:
    """A shipped vision scenario (by name) or a TOML file, with ``section.key=value`` overrides.

    Placements come from ``[setup]``; ``world.robots``, ``world.objects`` and ``world.seed`` are
    refused (the seed is the run's).
    """
    path = Path(name_or_path)
    if path.suffix != ".toml":
        if name_or_path not in scenario_names():
            import difflib

            close = difflib.get_close_matches(name_or_path, scenario_names(), n=1, cutoff=0.4)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise ConfigError(
                f"vision scenario '{name_or_path}': not shipped{hint} "
                f"(shipped: {', '.join(scenario_names())})"
            )
        path = _scenario_folder() / f"{name_or_path}.toml"
    data = apply_overrides(load_toml(path), list(overrides))
    for key in ("robots", "objects", "seed"):
        if key in data.get("world", {}):
            raise ConfigError(
                f"world.{key}: set by the layout and the run seed, not by the scenario"
            )
    return from_dict(VisionScenario, data)


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
        jitter = rng.uniform(-s.position_jitter_m, s.position_jitter_m, (2, 2))
        heading = rng.uniform(-s.heading_jitter_rad, s.heading_jitter_rad, 2)
        starts = np.array([[0.0, side * spacing / 2], [0.0, -side * spacing / 2]]) + jitter
        mid_y = float(starts[:, 1].mean())
        if s.experiment == 1:
            ball = (rng.uniform(*s.ball_distance_m), mid_y + rng.uniform(*s.ball_lateral_m))
            objects = [make_object("ball", *ball)]
            goals = ("ball", "ball")
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
            d = [math.hypot(obstacle[0] - p[0], obstacle[1] - p[1]) for p in starts]
            if abs(d[0] - d[1]) < s.min_assignment_gap_m:
                continue
            nearest = int(np.argmin(d))
            goals = tuple("obstacle" if i == nearest else "ball" for i in range(2))
            variant = "a" if nearest == 1 else "b"
        # Start poses and head pans: each robot looks at the middle of the objects.
        robots, ok = [], True
        points = [o.centre_m for o in objects]
        for i in range(2):
            pose = (float(starts[i, 0]), float(starts[i, 1]), float(heading[i]))
            if blind == i:
                pan = _aim(pose, [o.centre_m for o in objects if o.kind == "obstacle"])
            else:
                pan = _aim(pose, points)
            if abs(pan) > camera.pan_limit_rad:
                ok = False
                break
            others = [make_object("teammate", *starts[1 - i])]
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


# -- the team channel ---------------------------------------------------------------------------


class TeamChannel:
    """In-process stand-in for the Zenoh keys ``swarmloc/<run>/team/<team>/blobs/<id>``.

    Payloads published at tick k are delivered at tick k+1 to every other robot of the team, as
    the bytes that were published.
    """

    def __init__(self, run: str, teams: list[str]):
        self.keys = Keys(run)
        self.teams = list(teams)
        self._outbox: list[tuple[str, str, int, bytes]] = []
        self.published = 0

    def publish(self, robot_id: int, payload: bytes) -> str:
        team = self.teams[robot_id]
        key = self.keys.team_blobs(team, robot_id)
        self._outbox.append((key, team, robot_id, bytes(payload)))
        self.published += 1
        return key

    def deliver(self) -> list[list[tuple[int, bytes]]]:
        """Per receiver, the ``(sender, payload)`` pairs published since the last delivery."""
        inbox: list[list[tuple[int, bytes]]] = [[] for _ in self.teams]
        for _key, team, sender, payload in self._outbox:
            for receiver, receiver_team in enumerate(self.teams):
                if receiver != sender and receiver_team == team:
                    inbox[receiver].append((sender, payload))
        self._outbox = []
        return inbox


# -- one run ------------------------------------------------------------------------------------


@dataclass
class RunRecord:
    """What a run leaves for the figures: per tick the true poses and the estimates (world
    frame, through the robot's true pose) of teammate and ball, NaN where unknown."""

    layout: Layout
    poses: list[np.ndarray] = field(default_factory=list)
    teammate_world: list[np.ndarray] = field(default_factory=list)
    ball_world: list[np.ndarray] = field(default_factory=list)
    collision_points: list[tuple[float, float]] = field(default_factory=list)


def _to_world(pose: np.ndarray, body_xy) -> np.ndarray:
    c, s = math.cos(pose[2]), math.sin(pose[2])
    return pose[:2] + np.array([c * body_xy[0] - s * body_xy[1], s * body_xy[0] + c * body_xy[1]])


def _corrupt(payload: bytes, rng: np.random.Generator) -> bytes:
    """Fault injection: a payload cut short, or one with flipped bytes."""
    data = bytearray(payload)
    if rng.random() < 0.5 or len(data) < 4:
        return bytes(data[: len(data) // 3])
    idx = rng.integers(0, len(data), size=max(1, len(data) // 50))
    for i in idx:
        data[i] ^= 0xFF
    return bytes(data)


def run_vision(
    scenario: VisionScenario,
    seed: int,
    sharing: bool | None = None,
    fault_rate: float = 0.0,
    record: bool = False,
    run: str = "vision",
):
    """Run one seeded replication; returns ``(metrics dict, RunRecord or None)``.

    ``sharing`` overrides ``scenario.agent.sharing``. ``fault_rate``: probability that each image
    and each payload is corrupted on its way (for tests of the error counting).
    """
    agent_cfg = (
        scenario.agent if sharing is None else dataclasses.replace(scenario.agent, sharing=sharing)
    )
    wcfg, lay = world_config(scenario, seed)
    world = VisionWorld(wcfg)
    n = world.n_robots
    teams = [r.team for r in lay.robots]
    brains = [
        VisionBrain(
            i,
            [j for j in range(n) if j != i and teams[j] == teams[i]],
            agent_cfg,
            wcfg.camera,
            np.random.default_rng([seed, AGENT_STREAM, i]),
        )
        for i in range(n)
    ]
    channel = TeamChannel(run, teams)
    faults = np.random.default_rng([seed, FAULT_STREAM])
    body_r = wcfg.body_radius_m
    ball_xy = next((o.x_m, o.y_m) for o in lay.objects if o.kind == "ball")
    goal_xy = {o.kind: np.array([o.x_m, o.y_m]) for o in lay.objects}
    reach_m = [body_r + OBJECT_KINDS[g].radius_m + scenario.setup.reach_margin_m for g in lay.goals]
    reach_time: list[float | None] = [None] * n
    n_ticks = round(scenario.setup.duration_s / wcfg.tick_s)
    teammate_err: list[list[float]] = [[] for _ in range(n)]
    ball_err: list[list[float]] = [[] for _ in range(n)]
    relayed_err: list[float] = []
    ticks_known_teammate = np.zeros(n, dtype=int)
    ticks_known_ball = np.zeros(n, dtype=int)
    blind_first_ball_s: float | None = None
    bad_images = bad_payloads = 0
    commands = [STOP] * n
    all_reached_since: float | None = None
    rec = RunRecord(lay) if record else None
    t_cpu = time.process_time()
    tick = 0
    for tick in range(n_ticks):
        observations = world.observe()
        for receiver, messages in enumerate(channel.deliver()):
            for sender, payload in messages:
                if fault_rate and faults.random() < fault_rate:
                    payload = _corrupt(payload, faults)
                try:
                    brains[receiver].receive(sender, payload)
                except ValueError:
                    bad_payloads += 1
        for i, (brain, obs) in enumerate(zip(brains, observations)):
            if fault_rate and faults.random() < fault_rate:
                obs = dataclasses.replace(obs, image=_corrupt(obs.image, faults))
            try:
                commands[i] = brain.step(obs)
            except ValueError:
                bad_images += 1  # keeps its previous command
        collisions_before = world.robot_collisions
        # Ground truth and the brains' estimates.
        for i, brain in enumerate(brains):
            est = brain.estimates()
            for j, xy in est.teammates.items():
                truth = world.relative_position(i, world.pose[j, :2])
                teammate_err[i].append(float(np.hypot(*(np.asarray(xy) - truth))))
            ticks_known_teammate[i] += bool(est.teammates)
            if est.ball is not None:
                err = float(np.hypot(*(np.asarray(est.ball) - world.relative_position(i, ball_xy))))
                ball_err[i].append(err)
                ticks_known_ball[i] += 1
                if i == lay.blind and est.ball_source == "teammate":
                    relayed_err.append(err)
                if i == lay.blind and blind_first_ball_s is None:
                    blind_first_ball_s = round(world.time_s, 3)
            if (
                reach_time[i] is None
                and np.hypot(*(world.pose[i, :2] - goal_xy[lay.goals[i]])) <= reach_m[i]
            ):
                reach_time[i] = round(world.time_s, 3)
            if rec is not None:
                tm = next(iter(est.teammates.values()), None)
                rec.teammate_world.append(
                    np.full(2, np.nan) if tm is None else _to_world(world.pose[i], tm)
                )
                rec.ball_world.append(
                    np.full(2, np.nan) if est.ball is None else _to_world(world.pose[i], est.ball)
                )
        if rec is not None:
            rec.poses.append(world.pose.copy())
        for i, brain in enumerate(brains):
            payload = brain.share()
            if payload is not None:
                channel.publish(i, payload)
        world.step(commands)
        if rec is not None and world.robot_collisions > collisions_before:
            rec.collision_points.append(tuple(world.pose[:, :2].mean(axis=0)))
        if all(b.reached for b in brains):
            all_reached_since = world.time_s if all_reached_since is None else all_reached_since
            if world.time_s - all_reached_since >= 1.0:
                break
        else:
            all_reached_since = None
    for i in range(n):  # the last move
        if (
            reach_time[i] is None
            and np.hypot(*(world.pose[i, :2] - goal_xy[lay.goals[i]])) <= reach_m[i]
        ):
            reach_time[i] = world.time_s
    goals = [b.goal for b in brains]

    def _median(values):
        return round(float(np.median(values)), 4) if len(values) else None

    def _p90(values):
        return round(float(np.percentile(values, 90)), 4) if len(values) else None

    all_teammate = [e for errs in teammate_err for e in errs]
    all_ball = [e for errs in ball_err for e in errs]
    ticks = tick + 1
    metrics = {
        "experiment": scenario.setup.experiment,
        "scenario": scenario.name,
        "sharing": agent_cfg.sharing,
        "seed": seed,
        "variant": lay.variant,
        "collisions": world.robot_collisions,
        "contact_s": round(world.robot_contact_ticks * wcfg.tick_s, 3),
        "obstacle_collisions": world.obstacle_collisions,
        "goals_correct": all(g == t for g, t in zip(goals, lay.goals)),
        "goals": "/".join(str(g) for g in goals),
        "true_goals": "/".join(lay.goals),
        "reach_s_0": reach_time[0],
        "reach_s_1": reach_time[1] if n > 1 else None,
        "all_reached": all(t is not None for t in reach_time),
        "all_reached_s": max(reach_time) if all(t is not None for t in reach_time) else None,
        "teammate_err_median_m": _median(all_teammate),
        "teammate_err_p90_m": _p90(all_teammate),
        "teammate_known_fraction": round(float(ticks_known_teammate.sum()) / (n * ticks), 4),
        "ball_err_median_m": _median(all_ball),
        "ball_known_fraction": round(float(ticks_known_ball.sum()) / (n * ticks), 4),
        "blind_ball_first_s": blind_first_ball_s,
        "blind_relayed_ball_err_median_m": _median(relayed_err),
        "bad_images": bad_images,
        "bad_payloads": bad_payloads,
        "payloads": channel.published,
        "sim_s": round(world.time_s, 2),
        "cpu_s": round(time.process_time() - t_cpu, 3),
    }
    return metrics, rec


# -- experiments --------------------------------------------------------------------------------

COLUMNS = [
    "experiment",
    "scenario",
    "sharing",
    "seed",
    "variant",
    "collisions",
    "contact_s",
    "obstacle_collisions",
    "goals_correct",
    "goals",
    "true_goals",
    "reach_s_0",
    "reach_s_1",
    "all_reached",
    "all_reached_s",
    "teammate_err_median_m",
    "teammate_err_p90_m",
    "teammate_known_fraction",
    "ball_err_median_m",
    "ball_known_fraction",
    "blind_ball_first_s",
    "blind_relayed_ball_err_median_m",
    "bad_images",
    "bad_payloads",
    "payloads",
    "sim_s",
    "cpu_s",
]


def _job(args: tuple[str, int, bool, tuple[str, ...]]) -> dict:
    import cv2

    cv2.setNumThreads(1)
    name, seed, sharing, overrides = args
    metrics, _ = run_vision(load_vision_scenario(name, list(overrides)), seed, sharing)
    return metrics


def run_experiments(
    names: list[str],
    runs: int,
    seed: int = 1,
    sharing_modes=(True, False),
    workers: int = 2,
    overrides: tuple[str, ...] = (),
    progress=None,
) -> list[dict]:
    """Every (scenario, sharing mode, seed ``seed .. seed + runs - 1``) run; rows in job order."""
    for name in names:
        load_vision_scenario(name, list(overrides))  # refuse a bad name or override up front
    jobs = [
        (name, seed + r, sharing, tuple(overrides))
        for name in names
        for sharing in sharing_modes
        for r in range(runs)
    ]
    if workers <= 1:
        rows = []
        for job in jobs:
            rows.append(_job(job))
            if progress:
                progress(len(rows), len(jobs))
        return rows
    saved = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
    os.environ.update({k: "1" for k in saved})
    try:
        with ProcessPoolExecutor(
            max_workers=workers, mp_context=multiprocessing.get_context("spawn")
        ) as pool:
            rows = []
            for row in pool.map(_job, jobs, chunksize=1):
                rows.append(row)
                if progress:
                    progress(len(rows), len(jobs))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return rows


_TEXT_COLUMNS = ("scenario", "variant", "goals", "true_goals")


def write_csv(rows: list[dict], path: str | Path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in COLUMNS})


def read_csv(path: str | Path) -> list[dict]:
    """Rows of :func:`write_csv`, with numbers and booleans parsed back."""
    rows = []
    with Path(path).open(newline="") as handle:
        for raw in csv.DictReader(handle):
            row: dict = {}
            for k, v in raw.items():
                if k in _TEXT_COLUMNS:
                    row[k] = v
                elif v == "":
                    row[k] = None
                elif v in ("True", "False"):
                    row[k] = v == "True"
                else:
                    try:
                        row[k] = int(v)
                    except ValueError:
                        try:
                            row[k] = float(v)
                        except ValueError:
                            row[k] = v
            rows.append(row)
    return rows


def summarize(rows: list[dict]) -> list[dict]:
    """One line per (scenario, sharing): rates, medians and interquartile ranges."""
    out = []
    keys = sorted({(r["scenario"], r["sharing"]) for r in rows}, key=lambda k: (k[0], not k[1]))
    for scenario, sharing in keys:
        group = [r for r in rows if r["scenario"] == scenario and r["sharing"] == sharing]
        n = len(group)

        def values(key, group=group):
            return [r[key] for r in group if r[key] is not None]

        def median(key, values=values):
            v = values(key)
            return float(np.median(v)) if v else None

        out.append(
            {
                "scenario": scenario,
                "sharing": sharing,
                "runs": n,
                "runs_with_collision": sum(r["collisions"] > 0 for r in group),
                "collisions_mean": float(np.mean([r["collisions"] for r in group])),
                "contact_s_median": median("contact_s"),
                "obstacle_collision_runs": sum(r["obstacle_collisions"] > 0 for r in group),
                "goals_correct": sum(bool(r["goals_correct"]) for r in group),
                "all_reached": sum(bool(r["all_reached"]) for r in group),
                "all_reached_s_median": median("all_reached_s"),
                "reach_s_median": (
                    float(np.median(values("reach_s_0") + values("reach_s_1")))
                    if values("reach_s_0") + values("reach_s_1")
                    else None
                ),
                "teammate_err_median_m": median("teammate_err_median_m"),
                "teammate_err_p90_m": median("teammate_err_p90_m"),
                "teammate_known_fraction": median("teammate_known_fraction"),
                "ball_err_median_m": median("ball_err_median_m"),
                "blind_ball_runs": sum(r["blind_ball_first_s"] is not None for r in group),
                "blind_ball_first_s": median("blind_ball_first_s"),
                "blind_relayed_ball_err_median_m": median("blind_relayed_ball_err_median_m"),
                "bad_images": sum(r["bad_images"] for r in group),
                "bad_payloads": sum(r["bad_payloads"] for r in group),
                "cpu_s_mean": float(np.mean([r["cpu_s"] for r in group])),
                "variants": "/".join(
                    f"{v}:{sum(r['variant'] == v for r in group)}"
                    for v in sorted({r["variant"] for r in group})
                    if v
                ),
            }
        )
    return out


# -- detection accuracy -------------------------------------------------------------------------

DETECTION_DISTANCE_BINS_M = ((0.3, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 4.0))
DETECTION_VISIBLE_BINS = ((0.75, 1.0), (0.5, 0.75), (0.25, 0.5), (0.0, 0.25))
_KIND_COLOUR = {"ball": "pink", "teammate": "yellow", "obstacle": "orange", "beacon": "blue"}


def _view(rng):
    return (rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-math.pi, math.pi)), rng.uniform(
        -1, 1
    )


def _place(pose, pan, bearing, distance):
    yaw = pose[2] + pan + bearing
    return pose[0] + distance * math.cos(yaw), pose[1] + distance * math.sin(yaw)


def _wholly_in_view(pose, pan, obj, camera: CameraParams) -> bool:
    u, v, r, _ = project(pose, pan, obj, camera)
    if obj.is_sphere:
        return (
            u - r >= 0
            and u + r <= camera.width_px - 1
            and v - r >= 0
            and v + r <= camera.height_px - 1
        )
    depth = camera.focal_px * obj.radius_m / r
    scale = camera.focal_px / depth
    top = camera.cy_px + scale * (camera.camera_height_m - obj.height_m)
    bottom = camera.cy_px + scale * camera.camera_height_m
    return (
        u - r >= 0 and u + r <= camera.width_px - 1 and top >= 0 and bottom <= camera.height_px - 1
    )


def _agent_sees(image, pose_pan, camera, world_cfg):
    """Blobs and usable detections of a frame as the agent gets it (encoded, decoded)."""
    payload = encode_image(image, world_cfg.image_format, world_cfg.jpeg_quality)
    decoded = decode_image(payload, camera)
    blobs = detect_blobs(decoded, camera)
    return blobs, detections_from_blobs(blobs, 0, 0.0, pose_pan, camera)


class _Tally:
    """Counts and errors of one detection bin."""

    def __init__(self) -> None:
        self.n = self.blob_hits = 0
        self.used: list[tuple[float, float]] = []  # (bearing error deg, relative distance error)
        self.raw: list[float] = []  # relative distance error of the largest blob, used or not

    def add(self, blobs, used, colour: str, bearing: float, distance: float) -> None:
        self.n += 1
        raw = [b for b in blobs if b.colour == colour]
        if raw:
            self.blob_hits += 1
            self.raw.append(abs(raw[0].distance_m / distance - 1.0))
        mine = [d for d in used if d.colour == colour]
        if len(mine) == 1:
            d = mine[0]
            self.used.append(
                (
                    abs(math.degrees(float(d.bearing_rad) - bearing)),
                    abs(d.distance_m / distance - 1),
                )
            )

    def row(self, kind: str, label: str) -> tuple:
        n = max(self.n, 1)
        bearing = dist = None
        if self.used:
            bearing, dist = (float(v) for v in np.median(np.array(self.used), axis=0))
            dist *= 100.0
        raw = 100.0 * float(np.median(self.raw)) if self.raw else None
        return (
            kind,
            label,
            self.n,
            100.0 * self.blob_hits / n,
            100.0 * len(self.used) / n,
            bearing,
            dist,
            raw,
        )


def detection_accuracy(
    n_per_bin: int = 200, seed: int = 20240505, world: VisionWorldConfig | None = None
) -> dict:
    """Detection rate and errors over distance (every kind) and over partial occlusion (ball and
    teammate behind a nearer robot), on rendered frames through the agent's whole pipeline
    (JPEG encode, decode, blobs, usable detections), default noise and lighting.

    Returns ``{"distance": rows, "occlusion": rows}``; a row is ``(kind, bin label, n, blob
    rate %, used rate %, median bearing error deg, median distance error %, median distance
    error % of the raw blob)``: the errors are those of the *used* detections (``None`` if none);
    the blob rate and the raw error count the largest blob of the colour, used or not. Bearing
    is in the camera frame.
    """
    world = world or VisionWorldConfig()
    camera = world.camera
    rng = np.random.default_rng(seed)
    distance_rows = []
    for kind in ("ball", "teammate", "obstacle", "beacon"):
        colour = _KIND_COLOUR[kind]
        for lo, hi in DETECTION_DISTANCE_BINS_M:
            tally = _Tally()
            while tally.n < n_per_bin:
                pose, pan = _view(rng)
                bearing = rng.uniform(-camera.half_fov_rad, camera.half_fov_rad)
                distance = rng.uniform(lo, hi)
                obj = make_object(kind, *_place(pose, pan, bearing, distance))
                if not _wholly_in_view(pose, pan, obj, camera):
                    continue
                blobs, used = _agent_sees(render(pose, pan, [obj], camera, rng), 0.0, camera, world)
                tally.add(blobs, used, colour, bearing, distance)
            distance_rows.append(tally.row(kind, f"{lo:.1f}-{hi:.1f} m"))
    occlusion_rows = []
    clean = dataclasses.replace(camera, noise_sigma=0.0, gain_min=1.0, gain_max=1.0)
    for kind in ("ball", "teammate"):
        colour = _KIND_COLOUR[kind]
        tallies = {b: _Tally() for b in DETECTION_VISIBLE_BINS}
        radius = OBJECT_KINDS[kind].radius_m
        while min(t.n for t in tallies.values()) < n_per_bin:
            pose, pan = _view(rng)
            bearing = rng.uniform(-0.5 * camera.half_fov_rad, 0.5 * camera.half_fov_rad)
            distance = rng.uniform(1.0, 2.0)
            target = make_object(kind, *_place(pose, pan, bearing, distance))
            if not _wholly_in_view(pose, pan, target, camera):
                continue
            # An orange robot halfway, its edge somewhere across the target's width.
            half = math.atan(radius / distance)
            blocker_half = math.atan(0.10 / (distance / 2))
            side = rng.choice([-1.0, 1.0])
            edge = bearing + side * rng.uniform(-1.0, 1.0) * half
            blocker = make_object(
                "rival", *_place(pose, pan, edge + side * blocker_half, distance / 2)
            )
            # Visible fraction: the target's pixels with and without the blocker (no noise).
            u_px, v_px, _, _ = project(pose, pan, target, clean)
            alone = render(pose, pan, [target], clean, np.random.default_rng(0))
            hidden = render(pose, pan, [target, blocker], clean, np.random.default_rng(0))
            colour_bgr = alone[round(v_px), round(u_px)]
            area_alone = int(np.all(alone == colour_bgr, axis=2).sum())
            area_hidden = int(np.all(hidden == colour_bgr, axis=2).sum())
            visible = area_hidden / area_alone if area_alone else 0.0
            for b in DETECTION_VISIBLE_BINS:
                if b[0] < visible <= b[1] or (b[0] == 0.0 and visible == 0.0):
                    if tallies[b].n < n_per_bin:
                        image = render(pose, pan, [target, blocker], camera, rng)
                        blobs, used = _agent_sees(image, 0.0, camera, world)
                        tallies[b].add(blobs, used, colour, bearing, distance)
                    break
        for b in DETECTION_VISIBLE_BINS:
            occlusion_rows.append(tallies[b].row(kind, f"{100 * b[0]:.0f}-{100 * b[1]:.0f} %"))
    return {"distance": distance_rows, "occlusion": occlusion_rows}


def detection_table(result: dict) -> str:
    """Markdown tables of :func:`detection_accuracy`."""

    def fmt(v, spec):
        return "-" if v is None else format(v, spec)

    columns = (
        "| n | blob found % | used % | bearing error ° | distance error % | "
        "distance error % of the raw blob |"
    )
    lines = ["| object | distance " + columns, "|---" * 8 + "|"]
    for kind, label, n, blob, used, bearing, dist, raw in result["distance"]:
        lines.append(
            f"| {kind} | {label} | {n} | {blob:.1f} | {used:.1f} | {fmt(bearing, '.3f')} | "
            f"{fmt(dist, '.2f')} | {fmt(raw, '.2f')} |"
        )
    lines += ["", "| object | visible at 1-2 m " + columns, "|---" * 8 + "|"]
    for kind, label, n, blob, used, bearing, dist, raw in result["occlusion"]:
        lines.append(
            f"| {kind} | {label} | {n} | {blob:.1f} | {used:.1f} | {fmt(bearing, '.3f')} | "
            f"{fmt(dist, '.2f')} | {fmt(raw, '.2f')} |"
        )
    return "\n".join(lines)


#: Scene timed by :func:`frame_costs` (the scene of ``benchmarks/bench_vision.py``).
TIMING_SCENE = (
    ("ball", 1.5, 0.1),
    ("teammate", 2.0, 0.6),
    ("teammate", 2.5, -0.5),
    ("rival", 1.2, -0.4),
    ("rival", 3.0, 0.3),
    ("beacon", 3.5, 1.2),
)


def frame_costs(n_frames: int = 500, seed: int = 20240505) -> tuple[float, float]:
    """Median CPU ms (``time.process_time``) per frame of render + detect, and of the path a
    frame takes to the agent: render + JPEG encode + decode + detect + the agent's detections;
    :data:`TIMING_SCENE`, default noise and lighting, this process's threads."""
    world = VisionWorldConfig()
    camera = world.camera
    rng = np.random.default_rng(seed)
    objects = [make_object(kind, x, y) for kind, x, y in TIMING_SCENE]
    pose = (0.0, 0.0, 0.0)
    short, full = [], []
    for _ in range(n_frames):
        t0 = time.process_time()
        detect_blobs(render(pose, 0.0, objects, camera, rng), camera)
        t1 = time.process_time()
        image = render(pose, 0.0, objects, camera, rng)
        payload = encode_image(image, world.image_format, world.jpeg_quality)
        blobs = detect_blobs(decode_image(payload, camera), camera)
        detections_from_blobs(blobs, 0, 0.0, 0.0, camera)
        t2 = time.process_time()
        short.append(t1 - t0)
        full.append(t2 - t1)
    return float(np.median(short)) * 1e3, float(np.median(full)) * 1e3


#: Sensitivity runs of the report (sharing on): what breaks the parallel-start assumption.
SENSITIVITY = (
    (
        (
            "start headings drawn within ±0.15 rad instead of ±0.03 rad: the brains' assumption of "
            "parallel bodies at the start is off by up to 0.3 rad"
        ),
        EXPERIMENTS,
        ("setup.heading_jitter_rad=0.15",),
    ),
    (
        (
            "the same, with the relative heading from the two objects both robots see (Fig. 2, "
            '`agent.relative_heading = "objects"`; experiment 2, where both see ball and obstacle)'
        ),
        ("vision-exp2",),
        ("setup.heading_jitter_rad=0.15", 'agent.relative_heading="objects"'),
    ),
)


# -- the report ---------------------------------------------------------------------------------

#: Seed 004 §IV's claims, one per (experiment, aspect). The paper shows one or two trials per
#: experiment in figures; it gives no numbers.
PAPER_CLAIMS = {
    "vision-exp1": [
        (
            "collisions without sharing",
            "§IV-A, Fig. 6a",
            (
                '"the two AIBOs crash in the middle of the experiment, and they go on crashing till '
                'they catch the ball"'
            ),
        ),
        (
            "collisions with sharing",
            "§IV-A, Fig. 6b",
            (
                '"they correctly estimate their position. Thus they avoid crashing and finally they '
                'catch the ball from opposite sides"'
            ),
        ),
    ],
    "vision-exp2": [
        (
            "goals and collisions with sharing",
            "§IV-B, Fig. 7a/7b",
            (
                '"they correctly estimate where they are to avoid crash and ... they catch the correct '
                'objective", in both assignments'
            ),
        ),
    ],
    "vision-exp3": [
        (
            "the robot that cannot see the ball",
            "§IV-C, Fig. 8a/8b",
            (
                '"they establish their goals correctly. This shows that they have correctly shared '
                'information about the estimated position of the ball"; no crash'
            ),
        ),
    ],
}


def _pct(k: int, n: int) -> str:
    return f"{k}/{n} ({100.0 * k / n:.0f} %)" if n else "-"


def _fmt(value, spec=".2f", unit="") -> str:
    return "-" if value is None else f"{format(value, spec)}{unit}"


def _ours(summary: list[dict], scenario: str, aspect: str) -> tuple[str, str]:
    by = {s["sharing"]: s for s in summary if s["scenario"] == scenario}
    on, off = by.get(True), by.get(False)
    if aspect == "collisions without sharing" and off:
        return (
            (
                f"collided in {_pct(off['runs_with_collision'], off['runs'])} runs without sharing, "
                f"in contact {_fmt(off['contact_s_median'], '.1f')} s (median); both still reach "
                f"the ball in {_pct(off['all_reached'], off['runs'])}"
            ),
            "agrees" if off["runs_with_collision"] >= 0.8 * off["runs"] else "differs",
        )
    if aspect == "collisions with sharing" and on:
        return (
            (
                f"collided in {_pct(on['runs_with_collision'], on['runs'])} runs with sharing; both "
                f"reached the ball in {_pct(on['all_reached'], on['runs'])}, median "
                f"{_fmt(on['all_reached_s_median'], '.1f')} s; teammate error "
                f"{_fmt(on['teammate_err_median_m'], '.3f')} m (median of run medians). They "
                "arrive side by side, not from opposite sides"
            ),
            "agrees (collisions)" if on["runs_with_collision"] == 0 else "differs",
        )
    if aspect == "goals and collisions with sharing" and on:
        text = (
            f"goals right in {_pct(on['goals_correct'], on['runs'])} runs ({on['variants']}), "
            f"collided in {on['runs_with_collision']}, both reached their goal in "
            f"{_pct(on['all_reached'], on['runs'])}"
        )
        if off:
            text += (
                f"; without sharing: goals right in {_pct(off['goals_correct'], off['runs'])}, "
                f"collided in {_pct(off['runs_with_collision'], off['runs'])}"
            )
        ok = on["goals_correct"] == on["runs"] and on["runs_with_collision"] == 0
        return text, "agrees" if ok else "differs"
    if aspect == "the robot that cannot see the ball" and on:
        text = (
            f"with sharing the blind robot placed the ball in "
            f"{_pct(on['blind_ball_runs'], on['runs'])} runs (first after "
            f"{_fmt(on['blind_ball_first_s'], '.1f')} s, relayed-ball error "
            f"{_fmt(on['blind_relayed_ball_err_median_m'], '.3f')} m), goals right in "
            f"{_pct(on['goals_correct'], on['runs'])} ({on['variants']}), collided in "
            f"{on['runs_with_collision']}, both reached in {_pct(on['all_reached'], on['runs'])}"
        )
        if off:
            text += (
                f"; without sharing: goals right in {_pct(off['goals_correct'], off['runs'])}, "
                f"collided in {_pct(off['runs_with_collision'], off['runs'])}"
            )
        ok = on["goals_correct"] == on["runs"] and on["runs_with_collision"] == 0
        return text, "agrees" if ok else "differs"
    return "not measured", "-"


def summary_table(summary: list[dict]) -> str:
    header = (
        "| scenario | sharing | runs | runs with a robot-robot collision | collisions per run "
        "(mean) | contact s (median) | runs touching the obstacle | goals right | both reached "
        "| time to both reached s (median) | teammate error m (median / p90) | teammate known "
        "| ball error m (median) | blind robot: ball known in runs, first at s, relayed error m |"
    )
    lines = [header, "|" + "---|" * 14]
    for s in summary:
        blind = "-"
        if s["scenario"] == "vision-exp3":
            blind = (
                f"{s['blind_ball_runs']}/{s['runs']}, {_fmt(s['blind_ball_first_s'], '.1f')}, "
                f"{_fmt(s['blind_relayed_ball_err_median_m'], '.3f')}"
            )
        lines.append(
            f"| {s['scenario']} | {'on' if s['sharing'] else 'off'} | {s['runs']} | "
            f"{s['runs_with_collision']} | {s['collisions_mean']:.2f} | "
            f"{_fmt(s['contact_s_median'], '.1f')} | {s['obstacle_collision_runs']} | "
            f"{s['goals_correct']} | {s['all_reached']} | {_fmt(s['all_reached_s_median'], '.1f')} | "
            f"{_fmt(s['teammate_err_median_m'], '.3f')} / {_fmt(s['teammate_err_p90_m'], '.3f')} | "
            f"{_fmt(s['teammate_known_fraction'], '.2f')} | {_fmt(s['ball_err_median_m'], '.3f')} | "
            f"{blind} |"
        )
    return "\n".join(lines)


def _trajectory_figure(records: dict, path: Path) -> None:
    from matplotlib.figure import Figure
    from matplotlib.patches import Circle

    names = [n for n in EXPERIMENTS if any(k[0] == n for k in records)]
    fig = Figure(figsize=(11, 3.0 * len(names)), layout="constrained")
    axes = fig.subplots(len(names), 2, squeeze=False)
    colours = ("tab:blue", "black")
    for row, name in enumerate(names):
        for col, sharing in enumerate((False, True)):
            ax = axes[row][col]
            key = (name, sharing)
            if key not in records:
                ax.set_visible(False)
                continue
            seed, metrics, rec = records[key]
            poses = np.array(rec.poses)
            for o in rec.layout.objects:
                colour = {"ball": "deeppink", "obstacle": "darkorange"}.get(o.kind, "grey")
                ax.add_patch(Circle((o.x_m, o.y_m), OBJECT_KINDS[o.kind].radius_m, color=colour))
            tm = np.array(rec.teammate_world).reshape(len(poses), -1, 2)
            ball = np.array(rec.ball_world).reshape(len(poses), -1, 2)
            for i in range(poses.shape[1]):
                chosen = metrics["goals"].split("/")[i]
                label = f"robot {i}" + (" (white, blind)" if rec.layout.blind == i else "")
                label += f": should take the {rec.layout.goals[i]}, took the {chosen}"
                ax.plot(poses[:, i, 0], poses[:, i, 1], color=colours[i], lw=1.5, label=label)
                ax.add_patch(Circle(poses[0, i, :2], 0.1, fill=False, color=colours[i], ls="--"))
                ax.add_patch(Circle(poses[-1, i, :2], 0.1, fill=False, color=colours[i]))
                ax.plot(tm[::3, i, 0], tm[::3, i, 1], ".", ms=2.5, color=colours[1 - i], alpha=0.5)
                if rec.layout.blind == i:
                    ax.plot(
                        ball[::3, i, 0],
                        ball[::3, i, 1],
                        "x",
                        ms=3,
                        color="deeppink",
                        alpha=0.6,
                        label="white's ball estimate",
                    )
            for x, y in rec.collision_points:
                ax.plot(x, y, "r*", ms=12)
            ax.set_aspect("equal")
            ax.set_title(
                f"{name}, sharing {'on' if sharing else 'off'} (seed {seed}): "
                f"{metrics['collisions']} collision(s), goals "
                f"{'right' if metrics['goals_correct'] else 'wrong'}",
                fontsize=9,
            )
            ax.set_xlabel("x (m)")
            ax.set_ylabel("y (m)")
            ax.legend(fontsize=7, loc="best")
            ax.grid(alpha=0.3)
    fig.savefig(path, dpi=100, metadata={"Software": None})


def _summary_figure(summary: list[dict], path: Path) -> None:
    from matplotlib.figure import Figure

    fig = Figure(figsize=(10, 3.4), layout="constrained")
    axes = fig.subplots(1, 3)
    names = [n for n in EXPERIMENTS if any(s["scenario"] == n for s in summary)]
    x = np.arange(len(names))
    for ax, (key, title) in zip(
        axes,
        (
            ("runs_with_collision", "runs with a robot-robot collision"),
            ("goals_correct", "runs with the right goals"),
            ("all_reached", "runs where both reach their goal"),
        ),
    ):
        for k, sharing in enumerate((False, True)):
            vals = []
            for n in names:
                s = next(
                    (s for s in summary if s["scenario"] == n and s["sharing"] == sharing), None
                )
                vals.append(100.0 * s[key] / s["runs"] if s else np.nan)
            ax.bar(
                x + (k - 0.5) * 0.38,
                vals,
                width=0.38,
                label=f"sharing {'on' if sharing else 'off'}",
                color="tab:green" if sharing else "tab:grey",
            )
        ax.set_xticks(x, [n.replace("vision-", "") for n in names])
        ax.set_ylim(0, 125)
        ax.set_yticks(range(0, 101, 20))
        ax.set_ylabel("% of runs")
        ax.set_title(title, fontsize=9)
        ax.legend(fontsize=7, loc="upper center", ncol=2)
    fig.savefig(path, dpi=100, metadata={"Software": None})


def write_report(
    out_dir: str | Path,
    rows: list[dict],
    detection: dict | None,
    commands: list[str],
    timing: str = "",
    figure_seeds: dict | None = None,
    sensitivity: list[tuple[str, str, list[dict]]] = (),
) -> Path:
    """``README.md``, ``results.csv`` and the figures in ``out_dir``; returns the README path.

    ``figure_seeds``: the seed whose trajectories are drawn, per scenario (default: the first
    seed of the rows, for experiment 3 the first of variant "a", where the blind robot must
    walk around the obstacle). ``sensitivity``: ``(what, command, rows)`` of extra runs, each
    shown as its own table.
    """
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    write_csv(rows, out / "results.csv")
    summary = summarize(rows)
    figure_seeds = dict(figure_seeds or {})
    records = {}
    for name in sorted({r["scenario"] for r in rows}):
        seeds = [r["seed"] for r in rows if r["scenario"] == name]
        if name not in figure_seeds:
            pick = [r["seed"] for r in rows if r["scenario"] == name and r["variant"] == "a"]
            figure_seeds[name] = (pick or seeds)[0]
        scenario = load_vision_scenario(name)
        for sharing in sorted({r["sharing"] for r in rows if r["scenario"] == name}):
            metrics, rec = run_vision(scenario, figure_seeds[name], sharing, record=True)
            records[(name, sharing)] = (figure_seeds[name], metrics, rec)
    _trajectory_figure(records, out / "vision_trajectories.png")
    _summary_figure(summary, out / "vision_summary.png")
    seeds = sorted({r["seed"] for r in rows})
    lines = [
        "# Seed 004: cooperative localization from shared colour blobs (vision robots)",
        "",
        (
            "Two simulated legged robots with one camera each (pinhole, f = 190 px, 208 x 160 px, noise "
            "and lighting variation, JPEG frames) detect colour blobs with OpenCV, share their "
            'detections ("Telepathy"), locate each other by stereo (eq. 1) and the law of cosines '
            "(eq. 2) from objects seen in common, and walk with a potential field (eq. 3-5) to the goals "
            "of seed 004 §IV. Each run draws its own layout (mirror image and variant a/b of the "
            "paper's figures at random), checked by rendering: each robot sees at the start what the "
            "paper says it sees."
        ),
        "",
        "## Regenerate",
        "",
        "```sh",
        *commands,
        "```",
        "",
        (
            f"Seeds {seeds[0]}-{seeds[-1]} ({len(seeds)} runs per scenario and sharing mode); run "
            "seed s draws its layout from `default_rng([s, 2])`, the world from `[s, 0]`, robot i's "
            "brain from `[s, 1, i]`. Scenarios: `deploy/scenarios/vision/vision-exp{1,2,3}.toml`."
        ),
        "",
        "## The paper's claims and ours",
        "",
        (
            "The paper shows one or two trials per experiment (Fig. 6-8) and gives no numbers; ours are "
            "counts over the seeded runs below."
        ),
        "",
        "| experiment | claim | source | paper | ours | verdict |",
        "|---|---|---|---|---|---|",
    ]
    for name in EXPERIMENTS:
        if not any(s["scenario"] == name for s in summary):
            continue
        for aspect, source, paper in PAPER_CLAIMS[name]:
            ours, verdict = _ours(summary, name, aspect)
            lines.append(f"| {name} | {aspect} | {source} | {paper} | {ours} | {verdict} |")
    lines += [
        "",
        "## All measurements",
        "",
        (
            "Per scenario and sharing mode. A collision is a pair of bodies coming into contact; "
            '"goals right": every robot chose the goal the rule of §IV gives on the true start '
            'positions (the robot nearest the obstacle takes it); "both reached": each robot\'s centre '
            "came within body + goal radius + 10 cm of its right goal within 40 s; errors are each "
            "run's median over the ticks where the robot had an estimate, then the median over runs "
            '(p90: the median over runs of each run\'s 90th percentile); "teammate known": fraction '
            "of robot-ticks with a teammate estimate. Rejected images and payloads: "
            f"{sum(s['bad_images'] for s in summary)} and {sum(s['bad_payloads'] for s in summary)} "
            "(none are injected in these runs). Raw rows: `results.csv`."
        ),
        "",
        summary_table(summary),
        "",
        "CPU per run (mean): "
        + ", ".join(
            f"{s['scenario']} {'on' if s['sharing'] else 'off'} {s['cpu_s_mean']:.2f} s"
            for s in summary
        )
        + ".",
        "",
        "![summary](vision_summary.png)",
        "",
        (
            "Trajectories of one run per experiment (left: sharing off, right: on). Lines: true paths "
            "(dashed circle: start, solid: end); dots: each robot's estimate of the other, drawn in "
            "the colour of the robot estimated; crosses: the blind robot's estimate of the ball; red "
            "stars: collisions."
        ),
        "",
        "![trajectories](vision_trajectories.png)",
        "",
    ]
    if sensitivity:
        lines += ["## Sensitivity", ""]
        for what, command, sens_rows in sensitivity:
            lines += [
                f"{what}:",
                "",
                "```sh",
                command,
                "```",
                "",
                summary_table(summarize(sens_rows)),
                "",
            ]
    if detection is not None:
        lines += [
            "## Blob detection against ground truth",
            "",
            (
                "Rendered frames with the default noise (sigma 6 grey levels) and lighting (gain "
                "0.7-1.3), JPEG-encoded and decoded as the agent receives them, then `detect_blobs` and "
                "the agent's shape check (`detections_from_blobs`). Random camera poses; the object wholly "
                'in the image. "Blob found": any blob of the object\'s colour; "used": a detection '
                "the agent keeps; errors are those of the used detections (bearing in the camera "
                "frame, distance relative). Occlusion: an orange robot halfway hides part of the "
                "object; the agent drops a blob whose shape shows it is partly hidden, rather than "
                "trusting its too-small size."
            ),
            "",
            detection_table(detection),
            "",
        ]
        if timing:
            lines += [timing, ""]
    lines += [
        "## Model notes and limits",
        "",
        (
            "- The robots start side by side and parallel, as in §IV; each brain assumes that initial "
            "relative heading (0) and follows it with both robots' odometry (shared in the payload). "
            "Start headings are jittered by up to ±0.03 rad, so that assumption is off by up to "
            "0.06 rad."
        ),
        (
            "- Odometry is the commanded walk; the true motion has 5 % Gaussian errors per tick on "
            "translation and rotation plus a heading drift (0.01 rad/√s); being pushed in a "
            "collision is not in the odometry."
        ),
        (
            "- Gains of eq. 3-5 are not in the paper: k1 = 0.5 /s, obstacle k2 = 0.02 m³/s within "
            "0.5 m, teammate k2 = 0.02 m³/s within 0.6 m, speed 0.3 m/s; a detour force (not in the "
            "paper) gets a robot around an obstacle that stands between it and its goal."
        ),
        (
            "- The simulated images are clean compared with an Aibo's: pure colours, no blur, no "
            "shadows; so the size-based distances (a few % error) and the teammate estimates "
            "(a few cm) are better than the paper's robots would get."
        ),
        (
            "- A blob is used only if its shape is that of a whole object (within 15 %): a partly "
            "hidden ball or robot would look farther than it is. The price: about half of the "
            "slightly hidden objects (75-100 % visible) are dropped too, and a sliver of a mostly "
            "hidden ball is occasionally kept (a few pixels cannot tell a sliver from a far ball)."
        ),
        (
            "- The relative heading of two robots with one object in common comes from the "
            "parallel start and their odometry (see Sensitivity for what a wrong start does); "
            "two objects in common give it directly (Fig. 2), as the option "
            '`agent.relative_heading = "objects"` does.'
        ),
        "- Goals are decided once; the ball does not move.",
        "",
    ]
    readme = out / "README.md"
    readme.write_text("\n".join(lines))
    return readme


# -- command line -------------------------------------------------------------------------------


def main(args) -> int:
    """``swarmloc vision-experiment``: run, print the summary, optionally write CSV and report."""
    import json
    import sys

    if args.runs < 1:
        raise ConfigError(f"--runs: must be >= 1, got {args.runs}")
    names = list(EXPERIMENTS) if args.name == "all" else [args.name]
    modes = (True, False) if args.both else ((False,) if args.no_sharing else (True,))
    t0 = time.perf_counter()

    def progress(done, total):
        if done == total or done % max(1, total // 10) == 0:
            print(
                f"  {done}/{total} runs ({time.perf_counter() - t0:.0f} s)",
                file=sys.stderr,
                flush=True,
            )

    rows = run_experiments(
        names, args.runs, args.seed, modes, args.workers, tuple(args.set), progress=progress
    )
    summary = summarize(rows)
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(summary_table(summary))
    if args.csv:
        write_csv(rows, args.csv)
        print(f"rows: {args.csv}", file=sys.stderr)
    if args.report:
        import cv2

        cv2.setNumThreads(1)  # the frame timing below is per core
        sensitivity = []
        if args.name == "all":
            n_sens = min(args.runs, 10)
            for what, names_sens, overrides in SENSITIVITY:
                sens_rows = run_experiments(
                    list(names_sens),
                    n_sens,
                    args.seed,
                    (True,),
                    args.workers,
                    tuple(args.set) + overrides,
                )
                sets = " ".join(f"--set '{o}'" for o in (*args.set, *overrides))
                command = (
                    f"swarmloc vision-experiment {names_sens[0] if len(names_sens) == 1 else 'all'}"
                    f" --runs {n_sens} --seed {args.seed} {sets}"
                )
                sensitivity.append((what, command, sens_rows))
        detection = detection_accuracy(args.detection_n)
        render_ms, path_ms = frame_costs()
        timing = (
            f"Cost per frame (median CPU of 500 frames, 6 objects, this machine): render + detect "
            f"{render_ms:.2f} ms (target 5 ms); render + JPEG encode + decode + detect + the "
            f"agent's detections {path_ms:.2f} ms."
        )
        cli = f"swarmloc vision-experiment {args.name} --runs {args.runs} --seed {args.seed}"
        cli += " --both" if args.both else (" --no-sharing" if args.no_sharing else "")
        cli += "".join(f" --set {s}" for s in args.set)
        cli += f" --report {args.report}"
        readme = write_report(
            args.report,
            rows,
            detection,
            [cli, "python benchmarks/bench_vision_detection.py   # detection table and timing"],
            timing=timing,
            sensitivity=sensitivity,
        )
        print(f"report: {readme}", file=sys.stderr)
    return 0
