"""The vision world of seed 004 served to agent processes (one vision brain per process).

A :class:`~swarmloc.world.service.ServedWorld` around :class:`~swarmloc.world.vision.world.VisionWorld`:
each frame it sends every live robot a :class:`VisionSense` (its encoded camera image, odometry and
head pan), takes each :class:`VisionAct` (walking command, head command, and the agent's
estimates), scores the estimates against ground truth, and steps the world. Detections travel
between agents directly on the team keys (``swarmloc/<run>/team/<team>/blobs/<id>``), not through
the world. The run's layout comes from the scenario and its seed exactly as the in-process runner
(:func:`swarmloc.deploy.lab.vision.runner.run_vision`) draws it, and the figures are the same ones.

An Act whose estimates are malformed is counted (``bad_estimates``) and its command still applies.
"""

from __future__ import annotations

import numpy as np

from swarmloc.protocol.messages import VisionAct, VisionSense, WorldState, encode

#: Once every robot believes it is at its goal for this long, the run ends (as in-process).
SETTLED_S = 1.0


def _xy(value) -> np.ndarray | None:
    if value is None:
        return None
    xy = np.asarray(value, dtype=float)
    if xy.shape != (2,) or not np.isfinite(xy).all():
        raise ValueError(f"expected [x_m, y_m], got {value!r}")
    return xy


class VisionService:
    family = "vision"
    act_type = VisionAct

    def __init__(self, scenario) -> None:
        from swarmloc.world.vision.camera import OBJECT_KINDS
        from swarmloc.world.vision.scenario import world_config
        from swarmloc.world.vision.world import STOP, VisionWorld

        self.scenario = scenario
        self.seed = scenario.world.seed
        wcfg, lay = world_config(scenario, self.seed)
        self.layout = lay
        self.world = VisionWorld(wcfg)
        n = self.world.n_robots
        self.n_robots = n
        self.tick_s = wcfg.tick_s
        self.n_ticks = round(scenario.setup.duration_s / wcfg.tick_s)
        self._tick = 0
        self._settled_since: float | None = None
        self._alive = np.ones(n, bool)
        self._commands = [STOP] * n
        self._ball_xy = next(np.array([o.x_m, o.y_m]) for o in lay.objects if o.kind == "ball")
        self._goal_xy = {o.kind: np.array([o.x_m, o.y_m]) for o in lay.objects}
        body_r = wcfg.body_radius_m
        self._reach_m = [body_r + OBJECT_KINDS[g].radius_m + scenario.setup.reach_margin_m
                         for g in lay.goals]
        self.reach_time: list[float | None] = [None] * n
        self.goals: list[str | None] = [None] * n
        self.reached = [False] * n
        self.teammate_err: list[float] = []
        self.ball_err: list[float] = []
        self.relayed_err: list[float] = []
        self.known_teammate = np.zeros(n, int)
        self.known_ball = np.zeros(n, int)
        self.blind_first_ball_s: float | None = None
        self.bad_estimates = 0

    @property
    def tick(self) -> int:
        return self._tick

    @property
    def done(self) -> bool:
        return self._tick >= self.n_ticks or (
            self._settled_since is not None and self.world.time_s - self._settled_since >= SETTLED_S
        )

    @property
    def alive(self) -> np.ndarray:
        return self._alive

    def kill(self, robot: int) -> None:
        from swarmloc.world.vision.world import STOP

        self._alive[robot] = False
        self._commands[robot] = STOP  # a robot whose agent died stands still

    def revive(self, robot: int) -> None:
        self._alive[robot] = True

    def senses(self) -> list[tuple[int, bytes]]:
        out = []
        for obs in self.world.observe():
            if self._alive[obs.robot_id]:
                sense = VisionSense(
                    tick=self._tick, robot_id=obs.robot_id, time_s=float(obs.time_s),
                    image=bytes(obs.image), odometry_pose=tuple(map(float, obs.odometry_pose)),
                    head_pan_rad=float(obs.head_pan_rad),
                )
                out.append((obs.robot_id, encode(sense)))
        return out

    def _score(self, i: int, est: dict) -> None:
        world = self.world
        teammates = est.get("teammates") or {}
        if not isinstance(teammates, dict):
            raise TypeError("teammates: expected a dict of robot id -> [x_m, y_m]")
        for j, xy in teammates.items():
            j = int(j)
            if not 0 <= j < self.n_robots:
                raise ValueError(f"teammates: {j} is not a robot of this run")
            truth = world.relative_position(i, world.pose[j, :2])
            self.teammate_err.append(float(np.hypot(*(_xy(xy) - truth))))
        self.known_teammate[i] += bool(teammates)
        ball = _xy(est.get("ball"))
        if ball is not None:
            err = float(np.hypot(*(ball - world.relative_position(i, self._ball_xy))))
            self.ball_err.append(err)
            self.known_ball[i] += 1
            if i == self.layout.blind and est.get("ball_source") == "teammate":
                self.relayed_err.append(err)
            if i == self.layout.blind and self.blind_first_ball_s is None:
                self.blind_first_ball_s = round(world.time_s, 3)
        goal = est.get("goal")
        self.goals[i] = goal if isinstance(goal, str) else None
        self.reached[i] = est.get("reached") is True

    def _note_arrivals(self, time_s: float) -> None:
        """Record ``time_s`` for every robot now within reach of its goal for the first time."""
        pose = self.world.pose
        for i, goal in enumerate(self.layout.goals):
            if self.reach_time[i] is None and np.hypot(*(pose[i, :2] - self._goal_xy[goal])) <= self._reach_m[i]:
                self.reach_time[i] = time_s

    def step(self, acts: list[VisionAct | None]) -> None:
        from swarmloc.world.vision.world import VisionCommand

        world = self.world
        for i, act in enumerate(acts):
            if act is None:
                continue
            self._commands[i] = VisionCommand(*act.command)
            try:
                self._score(i, act.estimates)
            except (ValueError, TypeError):
                self.bad_estimates += 1
        self._note_arrivals(round(world.time_s, 3))
        world.step(self._commands)
        self._tick += 1
        if all(self.reached):
            if self._settled_since is None:
                self._settled_since = world.time_s
        else:
            self._settled_since = None
        if self.done:
            self._note_arrivals(world.time_s)  # the last move

    def state(self) -> WorldState:
        poses = self.world.pose
        return WorldState(
            tick=self._tick, time_s=float(self.world.time_s),
            poses=tuple(tuple(p) for p in poses.tolist()), alive=tuple(self._alive.tolist()),
            round_trips=0,
        )

    def summary(self) -> dict:
        def median(values):
            return round(float(np.median(values)), 4) if values else None

        n, ticks = self.n_robots, max(self._tick, 1)
        lay = self.layout
        return {
            "experiment": self.scenario.setup.experiment,
            "sharing": self.scenario.agent.sharing,
            "seed": self.seed,
            "collisions": self.world.robot_collisions,
            "obstacle_collisions": self.world.obstacle_collisions,
            "goals_correct": all(g == t for g, t in zip(self.goals, lay.goals)),
            "goals": "/".join(str(g) for g in self.goals),
            "true_goals": "/".join(lay.goals),
            "all_reached": all(t is not None for t in self.reach_time),
            "reach_s": self.reach_time,
            "teammate_err_median_m": median(self.teammate_err),
            "teammate_known_fraction": round(float(self.known_teammate.sum()) / (n * ticks), 4),
            "ball_err_median_m": median(self.ball_err),
            "blind_ball_first_s": self.blind_first_ball_s,
            "blind_relayed_ball_err_median_m": median(self.relayed_err),
            "bad_estimates": self.bad_estimates,
            "sim_s": round(float(self.world.time_s), 2),
        }
