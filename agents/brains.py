"""The brains an agent process can run, behind one interface the agent-node shell calls.

The shell (:mod:`swarmloc.agents.node`) joins a run, subscribes to its robot's Sense key and, for
each Sense, asks its :class:`AgentBrain` for the Act to publish. Which brain runs follows the
scenario the world sent in its Welcome (its ``family`` key, ``"foraging"`` when absent): one
adapter per robot family, a few lines around a pure brain, in the family's folder
(``agents/epuck/agent.py``, ``agents/laser/agent.py``, ...). Family modules are imported only when
asked for.
"""

from __future__ import annotations

from typing import Any, Protocol

from swarmloc.config import ConfigError
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.messages import Welcome


class BrainError(RuntimeError):
    """The world's scenario cannot build this brain."""


class AgentBrain(Protocol):
    """One robot's brain as the agent shell sees it."""

    sense_type: type
    #: Optional (default False): True for a brain whose step is short and bounded (well under a
    #: millisecond); the shell then runs it on Zenoh's receiving thread, saving a thread
    #: hand-over per tick (agents/node.py: AgentNode.declare).
    # SENSE_ON_NETWORK_THREAD: bool

    def act(self, sense: Any, errors: ErrorCounter) -> Any:
        """The Act answering ``sense``; a teammate's undecodable payload inside it is recorded
        in ``errors`` and skipped."""


def brain_from_welcome(welcome: Welcome, *, null_brain: bool = False) -> AgentBrain:
    """The brain the world's scenario asks for; BrainError names what is unusable.

    ``null_brain``: a :class:`~swarmloc.agents.epuck.agent.StandstillAgent` instead (e-puck scenarios only), for transport
    benchmarks."""
    from swarmloc.families import scenario_from_dict

    try:
        loaded = scenario_from_dict(welcome.scenario)
    except (ConfigError, TypeError, ValueError) as exc:
        raise BrainError(f"the world's scenario is not usable: {exc}") from None
    if null_brain:
        from swarmloc.agents.epuck.agent import StandstillAgent

        if loaded.family != "foraging":
            raise BrainError(f"--null-brain stands in for e-puck brains only, not for the "
                             f"{loaded.family!r} family")
        return StandstillAgent(welcome.robot_id)
    from swarmloc.families import FAMILIES
    from swarmloc.registry import resolve

    return resolve(FAMILIES.get(loaded.family).brain)(welcome, loaded.scenario)
