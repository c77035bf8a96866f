"""A robot of a replayed data set (MRCLAM) as an agent process: one landmark localizer (EKF,
particle filter, CFS-GA, dead reckoning; alone or cooperative) fed by the replay world over Zenoh.

Built exactly as the in-process evaluation builds it (:func:`swarmloc.deploy.lab.replay.mrclam.replay_localizer`:
same calibration, initial pose and generator), so a process run gives the same estimates.
"""

from __future__ import annotations

import numpy as np

from swarmloc.agents.brains import BrainError
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.messages import EstimateAct, ReplaySense, Welcome


class ReplayAgent:
    sense_type = ReplaySense

    def __init__(self, localizer, robot_id: int, data_robot_id: int) -> None:
        self.localizer = localizer
        self.robot_id = robot_id
        self.data_robot_id = data_robot_id

    @classmethod
    def from_welcome(cls, welcome: Welcome, scenario) -> ReplayAgent:
        from swarmloc.config import ConfigError
        from swarmloc.world.replay.evaluation import replay_localizer, replay_world

        try:
            dataset = scenario.load()
            config = scenario.config()
            world = replay_world(dataset, config)
        except (ConfigError, ValueError, TypeError) as exc:
            raise BrainError(f"the world's replay scenario is not usable here: {exc}") from None
        if welcome.robot_id >= len(world.robot_ids):
            raise BrainError(f"robot {welcome.robot_id} is not in a replay of {len(world.robot_ids)}")
        rid = world.robot_ids[welcome.robot_id]
        return cls(replay_localizer(dataset, world, config, rid), welcome.robot_id, rid)

    def act(self, sense: ReplaySense, errors: ErrorCounter) -> EstimateAct:
        from swarmloc.world.replay.replay import LandmarkObservation, Message

        def columns(items):
            return (np.array([m.landmark_id for m in items], dtype=np.int64),
                    np.array([m.range_m for m in items], dtype=float),
                    np.array([m.bearing_rad for m in items], dtype=float))

        lm_ids, lm_range, lm_bearing = columns(sense.landmarks)
        r_ids, r_range, r_bearing = columns(sense.robots)
        obs = LandmarkObservation(
            robot_id=self.data_robot_id, tick=sense.tick, time_s=sense.time_s,
            odometry_v_mps=sense.speed_mps, odometry_omega_rad_s=sense.turn_rate_rad_s,
            odometry_dt_s=sense.dt_s, landmark_ids=lm_ids, landmark_range_m=lm_range,
            landmark_bearing_rad=lm_bearing, robot_ids=r_ids, robot_range_m=r_range,
            robot_bearing_rad=r_bearing,
            received=tuple(Message(m.sender_id, m.payload) for m in sense.received),
            true_heading_rad=sense.true_heading_rad[0] if sense.true_heading_rad else None,
            odometry_gap2_s2=sense.odometry_gap2_s2[0] if sense.odometry_gap2_s2 else None,
        )
        self.localizer.step(obs)
        for sender, exc in getattr(self.localizer, "rejected", ()):
            errors.record(f"robot {sender}", "payload", exc)
        estimate = np.asarray(self.localizer.estimate(), dtype=float)
        return EstimateAct(tick=sense.tick, robot_id=self.robot_id,
                           pose_estimate=tuple(estimate.tolist()),
                           payload=self.localizer.outgoing(), command=())
