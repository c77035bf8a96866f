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
reach_margin_m``), the error of each robot's estimate of its teammates (all pairs, and robots
0-1 alone: ``pair01_err_median_m``) and of the ball, the fraction of robot-ticks whose teammate
direction was resolved (perception mode), and the angle at the ball between robots 0 and 1 at
the end (``ball_angle_end_deg``; §IV-A: "they catch the ball from opposite sides").

Beyond §IV (issue #49): ``setup.robots`` puts 2-8 robots in the row (experiments 1 and 2; §II's
"the larger the number of robots with common perception, the more precise localization", tested
by the scenario ``vision-count``); ``setup.start_heading_error_rad`` turns robot 1's true start
heading, i.e. the error of the parallel-start prior, an addition beyond the paper that only
``agent.relative_heading = "odometry"`` or ``"objects"`` uses.

``swarmloc experiment vision`` (the vision family's hooks,
:mod:`swarmloc.deploy.lab.vision.experiment`) repeats runs over seeds and both sharing modes;
:func:`~swarmloc.deploy.lab.vision.report.write_report` writes ``docs/vision/README.md`` with the
table next to the paper's claims, figures, and the detection accuracy of
:func:`~swarmloc.deploy.lab.vision.experiment.detection_accuracy` (also printed by
``benchmarks/bench_vision_detection.py``). Command line: ``swarmloc experiment vision`` then
``swarmloc report results/vision.csv --out docs/vision``.
"""

from __future__ import annotations

import dataclasses
import math
import time
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

import numpy as np

from swarmloc.agents.vision.brain import (
    VisionBrain,
)
from swarmloc.config import (
    ConfigError,
    apply_overrides,
    did_you_mean,
    from_dict,
    load_toml,
)
from swarmloc.protocol.keys import Keys
from swarmloc.world.vision.camera import OBJECT_KINDS

# The scenario (SetupConfig, VisionScenario), its layouts and the world of a run (world_config)
# live in world/vision/scenario.py, below deploy/ (issue 48: the vision agent and world-server
# built from this module); re-exported here.
from swarmloc.world.vision.scenario import (  # noqa: F401 -- re-exported
    AGENT_STREAM,
    EXPERIMENTS,
    FAULT_STREAM,
    LAYOUT_STREAM,
    TEAM,
    Layout,
    SetupConfig,
    VisionScenario,
    layout,
    world_config,
)
from swarmloc.world.vision.world import (
    STOP,
    VisionWorld,
)


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
            hint = did_you_mean(str(name_or_path), scenario_names(), 0.4)
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
    resolved_ticks: list[bool | None] = []
    pair01_err: list[float] = []
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
                if i + j == 1:  # robots 0 and 1, whatever the team's size
                    pair01_err.append(teammate_err[i][-1])
            ticks_known_teammate[i] += bool(est.teammates)
            resolved_ticks += [brain.teammate_resolved(j) for j in est.teammates]
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
    # The angle at the ball between robots 0 and 1 at the end (§IV-A: "they catch the ball
    # from opposite sides"): 180 deg opposite, 0 deg one behind the other.
    to_0 = world.pose[0, :2] - np.asarray(ball_xy)
    to_1 = world.pose[1, :2] - np.asarray(ball_xy) if n > 1 else to_0
    ball_angle_end_deg = round(math.degrees(abs(math.atan2(
        to_0[0] * to_1[1] - to_0[1] * to_1[0], float(to_0 @ to_1)))), 1)
    resolved = [r for r in resolved_ticks if r is not None]

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
        "robots": n,
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
        "pair01_err_median_m": _median(pair01_err),
        "teammate_known_fraction": round(float(ticks_known_teammate.sum()) / (n * ticks), 4),
        "ball_err_median_m": _median(all_ball),
        "ball_known_fraction": round(float(ticks_known_ball.sum()) / (n * ticks), 4),
        "blind_ball_first_s": blind_first_ball_s,
        "ball_angle_end_deg": ball_angle_end_deg,
        "heading_resolved_fraction": (
            round(sum(resolved) / len(resolved), 4) if resolved else None
        ),
        "blind_relayed_ball_err_median_m": _median(relayed_err),
        "bad_images": bad_images,
        "bad_payloads": bad_payloads,
        "payloads": channel.published,
        "sim_s": round(world.time_s, 2),
        "cpu_s": round(time.process_time() - t_cpu, 3),
    }
    return metrics, rec
