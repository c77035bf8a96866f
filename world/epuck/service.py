"""The e-puck foraging world of seeds 000/001 as a served world (:class:`ForagingService`).

The adapter the world-server shell (:mod:`swarmloc.world.server`) runs for scenarios of the
``foraging`` family, around the pure model :class:`~swarmloc.world.epuck.foraging.ForagingWorld`;
:data:`swarmloc.families.FAMILIES` names :func:`_foraging`.
"""

from __future__ import annotations

import numpy as np

from swarmloc.protocol.epuck import on_path
from swarmloc.protocol.messages import EpuckAct, EpuckSense, RabMessage, WorldState, encode


class ForagingService:
    """The e-puck foraging world of seeds 000/001 (:class:`ForagingWorld`) as a served world.

    Messages an agent emits at tick ``k`` (its Act's payload) reach the robots the medium chose
    at ``k`` (measured in :meth:`ForagingWorld.step`) in their Sense of ``k + 1``.
    """

    family = "foraging"
    act_type = EpuckAct

    def __init__(self, world) -> None:
        self.world = world
        n = world.n_robots
        self.n_robots = n
        self.seed = world.config.seed
        self.tick_s = world.config.tick_s
        self._cmd = np.zeros((n, 2))  # a missing Act keeps the previous wheel command
        self._state = np.zeros(n, np.int64)
        self._outgoing: list[bytes | None] = [None] * n

    @property
    def tick(self) -> int:
        return self.world.tick

    @property
    def done(self) -> bool:
        return self.world.done

    @property
    def alive(self) -> np.ndarray:
        return self.world.alive

    def kill(self, robot: int) -> None:
        self.world.kill(robot)

    def revive(self, robot: int) -> None:
        self.world.revive(robot)

    def senses(self) -> list[tuple[int, bytes]]:
        world = self.world
        obs = world.observe()
        d = obs.deliveries
        received: list[list[RabMessage]] = [[] for _ in range(self.n_robots)]
        if len(d.sender):
            outgoing = self._outgoing
            for s, r, rng_m, b in zip(
                d.sender.tolist(), d.receiver.tolist(), d.range_m.tolist(), d.bearing_rad.tolist()
            ):
                payload = outgoing[s]
                if payload is not None:
                    received[r].append(RabMessage(s, rng_m, b, payload))
        enc, ir, ground = obs.encoder_steps.tolist(), obs.ir.tolist(), obs.ground.tolist()
        out = []
        for i in np.flatnonzero(world.alive).tolist():
            sense = EpuckSense(
                tick=obs.tick, robot_id=i, encoder_steps=tuple(enc[i]), ir=tuple(ir[i]),
                ground=tuple(ground[i]), received=tuple(received[i]),
            )
            out.append((i, encode(sense)))
        return out

    def step(self, acts: list[EpuckAct | None]) -> None:
        n = self.n_robots
        sending = np.zeros(n, bool)
        payloads: list[bytes | None] = [None] * n
        for i, act in enumerate(acts):
            if act is None:
                continue
            self._cmd[i] = act.wheel_speed_steps_s
            self._state[i] = act.state
            sending[i] = act.payload is not None
            payloads[i] = act.payload
        self.world.step(self._cmd.copy(), sending, on_path(self._state))
        self._outgoing = payloads

    def state(self) -> WorldState:
        w = self.world
        return WorldState(
            tick=w.tick, time_s=w.tick * self.tick_s,
            poses=tuple(tuple(p) for p in w.pose.tolist()), alive=tuple(w.alive.tolist()),
            round_trips=int(w.metrics.round_trips.sum()),
        )

    def summary(self) -> dict:
        return self.world.metrics.summary()


def _foraging(scenario) -> ForagingService:
    from swarmloc.agents.epuck.social_odometry import STRATEGIES
    from swarmloc.world.epuck.foraging import ForagingWorld

    if STRATEGIES[scenario.agent.strategy].central:
        raise ValueError(f"agent.strategy: {scenario.agent.strategy} needs the batch engine's central "
                         f"system; a world-server cannot serve it")
    return ForagingService(ForagingWorld(scenario.world))
