"""Zenoh key expressions of a run: one prefix per run, so that runs never mix.

The key space (ARCHITECTURE.md, "Processes and keys")::

    swarmloc/<run>/robot/<id>/sense        world -> agent, each tick (EpuckSense)
    swarmloc/<run>/robot/<id>/act          agent -> world, each tick (EpuckAct)
    swarmloc/<run>/world/join              queryable of the world: Join -> Welcome
    swarmloc/<run>/world/state             world -> observers (WorldState)
    swarmloc/<run>/world/end               world -> everyone (RunEnd)
    swarmloc/<run>/alive/<id>              liveliness token of an agent
    swarmloc/<run>/alive/world             liveliness token of the world-server
    swarmloc/<run>/team/<team>/blobs/<id>  vision agents' shared detections

Run and team names are single key chunks, ``[A-Za-z0-9_-]{1,64}``: no ``/`` and none of Zenoh's
wildcard or reserved characters, so a name can never widen a subscription.
"""

from __future__ import annotations

from dataclasses import dataclass

from swarmloc.protocol.messages import MAX_ROBOT_ID, NAME_PATTERN, NAME_RE

ROOT = "swarmloc"


def validate_run_name(run: str) -> str:
    """Return ``run`` if it is a valid run name (``[A-Za-z0-9_-]{1,64}``), else ValueError."""
    return _validate_name(run, "run name")


def _validate_name(name: object, what: str) -> str:
    if type(name) is not str or NAME_RE.fullmatch(name) is None:
        raise ValueError(f"invalid {what} {name!r}: expected {NAME_PATTERN}")
    return name


def _validate_robot_id(robot_id: object) -> int:
    if type(robot_id) is not int or not 0 <= robot_id <= MAX_ROBOT_ID:
        raise ValueError(f"invalid robot id {robot_id!r}: expected an int in 0..{MAX_ROBOT_ID}")
    return robot_id


@dataclass(frozen=True)
class Keys:
    """The key expressions of one run."""

    run: str

    def __post_init__(self) -> None:
        validate_run_name(self.run)

    @property
    def prefix(self) -> str:
        return f"{ROOT}/{self.run}"

    def sense(self, robot_id: int) -> str:
        return f"{self.prefix}/robot/{_validate_robot_id(robot_id)}/sense"

    def act(self, robot_id: int) -> str:
        return f"{self.prefix}/robot/{_validate_robot_id(robot_id)}/act"

    @property
    def act_all(self) -> str:
        """Every robot's act: the world declares one subscriber on this, not one per robot."""
        return f"{self.prefix}/robot/*/act"

    def alive(self, robot_id: int) -> str:
        return f"{self.prefix}/alive/{_validate_robot_id(robot_id)}"

    @property
    def alive_all(self) -> str:
        """Every liveliness token of the run, the world's included (``alive/world``)."""
        return f"{self.prefix}/alive/*"

    @property
    def join(self) -> str:
        """The world's queryable: an agent sends a Join, the world replies a Welcome."""
        return f"{self.prefix}/world/join"

    @property
    def world_state(self) -> str:
        return f"{self.prefix}/world/state"

    @property
    def run_end(self) -> str:
        return f"{self.prefix}/world/end"

    @property
    def world_alive(self) -> str:
        return f"{self.prefix}/alive/world"

    def team_blobs(self, team: str, robot_id: int) -> str:
        team = _validate_name(team, "team name")
        return f"{self.prefix}/team/{team}/blobs/{_validate_robot_id(robot_id)}"

    @staticmethod
    def robot_id_from_key(key: str) -> int:
        """The robot id in ``swarmloc/<run>/robot/<id>/act`` (or ``.../sense``) or
        ``swarmloc/<run>/alive/<id>``; ValueError for anything else (``alive/world`` included).

        The id must be written canonically (``7``, not ``07`` or ``+7``), as :class:`Keys`
        writes it. ``key`` may be a ``zenoh.KeyExpr``.
        """
        key = str(key)
        chunks = key.split("/")
        robot_key = len(chunks) == 5 and chunks[2] == "robot" and chunks[4] in ("act", "sense")
        alive_key = len(chunks) == 4 and chunks[2] == "alive"
        if not (robot_key or alive_key):
            raise ValueError(
                f"not a robot key: {key!r} (expected {ROOT}/<run>/robot/<id>/act or "
                f"{ROOT}/<run>/alive/<id>)"
            )
        id_chunk = chunks[3]
        if chunks[0] != ROOT or NAME_RE.fullmatch(chunks[1]) is None:
            raise ValueError(f"not a {ROOT} key: {key!r}")
        if not (id_chunk.isascii() and id_chunk.isdigit()) or str(int(id_chunk)) != id_chunk:
            raise ValueError(f"invalid robot id {id_chunk!r} in key {key!r}")
        robot_id = int(id_chunk)
        if robot_id > MAX_ROBOT_ID:
            raise ValueError(f"robot id {robot_id} in key {key!r} exceeds {MAX_ROBOT_ID}")
        return robot_id
