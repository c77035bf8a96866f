"""The compiled e-puck wire fast path (agents/epuck/wire.py) against protocol.messages.

``decode``/``encode`` are the reference. ``parse_sense`` must accept every Sense a served world
emits, with decode's values bit for bit, and whenever it accepts any other input decode must
accept it too with the same values (the one-way property); ``encode_act`` must give encode's bytes
and refuse exactly where encode raises. Mutated Senses are built here with msgpack directly (not
through the protocol encoder) from the msgpack spec (https://github.com/msgpack/msgpack/blob/
master/spec.md): key reordering, ints and float32 where float64 is expected, out-of-range values,
byte flips, truncation, trailing bytes.
"""

from __future__ import annotations

import math
import struct

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmloc.agents.epuck.wire import ACT_MAX_BYTES, N_PERCEPTS, encode_act, parse_sense
from swarmloc.protocol.messages import (
    BEARING_TOLERANCE_RAD,
    MAX_RAB_PAYLOAD_BYTES,
    MAX_RANGE_M,
    MAX_RECEIVED,
    MAX_ROBOT_ID,
    MAX_TICK,
    MAX_WHEEL_SPEED_STEPS_S,
    PROTOCOL_VERSION,
    EpuckAct,
    EpuckSense,
    ProtocolError,
    RabMessage,
    decode,
    encode,
)

SETTINGS = settings(max_examples=300, deadline=None,
                    suppress_health_check=[HealthCheck.too_slow, HealthCheck.data_too_large])


# ------------------------------------------------------------------------------------ helpers


class Parsed:
    def __init__(self) -> None:
        self.percepts = np.zeros(N_PERCEPTS)
        self.range_bearing = np.zeros((MAX_RECEIVED, 2))
        self.sender_len = np.zeros((MAX_RECEIVED, 2), np.int64)
        self.payload_start = np.zeros(MAX_RECEIVED, np.int64)
        self.tick = np.zeros(1, np.int64)

    def parse(self, buf: np.ndarray, robot_id: int) -> int:
        return parse_sense(buf, robot_id, self.percepts, self.range_bearing, self.sender_len,
                           self.payload_start, self.tick)


def bits(values) -> list[int]:
    return [struct.unpack(">Q", struct.pack(">d", v))[0] for v in values]


def assert_same_as_decode(data: bytes, out: Parsed, n: int) -> None:
    """decode(data) must accept, with the values parse_sense wrote (floats bit for bit)."""
    sense = decode(data, EpuckSense)
    assert not sense.final
    assert n == len(sense.received)
    assert out.tick[0] == sense.tick
    assert bits(out.percepts) == bits(sense.encoder_steps + sense.ir + sense.ground)
    for k, msg in enumerate(sense.received):
        assert out.sender_len[k, 0] == msg.sender_id
        assert bits(out.range_bearing[k]) == bits((msg.range_m, msg.bearing_rad))
        start, length = out.payload_start[k], out.sender_len[k, 1]
        assert data[start:start + length] == msg.payload


def one_way(data: bytes, robot_id: int) -> bool:
    """parse_sense on ``data``; if it accepts, decode must agree. True when it accepted."""
    out = Parsed()
    n = out.parse(np.frombuffer(data, np.uint8), robot_id)
    assert -1 <= n <= MAX_RECEIVED
    if n >= 0:
        assert_same_as_decode(data, out, n)
    return n >= 0


def wire(sense: EpuckSense) -> dict:
    """The map encode() builds for ``sense``, by hand (dataclass field order)."""
    return {
        "v": PROTOCOL_VERSION, "t": "sense", "tick": sense.tick, "robot_id": sense.robot_id,
        "encoder_steps": list(sense.encoder_steps), "ir": list(sense.ir),
        "ground": list(sense.ground),
        "received": [{"sender_id": m.sender_id, "range_m": m.range_m,
                      "bearing_rad": m.bearing_rad, "payload": m.payload} for m in sense.received],
        "final": sense.final,
    }  # fmt: skip


def pack(obj, **kwargs) -> bytes:
    return msgpack.packb(obj, use_bin_type=True, **kwargs)


def make_sense(n_received: int, robot_id: int = 7, tick: int = 300, final: bool = False,
               rng: np.random.Generator | None = None) -> EpuckSense:
    rng = rng or np.random.default_rng(n_received)
    received = tuple(
        RabMessage(int(rng.integers(0, MAX_ROBOT_ID + 1)), float(rng.uniform(0, MAX_RANGE_M)),
                   float(rng.uniform(-math.pi, math.pi)),
                   rng.integers(0, 256, int(rng.integers(0, MAX_RAB_PAYLOAD_BYTES + 1)),
                                np.uint8).tobytes())
        for _ in range(n_received))
    return EpuckSense(tick=tick, robot_id=robot_id,
                      encoder_steps=tuple(rng.normal(0, 50, 2).tolist()),
                      ir=tuple(rng.uniform(0, 1, 8).tolist()),
                      ground=tuple(rng.uniform(0, 2, 3).tolist()), received=received, final=final)


# ------------------------------------------------------------------------- served-world Senses


def _record(overrides: list[str], ticks: int) -> list[tuple[int, bytes]]:
    from swarmloc.agents.epuck.agent import ForagingAgent
    from swarmloc.agents.epuck.foraging import ForagingBrain, agent_rng
    from swarmloc.deploy.lab.netns import SMALL_ARENA
    from swarmloc.deploy.scenario import load_any
    from swarmloc.protocol.errors import ErrorCounter
    from swarmloc.world.service import served_world

    loaded = load_any("ES1", {}, ["world.robots=20", "world.duration_s=10", "world.seed=3",
                                  *SMALL_ARENA, *overrides])
    sc = loaded.scenario
    world = served_world(loaded)
    agents = [ForagingAgent(ForagingBrain(sc.agent, sc.world.body, [i],
                                          [agent_rng(sc.world.seed, i)], sc.world.tick_s), i)
              for i in range(sc.world.robots)]
    errors, out = ErrorCounter(), []
    for _ in range(ticks):
        acts = []
        for rid, data in world.senses():
            out.append((rid, data))
            acts.append(agents[rid].act(decode(data, EpuckSense), errors))
        world.step(acts)
    return out


@pytest.fixture(scope="module")
def served() -> list[tuple[int, bytes]]:
    """Every robot's Senses of two short ES1 runs, 20 robots in the small arena: the board's
    default decoding cap (1..4 messages), and a wide medium without cap (up to 16)."""
    return (_record([], 20)
            + _record(["world.medium.max_received_per_tick=16", "world.medium.range_m=0.6"], 20))


def test_parse_accepts_every_served_sense(served):
    counts = set()
    for rid, data in served:
        out = Parsed()
        n = out.parse(np.frombuffer(data, np.uint8), rid)
        assert n >= 0, "a Sense the world emitted was refused"
        assert_same_as_decode(data, out, n)
        counts.add(n)
    # The run exercised empty, small and full inboxes (16 is msgpack's array16 header).
    assert {0, 1, 2, 3, 4, 15, 16} <= counts


def test_parse_of_a_served_sense_is_refused_for_another_robot(served):
    rid, data = served[-1]
    assert Parsed().parse(np.frombuffer(data, np.uint8), rid + 1) == -1
    assert Parsed().parse(np.frombuffer(data, np.uint8), -1) == -1


@pytest.mark.parametrize("n_received", [0, 1, 15, 16])
def test_parse_constructed_senses(n_received):
    sense = make_sense(n_received)
    data = encode(sense)
    # msgpack spec: fixarray (0x90|n) up to 15 entries, array16 (0xdc, 2-byte length) above.
    header = bytes([0x90 | n_received]) if n_received <= 15 else b"\xdc" + n_received.to_bytes(2, "big")
    assert b"\xa8received" + header in data
    assert one_way(data, sense.robot_id)
    # array16 with fewer entries is not what msgpack emits but is the same message: either way.
    if n_received <= 15:
        i = data.index(b"\xa8received") + 9
        alt = data[:i] + b"\xdc" + n_received.to_bytes(2, "big") + data[i + 1:]
        assert decode(alt, EpuckSense) == decode(data, EpuckSense)
        one_way(alt, sense.robot_id)


def test_parse_refuses_final_wrong_robot_and_too_many_messages():
    sense = make_sense(3, robot_id=9)
    assert one_way(encode(sense), 9)
    assert not one_way(encode(make_sense(3, robot_id=9, final=True)), 9)
    assert not one_way(encode(sense), 8)
    # 17 messages: packed by hand (encode refuses it), decode refuses too.
    d = wire(make_sense(16, robot_id=9))
    d["received"].append(d["received"][0])
    data = pack(d)
    with pytest.raises(ProtocolError):
        decode(data, EpuckSense)
    assert not one_way(data, 9)


def test_parse_never_reads_past_the_end_of_buf():
    """Every truncation, given as a view of the full message: reading past the view's end would
    see the real continuation and could accept."""
    data = encode(make_sense(16))
    full = np.frombuffer(data, np.uint8)
    out = Parsed()
    for cut in range(len(data)):
        assert out.parse(full[:cut], 7) == -1


def test_parse_refuses_small_output_arrays():
    buf = np.frombuffer(encode(make_sense(2)), np.uint8)
    z = np.zeros
    i64 = np.int64
    good = (z(13), z((16, 2)), z((16, 2), i64), z(16, i64), z(1, i64))
    assert parse_sense(buf, 7, *good) == 2
    for i, small in enumerate((z(12), z((15, 2)), z((15, 2), i64), z(15, i64), z(0, i64))):
        args = list(good)
        args[i] = small
        assert parse_sense(buf, 7, *args) == -1


# Exact range edges of the Sense's float fields (protocol/messages.py, _FIELD_SPECS), and the
# next float64 beyond each: the edge is accepted by both, beyond it by neither.
_BEARING_EDGE = math.pi + BEARING_TOLERANCE_RAD
EDGES = [("ir", 0, 0.0, -1), ("ir", 3, 1.0, +1), ("ground", 1, 0.0, -1), ("ground", 2, 2.0, +1),
         ("range_m", None, 0.0, -1), ("range_m", None, MAX_RANGE_M, +1),
         ("bearing_rad", None, -_BEARING_EDGE, -1), ("bearing_rad", None, _BEARING_EDGE, +1),
         ("encoder_steps", 0, 1.7976931348623157e308, +1)]


@pytest.mark.parametrize(("field", "index", "edge", "side"), EDGES)
def test_parse_range_edges_as_decode(field, index, edge, side):
    for value, valid in ((edge, True), (math.nextafter(edge, side * math.inf), False)):
        d = wire(make_sense(2))
        if index is None:
            d["received"][1][field] = value
        else:
            d[field][index] = value
        data = pack(d)
        if valid:
            assert decode(data, EpuckSense) is not None
        else:
            with pytest.raises(ProtocolError):
                decode(data, EpuckSense)
        assert one_way(data, 7) == valid
    # -0.0 at a lower edge of 0: inside, and kept with its sign bit.
    d = wire(make_sense(2))
    d["ir"][0] = -0.0
    d["received"][0]["range_m"] = -0.0
    assert one_way(pack(d), 7)


# ---------------------------------------------------------------------- mutations (one-way)


def _floats_paths(d: dict) -> list[tuple]:
    paths = [(k, i) for k in ("encoder_steps", "ir", "ground") for i in range(len(d[k]))]
    for j in range(len(d["received"])):
        paths += [("received", j, "range_m"), ("received", j, "bearing_rad")]
    return paths


def _set(d: dict, path: tuple, value) -> None:
    target = d
    for p in path[:-1]:
        target = target[p]
    target[path[-1]] = value


def _get(d: dict, path: tuple):
    target = d
    for p in path:
        target = target[p]
    return target


_BASES = [make_sense(n, robot_id=rid, tick=tick, rng=np.random.default_rng(n + 100))
          for n, rid, tick in ((0, 0, 0), (2, 127, 127), (5, 128, 65535), (16, MAX_ROBOT_ID,
                                                                               MAX_TICK))]
_ODD_VALUES = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([-1.0, 1.0000000000000002, 2.0000000000000004, 100.00000000000001, -0.0,
                     -4.0, 4.0]),
    st.integers(-(2**63), 2**64 - 1), st.none(), st.booleans(), st.text(max_size=3),
    st.binary(max_size=3))

STRUCTURAL = ("reorder", "int_for_float", "float32", "odd_value", "odd_int", "truncate",
              "append", "extra_key")


@st.composite
def mutated(draw):
    base = draw(st.sampled_from(_BASES))
    kind = draw(st.sampled_from(STRUCTURAL + ("flip", "flip")))
    d = wire(base)
    if kind == "flip":
        data = bytearray(encode(base))
        for _ in range(draw(st.integers(1, 3))):
            i = draw(st.integers(0, len(data) - 1))
            data[i] ^= draw(st.integers(1, 255))
        return kind, base.robot_id, bytes(data)
    if kind == "truncate":
        data = encode(base)
        return kind, base.robot_id, data[:draw(st.integers(0, len(data) - 1))]
    if kind == "append":
        return kind, base.robot_id, encode(base) + draw(st.binary(min_size=1, max_size=4))
    if kind == "reorder":
        keys = list(d)
        i, j = draw(st.lists(st.integers(0, len(keys) - 1), min_size=2, max_size=2, unique=True))
        keys[i], keys[j] = keys[j], keys[i]
        d = {k: d[k] for k in keys}
        if base.received and draw(st.booleans()):  # or inside a received message
            m = d["received"][0]
            d["received"][0] = dict(reversed(m.items()))
    elif kind == "int_for_float":
        path = draw(st.sampled_from(_floats_paths(d)))
        _set(d, path, int(_get(d, path)))
    elif kind == "float32":
        return kind, base.robot_id, pack(d, use_single_float=True)
    elif kind == "odd_value":
        path = draw(st.sampled_from(_floats_paths(d) + [("final",), ("received",)]))
        _set(d, path, draw(_ODD_VALUES))
    elif kind == "odd_int":
        int_paths = [("tick",), ("robot_id",), ("v",)]
        int_paths += [("received", j, "sender_id") for j in range(len(d["received"]))]
        path = draw(st.sampled_from(int_paths))
        _set(d, path, draw(st.one_of(st.integers(-(2**63), 2**64 - 1), _ODD_VALUES)))
        if path == ("robot_id",):
            return kind, base.robot_id, pack(d)  # the agent's id stays the base's
    elif kind == "extra_key":
        d[draw(st.sampled_from(["x", "v", "tick"])) + "_"] = 0
    return kind, base.robot_id, pack(d)


def test_parse_mutations_one_way():
    seen = {"flip": [0, 0]}

    @SETTINGS
    @given(mutated())
    def check(case):
        kind, robot_id, data = case
        accepted = one_way(data, robot_id)
        if kind == "flip":
            seen["flip"][0] += 1
            seen["flip"][1] += not accepted
        elif kind in ("reorder", "int_for_float", "float32", "truncate", "append", "extra_key"):
            # Not the canonical form (or not a whole message): the fast path must say no.
            assert not accepted, kind

    check()
    flips, refused = seen["flip"]
    assert flips >= 30
    assert refused >= 0.3 * flips, f"only {refused} of {flips} byte flips refused"


def test_parse_many_byte_flips_one_way():
    """Deterministic complement of the Hypothesis test: every single-byte corruption of a
    16-message Sense, to 3 values each."""
    base = make_sense(16, robot_id=3)
    data = encode(base)
    refused = total = 0
    for i in range(len(data)):
        for x in (0x01, 0x80, 0xFF):
            mutated_data = bytearray(data)
            mutated_data[i] ^= x
            total += 1
            refused += not one_way(bytes(mutated_data), 3)
    assert refused >= 0.3 * total


# ------------------------------------------------------------------------------------ encode


def reference_act(tick, robot_id, wheel, payload, state, pose) -> bytes | None:
    try:
        return encode(EpuckAct(tick=tick, robot_id=robot_id, wheel_speed_steps_s=tuple(wheel),
                               payload=payload, state=state, pose_estimate=tuple(pose)))
    except ProtocolError:
        return None


def fast_act(tick, robot_id, wheel, payload, state, pose, out_size=ACT_MAX_BYTES) -> bytes | None:
    out = np.full(out_size, 0xEE, np.uint8)
    buf = np.frombuffer(payload or b"\0", np.uint8)
    n = encode_act(tick, robot_id, np.array(wheel, np.float64), buf,
                   -1 if payload is None else len(payload), state, np.array(pose, np.float64), out)
    return None if n == -1 else out[:n].tobytes()


def check_act(tick, robot_id, wheel, payload, state, pose) -> bytes | None:
    expected = reference_act(tick, robot_id, wheel, payload, state, pose)
    assert fast_act(tick, robot_id, wheel, payload, state, pose) == expected
    return expected


_W = MAX_WHEEL_SPEED_STEPS_S
_HAND = (
    [{"tick": t} for t in (0, 127, 128, 255, 256, 65535, 65536, 2**32 - 1, 2**32, MAX_TICK,
                            MAX_TICK + 1, -1)]
    + [{"robot_id": r} for r in (0, 127, 128, 255, 256, MAX_ROBOT_ID, MAX_ROBOT_ID + 1, -1)]
    + [{"state": s} for s in (0, 127, 128, 255, 256, -1)]
    + [{"payload": p} for p in (None, b"", b"\x00", bytes(range(64)), bytes(65))]
    + [{"wheel": w} for w in ((_W, -_W), (-0.0, 0.0), (math.nextafter(_W, 2e3), 0.0),
                               (0.0, math.nextafter(-_W, -2e3)), (math.nan, 0.0), (0.0, math.inf),
                               (1, 2))]
    + [{"pose": p} for p in ((-0.0, 0.0, -0.0), (1e308, -1e308, 5e-324), (math.inf, 0, 0),
                              (0, math.nan, 0), (0, 0, -math.inf))]
)


@pytest.mark.parametrize("case", _HAND, ids=repr)
def test_encode_act_hand_cases(case):
    args = {"tick": 42, "robot_id": 3, "wheel": (12.5, -300.25), "payload": b"abc", "state": 2,
                "pose": (0.1, -0.2, 3.0)}
    args.update(case)
    check_act(**args)


def test_encode_act_edges_refused_and_valid_as_expected():
    ok = {"tick": 1, "robot_id": 1, "wheel": (0.0, 0.0), "payload": None, "state": 0, "pose": (0.0, 0.0, 0.0)}
    assert check_act(**ok) is not None
    assert check_act(**{**ok, "tick": MAX_TICK}) is not None
    assert check_act(**{**ok, "tick": MAX_TICK + 1}) is None
    assert check_act(**{**ok, "wheel": (_W, -_W)}) is not None
    assert check_act(**{**ok, "state": 256}) is None
    data = check_act(**{**ok, "wheel": (-0.0, 0.0)})
    assert b"\x92\xcb\x80" + bytes(7) + b"\xcb" + bytes(8) in data  # -0.0 keeps its sign bit


def test_encode_act_small_out_and_bad_payload_len():
    args = (5, 6, np.zeros(2), np.zeros(64, np.uint8), 64, 1, np.zeros(3))
    size = len(encode(EpuckAct(5, 6, (0.0, 0.0), bytes(64), 1, (0.0, 0.0, 0.0))))
    assert encode_act(*args, np.zeros(size, np.uint8)) == size
    assert encode_act(*args, np.zeros(size - 1, np.uint8)) == -1
    payload = np.zeros(10, np.uint8)
    out = np.zeros(ACT_MAX_BYTES, np.uint8)
    assert encode_act(5, 6, np.zeros(2), payload, 11, 1, np.zeros(3), out) == -1
    assert encode_act(5, 6, np.zeros(2), payload, -2, 1, np.zeros(3), out) == -1


_ANY_FLOAT = st.one_of(st.floats(allow_nan=True, allow_infinity=True),
                       st.floats(-1.5 * _W, 1.5 * _W),
                       st.sampled_from([_W, -_W, -0.0, math.nextafter(_W, 2e3)]))


@SETTINGS
@given(tick=st.one_of(st.integers(-3, 2**40), st.integers(MAX_TICK - 3, MAX_TICK + 3)),
       robot_id=st.integers(-3, MAX_ROBOT_ID + 3), wheel=st.tuples(_ANY_FLOAT, _ANY_FLOAT),
       payload=st.one_of(st.none(), st.binary(max_size=MAX_RAB_PAYLOAD_BYTES + 2)),
       state=st.integers(-3, 260), pose=st.tuples(_ANY_FLOAT, _ANY_FLOAT, _ANY_FLOAT))
def test_encode_act_property(tick, robot_id, wheel, payload, state, pose):
    data = check_act(tick, robot_id, wheel, payload, state, pose)
    if data is not None:
        act = decode(data, EpuckAct)
        assert bits(act.wheel_speed_steps_s) == bits(wheel)
        assert bits(act.pose_estimate) == bits(pose)


_BOUNDSCHECK_SCRIPT = """
import numpy as np
from swarmloc.agents.epuck.wire import parse_sense
data = bytes.fromhex(HEX)
full = np.frombuffer(data, np.uint8)
out = (np.zeros(13), np.zeros((16, 2)), np.zeros((16, 2), np.int64), np.zeros(16, np.int64),
       np.zeros(1, np.int64))
rng = np.random.default_rng(5)
for cut in range(len(data) + 1):
    parse_sense(full[:cut], 7, *out)
for _ in range(3000):
    flipped = bytearray(data)
    flipped[rng.integers(len(data))] ^= rng.integers(1, 256)
    parse_sense(np.frombuffer(bytes(flipped), np.uint8), 7, *out)
print("ok")
"""


def test_parse_in_bounds_under_numba_boundscheck(tmp_path):
    """Every truncation and 3000 byte flips, compiled with NUMBA_BOUNDSCHECK=1 (an index outside
    any array raises IndexError), in a subprocess with its own cache directory."""
    import os
    import subprocess
    import sys

    script = _BOUNDSCHECK_SCRIPT.replace("HEX", repr(encode(make_sense(16)).hex()))
    env = {**os.environ, "NUMBA_BOUNDSCHECK": "1", "NUMBA_CACHE_DIR": str(tmp_path)}
    result = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True,
                            text=True, timeout=120, check=False)
    assert result.returncode == 0, result.stderr[-2000:]
    assert result.stdout.strip() == "ok"
