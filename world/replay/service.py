"""A recorded data set (MRCLAM) served to agent processes: the replay world behind the one
world-server shell (issue 7).

:class:`ReplayScenario` names the data set folder and the localizer configuration
(:class:`~swarmloc.deploy.lab.replay.mrclam.ReplayConfig`); :class:`ReplayService` feeds every live robot a
:class:`ReplaySense` per tick (recorded odometry, landmark and robot measurements, teammates'
broadcasts of the previous tick), takes its :class:`EstimateAct` and scores the estimates against
the Vicon ground truth with the in-process evaluation's :func:`~swarmloc.deploy.lab.replay.mrclam.score`.
Agents read the data set's landmark map and their calibration from the same folder (the map of a
replay is part of the scenario), so a replay over processes runs where the folder is readable.
Robot ``i`` of the run (its keys) is the data set's ``robot_ids[i]``.
"""

from __future__ import annotations

import dataclasses
import functools
import math
from dataclasses import dataclass, field

import numpy as np

from swarmloc.config import ConfigError
from swarmloc.protocol.messages import (
    EstimateAct,
    LandmarkMsg,
    RadioMsg,
    ReplaySense,
    WorldState,
    encode,
)
from swarmloc.world.service import DrivenRobots


@dataclass(frozen=True)
class ReplayScenario:
    """A replay of an MRCLAM data set with one localizer configuration."""

    name: str = "mrclam"
    description: str = ""
    family: str = "replay"
    dataset: str = "../shared/data/mrclam/MRCLAM_Dataset6"
    algorithm: str = "ekf"
    cooperative: bool = True
    seed: int = 0
    dt_s: float = 0.02
    duration_s: float | None = None
    calibration: str = "self"
    calibration_s: float | None = 120.0
    start: str = "known"
    kidnap_s: float | None = None
    kidnap_robot: int | None = None
    params: dict = field(default_factory=dict)
    #: CoLo-AT's setting (issue 46): ``heading = "truth"``, ``landmark_robots = [1, 2, 3]``,
    #: ``links = {"1" = [2], "2" = [3]}``, ``initial_std = [0.2, 0.2, 0.0]``.
    heading: str = "estimate"
    landmark_robots: list | None = None
    links: dict | None = None
    initial_std: list | None = None

    def __post_init__(self) -> None:
        if self.family != "replay":
            raise ConfigError(f"family: {self.family!r} is not a replay scenario")
        try:
            self.config()
        except (TypeError, ValueError) as exc:
            raise ConfigError(f"replay scenario: {exc}") from None

    def config(self):
        from swarmloc.world.replay.evaluation import ReplayConfig

        return ReplayConfig(algorithm=self.algorithm, cooperative=self.cooperative, seed=self.seed,
                            dt_s=self.dt_s, params=dict(self.params), duration_s=self.duration_s,
                            calibration=self.calibration, calibration_s=self.calibration_s,
                            start=self.start, kidnap_s=self.kidnap_s,
                            kidnap_robot=self.kidnap_robot, heading=self.heading,
                            landmark_robots=None if self.landmark_robots is None
                            else tuple(self.landmark_robots),
                            links=self.links,
                            **({} if self.initial_std is None
                               else {"initial_std": tuple(self.initial_std)}))

    @functools.cached_property
    def world(self):  # what the process commands read: seed, robot count, ticks
        return _ReplayFacts(self)

    @property
    def n_ticks(self) -> int:
        """Ticks of a run (``swarmloc.families.Family``'s scenario contract)."""
        return self.world.steps

    @property
    def label(self) -> str:
        """What tells runs of this scenario apart: the localizer."""
        return self.algorithm

    def load(self):
        """The data set (read once per scenario object; ConfigError if it cannot be read)."""
        return self._loaded

    @functools.cached_property
    def _loaded(self):
        from swarmloc.world.replay.mrclam import load_dataset

        try:
            return load_dataset(self.dataset)
        except (OSError, ValueError) as exc:
            raise ConfigError(f"dataset: {exc}") from None

    def to_dict(self) -> dict:
        return {f.name: getattr(self, f.name) for f in dataclasses.fields(self)}

    @classmethod
    def from_dict(cls, data: dict) -> ReplayScenario:
        names = {f.name for f in dataclasses.fields(cls)}
        unknown = sorted(set(data) - names)
        if unknown:
            raise ConfigError(f"replay scenario: unknown key {unknown[0]!r} (known: {', '.join(sorted(names))})")
        return cls(**{k: (dict(v) if k == "params" else v) for k, v in data.items()})


class _ReplayFacts:
    def __init__(self, scenario: ReplayScenario) -> None:
        self.seed = scenario.seed
        dataset = scenario.load()
        self.robots = len(dataset.robot_ids)
        from swarmloc.world.replay.evaluation import replay_world

        self.steps = replay_world(dataset, scenario.config()).n_ticks


class ReplayService(DrivenRobots):
    family = "replay"
    act_type = EstimateAct

    def __init__(self, scenario: ReplayScenario) -> None:
        from swarmloc.world.replay.evaluation import replay_world

        self.scenario = scenario
        self.config = scenario.config()
        self.dataset = scenario.load()
        self.world = replay_world(self.dataset, self.config)
        self.robot_ids = self.world.robot_ids
        n = len(self.robot_ids)
        self.n_robots = n
        self.seed = scenario.seed
        self.tick_s = self.world.dt_s
        self._alive = np.ones(n, bool)
        self._estimate = self.world.initial_poses()  # a robot that never answers stays there
        self.estimates = np.full((self.world.n_ticks, n, 3), np.nan)

    @property
    def tick(self) -> int:
        return self.world.tick

    def senses(self) -> list[tuple[int, bytes]]:
        out = []
        for i, obs in enumerate(self.world.observe()):
            if not self._alive[i]:
                continue
            sense = ReplaySense(
                tick=obs.tick, robot_id=i, time_s=float(obs.time_s),
                speed_mps=float(obs.odometry_v_mps), turn_rate_rad_s=float(obs.odometry_omega_rad_s),
                dt_s=float(obs.odometry_dt_s),
                landmarks=tuple(LandmarkMsg(int(a), float(r), float(b)) for a, r, b in zip(
                    obs.landmark_ids.tolist(), obs.landmark_range_m.tolist(),
                    obs.landmark_bearing_rad.tolist())),
                robots=tuple(LandmarkMsg(int(a), float(r), float(b)) for a, r, b in zip(
                    obs.robot_ids.tolist(), obs.robot_range_m.tolist(), obs.robot_bearing_rad.tolist())),
                received=tuple(RadioMsg(m.sender_id, m.payload) for m in obs.received),
                true_heading_rad=() if obs.true_heading_rad is None else (float(obs.true_heading_rad),),
                odometry_gap2_s2=() if obs.odometry_gap2_s2 is None else (float(obs.odometry_gap2_s2),),
            )
            out.append((i, encode(sense)))
        return out

    def step(self, acts: list[EstimateAct | None]) -> None:
        k = self.world.tick
        outgoing: dict[int, bytes | None] = {}
        for i, act in enumerate(acts):
            if act is not None:
                self._estimate[i] = act.pose_estimate
                outgoing[self.robot_ids[i]] = act.payload
        self.estimates[k] = self._estimate
        self.world.step(outgoing)

    def state(self) -> WorldState:
        return WorldState(
            tick=self.tick, time_s=self.tick * self.tick_s,
            poses=tuple(tuple(p) for p in self._estimate.tolist()), alive=tuple(self._alive.tolist()),
            round_trips=0,
        )

    def summary(self) -> dict:
        from swarmloc.world.replay.evaluation import ReplayResult, score

        k = self.world.tick
        if k == 0:
            return {"ticks": 0}
        truth = self.world.ground_truth()[:k]
        result = ReplayResult(self.config, self.robot_ids, self.world.tick_end_times_s[:k].copy(),
                              self.estimates[:k], truth, 0.0, kidnap=self.world.kidnap_tick)
        # The metrics are finite numbers: a score that does not exist (never localized, no
        # kidnap) is left out.
        return {"ticks": k, "robots": {str(rid): {key: v for key, v in s.items()
                                                  if math.isfinite(v)}
                                       for rid, s in score(result).items()}}
