"""Message types that cross a process boundary, and their msgpack codec with validation.

This module is the contract between the world-server, the agent nodes and the observers
(ARCHITECTURE.md, "Processes and keys"). Every message is a frozen dataclass: the ones every
family shares are defined here, each robot family's Sense and Act types in
:mod:`swarmloc.protocol.family_messages` (imported here, so ``from swarmloc.protocol.messages
import EpuckSense`` works as for any message). On the wire a message is a msgpack map::

    {"v": PROTOCOL_VERSION, "t": <type tag>, <field name>: <value>, ...}

Tuples travel as msgpack arrays, ``bytes`` as msgpack bin, nested messages (the
:class:`RabMessage` entries of :attr:`EpuckSense.received`) as maps of their fields, without
``"v"`` or ``"t"``.

:func:`decode` is strict: anything malformed, oversized, out of range or of the wrong type is
rejected with a :class:`ProtocolError` whose ``field`` names the offending field as a dotted path
(``"received[3].range_m"``, ``"wheel_speed_steps_s[1]"``, ``"scenario.arena.size[0]"``), so that a
receiver can count the error, log it once per sender, and keep running. :func:`encode` runs the
same validator, so a sender's bug is caught at the sender.

The validator is table-driven: :data:`_FIELD_SPECS` holds one spec per field (type, length,
bounds), and :class:`_Codec` compiles each row into small decode/encode functions that inline the
specs' cheap acceptance tests and call a spec only to convert a value or to report its error
precisely. The dataclasses themselves do not validate on construction: decode has validated
already, and a second pass would double the cost.

Checks are made in this order, and the first failure is reported:

1. size > ``max_bytes`` (field ``"message"``);
2. not msgpack (``"message"``); not a map (``"message"``);
3. ``"v"`` missing or not :data:`PROTOCOL_VERSION` (``"v"``);
4. ``"t"`` unknown, or not one of the ``expected`` types (``"t"``);
5. a missing field, then an unknown extra field;
6. per field, in declaration order: wrong type (``bool`` is not an ``int``; an ``int`` is accepted
   where a ``float`` is expected and converted; NaN and infinities are rejected), wrong length, out
   of range;
7. checks across fields (a WorldState has one ``alive`` flag per pose).

Error details use Python type names: on the wire an array decodes to ``tuple`` and a map to
``dict``.
"""

from __future__ import annotations

import math
import re
import threading
from dataclasses import dataclass
from numbers import Integral, Real
from typing import Any

import msgpack

from swarmloc.protocol.epuck import EpuckBody
from swarmloc.protocol.family_messages import (
    EpuckAct,
    EpuckSense,
    EstimateAct,
    LandmarkMsg,
    LaserSense,
    RabMessage,
    RadioMsg,
    ReplaySense,
    SightingMsg,
    VisionAct,
    VisionSense,
)

PROTOCOL_VERSION = 1
#: Anything larger is rejected before decoding (and refused by :func:`encode`).
MAX_MESSAGE_BYTES = 256 * 1024
#: Range-and-bearing payload bound of the e-puck board.
MAX_RAB_PAYLOAD_BYTES = 64
MAX_ROBOT_ID = 65535
#: Ticks and counters stay below 2**53 so that they are exact in a float64 anywhere.
MAX_TICK = 2**53 - 1
MAX_RECEIVED = 16
#: Radio payloads of the laser and replay families (a CFS-GA robot's above-average individuals).
MAX_RADIO_PAYLOAD_BYTES = 32 * 1024
MAX_BEAMS = 1024
#: A vision robot's camera frame (208x160 JPEG: a few KB; PNG: up to about 100 KB).
MAX_IMAGE_BYTES = 192 * 1024
MAX_TEAMMATES = 64
#: Poses of a belief's population (particles, GA individuals) one Act may log for observers, when
#: the world asks (Welcome.samples): 256 poses are about 7 KB of msgpack.
MAX_SAMPLES = 256
MAX_POSES = 100_000
MAX_STRING_CHARS = 256
MAX_DICT_DEPTH = 8
MAX_WHEEL_SPEED_STEPS_S = EpuckBody().max_wheel_speed_steps_s
MAX_RANGE_M = 100.0
BEARING_TOLERANCE_RAD = 1e-9
#: Run names (and team names) are key-expression chunks: no '/', '*', '$', '?', '#'.
NAME_PATTERN = r"[A-Za-z0-9_-]{1,64}"
NAME_RE = re.compile(NAME_PATTERN)

_MAX_FINITE = 1.7976931348623157e308
_MSGPACK_INT_MIN = -(2**63)
_MSGPACK_INT_MAX = 2**64 - 1


class ProtocolError(ValueError):
    """A message that breaks the contract.

    ``field`` is a dotted path to the offending value (``"received[3].range_m"``), ``"message"``
    for the message as a whole, or ``""``; ``detail`` says what is wrong. ``str()`` reads
    ``"field: detail"``.
    """

    def __init__(self, field: str, detail: str) -> None:
        super().__init__(field, detail)
        self.field = field
        self.detail = detail

    def __str__(self) -> str:
        return f"{self.field}: {self.detail}" if self.field else self.detail

    def prefixed(self, prefix: str) -> ProtocolError:
        """The same error seen from a container: its path is put behind ``prefix``."""
        return ProtocolError(_join_path(prefix, self.field), self.detail)


def _join_path(prefix: str, sub: str) -> str:
    if not sub:
        return prefix
    if not prefix:
        return sub
    if sub[0] == "[":
        return prefix + sub
    return prefix + "." + sub


def _short(value: Any, limit: int = 40) -> str:
    text = repr(value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def _tname(value: Any) -> str:
    return "None" if value is None else type(value).__name__


# --------------------------------------------------------------------------------------------
# Messages every family shares (each family's own Sense and Act: protocol/family_messages.py)
# --------------------------------------------------------------------------------------------


@dataclass(frozen=True, slots=True)
class Join:
    """Agent to world, as the payload of a query on ``Keys.join``: "I am robot ``robot_id``"."""

    robot_id: int  #: 0..65535
    brain: str  #: name of the brain the agent runs, 1..256 characters
    pid: int  #: the agent's OS process id, 0..2**32-1 (for logs and supervision)


@dataclass(frozen=True, slots=True)
class Welcome:
    """World to agent, the reply to :class:`Join`: the run and its scenario."""

    robot_id: int  #: 0..65535, echoes the join
    run: str  #: run name, ``[A-Za-z0-9_-]{1,64}``
    seed: int  #: run seed, 0..2**64-1; the agent derives its own generator from it and its id
    scenario: dict  #: plain nested dict of str/int/float/bool/None/list/dict, depth <= 8
    #: observers' request: log up to this many poses of the belief's population in each Act
    #: (EstimateAct.samples), 0..MAX_SAMPLES; 0, the default, asks for none
    samples: int = 0


@dataclass(frozen=True, slots=True)
class WorldState:
    """World to observers, each tick: ground truth."""

    tick: int  #: 0..2**53-1
    time_s: float  #: simulated time, finite, >= 0
    poses: tuple[tuple[float, float, float], ...]  #: (x_m, y_m, theta_rad) per robot, <= 100000
    alive: tuple[bool, ...]  #: one flag per pose
    round_trips: int  #: Sense/Act round trips completed so far, 0..2**53-1


@dataclass(frozen=True, slots=True)
class RunEnd:
    """World to everyone: the run is over."""

    tick: int  #: 0..2**53-1
    reason: str  #: 1..256 characters
    metrics: dict  #: plain nested dict, as :attr:`Welcome.scenario`


@dataclass(frozen=True, slots=True)
class ErrorReport:
    """Any process to any other: "your message was rejected", naming the field."""

    code: str  #: short machine-readable code, ``[A-Za-z0-9_.-]{1,64}``
    field: str  #: dotted field path as in :attr:`ProtocolError.field`, may be empty
    detail: str  #: at most 256 characters

    @classmethod
    def from_protocol_error(cls, error: ProtocolError, code: str = "protocol") -> ErrorReport:
        """Report ``error``, truncated to the string bounds."""
        return cls(code, error.field[:MAX_STRING_CHARS], error.detail[:MAX_STRING_CHARS])


# --------------------------------------------------------------------------------------------
# Field specs. Each has ``check(value)`` (decode direction: wire value to Python value) and
# ``to_wire(value)`` (encode direction). Both validate with the same rules; they differ only for
# nested messages (dict <-> dataclass) and plain dicts (arrays arrive as tuples, leave as lists).
# A spec raises ProtocolError with a path relative to its value ("" for the value itself, "[3]"
# for an element); the container puts its own name in front.
# --------------------------------------------------------------------------------------------


class _Spec:
    __slots__ = ()

    def check(self, value: Any) -> Any:
        raise NotImplementedError

    def to_wire(self, value: Any) -> Any:
        return self.check(value)

    def fast_test(self, var: str) -> str | None:
        """A Python expression over the variable ``var`` that is true only when ``check`` would
        accept the value unchanged (in both directions); the compiled codec inlines it and falls
        back to ``check``/``to_wire`` (which raise the precise error) when it is false. None: no
        shortcut, always call the spec."""
        return None


def _as_int(value: Any) -> int:
    """``value`` as an exact int (numpy integers accepted), else ProtocolError."""
    if type(value) is int:
        return value
    if isinstance(value, Integral) and not isinstance(value, bool):
        return int(value)
    raise ProtocolError("", f"expected int, got {_tname(value)}")


def _as_float(value: Any) -> float:
    """``value`` as a finite float (ints and numpy scalars converted), else ProtocolError."""
    if type(value) is float:
        number = value
    elif isinstance(value, Real) and not isinstance(value, bool):
        try:
            number = float(value)
        except OverflowError:
            raise ProtocolError("", f"{_short(value)} does not fit a float") from None
    else:
        raise ProtocolError("", f"expected float, got {_tname(value)}")
    if not math.isfinite(number):
        raise ProtocolError("", f"must be finite, got {number!r}")
    return number


def _range_error(value: Any, lo: Any, hi: Any) -> ProtocolError:
    return ProtocolError("", f"{value!r} is out of range [{lo!r}, {hi!r}]")


class _Int(_Spec):
    __slots__ = ("hi", "lo")

    def __init__(self, lo: int, hi: int) -> None:
        self.lo, self.hi = lo, hi

    def check(self, value: Any) -> int:
        if type(value) is int and self.lo <= value <= self.hi:
            return value
        value = _as_int(value)
        if not self.lo <= value <= self.hi:
            raise _range_error(value, self.lo, self.hi)
        return value

    to_wire = check

    def fast_test(self, var: str) -> str:
        return f"type({var}) is int and {self.lo!r} <= {var} <= {self.hi!r}"


class _Float(_Spec):
    __slots__ = ("hi", "lo")

    def __init__(self, lo: float = -_MAX_FINITE, hi: float = _MAX_FINITE) -> None:
        self.lo, self.hi = lo, hi

    def check(self, value: Any) -> float:
        # NaN fails both comparisons and the infinities are outside [-max, max]: one test.
        if type(value) is float and self.lo <= value <= self.hi:
            return value
        value = _as_float(value)
        if not self.lo <= value <= self.hi:
            raise _range_error(value, self.lo, self.hi)
        return value

    to_wire = check

    def fast_test(self, var: str) -> str:
        return f"type({var}) is float and {self.lo!r} <= {var} <= {self.hi!r}"


class _Bool(_Spec):
    __slots__ = ()

    def check(self, value: Any) -> bool:
        if type(value) is bool:
            return value
        if type(value).__module__ == "numpy" and type(value).__name__ in ("bool", "bool_"):
            return bool(value)
        raise ProtocolError("", f"expected bool, got {_tname(value)}")

    to_wire = check

    def fast_test(self, var: str) -> str:
        return f"type({var}) is bool"


class _Str(_Spec):
    __slots__ = ("max_chars", "min_chars", "pattern")

    def __init__(
        self, min_chars: int = 0, max_chars: int = MAX_STRING_CHARS, pattern: str | None = None
    ) -> None:
        self.min_chars, self.max_chars = min_chars, max_chars
        self.pattern = re.compile(pattern) if pattern is not None else None

    def check(self, value: Any) -> str:
        if type(value) is not str:
            raise ProtocolError("", f"expected str, got {_tname(value)}")
        if not self.min_chars <= len(value) <= self.max_chars:
            raise ProtocolError(
                "", f"{len(value)} characters, expected {self.min_chars}..{self.max_chars}"
            )
        if self.pattern is not None and self.pattern.fullmatch(value) is None:
            raise ProtocolError("", f"{_short(value)} does not match {self.pattern.pattern}")
        return value

    to_wire = check

    def fast_test(self, var: str) -> str | None:
        if self.pattern is not None:
            return None
        return f"type({var}) is str and {self.min_chars} <= len({var}) <= {self.max_chars}"


class _Bytes(_Spec):
    __slots__ = ("max_len", "optional")

    def __init__(self, max_len: int, optional: bool = False) -> None:
        self.max_len, self.optional = max_len, optional

    def check(self, value: Any) -> bytes | None:
        if type(value) is bytes:
            if len(value) > self.max_len:
                raise ProtocolError("", f"{len(value)} bytes exceeds the limit of {self.max_len}")
            return value
        if value is None and self.optional:
            return None
        expected = "bytes or None" if self.optional else "bytes"
        raise ProtocolError("", f"expected {expected}, got {_tname(value)}")

    to_wire = check

    def fast_test(self, var: str) -> str:
        test = f"type({var}) is bytes and len({var}) <= {self.max_len}"
        return f"({var} is None or {test})" if self.optional else test


class _FloatTuple(_Spec):
    """A fixed-length tuple of floats, each in [lo, hi] (finite by default)."""

    __slots__ = ("hi", "length", "lo")

    def __init__(self, length: int, lo: float = -_MAX_FINITE, hi: float = _MAX_FINITE) -> None:
        self.length, self.lo, self.hi = length, lo, hi

    def check(self, value: Any) -> tuple[float, ...]:
        if type(value) is tuple and len(value) == self.length:
            lo, hi = self.lo, self.hi
            for x in value:
                if type(x) is not float or not lo <= x <= hi:
                    break
            else:
                return value
        return self._slow_check(value)

    to_wire = check

    def fast_test(self, var: str) -> str:
        # Unrolled: about three times faster than a loop for the short tuples used here.
        tests = [f"type({var}) is tuple", f"len({var}) == {self.length}"]
        for i in range(self.length):
            tests.append(f"type({var}[{i}]) is float and {self.lo!r} <= {var}[{i}] <= {self.hi!r}")
        return " and ".join(tests)

    def _slow_check(self, value: Any) -> tuple[float, ...]:
        if type(value) is not tuple:
            raise ProtocolError("", f"expected tuple, got {_tname(value)}")
        if len(value) != self.length:
            raise ProtocolError("", f"expected {self.length} values, got {len(value)}")
        converted = []
        for i, x in enumerate(value):  # every type before any range
            try:
                converted.append(_as_float(x))
            except ProtocolError as error:
                raise error.prefixed(f"[{i}]") from None
        for i, x in enumerate(converted):
            if not self.lo <= x <= self.hi:
                raise _range_error(x, self.lo, self.hi).prefixed(f"[{i}]")
        return tuple(converted)


class _Tuple(_Spec):
    """A variable-length tuple of at most ``max_len`` items, each checked by ``item``."""

    __slots__ = ("item", "max_len", "min_len")

    def __init__(self, item: _Spec, max_len: int, min_len: int = 0) -> None:
        self.item, self.max_len, self.min_len = item, max_len, min_len

    def check(self, value: Any) -> tuple:
        return self._map(value, self.item.check)

    def to_wire(self, value: Any) -> tuple:
        return self._map(value, self.item.to_wire)

    def _map(self, value: Any, check: Any) -> tuple:
        if type(value) is not tuple:
            raise ProtocolError("", f"expected tuple, got {_tname(value)}")
        if len(value) > self.max_len:
            raise ProtocolError("", f"{len(value)} entries exceeds the limit of {self.max_len}")
        if len(value) < self.min_len:
            raise ProtocolError("", f"{len(value)} entries, expected at least {self.min_len}")
        try:
            return tuple([check(x) for x in value])
        except ProtocolError:
            pass
        for i, x in enumerate(value):  # find which entry failed, and say so
            try:
                check(x)
            except ProtocolError as error:
                raise error.prefixed(f"[{i}]") from None
        raise AssertionError("unreachable")  # pragma: no cover


class _Message(_Spec):
    """A nested message, as a map of its fields (no "v" or "t").

    ``check`` and ``to_wire`` are the compiled functions of the nested type's codec, bound by
    :meth:`bind` when that codec is built (the nested type comes first in the table).
    """

    __slots__ = ("check", "cls", "to_wire")

    def __init__(self, cls: type) -> None:
        self.cls = cls

    def bind(self, codec: _Codec) -> None:
        self.check = codec.decode_nested
        self.to_wire = codec.encode_nested


_KEY_PATH_RE = re.compile(r"[A-Za-z0-9_-]+")


def _key_path(key: str) -> str:
    return key if _KEY_PATH_RE.fullmatch(key) else f"[{_short(key)}]"


def _plain_value(value: Any, depth: int, max_depth: int, from_wire: bool) -> Any:
    """Validate (and copy) a plain JSON-like value; arrays from the wire become lists."""
    kind = type(value)
    if kind is str:
        if len(value) > MAX_STRING_CHARS:
            raise ProtocolError("", f"{len(value)} characters exceeds {MAX_STRING_CHARS}")
        return value
    if kind is bool or value is None:
        return value
    if kind is int:
        if not _MSGPACK_INT_MIN <= value <= _MSGPACK_INT_MAX:
            raise ProtocolError("", f"{_short(value)} does not fit a msgpack int")
        return value
    if kind is float:
        if not math.isfinite(value):
            raise ProtocolError("", f"must be finite, got {value!r}")
        return value
    if kind is dict or kind is list or (from_wire and kind is tuple):
        if depth > max_depth:
            raise ProtocolError("", f"nested deeper than {max_depth} levels")
        if kind is dict:
            out = {}
            for key, item in value.items():
                if type(key) is not str:
                    raise ProtocolError("", f"key {_short(key)} is not a str")
                if len(key) > MAX_STRING_CHARS:
                    raise ProtocolError("", f"key of {len(key)} characters exceeds 256")
                try:
                    out[key] = _plain_value(item, depth + 1, max_depth, from_wire)
                except ProtocolError as error:
                    raise error.prefixed(_key_path(key)) from None
            return out
        items = []
        for i, item in enumerate(value):
            try:
                items.append(_plain_value(item, depth + 1, max_depth, from_wire))
            except ProtocolError as error:
                raise error.prefixed(f"[{i}]") from None
        return items
    raise ProtocolError(
        "", f"expected str, int, float, bool, None, list or dict, got {_tname(value)}"
    )


class _PlainDict(_Spec):
    """A plain nested dict (scenario, metrics): str keys, JSON-like values, bounded depth."""

    __slots__ = ("max_depth",)

    def __init__(self, max_depth: int = MAX_DICT_DEPTH) -> None:
        self.max_depth = max_depth

    def check(self, value: Any) -> dict:
        if type(value) is not dict:
            raise ProtocolError("", f"expected dict, got {_tname(value)}")
        return _plain_value(value, 1, self.max_depth, True)

    def to_wire(self, value: Any) -> dict:
        if type(value) is not dict:
            raise ProtocolError("", f"expected dict, got {_tname(value)}")
        return _plain_value(value, 1, self.max_depth, False)


# --------------------------------------------------------------------------------------------
# The table: one spec per field, in dataclass field order, and one tag per message type.
# --------------------------------------------------------------------------------------------

_ROBOT_ID = _Int(0, MAX_ROBOT_ID)
_TICK = _Int(0, MAX_TICK)
_FINITE = _Float()
_BEARING = _Float(-math.pi - BEARING_TOLERANCE_RAD, math.pi + BEARING_TOLERANCE_RAD)

_FIELD_SPECS: dict[type, tuple[str, dict[str, _Spec]]] = {
    Join: ("join", {
        "robot_id": _ROBOT_ID,
        "brain": _Str(1),
        "pid": _Int(0, 2**32 - 1),
    }),
    Welcome: ("welcome", {
        "robot_id": _ROBOT_ID,
        "run": _Str(pattern=NAME_PATTERN),
        "seed": _Int(0, 2**64 - 1),
        "scenario": _PlainDict(),
        "samples": _Int(0, MAX_SAMPLES),
    }),
    RabMessage: ("rab", {
        "sender_id": _ROBOT_ID,
        "range_m": _Float(0.0, MAX_RANGE_M),
        "bearing_rad": _Float(-math.pi - BEARING_TOLERANCE_RAD, math.pi + BEARING_TOLERANCE_RAD),
        "payload": _Bytes(MAX_RAB_PAYLOAD_BYTES),
    }),
    EpuckSense: ("sense", {
        "tick": _TICK,
        "robot_id": _ROBOT_ID,
        "encoder_steps": _FloatTuple(2),
        "ir": _FloatTuple(8, 0.0, 1.0),
        "ground": _FloatTuple(3, 0.0, 2.0),
        "received": _Tuple(_Message(RabMessage), MAX_RECEIVED),
        "final": _Bool(),
    }),
    EpuckAct: ("act", {
        "tick": _TICK,
        "robot_id": _ROBOT_ID,
        "wheel_speed_steps_s": _FloatTuple(2, -MAX_WHEEL_SPEED_STEPS_S, MAX_WHEEL_SPEED_STEPS_S),
        "payload": _Bytes(MAX_RAB_PAYLOAD_BYTES, optional=True),
        "state": _Int(0, 255),
        "pose_estimate": _FloatTuple(3),
    }),
    SightingMsg: ("sighting", {
        "robot_id": _ROBOT_ID,
        "distance_m": _Float(0.0, MAX_RANGE_M),
        "bearing_rad": _BEARING,
        "relative_heading_rad": _BEARING,
    }),
    RadioMsg: ("radio", {
        "sender_id": _ROBOT_ID,
        "payload": _Bytes(MAX_RADIO_PAYLOAD_BYTES),
    }),
    LaserSense: ("laser_sense", {
        "tick": _TICK,
        "robot_id": _ROBOT_ID,
        "odometry_delta_s_m": _FINITE,
        "odometry_delta_phi_rad": _FINITE,
        "ranges_m": _Tuple(_Float(0.0, MAX_RANGE_M), MAX_BEAMS, min_len=1),
        "sightings": _Tuple(_Message(SightingMsg), MAX_TEAMMATES),
        "received": _Tuple(_Message(RadioMsg), MAX_TEAMMATES),
        "final": _Bool(),
    }),
    LandmarkMsg: ("landmark", {
        "landmark_id": _ROBOT_ID,
        "range_m": _Float(0.0, MAX_RANGE_M),
        "bearing_rad": _BEARING,
    }),
    ReplaySense: ("replay_sense", {
        "tick": _TICK,
        "robot_id": _ROBOT_ID,
        "time_s": _Float(0.0),
        "speed_mps": _FINITE,
        "turn_rate_rad_s": _FINITE,
        "dt_s": _Float(1e-9, 10.0),
        "landmarks": _Tuple(_Message(LandmarkMsg), MAX_TEAMMATES),
        "robots": _Tuple(_Message(LandmarkMsg), MAX_TEAMMATES),
        "received": _Tuple(_Message(RadioMsg), MAX_TEAMMATES),
        "final": _Bool(),
        "true_heading_rad": _Tuple(_BEARING, 1),
        "odometry_gap2_s2": _Tuple(_Float(0.0), 1),
    }),
    EstimateAct: ("estimate_act", {
        "tick": _TICK,
        "robot_id": _ROBOT_ID,
        "pose_estimate": _FloatTuple(3),
        "payload": _Bytes(MAX_RADIO_PAYLOAD_BYTES, optional=True),
        "command": _Tuple(_FINITE, 8),
        "samples": _Tuple(_FloatTuple(3), MAX_SAMPLES),
    }),
    VisionSense: ("vision_sense", {
        "tick": _TICK,
        "robot_id": _ROBOT_ID,
        "time_s": _Float(0.0),
        "image": _Bytes(MAX_IMAGE_BYTES),
        "odometry_pose": _FloatTuple(3),
        "head_pan_rad": _BEARING,
        "final": _Bool(),
    }),
    VisionAct: ("vision_act", {
        "tick": _TICK,
        "robot_id": _ROBOT_ID,
        "command": _FloatTuple(4, -1000.0, 1000.0),
        "estimates": _PlainDict(),
    }),
    WorldState: ("world_state", {
        "tick": _TICK,
        "time_s": _Float(0.0),
        "poses": _Tuple(_FloatTuple(3), MAX_POSES),
        "alive": _Tuple(_Bool(), MAX_POSES),
        "round_trips": _Int(0, MAX_TICK),
    }),
    RunEnd: ("run_end", {
        "tick": _TICK,
        "reason": _Str(1),
        "metrics": _PlainDict(),
    }),
    ErrorReport: ("error", {
        "code": _Str(pattern=r"[A-Za-z0-9_.-]{1,64}"),
        "field": _Str(),
        "detail": _Str(),
    }),
}  # fmt: skip


def _world_state_consistent(msg_fields: list) -> None:
    poses, alive = msg_fields[2], msg_fields[3]
    if len(alive) != len(poses):
        raise ProtocolError("alive", f"{len(alive)} flags for {len(poses)} poses")


#: Checks across fields, run after every field passed, given the checked values in field order.
_CROSS_CHECKS = {WorldState: _world_state_consistent}


def _slow(check: Any, name: str, value: Any) -> Any:
    """Run a field's full check, naming the field in its error."""
    try:
        return check(value)
    except ProtocolError as error:
        raise error.prefixed(name) from None


class _Codec:
    """Validation and (un)packing of one message type, compiled from its row of the table.

    The row is turned into four small Python functions (decode/encode, top-level/nested) that
    inline each field's ``fast_test`` and call the field's spec only when that test fails, so
    a valid message costs a few comparisons per field and an invalid one gets the spec's
    precise error. Decoding builds the instance through its slots, without ``__init__``: the
    values have been validated, and the frozen dataclass ``__init__`` costs twice as much.
    """

    __slots__ = (
        "cls",
        "cross_check",
        "decode_nested",
        "decode_top",
        "encode_nested",
        "encode_top",
        "names",
        "specs",
        "tag",
    )

    def __init__(self, cls: type, tag: str, specs: dict[str, _Spec]) -> None:
        names = tuple(cls.__dataclass_fields__)
        if names != tuple(specs):
            raise TypeError(f"specs of {cls.__name__} do not match its fields: {tuple(specs)}")
        if hasattr(cls, "__post_init__") or not hasattr(cls, "__slots__"):
            raise TypeError(f"{cls.__name__} must be a slots dataclass without __post_init__")
        self.cls, self.tag, self.names = cls, tag, names
        self.specs = tuple(specs.values())
        self.cross_check = _CROSS_CHECKS.get(cls)
        for spec in _walk_specs(self.specs):
            if isinstance(spec, _Message):
                spec.bind(_CODECS[spec.cls])  # KeyError: the nested type must come first
        self.decode_top = self._compile_decoder(nested=False)
        self.decode_nested = self._compile_decoder(nested=True)
        self.encode_top = self._compile_encoder(nested=False)
        self.encode_nested = self._compile_encoder(nested=True)

    def _namespace(self) -> dict[str, Any]:
        namespace: dict[str, Any] = {
            "_cls": self.cls, "_new": object.__new__, "_slow": _slow, "_tname": _tname,
            "ProtocolError": ProtocolError, "_key_error": self._key_error,
            "_cross_check": self.cross_check,
        }  # fmt: skip
        for i, (name, spec) in enumerate(zip(self.names, self.specs)):
            namespace[f"_check{i}"] = spec.check
            namespace[f"_to_wire{i}"] = spec.to_wire
            namespace[f"_set{i}"] = self.cls.__dict__[name].__set__  # the slot's descriptor
        return namespace

    def _compile(self, lines: list[str], function: str) -> Any:
        namespace = self._namespace()
        exec("\n".join(lines), namespace)  # noqa: S102 -- source built from the table only
        return namespace[function]

    def _compile_decoder(self, nested: bool) -> Any:
        n = len(self.names)
        lines = ["def decode(wire):"]
        if nested:
            lines += [
                "    if type(wire) is not dict:",
                "        raise ProtocolError('', 'expected dict, got ' + _tname(wire))",
            ]
        # Same length and every field present means exactly the expected keys ("v" and "t"
        # were checked by decode()); all lookups come first so a missing field is reported
        # before any field's value.
        lines += [
            f"    if len(wire) != {n if nested else n + 2}:",
            f"        _key_error(wire, {nested})",
            "    try:",
        ]
        lines += [f"        v{i} = wire[{name!r}]" for i, name in enumerate(self.names)]
        lines += ["    except KeyError:", f"        _key_error(wire, {nested})"]
        for i, (name, spec) in enumerate(zip(self.names, self.specs)):
            test = spec.fast_test(f"v{i}")
            slow = f"v{i} = _slow(_check{i}, {name!r}, v{i})"
            lines += [f"    if not ({test}):", f"        {slow}"] if test else [f"    {slow}"]
        values = ", ".join(f"v{i}" for i in range(n))
        if self.cross_check is not None:
            lines.append(f"    _cross_check([{values}])")
        lines.append("    obj = _new(_cls)")
        lines += [f"    _set{i}(obj, v{i})" for i in range(n)]
        lines.append("    return obj")
        return self._compile(lines, "decode")

    def _compile_encoder(self, nested: bool) -> Any:
        n = len(self.names)
        lines = ["def encode(msg):"]
        if nested:
            lines += [
                "    if type(msg) is not _cls:",
                f"        raise ProtocolError('', 'expected {self.cls.__name__}, got ' + _tname(msg))",
            ]
        lines += [f"    v{i} = msg.{name}" for i, name in enumerate(self.names)]
        for i, (name, spec) in enumerate(zip(self.names, self.specs)):
            test = spec.fast_test(f"v{i}")
            slow = f"v{i} = _slow(_to_wire{i}, {name!r}, v{i})"
            lines += [f"    if not ({test}):", f"        {slow}"] if test else [f"    {slow}"]
        if self.cross_check is not None:
            lines.append(f"    _cross_check([{', '.join(f'v{i}' for i in range(n))}])")
        items = [] if nested else [f"'v': {PROTOCOL_VERSION}", f"'t': {self.tag!r}"]
        items += [f"{name!r}: v{i}" for i, name in enumerate(self.names)]
        lines.append("    return {" + ", ".join(items) + "}")
        return self._compile(lines, "encode")

    def _key_error(self, wire: dict, nested: bool) -> None:
        for name in self.names:
            if name not in wire:
                raise ProtocolError(name, "missing field")
        expected = set(self.names) if nested else {*self.names, "v", "t"}
        extra = sorted((key for key in wire if key not in expected), key=repr)
        field = extra[0] if type(extra[0]) is str else _short(extra[0])
        raise ProtocolError(field, f"unknown field of {self.cls.__name__}")


def _walk_specs(specs: Any) -> Any:
    for spec in specs:
        yield spec
        if isinstance(spec, _Tuple):
            yield from _walk_specs((spec.item,))


_CODECS: dict[type, _Codec] = {}
for _cls, (_tag, _specs) in _FIELD_SPECS.items():
    _CODECS[_cls] = _Codec(_cls, _tag, _specs)
del _cls, _tag, _specs
_BY_TAG: dict[str, _Codec] = {codec.tag: codec for codec in _CODECS.values()}
#: Message type by wire tag.
MESSAGE_TYPES: dict[str, type] = {tag: codec.cls for tag, codec in _BY_TAG.items()}


def tag_of(cls: type) -> str:
    """The wire tag ("t") of a message type."""
    return _CODECS[cls].tag


# --------------------------------------------------------------------------------------------
# Message types from plugins (issue 48: a family added by a plugin brings its Sense and Act)
# --------------------------------------------------------------------------------------------


class Field:
    """The field specs a plugin's message type is declared with (:func:`register_message`): the
    same specs, with the same strict checks and error paths, as the shipped messages' table.

    - ``Field.int(lo, hi)``; ``Field.float(lo=-max, hi=max)`` (finite; an int is converted);
      ``Field.bool()``;
    - ``Field.str(min_chars=0, max_chars=256, pattern=None)``;
      ``Field.bytes(max_len, optional=False)`` (optional: None allowed);
    - ``Field.floats(length, lo, hi)``: a fixed-length tuple of floats (a pose);
    - ``Field.tuple(item_spec, max_len, min_len=0)``: a bounded tuple of one spec;
    - ``Field.message(cls)``: a nested message (registered first, or a shipped one);
    - ``Field.dict(max_depth=8)``: a plain JSON-like dict.
    """

    int = staticmethod(lambda lo, hi: _Int(lo, hi))
    float = staticmethod(lambda lo=-_MAX_FINITE, hi=_MAX_FINITE: _Float(lo, hi))
    bool = staticmethod(lambda: _Bool())
    str = staticmethod(lambda min_chars=0, max_chars=MAX_STRING_CHARS, pattern=None:
                       _Str(min_chars, max_chars, pattern))
    bytes = staticmethod(lambda max_len, optional=False: _Bytes(max_len, optional))
    floats = staticmethod(lambda length, lo=-_MAX_FINITE, hi=_MAX_FINITE: _FloatTuple(length, lo, hi))
    tuple = staticmethod(lambda item, max_len, min_len=0: _Tuple(item, max_len, min_len))
    message = staticmethod(lambda cls: _Message(cls))
    dict = staticmethod(lambda max_depth=MAX_DICT_DEPTH: _PlainDict(max_depth))


_TAG_RE = re.compile(r"[a-z][a-z0-9_.-]{0,63}")
#: Where each plugin message type was registered (``file:line``), for a clash's error.
_ORIGINS: dict[type, str] = {}


def register_message(cls: type, tag: str, fields: dict[str, _Spec]) -> type:
    """Make ``cls`` a protocol message with wire tag ``tag``, validated by ``fields`` (one
    :class:`Field` spec per dataclass field, in field order): :func:`encode` and :func:`decode`
    then take it like a shipped message, with the same strictness and error paths.

    ``cls`` must be a frozen slots dataclass without ``__post_init__``
    (``@dataclass(frozen=True, slots=True)``). Registering the same class again under the same tag
    is a no-op (a plugin imported twice); a tag or class already taken is a ValueError naming
    where it was registered. Returns ``cls``.
    """
    import sys

    frame = sys._getframe(1)
    origin = f"{frame.f_code.co_filename}:{frame.f_lineno}"
    if not isinstance(tag, str) or not _TAG_RE.fullmatch(tag):
        raise ValueError(f"message tag {tag!r}: expected lower-case letters, digits, '_', '.', '-' "
                         f"(1-64, a letter first)")
    if not isinstance(fields, dict) or not all(isinstance(v, _Spec) for v in fields.values()):
        raise TypeError(f"fields of {getattr(cls, '__name__', cls)!r}: expected a dict of Field specs")
    known = _CODECS.get(cls)
    if known is not None:
        if known.tag == tag:
            return cls
        raise ValueError(f"message type {cls.__name__} is already registered as {known.tag!r} "
                         f"(at {_ORIGINS.get(cls, 'swarmloc.protocol.messages')}); again as {tag!r} at {origin}")
    if tag in _BY_TAG:
        other = _BY_TAG[tag].cls
        raise ValueError(f"message tag {tag!r} is already {other.__name__}'s "
                         f"(at {_ORIGINS.get(other, 'swarmloc.protocol.messages')}); registered again "
                         f"for {cls.__name__} at {origin}")
    for spec in _walk_specs(fields.values()):
        if isinstance(spec, _Message) and spec.cls not in _CODECS:
            raise ValueError(f"{cls.__name__}: nested message type {spec.cls.__name__} is not "
                             f"registered (register it first)")
    codec = _Codec(cls, tag, fields)
    _CODECS[cls] = codec
    _BY_TAG[tag] = codec
    MESSAGE_TYPES[tag] = cls
    _ORIGINS[cls] = origin
    return cls


def unregister_message(cls: type) -> None:
    """Remove a message type :func:`register_message` added (tests; a shipped one stays)."""
    if cls not in _ORIGINS:
        raise ValueError(f"{getattr(cls, '__name__', cls)!r} is not a plugin message type")
    codec = _CODECS.pop(cls)
    del _BY_TAG[codec.tag], MESSAGE_TYPES[codec.tag], _ORIGINS[cls]


# --------------------------------------------------------------------------------------------
# Codec
# --------------------------------------------------------------------------------------------


def _unpack_limits(max_bytes: int) -> dict[str, Any]:
    # Bounds on every msgpack container so that a hostile header cannot make the unpacker
    # preallocate much; ext types (timestamps and others) are refused outright.
    return {
        "raw": False,
        "use_list": False,
        "strict_map_key": True,
        "max_str_len": max_bytes,
        "max_bin_len": max_bytes,
        "max_array_len": min(max_bytes, MAX_POSES),
        "max_map_len": max_bytes // 2,
        "max_ext_len": 0,
    }


_DEFAULT_UNPACK_LIMITS = _unpack_limits(MAX_MESSAGE_BYTES)
_packers = threading.local()  # msgpack.Packer is reusable but not meant to be shared by threads


def encode(msg: Any, *, max_bytes: int = MAX_MESSAGE_BYTES) -> bytes:
    """Validate ``msg`` and pack it; raise ProtocolError (naming the field) if it is invalid.

    ``int`` values of float fields are sent as floats and numpy scalars as Python numbers, so the
    decoded message may differ from ``msg`` in those types but compares equal.
    """
    codec = _CODECS.get(type(msg))
    if codec is None:
        raise TypeError(f"not a protocol message: {_tname(msg)}")
    wire = codec.encode_top(msg)
    try:
        packer = _packers.packer
    except AttributeError:
        packer = _packers.packer = msgpack.Packer(use_bin_type=True)
    data = packer.pack(wire)
    if len(data) > max_bytes:
        raise ProtocolError("message", f"{len(data)} bytes exceeds the limit of {max_bytes} bytes")
    return data


def decode(
    data: bytes | bytearray | memoryview,
    expected: type | tuple[type, ...] | None = None,
    *,
    max_bytes: int = MAX_MESSAGE_BYTES,
) -> Any:
    """Decode and validate one message; raise ProtocolError naming the field if it is invalid.

    ``expected`` restricts the accepted message types (a type or a tuple of types); a message of
    another type is rejected with field ``"t"``. ``max_bytes`` is the size limit; an observer
    that accepts WorldState for very large swarms may raise it.
    """
    size = data.nbytes if type(data) is memoryview else len(data)
    if size > max_bytes:
        raise ProtocolError("message", f"{size} bytes exceeds the limit of {max_bytes} bytes")
    limits = _DEFAULT_UNPACK_LIMITS if max_bytes == MAX_MESSAGE_BYTES else _unpack_limits(max_bytes)
    try:
        wire = msgpack.unpackb(data, **limits)
    except Exception as error:  # noqa: BLE001 -- msgpack raises many types, all mean "invalid"
        reason = f"{type(error).__name__}: {error}" if str(error) else type(error).__name__
        raise ProtocolError("message", f"not msgpack ({reason[:120]})") from None
    if type(wire) is not dict:
        raise ProtocolError("message", f"expected a msgpack map, got {_tname(wire)}")
    version = wire.get("v")
    if type(version) is not int or version != PROTOCOL_VERSION:
        if "v" not in wire:
            raise ProtocolError("v", "missing protocol version")
        raise ProtocolError("v", f"protocol version {_short(version)}, expected {PROTOCOL_VERSION}")
    tag = wire.get("t")
    codec = _BY_TAG.get(tag) if type(tag) is str else None
    if codec is None:
        if "t" not in wire:
            raise ProtocolError("t", "missing message type")
        raise ProtocolError("t", f"unknown message type {_short(tag)}")
    if (
        expected is not None
        and codec.cls is not expected
        and (type(expected) is not tuple or codec.cls not in expected)
    ):
        wanted = expected if type(expected) is tuple else (expected,)
        names = ", ".join(_CODECS[cls].tag if cls in _CODECS else repr(cls) for cls in wanted)
        raise ProtocolError("t", f"got {tag}, expected {names}")
    return codec.decode_top(wire)
