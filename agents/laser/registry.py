"""The laser localizers by name: the registry scenarios, ``--algorithm``, specs and the agent
processes choose from (the papers' four, Player's AMCL of issue 43, and any a plugin registers:
``ALGORITHMS.register(AlgorithmEntry(...))``, docs/extending.md). Beside the localizers, below the
shells: the in-process runner (``deploy/lab/laser/runner.py``) and the agent process
(``agents/laser/agent.py``) both build from it."""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from swarmloc.agents.laser.localizer import Localizer, LocalizerSetup
from swarmloc.registry import Registry, resolve


@dataclass(frozen=True)
class AlgorithmEntry:
    """A localizer the runner can build by name.

    ``localizer``: a class with ``from_config(setup, params, rng)`` (or a ``"module:Class"`` path
    to one). ``params_type``: its parameter class with ``from_dict(mapping)`` (or a path; None:
    the parameters are checked only when a localizer is built). ``population_keys``: the
    parameters that :attr:`AlgorithmConfig.population` sets (all to the same value).
    ``communicates``: whether the localizer broadcasts to teammates when cooperative (False: it
    never sends, so no teammate payload ever reaches it, and the contract checker's "bad input"
    check has nothing to corrupt).
    """

    name: str
    label: str
    localizer: Any
    params_type: Any = None
    population_keys: tuple[str, ...] = ()
    communicates: bool = True

    def params(self, population: int | None, params: dict | None) -> dict:
        """The parameter dict a localizer is built with: the population, then ``params`` (which
        win: ``params.min_particles`` beats ``population``)."""
        out = {k: population for k in self.population_keys} if population is not None else {}
        out.update(params or {})
        return out

    def check(self, params: dict) -> None:
        """Refuse unknown or impossible parameters (ValueError naming them)."""
        if self.params_type is None:
            return
        try:
            resolve(self.params_type).from_dict(params)
        except (TypeError, ValueError) as exc:
            raise ValueError(f"{self.name}: {exc}") from None

    def population_text(self, params: dict) -> str:
        """The population as a results column: ``"300"``, or ``"1000-10000"`` for a range."""
        if self.params_type is None or not self.population_keys:
            values = [params[k] for k in self.population_keys if k in params]
        else:
            built = resolve(self.params_type).from_dict(params)
            values = [getattr(built, k) for k in self.population_keys]
        values = sorted(set(values))
        return "-".join(str(v) for v in values)

    def build(self, setup: LocalizerSetup, params: dict, rng: np.random.Generator) -> Localizer:
        return resolve(self.localizer).from_config(setup, params, rng)


class AlgorithmRegistry(Registry[AlgorithmEntry]):
    """Localizers by name (:class:`swarmloc.registry.Registry`: a name registers once, an
    unknown name suggests the closest)."""

    def __init__(self) -> None:
        super().__init__("algorithm")


def default_algorithms() -> AlgorithmRegistry:
    """The four localizers of issue 4, and Player's AMCL of issue 43."""
    registry = AlgorithmRegistry()
    registry.register(AlgorithmEntry(
        "ssga", "MR-SSGA", "swarmloc.agents.laser.ssga:SSGALocalizer",
        "swarmloc.agents.laser.ssga:SSGAParams", ("population_size",)))
    registry.register(AlgorithmEntry(
        "simple_ga", "simple GA", "swarmloc.agents.laser.simple_ga:SimpleGALocalizer",
        "swarmloc.agents.laser.simple_ga:SimpleGAParams", ("population_size",)))
    registry.register(AlgorithmEntry(
        "cfsga", "CFS-GA", "swarmloc.agents.laser.cfsga:CFSGALocalizer",
        "swarmloc.agents.laser.cfsga:CFSGAParams", ("population_size",)))
    registry.register(AlgorithmEntry(
        "amcl", "modern AMCL", "swarmloc.agents.laser.amcl:AMCLLocalizer",
        "swarmloc.agents.laser.amcl:AMCLParams", ("min_particles", "max_particles")))
    registry.register(AlgorithmEntry(
        "amcl-player", "Player AMCL", "swarmloc.agents.laser.amcl_player:PlayerAMCLLocalizer",
        "swarmloc.agents.laser.amcl_player:PlayerAMCLParams", ("min_particles", "max_particles"),
        communicates=False))
    return registry


#: The localizers scenarios, ``--algorithm`` and specs choose from: the built-in four, and any a
#: plugin registers (``ALGORITHMS.register(AlgorithmEntry(...))``, docs/extending.md).
ALGORITHMS = default_algorithms()


# -- the scenario -----------------------------------------------------------------------------
