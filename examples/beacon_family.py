"""A robot family of one's own, whole, in one plugin file (docs/extending.md, "A new family").

Robots drive circles in a square room with four radio beacons at its corners. Each tick a robot
gets its odometry (the displacement it measured, with noise growing with the distance) and the
noisy range to every beacon within reach; it answers with its position estimate. Two localizers
stand in for "the baseline" and "the algorithm": dead reckoning (``agent.algorithm = "dr"``) and an
extended Kalman filter over the position (``"ekf"``: predict with the odometry, update with each
range, H = (x - b)^T / |x - b|).

Everything a family is, registered under one name (``swarmloc.families.Family``):

- its messages: a Sense and an Act, registered with the protocol codec
  (:func:`swarmloc.protocol.messages.register_message`), so the world-server and the agents
  validate them like the shipped ones;
- its scenario (``BeaconScenario``: a ``[world]`` and an ``[agent]`` table, strict like every
  scenario; ``n_ticks`` and ``label`` for the shells);
- its served world (``BeaconService``), the brain of an agent process (``BeaconBrain``), the frames
  the view and the recorder draw (``BeaconFrames``), and the experiment engine's hooks
  (``settings``, ``run_job``, ``columns``, ``row``). No report template: ``swarmloc report``
  writes the generic comparison page for its rows.

Run it (from the repository's root)::

    swarmloc --plugin examples/beacon_family.py check examples/beacon.toml
    swarmloc --plugin examples/beacon_family.py run examples/beacon.toml --record beacon.mcap
    swarmloc --plugin examples/beacon_family.py experiment examples/beacon-ekf-vs-dr.toml --out beacon.csv
    swarmloc --plugin examples/beacon_family.py report beacon.csv --family generic --out beacon-report
"""

from __future__ import annotations

import json
import math
import time
import types
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from swarmloc.config import ConfigError, from_dict, to_dict
from swarmloc.families import FAMILIES, Family
from swarmloc.protocol.messages import Field, WorldState, encode, register_message
from swarmloc.world.service import DrivenRobots

FAMILY = "beacon"
#: Where the world's random stream branches off the run seed (the brains draw nothing).
WORLD_STREAM = 0xBEAC


# -- messages ------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class BeaconRange:
    beacon_id: int
    range_m: float


@dataclass(frozen=True, slots=True)
class BeaconSense:
    tick: int
    robot_id: int
    odometry_m: tuple  # (dx, dy) measured this tick, world frame (the robots carry a compass)
    ranges: tuple  # BeaconRange of every beacon within reach


@dataclass(frozen=True, slots=True)
class BeaconAct:
    tick: int
    robot_id: int
    position_m: tuple  # (x, y) estimate


register_message(BeaconRange, "beacon.range", {
    "beacon_id": Field.int(0, 63), "range_m": Field.float(0.0, 100.0)})
register_message(BeaconSense, "beacon.sense", {
    "tick": Field.int(0, 2**53 - 1), "robot_id": Field.int(0, 65535),
    "odometry_m": Field.floats(2, -10.0, 10.0),
    "ranges": Field.tuple(Field.message(BeaconRange), 64)})
register_message(BeaconAct, "beacon.act", {
    "tick": Field.int(0, 2**53 - 1), "robot_id": Field.int(0, 65535),
    "position_m": Field.floats(2, -1e6, 1e6)})


# -- the scenario ----------------------------------------------------------------------------------


@dataclass(frozen=True)
class BeaconWorld:
    robots: int = 4
    seed: int = 0
    steps: int = 300
    dt_s: float = 0.1
    room_m: float = 5.0
    speed_mps: float = 0.3
    #: Odometry noise: standard deviation per metre driven, per axis (a random walk).
    odometry_std_per_m: float = 0.1
    range_std_m: float = 0.05
    max_range_m: float = 4.0

    def __post_init__(self) -> None:
        for key, ok in (("robots", 1 <= self.robots <= 64), ("steps", self.steps >= 1),
                        ("dt_s", self.dt_s > 0), ("room_m", self.room_m > 0), ("speed_mps", self.speed_mps >= 0),
                        ("odometry_std_per_m", self.odometry_std_per_m >= 0),
                        ("range_std_m", self.range_std_m >= 0), ("max_range_m", self.max_range_m > 0)):
            if not ok:
                raise ConfigError(f"world.{key}: out of range: {getattr(self, key)!r}")

    def beacons_m(self) -> np.ndarray:
        r = self.room_m
        return np.array([[0.0, 0.0], [r, 0.0], [0.0, r], [r, r]])

    def circle(self, robot: int) -> tuple[float, float, float]:
        """Robot ``robot``'s circle: radius, angular speed, starting phase."""
        radius = 0.5 + (0.45 * self.room_m - 0.5) * (robot + 0.5) / self.robots
        return radius, self.speed_mps / radius, 2.0 * math.pi * robot / self.robots

    def position(self, robot: int, step: int) -> np.ndarray:
        radius, omega, phase = self.circle(robot)
        a = phase + omega * step * self.dt_s
        return np.array([0.5 * self.room_m + radius * math.cos(a), 0.5 * self.room_m + radius * math.sin(a)])


@dataclass(frozen=True)
class BeaconAgent:
    algorithm: str = "ekf"

    def __post_init__(self) -> None:
        if self.algorithm not in ("dr", "ekf"):
            raise ConfigError(f"agent.algorithm: {self.algorithm!r} is not one of dr, ekf")


@dataclass(frozen=True)
class BeaconScenario:
    name: str = "beacon"
    description: str = ""
    family: str = FAMILY
    world: BeaconWorld = field(default_factory=BeaconWorld)
    agent: BeaconAgent = field(default_factory=BeaconAgent)

    @property
    def n_ticks(self) -> int:
        return self.world.steps

    @property
    def label(self) -> str:
        return self.agent.algorithm

    def to_dict(self) -> dict:
        return to_dict(self)

    @classmethod
    def from_dict(cls, data: dict) -> BeaconScenario:
        return from_dict(cls, data)


# -- the world (pure) and its service ----------------------------------------------------------


class BeaconService(DrivenRobots):
    """The served world: it drives the robots, makes their Senses, keeps their estimates."""

    family = FAMILY
    act_type = BeaconAct

    def __init__(self, scenario: BeaconScenario) -> None:
        w = self.config = scenario.world
        self.scenario = scenario
        self.n_robots, self.seed, self.tick_s = w.robots, w.seed, w.dt_s
        self.rng = np.random.default_rng([w.seed, WORLD_STREAM])
        self.beacons = w.beacons_m()
        self._alive = np.ones(w.robots, bool)
        self.world = types.SimpleNamespace(done=False)  # DrivenRobots reads world.done
        self.step_index = 0
        self.truth = np.array([[w.position(r, k) for r in range(w.robots)] for k in range(w.steps + 1)])
        self.estimates = np.full((w.steps, w.robots, 2), np.nan)
        self._estimate = self.truth[0].copy()

    @property
    def tick(self) -> int:
        return self.step_index

    def senses(self) -> list[tuple[int, bytes]]:
        w, k = self.config, self.step_index
        moved = self.truth[k + 1] - self.truth[k]
        # The same draws whichever robots are alive: a dead agent does not change the others' noise.
        odometry = moved + self.rng.normal(0.0, 1.0, moved.shape) * (
            w.odometry_std_per_m * np.sqrt(np.linalg.norm(moved, axis=1, keepdims=True)))
        distance = np.linalg.norm(self.truth[k][:, None, :] - self.beacons[None], axis=2)
        measured = distance + self.rng.normal(0.0, w.range_std_m, distance.shape)
        out = []
        for r in np.flatnonzero(self._alive).tolist():
            ranges = tuple(BeaconRange(b, float(max(measured[r, b], 0.0)))
                           for b in range(len(self.beacons)) if distance[r, b] <= w.max_range_m)
            out.append((r, encode(BeaconSense(k, r, tuple(odometry[r].tolist()), ranges))))
        return out

    def step(self, acts: list[BeaconAct | None]) -> None:
        for r, act in enumerate(acts):
            if act is not None:
                self._estimate[r] = act.position_m
        self.estimates[self.step_index] = self._estimate
        self.step_index += 1
        self.world.done = self.step_index >= self.config.steps

    def state(self) -> WorldState:
        poses = tuple((float(x), float(y), 0.0) for x, y in self.truth[self.step_index].tolist())
        return WorldState(tick=self.step_index, time_s=self.step_index * self.tick_s, poses=poses,
                          alive=tuple(self._alive.tolist()), round_trips=0)

    def summary(self) -> dict:
        k = self.step_index
        if k == 0:
            return {"steps": 0}
        # estimates[k] answers the Sense of tick k, taken at truth[k]
        error = np.linalg.norm(self.estimates[:k] - self.truth[:k], axis=2)
        return {"steps": k, "mean_error_m": round(float(error.mean()), 6),
                "final_error_m": round(float(error[-1].mean()), 6),
                "worst_final_error_m": round(float(error[-1].max()), 6),
                "final_position_error_m": [round(float(e), 6) for e in error[-1]]}


# -- the brain of an agent process (pure) ------------------------------------------------------------


class BeaconBrain:
    """Dead reckoning or a position EKF, from the start the scenario gives every robot."""

    sense_type = BeaconSense

    def __init__(self, robot_id: int, scenario: BeaconScenario) -> None:
        w = scenario.world
        self.robot_id, self.algorithm = robot_id, scenario.agent.algorithm
        self.x = w.position(robot_id, 0)
        self.P = np.eye(2) * 1e-4
        self.q_per_m = w.odometry_std_per_m ** 2
        self.r = max(w.range_std_m, 1e-3) ** 2
        self.beacons = w.beacons_m()

    @classmethod
    def from_welcome(cls, welcome, scenario: BeaconScenario) -> BeaconBrain:
        return cls(welcome.robot_id, scenario)

    def act(self, sense: BeaconSense, errors) -> BeaconAct:
        odometry = np.asarray(sense.odometry_m)
        self.x = self.x + odometry
        self.P = self.P + np.eye(2) * self.q_per_m * float(np.linalg.norm(odometry))
        if self.algorithm == "ekf":
            for reading in sense.ranges:
                delta = self.x - self.beacons[reading.beacon_id]
                predicted = float(np.linalg.norm(delta))
                if predicted < 1e-6:
                    continue
                H = delta / predicted
                S = float(H @ self.P @ H) + self.r
                K = self.P @ H / S
                self.x = self.x + K * (reading.range_m - predicted)
                self.P = (np.eye(2) - np.outer(K, H)) @ self.P
        return BeaconAct(sense.tick, self.robot_id, (float(self.x[0]), float(self.x[1])))


# -- what the view and the recorder draw ---------------------------------------------------------------


def frames(service: BeaconService):
    from swarmloc.deploy.observe.frames import FrameSource, _mean_error

    class BeaconFrames(FrameSource):
        def scene(self) -> dict:
            r = service.config.room_m
            return {"family": FAMILY, "bounds_m": [0.0, 0.0, r, r],
                    "walls": [[0.0, 0.0, r, 0.0], [r, 0.0, r, r], [r, r, 0.0, r], [0.0, r, 0.0, 0.0]],
                    "discs": [], "landmarks": [{"id": i, "x": float(x), "y": float(y)}
                                               for i, (x, y) in enumerate(service.beacons.tolist())],
                    "robot_radius_m": 0.1, "n_robots": service.n_robots, "tick_s": service.tick_s,
                    "n_ticks": service.config.steps}

        def _drawn(self, state: dict) -> dict:
            truth = state["poses"]
            estimates = [None if a is None else [*a.position_m, 0.0] for a in self.last_acts]
            return {"truth": truth, "estimates": estimates, "beliefs": [[] for _ in truth], "links": [],
                    "metrics": {"round_trips": 0, "position_error_m": _mean_error(truth, estimates)}}

    return BeaconFrames(service)


# -- the experiment engine's hooks -------------------------------------------------------------------


SEED_KEY = "world.seed"
LEAD_COLUMNS = ("experiment", "group", "setting", "scenario", "algorithm", "robots", "steps", "seed",
                "replication")
METRIC_COLUMNS = ("mean_error_m", "final_error_m", "worst_final_error_m", "cpu_s", "wall_s", "config_hash")


def scenario_path(name: str) -> str:
    """A spec's scenario: a path as given, else beside this file (``beacon.toml``)."""
    return name if Path(name).exists() else str(Path(__file__).with_name(name))


def load(name: str, overrides=()):
    from swarmloc.deploy.scenario import load_any

    loaded = load_any(scenario_path(name), overrides=list(overrides))
    if loaded.family != FAMILY:
        raise ConfigError(f"scenario {name!r} is a {loaded.family} scenario, not a {FAMILY} one")
    return loaded


def settings(spec) -> list:
    import hashlib

    from swarmloc.deploy.lab.experiment import Setting, setting_grid

    out = []
    for g in spec.group:
        for name, sid, grid, overrides in setting_grid(g):  # the group's set, then each combination
            try:
                if g.duration_s is not None:
                    dt_s = load(name, overrides).scenario.world.dt_s
                    overrides.append(f"world.steps={max(1, round(g.duration_s / dt_s))}")
                s = load(name, overrides).scenario
            except ConfigError as exc:
                raise ConfigError(f"experiment '{spec.name}', setting '{sid}': {exc}") from None
            plain = s.to_dict()
            plain["world"].pop("seed")
            digest = hashlib.sha256(json.dumps(plain, sort_keys=True).encode()).hexdigest()[:12]
            out.append(Setting(sid, g.name, name, tuple(overrides), grid, digest, s.world.robots,
                               s.world.steps * s.world.dt_s, s.agent.algorithm,
                               cost=s.world.robots * s.world.steps))
    return out


def run_job(job) -> dict:
    from swarmloc.families import run_in_process

    t0, c0 = time.perf_counter(), time.process_time()
    loaded = load(job.scenario, job.overrides)
    summary = run_in_process(loaded)
    return {**summary, "algorithm": loaded.scenario.agent.algorithm, "robots": loaded.robots,
            "cpu_s": round(time.process_time() - c0, 3), "wall_s": round(time.perf_counter() - t0, 3)}


def columns(spec) -> list[str]:
    return [*LEAD_COLUMNS, *spec.grid_keys(), *METRIC_COLUMNS]


def row(spec, job, out: dict) -> list:
    values = {**out, "experiment": spec.name, "group": job.group, "setting": job.setting,
              "scenario": job.scenario, "seed": job.seed, "replication": job.replication,
              "config_hash": job.config_hash}
    grid = dict(job.grid)
    return [*(values[c] for c in LEAD_COLUMNS), *(grid.get(k) for k in spec.grid_keys()),
            *(values[c] for c in METRIC_COLUMNS)]


EXPERIMENT = types.SimpleNamespace(SEED_KEY=SEED_KEY, settings=settings, run_job=run_job,
                                   columns=columns, row=row)

FAMILIES.register(FAMILY, Family(
    scenario=BeaconScenario, world=BeaconService, brain=BeaconBrain.from_welcome,
    flags={"robots": "world.robots", "seed": "world.seed", "algorithm": "agent.algorithm"},
    frames=frames, experiment=EXPERIMENT))
