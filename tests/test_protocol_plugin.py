"""Message types registered by a plugin (issue 48): the codec takes them like shipped ones,
with the same strictness and error paths, and refuses clashes naming where the first came from."""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgpack
import pytest
from hypothesis import given
from hypothesis import strategies as st

from swarmloc.protocol import messages
from swarmloc.protocol.messages import (
    PROTOCOL_VERSION,
    EpuckSense,
    Field,
    LandmarkMsg,
    ProtocolError,
    decode,
    encode,
    register_message,
    unregister_message,
)


@dataclass(frozen=True, slots=True)
class Ping:
    sender_id: int
    range_m: float


@dataclass(frozen=True, slots=True)
class BeaconSense:
    tick: int
    robot_id: int
    ranges: tuple
    pings: tuple
    landmarks: tuple
    note: str


PING_FIELDS = {"sender_id": Field.int(0, 99), "range_m": Field.float(0.0, 10.0)}
SENSE_FIELDS = {
    "tick": Field.int(0, 2**53 - 1),
    "robot_id": Field.int(0, 65535),
    "ranges": Field.tuple(Field.float(0.0, 5.0), 4, min_len=1),
    "pings": Field.tuple(Field.message(Ping), 3),
    "landmarks": Field.tuple(Field.message(LandmarkMsg), 2),
    "note": Field.str(max_chars=8),
}


@pytest.fixture
def registered():
    register_message(Ping, "test.ping", PING_FIELDS)
    register_message(BeaconSense, "test.beacon_sense", SENSE_FIELDS)
    yield
    unregister_message(BeaconSense)
    unregister_message(Ping)


def sense(**changes) -> BeaconSense:
    values = {"tick": 3, "robot_id": 1, "ranges": (1.0, 2.5), "pings": (Ping(2, 0.5),),
              "landmarks": (LandmarkMsg(7, 1.5, -0.25),), "note": "ok"}
    values.update(changes)
    return BeaconSense(**values)


def wire(**fields) -> bytes:
    base = {"v": PROTOCOL_VERSION, "t": "test.beacon_sense", "tick": 3, "robot_id": 1,
            "ranges": [1.0], "pings": [], "landmarks": [], "note": ""}
    base.update(fields)
    return msgpack.packb(base, use_bin_type=True)


def test_a_registered_type_round_trips_with_its_nested_messages(registered):
    message = sense()
    assert decode(encode(message), BeaconSense) == message
    assert messages.MESSAGE_TYPES["test.beacon_sense"] is BeaconSense


def test_its_malformed_fields_are_refused_with_the_shipped_paths(registered):
    cases = {
        "ranges[1]": wire(ranges=[1.0, 7.0]),            # out of range in a tuple
        "ranges": wire(ranges=[]),                        # shorter than min_len
        "pings[0].sender_id": wire(pings=[{"sender_id": 100, "range_m": 1.0}]),  # nested plugin type
        "landmarks[0].bearing_rad": wire(landmarks=[{"landmark_id": 1, "range_m": 1.0, "bearing_rad": 9.0}]),
        "note": wire(note="far too long"),
        "tick": wire(tick=True),                          # bool is not an int
        "extra": wire(extra=1),                           # unknown field
    }
    for field, data in cases.items():
        with pytest.raises(ProtocolError) as caught:
            decode(data)
        assert caught.value.field == field, (field, caught.value)
    with pytest.raises(ProtocolError) as caught:
        encode(sense(ranges=(math.nan,)))
    assert caught.value.field == "ranges[0]"
    with pytest.raises(ProtocolError) as caught:
        decode(wire(), EpuckSense)                        # of another type than expected
    assert caught.value.field == "t"


def test_clashes_are_refused_naming_where_the_first_came_from(registered):
    assert register_message(Ping, "test.ping", PING_FIELDS) is Ping  # a plugin imported twice

    @dataclass(frozen=True, slots=True)
    class Other:
        x: float

    with pytest.raises(ValueError, match=r"'test.ping' is already Ping's \(at .*test_protocol_plugin.py:\d+\)"):
        register_message(Other, "test.ping", {"x": Field.float()})
    with pytest.raises(ValueError, match="already Join's"):
        register_message(Other, "join", {"x": Field.float()})
    with pytest.raises(ValueError, match="already registered as 'test.ping'"):
        register_message(Ping, "test.ping2", PING_FIELDS)


def test_bad_declarations_are_refused():
    @dataclass(frozen=True)
    class NoSlots:
        x: float

    @dataclass(frozen=True, slots=True)
    class Nested:
        inner: tuple

    with pytest.raises(TypeError, match="slots dataclass"):
        register_message(NoSlots, "test.noslots", {"x": Field.float()})
    with pytest.raises(TypeError, match="do not match its fields"):
        register_message(Ping, "test.ping", {"sender_id": Field.int(0, 1)})
    with pytest.raises(ValueError, match="message tag 'Bad Tag'"):
        register_message(Ping, "Bad Tag", PING_FIELDS)
    with pytest.raises(ValueError, match="nested message type Ping is not registered"):
        register_message(Nested, "test.nested", {"inner": Field.tuple(Field.message(Ping), 2)})
    assert Ping not in messages._CODECS


def test_after_unregistering_the_tag_is_unknown_again():
    register_message(Ping, "test.ping", PING_FIELDS)
    data = encode(Ping(1, 1.0))
    unregister_message(Ping)
    with pytest.raises(ProtocolError, match="unknown message type"):
        decode(data)
    with pytest.raises(ValueError, match="not a plugin message type"):
        unregister_message(EpuckSense)


@given(ranges=st.lists(st.floats(0.0, 5.0), min_size=1, max_size=4),
       pings=st.lists(st.tuples(st.integers(0, 99), st.floats(0.0, 10.0)), max_size=3),
       note=st.text(max_size=8))
def test_every_valid_message_round_trips(ranges, pings, note):
    register_message(Ping, "test.ping", PING_FIELDS)
    register_message(BeaconSense, "test.beacon_sense", SENSE_FIELDS)
    try:
        message = sense(ranges=tuple(ranges), pings=tuple(Ping(*p) for p in pings), note=note)
        assert decode(encode(message)) == message
    finally:
        unregister_message(BeaconSense)
        unregister_message(Ping)
