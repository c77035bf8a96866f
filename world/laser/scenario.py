"""The laser family's scenario (seeds 002 and 003): the world, the localizer every robot runs,
and the metrics, as one strict dataclass (issue 48: a family's scenario class lives in its
``world/<family>/`` folder; the loader of shipped scenarios is ``swarmloc.deploy.scenario``'s).
"""

from __future__ import annotations

import hashlib
import json
from dataclasses import dataclass, field
from typing import Any

from swarmloc.agents.laser.registry import ALGORITHMS, AlgorithmEntry
from swarmloc.config import from_dict, to_dict
from swarmloc.world.laser.scoring import MetricsConfig
from swarmloc.world.laser.world import LaserWorldConfig


@dataclass(frozen=True)
class AlgorithmConfig:
    """Which localizer every robot runs. ``population`` sets the algorithm's population
    parameter(s) (GA individuals; AMCL: min and max particles alike); ``params`` are the
    algorithm's own parameters (see its module)."""

    name: str = "cfsga"
    cooperative: bool = True
    population: int | None = None
    params: Any = None

    def __post_init__(self) -> None:
        entry = ALGORITHMS.get(self.name)
        if self.population is not None and (isinstance(self.population, bool)
                                            or not isinstance(self.population, int)
                                            or self.population < 1):
            raise ValueError(f"population: must be an integer >= 1, got {self.population!r}")
        if self.params is None:
            object.__setattr__(self, "params", {})
        if not isinstance(self.params, dict):
            raise TypeError(f"params: expected a table of the algorithm's parameters, "
                             f"got {self.params!r}")
        entry.check(entry.params(self.population, self.params))

    @property
    def entry(self) -> AlgorithmEntry:
        return ALGORITHMS.get(self.name)

    def resolved_params(self) -> dict:
        return self.entry.params(self.population, self.params)


@dataclass(frozen=True)
class LaserScenario:
    name: str = "custom"
    description: str = ""
    world: LaserWorldConfig = field(default_factory=LaserWorldConfig)
    algorithm: AlgorithmConfig = field(default_factory=AlgorithmConfig)
    metrics: MetricsConfig = field(default_factory=MetricsConfig)

    def to_dict(self) -> dict:
        return to_dict(self)

    @property
    def n_ticks(self) -> int:
        """Steps of a run (``swarmloc.families.Family``'s scenario contract)."""
        return self.world.steps

    @property
    def label(self) -> str:
        """What tells runs of this scenario apart: the localizer."""
        return self.algorithm.name

    @classmethod
    def from_dict(cls, data: dict) -> LaserScenario:
        return from_dict(cls, data)

    def config_hash(self) -> str:
        """Hash of the scenario without its seed: rows made with another configuration differ."""
        data = self.to_dict()
        data["world"].pop("seed", None)
        blob = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
        return hashlib.sha256(blob).hexdigest()[:12]
