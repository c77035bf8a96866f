"""What the world-server serves: any model that produces Senses and consumes Acts.

The world-server shell (:mod:`swarmloc.world.server`) knows nothing of e-pucks, lasers or cameras:
it runs the lockstep clock, the join queryable, liveliness and the Zenoh keys, and hands each
tick's decoded Acts to a :class:`ServedWorld`. One robot family = one adapter here, a few lines
around a pure world model; a replay of recorded data is another adapter behind the same shell.

Families are looked up by the scenario's family (its ``family`` key, ``"foraging"`` when absent)
through :func:`served_world`; each family's module is imported only when asked for.
"""

from __future__ import annotations

import importlib
from typing import Any, Protocol

import numpy as np

from swarmloc.protocol.epuck import on_path
from swarmloc.protocol.messages import EpuckAct, EpuckSense, RabMessage, WorldState, encode


class ServedWorld(Protocol):
    """A world model as the world-server sees it.

    Per tick the server calls :meth:`senses` (then publishes each robot's bytes on its sense
    key), collects the Acts (decoded as :attr:`act_type`, robot id checked against the key), and
    calls :meth:`step` with one Act or None per robot. A robot with None keeps its previous
    command: the adapter decides what "previous" means for its family.
    """

    family: str
    act_type: type
    n_robots: int
    seed: int
    tick_s: float

    @property
    def tick(self) -> int: ...

    @property
    def done(self) -> bool: ...

    @property
    def alive(self) -> np.ndarray: ...

    def kill(self, robot: int) -> None: ...

    def revive(self, robot: int) -> None: ...

    def senses(self) -> list[tuple[int, bytes]]:
        """This tick's encoded Sense for every live robot, as ``(robot, bytes)``."""

    def step(self, acts: list[Any | None]) -> None:
        """Apply this tick's Acts (None: no Act arrived) and advance one tick."""

    def state(self) -> WorldState:
        """Ground truth for observers."""

    def summary(self) -> dict:
        """The run's metrics so far (plain, JSON-friendly)."""


class DrivenRobots:
    """For worlds that move their robots themselves (laser driver, replay): a robot whose agent
    is gone keeps its trajectory and just stops getting Senses. Subclasses set ``_alive`` and
    ``world`` (with ``done``) and define :attr:`tick`."""

    _alive: np.ndarray

    @property
    def done(self) -> bool:
        return self.world.done

    @property
    def alive(self) -> np.ndarray:
        return self._alive

    def kill(self, robot: int) -> None:
        self._alive[robot] = False

    def revive(self, robot: int) -> None:
        self._alive[robot] = True


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
    from swarmloc.agents.social_odometry import STRATEGIES
    from swarmloc.world.foraging import ForagingWorld

    if STRATEGIES[scenario.agent.strategy].central:
        raise ValueError(f"agent.strategy: {scenario.agent.strategy} needs the batch engine's central "
                         f"system; a world-server cannot serve it")
    return ForagingService(ForagingWorld(scenario.world))


#: family name -> "module:callable" building a ServedWorld from that family's scenario object.
#: Imported lazily so that serving e-pucks never imports OpenCV or the laser maps.
FAMILIES: dict[str, str] = {
    "foraging": "swarmloc.world.service:_foraging",
    "laser": "swarmloc.world.laser_service:LaserService",
    "vision": "swarmloc.world.vision_service:VisionService",
    "replay": "swarmloc.world.replay_service:ReplayService",
}


def served_world(scenario) -> ServedWorld:
    """The served world of a loaded scenario of any family (``deploy.scenario.AnyScenario``)."""
    module, _, name = FAMILIES[scenario.family].partition(":")
    return getattr(importlib.import_module(module), name)(scenario.scenario)
