"""The e-puck foraging family's scenario (seeds 000 and 001): a world configuration and an agent
configuration, as one strict dataclass (issue 48: a family's scenario class lives in its
``world/<family>/`` folder; shipped scenarios, variants and the loader are in
``swarmloc.deploy.scenario``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

from swarmloc.agents.epuck.foraging import AgentConfig
from swarmloc.config import ConfigError, from_dict, to_dict
from swarmloc.world.epuck.foraging import WorldConfig


@dataclass(frozen=True)
class Scenario:
    """An e-puck foraging scenario (family ``"foraging"``; other families have their own)."""

    name: str = "custom"
    description: str = ""
    family: str = "foraging"
    world: WorldConfig = field(default_factory=WorldConfig)
    agent: AgentConfig = field(default_factory=AgentConfig)

    def __post_init__(self) -> None:
        if self.family != "foraging":
            raise ConfigError(f"family: {self.family!r} is not an e-puck foraging scenario")

    @property
    def n_ticks(self) -> int:
        """Ticks of a run (``swarmloc.families.Family``'s scenario contract)."""
        return self.world.n_ticks

    @property
    def label(self) -> str:
        """What tells runs of this scenario apart: the strategy."""
        return self.agent.strategy

    def to_dict(self) -> dict:
        return to_dict(self)

    @classmethod
    def from_dict(cls, data: dict) -> Scenario:
        return from_dict(cls, data)
