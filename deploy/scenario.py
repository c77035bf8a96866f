"""Scenarios: a world configuration and an agent configuration, loaded from TOML.

A scenario file has a name, a description, a ``[world]`` table (:class:`WorldConfig`) and an
``[agent]`` table (:class:`AgentConfig`). Shipped scenarios (``swarmloc scenarios`` lists them)
are the experimental setups ES1-ES3 of seed 000 table 2 and the four arenas of seed 001 §4.1.
Unknown keys and impossible values are refused with a message that names them, before anything
starts.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from importlib import resources
from pathlib import Path

from swarmloc.agents.foraging import AgentConfig
from swarmloc.config import ConfigError, apply_overrides, from_dict, load_toml, to_dict
from swarmloc.world.foraging import WorldConfig

DEFAULT_SCENARIO = "ES1"


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

    def to_dict(self) -> dict:
        return to_dict(self)

    @classmethod
    def from_dict(cls, data: dict) -> Scenario:
        return from_dict(cls, data)



def builtin_names() -> list[str]:
    folder = resources.files("swarmloc.deploy") / "scenarios"
    return sorted(p.name[:-5] for p in folder.iterdir() if p.name.endswith(".toml"))


def scenario_data(name_or_path: str) -> dict:
    """The raw dict of a shipped scenario (by name) or of a TOML file (by path)."""
    path = Path(name_or_path)
    if path.suffix == ".json":  # what a run folder records (scenario.json)
        try:
            return json.loads(path.read_text())
        except (OSError, ValueError) as exc:
            raise ConfigError(f"{path}: cannot read scenario: {exc}") from None
    if path.suffix == ".toml" or path.exists():
        return load_toml(path)
    names = builtin_names()
    if name_or_path not in names:
        import difflib

        close = difflib.get_close_matches(name_or_path, names, n=1, cutoff=0.4)
        hint = f"; did you mean '{close[0]}'?" if close else ""
        raise ConfigError(
            f"scenario '{name_or_path}': no such file or shipped scenario{hint} "
            f"(shipped: {', '.join(names)})"
        )
    folder = resources.files("swarmloc.deploy") / "scenarios"
    return load_toml(Path(str(folder / f"{name_or_path}.toml")))


def load_scenario(name_or_path: str = DEFAULT_SCENARIO, overrides: list[str] = ()) -> Scenario:
    """Load and validate a scenario, with ``section.key=value`` overrides applied."""
    data = apply_overrides(scenario_data(name_or_path), list(overrides))
    return Scenario.from_dict(data)
