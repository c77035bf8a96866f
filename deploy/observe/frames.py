"""What an observer draws: one family-neutral *frame* per tick and one static *scene* per run.

A frame (schema ``swarmloc.Frame``, docs/recording.md) is plain JSON-friendly data::

    {"tick", "time_s", "family",
     "state":     {"tick", "time_s", "poses", "alive", "round_trips"}   # the world's WorldState, exact
     "truth":     [[x, y, theta], ...]            # where each robot really is (replay: Vicon)
     "estimates": [[x, y, theta] | None, ...]     # each robot's belief of its own pose, world frame
     "beliefs":   [[{"label", "x", "y", "radius_m"}, ...], ...]   # what else it believes, world frame
     "links":     [[from, to], ...]               # who heard (or saw) whom this tick
     "metrics":   {"round_trips", "position_error_m", ...},
     "samples":   [[[x, y, theta], ...], ...]}    # optional: each robot's population (--particles)

and a scene (``swarmloc.Scene``) holds what does not move: the bounds, the walls, the discs (nest,
prey, ball, obstacles), the landmarks. One :class:`FrameSource` per robot family turns a served
world (world/service.py) and the Acts of the tick into a frame; :func:`frame_source` picks it by the
world's ``family``. The batch engine makes its frames with :class:`BatchForagingSource`, from the
brains' arrays instead of Acts, through the same helpers.

Beliefs that a robot holds in its own body frame (an e-puck's goals, a vision robot's teammate and
ball) are drawn from where the robot really is: the picture shows what the robot would find if it
went where it believes the thing is. Floats are Python floats: ``json`` writes them with ``repr``,
which reads back bit for bit.
"""

from __future__ import annotations

import math
from typing import Any, ClassVar

import msgpack
import numpy as np

#: Largest circle drawn for a belief's uncertainty (an e-puck's p grows without bound when lost).
MAX_BELIEF_RADIUS_M = 5.0


def _state_dict(state) -> dict:
    """A WorldState as plain data, its floats untouched."""
    return {"tick": state.tick, "time_s": state.time_s, "poses": [list(p) for p in state.poses],
            "alive": list(state.alive), "round_trips": state.round_trips}


def _from_body(pose, forward_m: float, left_m: float) -> tuple[float, float]:
    x, y, th = pose
    c, s = math.cos(th), math.sin(th)
    return x + c * forward_m - s * left_m, y + s * forward_m + c * left_m


def _compose(start, est) -> list[float]:
    """``start ⊕ est``: a pose in a frame whose origin is ``start``, in the world frame."""
    x, y = _from_body(start, est[0], est[1])
    return [x, y, start[2] + est[2]]


def _mean_error(truth: list, estimates: list) -> float | None:
    errs = [math.hypot(e[0] - t[0], e[1] - t[1]) for t, e in zip(truth, estimates)
            if e is not None and t is not None and math.isfinite(e[0]) and math.isfinite(t[0])]
    return sum(errs) / len(errs) if errs else None


def epuck_beliefs(truth: list, known, distance, angle, p) -> list[list[dict]]:
    """An e-puck's goal estimates (nest, prey) as world points: each is in the robot's body frame
    (distance, angle, inverse confidence p, as its range-and-bearing payload carries them)."""
    out = []
    for i, pose in enumerate(truth):
        marks = []
        for g, label in ((0, "nest"), (1, "prey")):
            if known[i][g]:
                a = pose[2] + angle[i][g]
                marks.append({"label": label, "x": pose[0] + distance[i][g] * math.cos(a),
                              "y": pose[1] + distance[i][g] * math.sin(a),
                              "radius_m": min(float(p[i][g]), MAX_BELIEF_RADIUS_M)})
        out.append(marks)
    return out


def epuck_scene(config) -> dict:
    a = config.arena
    return {
        "family": "foraging", "bounds_m": [0.0, 0.0, a.width_m, a.height_m],
        "walls": [[0.0, 0.0, a.width_m, 0.0], [a.width_m, 0.0, a.width_m, a.height_m],
                  [a.width_m, a.height_m, 0.0, a.height_m], [0.0, a.height_m, 0.0, 0.0]],
        "discs": [{"label": "nest", "x": a.nest_centre_m[0], "y": a.nest_centre_m[1],
                   "radius_m": a.nest_radius_m, "colour": "#222222"},
                  {"label": "prey", "x": a.prey_centre_m[0], "y": a.prey_centre_m[1],
                   "radius_m": a.prey_radius_m, "colour": "#9a9a9a"}],
        "landmarks": [], "robot_radius_m": config.body.body_radius_m, "n_robots": config.robots,
        "tick_s": config.tick_s, "n_ticks": config.n_ticks,
    }


class FrameSource:
    """Frames of one served world. :meth:`note` is called every tick with that tick's Acts (cheap:
    it keeps the latest Act per robot); :meth:`frame` builds the frame of the world's current tick."""

    def __init__(self, service) -> None:
        self.service = service
        self.last_acts: list[Any] = [None] * service.n_robots

    def note(self, acts: list) -> None:
        last = self.last_acts
        for i, act in enumerate(acts):
            if act is not None:
                last[i] = act

    def scene(self) -> dict:
        raise NotImplementedError

    def frame(self) -> dict:
        state = self.service.state()
        out = {"tick": state.tick, "time_s": state.time_s, "family": self.service.family,
               "state": _state_dict(state)}
        out.update(self._drawn(out["state"]))
        return out

    def _drawn(self, state: dict) -> dict:
        raise NotImplementedError


class ForagingSource(FrameSource):
    """E-pucks: the dead-reckoned pose (odometric frame, origin at the robot's start) composed with
    the start pose; the goals from each robot's last payload; the messages that crossed."""

    def __init__(self, service) -> None:
        super().__init__(service)
        self.start = service.world.pose.tolist()

    def scene(self) -> dict:
        return epuck_scene(self.service.world.config)

    def _drawn(self, state: dict) -> dict:
        from swarmloc.world.epuck import kernels

        truth = state["poses"]
        n = len(truth)
        estimates: list = [None] * n
        known, distance, angle, p = [[False, False]] * n, [[0, 0]] * n, [[0, 0]] * n, [[0, 0]] * n
        for i, act in enumerate(self.last_acts):
            if act is None:
                continue
            estimates[i] = _compose(self.start[i], act.pose_estimate)
            if act.payload is not None:
                try:
                    body = msgpack.unpackb(act.payload)
                    flags = int(body[0])
                    known[i] = [bool(flags & 1), bool(flags & 2)]
                    distance[i], angle[i], p[i] = [body[1], body[4]], [body[2], body[5]], [body[3], body[6]]
                except (ValueError, TypeError, IndexError, msgpack.UnpackException):
                    pass  # the world already counted a payload it could not read
        world = self.service.world
        k = int(world._counts[kernels.C_CROSSED])
        crossed = world._crossed_ij[:, :k].T.tolist()
        return {"truth": truth, "estimates": estimates,
                "beliefs": epuck_beliefs(truth, known, distance, angle, p), "links": crossed,
                "metrics": {"round_trips": state["round_trips"],
                            "position_error_m": _mean_error(truth, estimates)}}


class BatchForagingSource:
    """The batch engine's e-pucks: the same frame from the world and the swarm's brain arrays."""

    def __init__(self, world, brain) -> None:
        self.world, self.brain = world, brain
        self.start = world.pose.tolist()

    def scene(self) -> dict:
        return epuck_scene(self.world.config)

    def frame(self, estimates_odometric: np.ndarray | None, goals: tuple | None) -> dict:
        from swarmloc.world.epuck import kernels

        w = self.world
        poses = w.pose.tolist()
        state = {"tick": w.tick, "time_s": w.tick * w.config.tick_s, "poses": poses,
                 "alive": w.alive.tolist(), "round_trips": int(w.metrics.round_trips.sum())}
        n = len(poses)
        estimates = ([None] * n if estimates_odometric is None else
                     [_compose(s, e) for s, e in zip(self.start, estimates_odometric.tolist())])
        if goals is None:
            beliefs = [[] for _ in range(n)]
        else:
            beliefs = epuck_beliefs(poses, *(g.tolist() for g in goals))
        k = int(w._counts[kernels.C_CROSSED])
        return {"tick": state["tick"], "time_s": state["time_s"], "family": "foraging", "state": state,
                "truth": poses, "estimates": estimates, "beliefs": beliefs,
                "links": w._crossed_ij[:, :k].T.tolist(),
                "metrics": {"round_trips": state["round_trips"],
                            "position_error_m": _mean_error(poses, estimates)}}


def brain_goals(brain) -> tuple:
    """(known, distance, angle, p) of every robot's goals in its body frame, from its brain
    arrays: what its payload would carry (before the float32 rounding of the wire)."""
    pose, goal = brain.pose, brain.goal_xy  # (N, 3), (N, 2 goals, 2)
    d = goal - pose[:, None, :2]
    distance = np.hypot(d[..., 0], d[..., 1])
    angle = np.arctan2(d[..., 1], d[..., 0]) - pose[:, None, 2]
    angle = (angle + np.pi) % (2 * np.pi) - np.pi
    return brain.known, distance, angle, brain.goal_p_m


class LaserSource(FrameSource):
    """Laser robots: each one's best pose estimate (map frame); who saw whom and the radio; and,
    when the world asked for them (``--particles``), the poses of each one's population."""

    def scene(self) -> dict:
        w = self.service.world
        cfg = self.service.scenario.world
        return {"family": "laser", "bounds_m": [float(b) for b in w.map.bounds_m],
                "walls": w.map.segments_m.tolist(), "discs": [], "landmarks": [],
                "robot_radius_m": 0.2, "n_robots": self.service.n_robots, "tick_s": self.service.tick_s,
                "n_ticks": cfg.steps}

    def _drawn(self, state: dict) -> dict:
        truth = state["poses"]
        estimates = [None if a is None else list(a.pose_estimate) for a in self.last_acts]
        links = []
        if not self.service.done:
            for r, o in enumerate(self.service.world.observe()):
                links += [[s.robot_id, r] for s in o.sightings]
                links += [[m.sender_id, r] for m in o.received]
        out = {"truth": truth, "estimates": estimates, "beliefs": [[] for _ in truth], "links": links,
               "metrics": {"round_trips": 0, "position_error_m": _mean_error(truth, estimates)}}
        # Populations, when the world asked the agents for them (--particles): poses in the map frame.
        samples = [[list(p) for p in a.samples] if a is not None else [] for a in self.last_acts]
        if any(samples):
            out["samples"] = samples
        return out


class VisionSource(FrameSource):
    """Vision robots: their estimates of the teammates and the ball (body frame) from their Acts."""

    COLOURS: ClassVar[dict[str, str]] = {"ball": "#e75480", "obstacle": "#f28c28", "rival": "#f28c28", "beacon": "#3060d0"}

    def scene(self) -> dict:
        from swarmloc.world.vision.camera import OBJECT_KINDS

        s = self.service
        objects = s.layout.objects
        xs = [o.x_m for o in objects] + s.world.pose[:, 0].tolist()
        ys = [o.y_m for o in objects] + s.world.pose[:, 1].tolist()
        margin = 0.5
        return {"family": "vision",
                "bounds_m": [min(xs) - margin, min(ys) - margin, max(xs) + margin, max(ys) + margin],
                "walls": [], "landmarks": [],
                "discs": [{"label": o.kind, "x": o.x_m, "y": o.y_m, "radius_m": OBJECT_KINDS[o.kind].radius_m,
                           "colour": self.COLOURS.get(o.kind, "#888888")} for o in objects],
                "robot_radius_m": s.world.config.body_radius_m, "n_robots": s.n_robots,
                "tick_s": s.tick_s, "n_ticks": s.n_ticks}

    def _drawn(self, state: dict) -> dict:
        truth = state["poses"]
        beliefs = []
        for i, act in enumerate(self.last_acts):
            marks = []
            est = act.estimates if act is not None else {}
            try:
                for j, xy in (est.get("teammates") or {}).items():
                    x, y = _from_body(truth[i], float(xy[0]), float(xy[1]))
                    marks.append({"label": f"robot {int(j)}", "x": x, "y": y, "radius_m": 0.0})
                ball = est.get("ball")
                if ball is not None:
                    x, y = _from_body(truth[i], float(ball[0]), float(ball[1]))
                    marks.append({"label": "ball", "x": x, "y": y, "radius_m": 0.0})
            except (TypeError, ValueError, IndexError, AttributeError):
                marks = []  # malformed estimates: the world counts them (bad_estimates)
            beliefs.append(marks)
        return {"truth": truth, "estimates": [None] * len(truth), "beliefs": beliefs, "links": [],
                "metrics": {"round_trips": 0, "position_error_m": None}}


class ReplaySource(FrameSource):
    """MRCLAM replays: the world's state holds the estimates (no truth in the loop); the frame
    adds the Vicon ground truth for the eye, and who measured whom."""

    def __init__(self, service) -> None:
        super().__init__(service)
        self._truth = service.world.ground_truth()  # (n_ticks, N, 3), NaN where unknown

    def scene(self) -> dict:
        s = self.service
        lm = s.dataset.landmarks
        xy = lm.xy_m
        finite = self._truth[np.isfinite(self._truth[..., 0])]
        xs = np.concatenate([xy[:, 0], finite[:, 0]])
        ys = np.concatenate([xy[:, 1], finite[:, 1]])
        margin = 0.5
        return {"family": "replay",
                "bounds_m": [float(xs.min()) - margin, float(ys.min()) - margin,
                             float(xs.max()) + margin, float(ys.max()) + margin],
                "walls": [], "discs": [],
                "landmarks": [{"id": int(i), "x": float(x), "y": float(y)}
                              for i, (x, y) in zip(lm.ids.tolist(), xy.tolist())],
                "robot_radius_m": 0.2, "n_robots": s.n_robots, "tick_s": s.tick_s,
                "n_ticks": s.world.n_ticks}

    def _drawn(self, state: dict) -> dict:
        k = state["tick"]
        row = self._truth[max(k - 1, 0)] if len(self._truth) else np.full((len(state["poses"]), 3), np.nan)
        truth = [None if not np.isfinite(p[0]) else p for p in row.tolist()]
        estimates = state["poses"]
        links = []
        if not self.service.done:
            ids = list(self.service.robot_ids)
            for r, o in enumerate(self.service.world.observe()):
                links += [[ids.index(s), r] for s in o.robot_ids.tolist() if s in ids]
        return {"truth": truth, "estimates": estimates, "beliefs": [[] for _ in estimates],
                "links": links, "metrics": {"round_trips": 0,
                                            "position_error_m": _mean_error(truth, estimates)}}


def frame_source(service) -> FrameSource:
    """The frame source of a served world: its family's ``Family.frames`` (``swarmloc.families``);
    ValueError if the family has none (it can run, but not be viewed or recorded)."""
    from swarmloc.families import FAMILIES
    from swarmloc.registry import resolve

    frames = FAMILIES.get(service.family).frames
    if frames is None:
        raise ValueError(f"family {service.family!r} has no frame source (Family.frames): "
                         "its runs cannot be viewed or recorded")
    return resolve(frames)(service)
