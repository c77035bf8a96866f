"""A laser robot's agent: one map-based localizer (MR-SSGA, CFS-GA, simple GA, AMCL-style PF) fed
by the world-server over Zenoh.

The shell of :mod:`swarmloc.agents.node` calls :meth:`LaserAgent.act` with each decoded
:class:`LaserSense`; the localizer is built exactly as the in-process runner builds it
(:func:`swarmloc.deploy.lab.laser.runner.run_laser`): same registry entry, same parameters, same
setup, same generator from (seed, robot id). So a process run reproduces an in-process run.
"""

from __future__ import annotations

import numpy as np

from swarmloc.agents.brains import BrainError
from swarmloc.agents.laser.localizer import (
    LaserObservation,
    LocalizerSetup,
    RadioMessage,
    Sighting,
    population_samples,
)
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.messages import EstimateAct, LaserSense, Welcome


class LaserAgent:
    sense_type = LaserSense

    def __init__(self, localizer, robot_id: int, samples: int = 0) -> None:
        self.localizer = localizer
        self.robot_id = robot_id
        #: How many poses of its population each Act logs for observers (the world's
        #: ``Welcome.samples``: ``swarmloc run/world --particles N``); 0: none.
        self.samples = samples

    @classmethod
    def from_welcome(cls, welcome: Welcome, scenario) -> LaserAgent:
        from swarmloc.agents.epuck.foraging import agent_rng
        from swarmloc.agents.laser.registry import ALGORITHMS

        config, algo = scenario.world, scenario.algorithm
        if welcome.robot_id >= config.robots:
            raise BrainError(f"robot {welcome.robot_id} is not in a world of {config.robots}")
        try:
            entry = ALGORITHMS.get(algo.name)
            params = algo.resolved_params()
            entry.check(params)
        except (ValueError, TypeError) as exc:
            raise BrainError(f"the world's laser scenario is not usable: {exc}") from None
        setup = LocalizerSetup.from_world_config(config, welcome.robot_id, algo.cooperative)
        localizer = entry.build(setup, dict(params), agent_rng(config.seed, welcome.robot_id))
        return cls(localizer, welcome.robot_id, welcome.samples)

    def act(self, sense: LaserSense, errors: ErrorCounter) -> EstimateAct:
        obs = LaserObservation(
            step=sense.tick,
            odometry_delta_s_m=sense.odometry_delta_s_m,
            odometry_delta_phi_rad=sense.odometry_delta_phi_rad,
            ranges_m=np.array(sense.ranges_m),
            sightings=tuple(
                Sighting(s.robot_id, s.distance_m, s.bearing_rad, s.relative_heading_rad)
                for s in sense.sightings
            ),
            received=tuple(RadioMessage(m.sender_id, m.payload) for m in sense.received),
        )
        self.localizer.step(obs)
        for sender, exc in getattr(self.localizer, "rejected", ()):
            errors.record(f"robot {sender}", "payload", exc)
        estimate = np.asarray(self.localizer.estimate(), dtype=float)
        return EstimateAct(
            tick=sense.tick, robot_id=self.robot_id,
            pose_estimate=tuple(estimate.tolist()), payload=self.localizer.outgoing(), command=(),
            samples=population_samples(self.localizer, self.samples),
        )
