"""The laser world of seeds 002/003 served to agent processes (one localizer per process).

A :class:`~swarmloc.world.service.ServedWorld` around :class:`~swarmloc.world.laser.world.LaserWorld`:
each tick it sends every live robot a :class:`LaserSense` (odometry, scan, sightings, the radio
messages of the previous tick), takes each :class:`EstimateAct` (pose estimate, broadcast), scores
the estimates against the true poses the observation was taken at, and steps the world with the
broadcasts. The scoring is :func:`swarmloc.deploy.lab.laser.runner.summarize`, the in-process runner's,
so a process run and an in-process run of one seed report the same figures.

A robot whose agent is gone keeps being driven (the world moves the laser robots); it sends
nothing and its last estimate stands, so its error grows: a dead localizer is visible in the
figures.
"""

from __future__ import annotations

import numpy as np

from swarmloc.protocol.messages import (
    EstimateAct,
    LaserSense,
    RadioMsg,
    SightingMsg,
    WorldState,
    encode,
)
from swarmloc.world.service import DrivenRobots


class LaserService(DrivenRobots):
    family = "laser"
    act_type = EstimateAct

    def __init__(self, scenario) -> None:
        from swarmloc.world.laser.world import WORLD_STREAM, LaserWorld

        self.scenario = scenario
        config = scenario.world
        self.world = LaserWorld(config, np.random.default_rng([config.seed, WORLD_STREAM]))
        n, steps = config.robots, config.steps
        self.n_robots = n
        self.seed = config.seed
        self.tick_s = config.dt_s
        self._alive = np.ones(n, bool)
        self._estimate = np.full((n, 3), np.nan)
        self.true_poses = np.empty((steps, n, 3))
        self.estimates = np.full((steps, n, 3), np.nan)
        self.sightings = np.zeros(steps, np.int64)

    @property
    def tick(self) -> int:
        return self.world.step_index

    def senses(self) -> list[tuple[int, bytes]]:
        k = self.world.step_index
        observations = self.world.observe()
        self.true_poses[k] = self.world.true_poses
        self.sightings[k] = sum(len(o.sightings) for o in observations)
        out = []
        for r in np.flatnonzero(self._alive).tolist():
            o = observations[r]
            sense = LaserSense(
                tick=k, robot_id=r,
                odometry_delta_s_m=float(o.odometry_delta_s_m),
                odometry_delta_phi_rad=float(o.odometry_delta_phi_rad),
                ranges_m=tuple(np.asarray(o.ranges_m, dtype=float).tolist()),
                sightings=tuple(
                    SightingMsg(s.robot_id, float(s.distance_m), float(s.bearing_rad),
                                float(s.relative_heading_rad))
                    for s in o.sightings
                ),
                received=tuple(RadioMsg(m.sender_id, m.payload) for m in o.received),
            )
            out.append((r, encode(sense)))
        return out

    def step(self, acts: list[EstimateAct | None]) -> None:
        k = self.world.step_index
        outgoing: list[bytes | None] = [None] * self.n_robots
        for r, act in enumerate(acts):
            if act is not None:
                self._estimate[r] = act.pose_estimate
                outgoing[r] = act.payload
        self.estimates[k] = self._estimate
        self.world.step(outgoing)

    def state(self) -> WorldState:
        poses = self.world.true_poses
        return WorldState(
            tick=self.tick, time_s=self.tick * self.tick_s,
            poses=tuple(tuple(p) for p in poses.tolist()), alive=tuple(self._alive.tolist()),
            round_trips=0,
        )

    def summary(self) -> dict:
        from swarmloc.world.laser.scoring import pose_errors, summarize

        k = self.world.step_index
        if k == 0:
            return {"steps": 0}
        est, true = self.estimates[:k], self.true_poses[:k]
        # A robot that never reported an estimate is "nowhere": an infinite error would break
        # the JSON; the map's far corner is as wrong as any estimate can be.
        est = np.where(np.isnan(est), -1e3, est)
        position, heading = pose_errors(est, true)
        config = self.scenario.world
        kidnaps = [(kn.robot, kn.step) for kn in config.kidnaps if kn.step < k]
        summary = summarize(position, heading, kidnaps, self.scenario.metrics, self.sightings[:k])
        summary["steps"] = k
        summary["final_position_error_m"] = [round(float(e), 6) for e in position[-1]]
        return summary
