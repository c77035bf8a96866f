"""What the world-server serves: any model that produces Senses and consumes Acts.

The world-server shell (:mod:`swarmloc.world.server`) knows nothing of e-pucks, lasers or cameras:
it runs the lockstep clock, the join queryable, liveliness and the Zenoh keys, and hands each
tick's decoded Acts to a :class:`ServedWorld`. One robot family = one adapter, a few lines
around a pure world model, in the family's folder (``world/epuck/service.py``,
``world/laser/service.py``, ...); a replay of recorded data is another adapter behind the same shell.

Families are looked up by the scenario's family (its ``family`` key, ``"foraging"`` when absent)
through :func:`served_world`; each family's module is imported only when asked for.
"""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from swarmloc.protocol.messages import WorldState


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


def served_world(scenario) -> ServedWorld:
    """The served world of a loaded scenario of any family (``deploy.scenario.AnyScenario``)."""
    from swarmloc.families import FAMILIES
    from swarmloc.registry import resolve

    return resolve(FAMILIES.get(scenario.family).world)(scenario.scenario)
