"""The compiled payload codec (agents/epuck/social_codec.py) against SocialMessages.encode / decode.

The Python methods are the reference: ``encode_payload`` must give their bytes and
``decode_payload`` must accept exactly what ``SocialMessages.decode`` accepts, with the same row,
bit for bit. Payloads are built here, independently of both, from the msgpack spec
(https://github.com/msgpack/msgpack/blob/master/spec.md): every header and integer width, float32
and float64, the other types in value positions, truncation, trailing bytes, byte flips; and,
exhaustively, every item of a valid message replaced by each of ~150 encodings.
"""

from __future__ import annotations

import math
import struct

import msgpack
import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from swarmloc.agents.epuck.foraging import SocialMessages
from swarmloc.agents.epuck.social_codec import (
    ENCODE_FLOAT_OVERFLOW,
    ENCODE_TOO_SMALL,
    PAYLOAD_MAX_BYTES,
    decode_payload,
    encode_payload,
)

PROPERTY = settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
FIELDS = ("goal_known", "goal_distance_m", "goal_angle_rad", "goal_p_m", "heard_ids",
          "heard_bearing_rad")
ANGLE_LIMIT = math.pi + 1e-5


# -- helpers ------------------------------------------------------------------------------------


def make_row(known, distance, angle, p, ids, bearings) -> SocialMessages:
    return SocialMessages(
        np.array([known], bool), np.array([distance], float), np.array([angle], float),
        np.array([p], float), np.array([ids], np.int64).reshape(1, -1),
        np.array([bearings], float).reshape(1, -1),
    )


def compiled_encode(msgs: SocialMessages, size: int = PAYLOAD_MAX_BYTES) -> bytes | int:
    out = np.full(size, 0xEE, np.uint8)
    n = encode_payload(msgs.goal_known[0], msgs.goal_distance_m[0], msgs.goal_angle_rad[0],
                       msgs.goal_p_m[0], msgs.heard_ids[0], msgs.heard_bearing_rad[0], out)
    return n if n < 0 else bytes(out[:n])


def python_encode(msgs: SocialMessages) -> bytes | int:
    """``SocialMessages.encode``, its OverflowError as the codec's return code."""
    try:
        return msgs.encode(0)
    except OverflowError:
        return ENCODE_FLOAT_OVERFLOW


def python_decode(payload: bytes, capacity: int) -> SocialMessages | None:
    try:
        return SocialMessages.decode([payload], capacity)
    except ValueError:
        return None


def garbage_rows(m: int, capacity: int) -> SocialMessages:
    """Arrays full of values no decode writes, so that a row left partly unwritten shows."""
    return SocialMessages(np.ones((m, 2), bool), np.full((m, 2), 7.25), np.full((m, 2), -7.25),
                          np.full((m, 2), np.nan), np.full((m, capacity), 4242, np.int64),
                          np.full((m, capacity), 9.5))


def compiled_decode(payload: bytes, capacity: int) -> SocialMessages | None:
    """Decode with junk before and after the slice, into row 1 of 3 garbage rows."""
    buf = np.frombuffer(b"\x93\xc0\x01" + payload + b"\x00\xcb\x92", np.uint8)
    c = garbage_rows(3, capacity)
    ok = decode_payload(buf, 3, 3 + len(payload), capacity, 1, c.goal_known, c.goal_distance_m,
                        c.goal_angle_rad, c.goal_p_m, c.heard_ids, c.heard_bearing_rad)
    # The other rows are never touched.
    untouched = garbage_rows(3, capacity)
    for f in FIELDS:
        assert same(getattr(c, f)[[0, 2]], getattr(untouched, f)[[0, 2]]), f
    return c.take(np.array([1])) if ok else None


def as_sent(x: np.ndarray) -> np.ndarray:
    """float64 values as they cross the wire: rounded to float32 (numpy's cast, independent of
    msgpack and of the codec), back in float64."""
    return x.astype(np.float32).astype(np.float64)


def same(a: np.ndarray, b: np.ndarray) -> bool:
    """Equal dtype, shape and bits."""
    if a.dtype != b.dtype or a.shape != b.shape:
        return False
    if a.dtype.kind == "f":
        return np.array_equal(a.view(np.uint64), b.view(np.uint64))
    return np.array_equal(a, b)


def assert_agree(payload: bytes, capacity: int) -> bool:
    expected = python_decode(payload, capacity)
    got = compiled_decode(payload, capacity)
    assert (got is None) == (expected is None), (payload.hex(), capacity, expected)
    if expected is not None:
        for f in FIELDS:
            assert same(getattr(got, f), getattr(expected, f)), (f, payload.hex())
    return expected is not None


# -- msgpack written by hand from the spec ------------------------------------------------------


def array_header(n: int, form: str = "fix") -> bytes:
    if form == "fix":
        assert n <= 15
        return bytes([0x90 | n])
    if form == "16":
        return b"\xdc" + struct.pack(">H", n)
    return b"\xdd" + struct.pack(">I", n)


def int_forms(v: int) -> list[bytes]:
    """Every msgpack encoding of the int ``v``."""
    forms = []
    if 0 <= v <= 0x7F:
        forms.append(bytes([v]))
    if -32 <= v < 0:
        forms.append(struct.pack(">b", v))
    for tag, fmt, lo, hi in ((0xCC, ">B", 0, 2**8 - 1), (0xCD, ">H", 0, 2**16 - 1),
                             (0xCE, ">I", 0, 2**32 - 1), (0xCF, ">Q", 0, 2**64 - 1),
                             (0xD0, ">b", -(2**7), 2**7 - 1), (0xD1, ">h", -(2**15), 2**15 - 1),
                             (0xD2, ">i", -(2**31), 2**31 - 1), (0xD3, ">q", -(2**63), 2**63 - 1)):
        if lo <= v <= hi:
            forms.append(bytes([tag]) + struct.pack(fmt, v))
    return forms


def f32(v: float) -> bytes:
    with np.errstate(over="ignore"):  # past float32's range: infinity, on purpose
        return b"\xca" + struct.pack(">f", np.float32(v).item())


def f64(v: float) -> bytes:
    return b"\xcb" + struct.pack(">d", v)


#: Values no slot accepts: nil, false, true, "", "x", empty bin, {}, [], ext, timestamp, 0xc1.
JUNK = [b"\xc0", b"\xc2", b"\xc3", b"\xa0", b"\xa1x", b"\xc4\x00", b"\x80", b"\x90",
        b"\xc7\x00\x05", b"\xd6\xff\x00\x00\x00\x00", b"\xc1", b"\x81\xa0\x01", b"\x91\x01"]

EDGE_FLOATS = [0.0, -0.0, 100.0, math.nextafter(100.0, math.inf), ANGLE_LIMIT,
               math.nextafter(ANGLE_LIMIT, math.inf), -ANGLE_LIMIT,
               math.nextafter(-ANGLE_LIMIT, -math.inf), math.pi, -math.pi, 1e7,
               math.nextafter(1e7, math.inf), -5e-324, 5e-324, 1e-40, math.nan, -math.nan,
               math.inf, -math.inf, 0.5, 3.0, -3.0]


@st.composite
def encoded_int(draw, values):
    v = draw(values)
    return draw(st.sampled_from(int_forms(v)))


@st.composite
def encoded_float(draw, values):
    v = draw(values)
    return f32(v) if draw(st.booleans()) else f64(v)


# In-range values (edges included) and values just out of range, for each slot.
DISTANCES = st.one_of(st.sampled_from([0.0, -0.0, 100.0, 5e-324]), st.floats(0.0, 100.0))
ANGLES = st.one_of(st.sampled_from([-ANGLE_LIMIT, ANGLE_LIMIT, math.pi, -math.pi, -0.0]),
                   st.floats(-math.pi, math.pi))
PS = st.one_of(st.sampled_from([0.0, -0.0, 1e7]), st.floats(0.0, 1e7))
IDS = st.one_of(st.sampled_from([0, 127, 128, 255, 256, 32767, 32768, 65535]),
                st.integers(0, 65535))
OUT_OF_RANGE = {
    "flags": st.sampled_from([4, 5, 127, 128, 255, -1, -3, -32, -33, 2**63 - 1, 2**64 - 1,
                              -(2**63)]),
    "distance": st.sampled_from([math.nextafter(100.0, math.inf), -5e-324, -1.0, 1e300,
                                 math.nan, math.inf, -math.inf]),
    "angle": st.sampled_from([math.nextafter(ANGLE_LIMIT, math.inf), -4.0, 1e300, math.nan,
                              math.inf, -math.inf]),
    "p": st.sampled_from([math.nextafter(1e7, math.inf), -5e-324, math.nan, math.inf]),
    "id": st.sampled_from([65536, 2**32, 2**63 - 1, 2**64 - 1, -1, -2, -31, -32, -33,
                           -(2**63)]),
    "bearing": st.sampled_from([math.nextafter(ANGLE_LIMIT, math.inf), 4.0, -1e300, math.nan,
                                -math.inf]),
}


@st.composite
def hand_built(draw):
    """A payload from hand-built msgpack, ``(payload, capacity)``: a valid message in random
    (mostly non-canonical) encodings, then 0 to 2 defects: an item of the wrong type or out of
    range, a wrong array length, more pairs than capacity, truncation, trailing bytes."""
    capacity = draw(st.integers(0, 3))
    pairs = draw(st.integers(0, capacity))
    slots = ["flags", "distance", "angle", "p", "distance", "angle", "p"]
    slots += ["id", "bearing"] * pairs
    good = {"flags": encoded_int(st.integers(0, 3)), "distance": encoded_float(DISTANCES),
            "angle": encoded_float(ANGLES), "p": encoded_float(PS), "id": encoded_int(IDS),
            "bearing": encoded_float(ANGLES)}
    items = [draw(good[name]) for name in slots]
    top_len, heard_len = 8, 2 * pairs
    trail = b""
    truncate = False
    for _ in range(draw(st.sampled_from([0, 0, 0, 1, 1, 2]))):
        defect = draw(st.sampled_from(["junk", "kind", "range", "range", "range", "top_len",
                                       "heard_len",
                                       "extra_pair", "heard_not_array", "truncate", "trail"]))
        # A kind of slot first, then one of its items: ids and bearings get their share.
        kind = draw(st.sampled_from(sorted(set(slots))))
        i = draw(st.sampled_from([j for j, name in enumerate(slots) if name == kind]))
        if defect == "junk":
            items[i] = draw(st.sampled_from(JUNK))
        elif defect == "kind":  # an int where a float goes and vice versa
            items[i] = (draw(encoded_float(st.sampled_from([0.0, 1.0, 3.0])))
                        if slots[i] in ("flags", "id") else draw(encoded_int(st.integers(0, 3))))
        elif defect == "range":
            value = draw(OUT_OF_RANGE[slots[i]])
            if slots[i] in ("flags", "id"):
                forms = int_forms(value)  # the shortest form half the time
                items[i] = draw(st.sampled_from(forms[:1] * len(forms) + forms))
            else:
                items[i] = draw(encoded_float(st.just(value)))
        elif defect == "top_len":
            top_len = draw(st.sampled_from([0, 7, 9, 15, 16, 17]))
        elif defect == "heard_len":
            heard_len = draw(st.sampled_from([heard_len + 1, max(heard_len - 1, 0), 17, 18]))
        elif defect == "extra_pair":
            slots += ["id", "bearing"]
            items += [draw(good["id"]), draw(good["bearing"])]
            heard_len += 2
        elif defect == "heard_not_array":
            heard_len = -1
        elif defect == "truncate":
            truncate = True
        elif defect == "trail":
            trail += draw(st.sampled_from([b"\x00", b"\xc0", b"\x90", f64(1.0), b"\xcb"]))
    forms = ["fix", "16", "32"] if 0 <= heard_len <= 15 else ["16", "32"]
    heard = (draw(st.sampled_from(JUNK + [b"\x03", f32(0.0)])) if heard_len < 0
             else array_header(heard_len, draw(st.sampled_from(forms))))
    top_forms = ["fix", "16", "32"] if top_len <= 15 else ["16", "32"]
    payload = (array_header(top_len, draw(st.sampled_from(top_forms))) + b"".join(items[:7])
               + heard + b"".join(items[7:]) + trail)
    if truncate:
        payload = payload[: draw(st.integers(0, len(payload) - 1))]
    return payload, capacity


id_values = st.one_of(st.sampled_from([0, 127, 128, 255, 256, 65535, 65536, -1, 2**32, 2**64 - 1]),
                      st.integers(0, 65535), st.integers(-(2**63), 2**64 - 1))


def messages_rows(max_k: int = 3, finite_only: bool = False):
    floats = st.floats(allow_nan=False, allow_infinity=False) if finite_only else st.floats()
    ranged = st.one_of(st.sampled_from(EDGE_FLOATS), floats)

    @st.composite
    def rows(draw):
        k = draw(st.integers(0, max_k))
        ids = draw(st.lists(st.one_of(st.just(-1), id_values.filter(lambda v: v < 2**63)),
                            min_size=k, max_size=k))
        return make_row(draw(st.lists(st.booleans(), min_size=2, max_size=2)),
                        draw(st.lists(ranged, min_size=2, max_size=2)),
                        draw(st.lists(ranged, min_size=2, max_size=2)),
                        draw(st.lists(ranged, min_size=2, max_size=2)),
                        ids, draw(st.lists(ranged, min_size=k, max_size=k)))

    return rows()


def valid_rows():
    """Rows that ``SocialMessages.decode`` accepts once encoded (values in range)."""

    @st.composite
    def rows(draw):
        k = draw(st.integers(0, 3))
        ids = draw(st.lists(st.one_of(st.just(-1), st.integers(0, 65535)), min_size=k,
                            max_size=k))
        return make_row(draw(st.lists(st.booleans(), min_size=2, max_size=2)),
                        draw(st.lists(st.floats(0.0, 100.0), min_size=2, max_size=2)),
                        draw(st.lists(st.floats(-math.pi, math.pi), min_size=2, max_size=2)),
                        draw(st.lists(st.floats(0.0, 1e7), min_size=2, max_size=2)),
                        ids, draw(st.lists(st.floats(-math.pi, math.pi), min_size=k, max_size=k)))

    return rows()


# -- encode -------------------------------------------------------------------------------------


def test_encode_hand_written_bytes():
    """Bytes worked out from the spec: ints in their shortest form, floats as float32."""
    msgs = make_row([True, True], [0.5, 100.0], [-0.25, -3.0], [1.0, 0.0],
                    [0, 127, 128, 255, 256, 65535], [0.5] * 6)
    expected = (b"\x98\x03" + f32(0.5) + f32(-0.25) + f32(1.0) + f32(100.0) + f32(-3.0) + f32(0.0)
                + b"\x9c" + b"\x00" + f32(0.5) + b"\x7f" + f32(0.5) + b"\xcc\x80" + f32(0.5)
                + b"\xcc\xff" + f32(0.5) + b"\xcd\x01\x00" + f32(0.5) + b"\xcd\xff\xff" + f32(0.5))
    assert compiled_encode(msgs, 128) == expected == msgs.encode(0)


def test_encode_full_heard_fits_the_board():
    """Capacity 3 with the widest ids (65535) fits PAYLOAD_MAX_BYTES: 32 + 1 + 3 * (3 + 5)."""
    msgs = make_row([True, False], [99.5, 0.0], [math.pi, -math.pi], [1e7, 0.0],
                    [65535, 65535, 65535], [-1.0, 0.0, 1.0])
    payload = compiled_encode(msgs)
    assert len(payload) == 57
    assert payload == msgs.encode(0)
    assert payload[32:] == b"\x96" + b"".join(b"\xcd\xff\xff" + f32(b) for b in (-1.0, 0.0, 1.0))


@pytest.mark.parametrize("known, flags", [([False, False], 0), ([True, False], 1),
                                          ([False, True], 2), ([True, True], 3)])
def test_encode_flags_and_empty_heard(known, flags):
    msgs = make_row(known, [1.0, 2.0], [0.0, -0.0], [3.0, 4.0], [-1, -1, -1], [1.0, 1.0, 1.0])
    expected = (bytes([0x98, flags]) + f32(1.0) + f32(0.0) + f32(3.0) + f32(2.0) + f32(-0.0)
                + f32(4.0) + b"\x90")
    assert compiled_encode(msgs) == expected == msgs.encode(0)


def test_encode_float32_rounding():
    """float64 -> float32 to nearest, ties to even (bits worked out by hand)."""
    one_and_half_ulp = 1.0 + 2.0**-24  # halfway between 1 and 1 + 2^-23: ties to 1.0 (even)
    three_halves_ulp = 1.0 + 3 * 2.0**-24  # halfway between 1 + 2^-23 and 1 + 2^-22: to the latter
    # Just under halfway from FLT_MAX = 2^128 - 2^104 (0x7f7fffff) to 2^128: rounds to FLT_MAX.
    below_overflow = math.nextafter(2.0**128 - 2.0**103, 0.0)
    msgs = make_row([True, False], [one_and_half_ulp, three_halves_ulp], [-0.1, -math.pi],
                    [below_overflow, 1 / 3], [7, 300, 70000], [-2.5, 0.1, -1e-50])
    got = compiled_encode(msgs)
    assert got == msgs.encode(0)
    assert got[2:7] == b"\xca\x3f\x80\x00\x00"
    assert got[17:22] == b"\xca\x3f\x80\x00\x02"
    assert got[12:17] == b"\xca\x7f\x7f\xff\xff"  # FLT_MAX
    assert got[7:12] == b"\xca" + struct.pack(">f", -0.1)
    assert got[32:] == (b"\x96\x07" + f32(-2.5) + b"\xcd\x01\x2c" + f32(0.1)
                        + b"\xce\x00\x01\x11\x70" + b"\xca\x80\x00\x00\x00")


@pytest.mark.parametrize("field", ["goal_distance_m", "goal_angle_rad", "goal_p_m",
                                   "heard_bearing_rad"])
def test_encode_float32_overflow(field):
    """A finite value at or past 2^128 - 2^103 (halfway from FLT_MAX to 2^128) rounds to
    infinity: msgpack raises OverflowError, the codec returns ENCODE_FLOAT_OVERFLOW; infinity
    itself and unsent bearings pass."""
    for value, expected in ((2.0**128 - 2.0**103, ENCODE_FLOAT_OVERFLOW),
                            (-1e39, ENCODE_FLOAT_OVERFLOW), (math.inf, None)):
        msgs = make_row([True, True], [1.0, 2.0], [0.0, 0.0], [3.0, 4.0], [1, -1], [0.1, 1e300])
        getattr(msgs, field)[0, 0] = value
        got = compiled_encode(msgs)
        assert got == python_encode(msgs)
        assert (got == ENCODE_FLOAT_OVERFLOW) == (expected is not None)


def test_encode_nan_payloads():
    """NaNs keep sign and top payload bits and come out quiet, as msgpack's C cast does."""
    nans = np.array([0x7FF0000000000001, 0xFFF8000000000000, 0x7FF8DEAD00000000,
                     0x7FF4000000000000], np.uint64).view(np.float64)
    msgs = make_row([True, True], nans[:2], nans[2:], [0.0, 0.0], [5], [nans[0]])
    got = compiled_encode(msgs)
    assert got == msgs.encode(0)
    assert got[2:22] == (b"\xca\x7f\xc0\x00\x00" + b"\xca\x7f\xc6\xf5\x68"
                         + b"\xca\x00\x00\x00\x00" + b"\xca\xff\xc0\x00\x00")


def test_encode_refuses_a_small_buffer():
    msgs = make_row([True, True], [1.0, 2.0], [0.0, 0.0], [3.0, 4.0], [1, 2, 3], [0.1, 0.2, 0.3])
    n = len(msgs.encode(0))  # 1 + 1 + 30 + 1 + 3 * (1 + 5)
    assert n == 51
    assert compiled_encode(msgs, n - 1) == ENCODE_TOO_SMALL
    assert compiled_encode(msgs, n) == msgs.encode(0)


@PROPERTY
@given(messages_rows())
def test_encode_equals_python(msgs):
    assert compiled_encode(msgs, 128) == python_encode(msgs)


@settings(max_examples=150, deadline=None)
@given(messages_rows(max_k=12))
def test_encode_equals_python_many_pairs(msgs):
    """More than 7 pairs needs an array16 header; ids above 2**32 need 0xcf."""
    assert compiled_encode(msgs, 512) == python_encode(msgs)


# -- decode -------------------------------------------------------------------------------------


def test_decode_hand_written_cases():
    """Accepted or refused by the spec and the checks of SocialMessages.decode (worked by hand)."""
    goals = f32(1.0) + f32(0.5) + f32(2.0) + f32(0.0) + f32(-0.5) + f32(0.0)
    ok = b"\x98\x01" + goals + b"\x90"
    cases = [
        (ok, 0, True),
        (b"\xdc\x00\x08\xd0\x01" + goals + b"\xdd\x00\x00\x00\x00", 0, True),  # wide headers/ints
        (b"\x98\xcf" + b"\x00" * 7 + b"\x03" + goals + b"\x92\xd3" + b"\x00" * 6 + b"\xff\xff"
         + f64(-math.pi), 1, True),  # id 65535 as int64, bearing as float64
        (b"\x98\x01" + goals + b"\x92\xce\x00\x01\x00\x00" + f32(0.0), 1, False),  # id 65536
        (b"\x98\x01" + goals + b"\x92\xe0" + f32(0.0), 1, False),  # id -32 (negative fixint)
        (b"\x98\x01" + goals + b"\x92\xd0\xff" + f32(0.0), 1, False),  # id -1 as int8
        (b"\x98\x01" + goals + b"\x92\xd0\x7f" + f32(0.0), 1, True),  # id 127 as int8
        (ok[:-1], 0, False),  # truncated
        (ok + b"\x00", 0, False),  # trailing byte (ExtraData)
        (b"\x98\xc3" + goals + b"\x90", 0, False),  # true is not an int
        (b"\x98\x04" + goals + b"\x90", 0, False),  # flags out of range
        (b"\x98\xff" + goals + b"\x90", 0, False),  # -1
        (b"\x98\x01" + b"\x01" + goals[5:] + b"\x90", 0, False),  # an int in a float slot
        (b"\x98\x01" + goals + b"\x92\x01" + f32(0.0), 0, False),  # more pairs than capacity
        (b"\x98\x01" + goals + b"\x91\x01", 1, False),  # odd heard
        (b"\x98\x01" + goals + b"\xc0", 1, False),  # heard is nil
        (b"\x98\x01" + f64(math.nextafter(100.0, 200.0)) + goals[5:] + b"\x90", 0, False),
        (b"\x98\x01" + f64(-0.0) + goals[5:] + b"\x90", 0, True),  # -0.0 <= d holds
        (b"\x98\x01" + f64(math.nan) + goals[5:] + b"\x90", 0, False),
        (b"\x98\x01" + goals + b"\x92\x01" + f64(ANGLE_LIMIT), 1, True),
        (b"\x98\x01" + goals + b"\x92\x01" + f64(math.nextafter(ANGLE_LIMIT, 9.0)), 1, False),
        (b"\x97\x01" + goals, 0, False),  # 7 items
        (b"\xdc\x00\x11" + b"\x00" * 17, 0, False),  # over max_array_len
        (b"", 0, False),
    ]
    for payload, capacity, valid in cases:
        assert (python_decode(payload, capacity) is not None) == valid, payload.hex()
        assert assert_agree(payload, capacity) == valid, payload.hex()


def substitutes() -> list[bytes]:
    """Many encodings of one item: every int form of edge values, float32 and float64 of edge
    values, the other types, small arrays."""
    ints = [0, 1, 2, 3, 4, 31, 127, 128, 255, 256, 32767, 32768, 65535, 65536, 2**31, 2**32,
            2**63 - 1, 2**64 - 1, -1, -2, -31, -32, -33, -128, -129, -(2**63)]
    floats = EDGE_FLOATS + [math.nextafter(0.0, -1.0), 1e300, -1e300, 0.1]
    return ([form for v in ints for form in int_forms(v)] + [f32(v) for v in floats]
            + [f64(v) for v in floats] + JUNK + [b"\x92\x01" + f32(0.0), b"\xdc\x00\x00"])


@pytest.mark.parametrize("capacity", [1, 2])
def test_decode_every_item_substitution(capacity):
    """Each item of a valid message (capacity 1: one pair) and each array header replaced by
    every substitute: the same verdict and row as the Python decode."""
    items = [b"\x03", f32(1.0), f32(-0.5), f32(2.0), f32(0.0), f32(3.0), f32(1e7), b"\x92",
             b"\x07", f32(-3.0)]
    accepted = 0
    for i in range(len(items)):
        for sub in substitutes() + [array_header(n, form) for n in range(18)
                                    for form in ("fix", "16", "32") if form != "fix" or n < 16]:
            payload = b"\x98" + b"".join(items[:i]) + sub + b"".join(items[i + 1:])
            accepted += assert_agree(payload, capacity)
    for top in [array_header(n, form) for n in range(18) for form in ("16", "32")]:
        accepted += assert_agree(top + b"".join(items), capacity)
    assert accepted > 100  # the test does exercise both verdicts


def test_decode_heard_longer_than_max_array_len():
    """With capacity 9 a heard array of 18 passes the length check but not msgpack's
    max_array_len=16."""
    goals = f32(1.0) * 6
    body = b"\x98\x00" + goals + b"\xdc\x00\x12" + (b"\x01" + f32(0.0)) * 9
    assert python_decode(body, 9) is None
    assert not assert_agree(body, 9)
    body16 = b"\x98\x00" + goals + b"\xdc\x00\x10" + (b"\x01" + f32(0.0)) * 8
    assert assert_agree(body16, 9)


@PROPERTY
@given(valid_rows())
def test_decode_of_encoded_rows(msgs):
    payload = msgs.encode(0)
    assert assert_agree(payload, msgs.heard_ids.shape[1])


@PROPERTY
@given(messages_rows(finite_only=False), st.integers(0, 3))
def test_round_trip(msgs, capacity):
    """decode(encode(x)) equals the Python decode of the same bytes, and, for rows in range,
    the float32-rounded row itself."""
    payload = compiled_encode(msgs, 128)
    if payload == ENCODE_FLOAT_OVERFLOW:
        assert python_encode(msgs) == ENCODE_FLOAT_OVERFLOW
        return
    valid = assert_agree(payload, capacity)
    sent = msgs.heard_ids[0] >= 0
    d, a, p = (as_sent(msgs.goal_distance_m), as_sent(msgs.goal_angle_rad), as_sent(msgs.goal_p_m))
    b = as_sent(msgs.heard_bearing_rad[0][sent])
    in_range = bool(
        np.all((d >= 0) & (d <= 100)) and np.all(np.abs(a) <= ANGLE_LIMIT)
        and np.all((p >= 0) & (p <= 1e7)) and np.all(np.abs(b) <= ANGLE_LIMIT)
        and np.all(msgs.heard_ids[0][sent] <= 65535) and sent.sum() <= capacity
    )
    assert valid == in_range
    if valid:
        got = compiled_decode(payload, capacity)
        assert same(got.goal_known, msgs.goal_known)
        for f in ("goal_distance_m", "goal_angle_rad", "goal_p_m"):
            assert same(getattr(got, f), as_sent(getattr(msgs, f)))
        n = int(sent.sum())
        assert same(got.heard_ids[0, :n], msgs.heard_ids[0][sent])
        assert same(got.heard_bearing_rad[0, :n], b)
        assert np.all(got.heard_ids[0, n:] == -1) and np.all(got.heard_bearing_rad[0, n:] == 0)


@settings(max_examples=1000, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(hand_built())
def test_decode_hand_built_payloads(case):
    payload, capacity = case
    assert_agree(payload, capacity)


@PROPERTY
@given(valid_rows(), st.data())
def test_decode_corrupted_payloads(msgs, data):
    payload = bytearray(msgs.encode(0))
    capacity = data.draw(st.integers(0, 3))
    how = data.draw(st.sampled_from(["flip", "bits", "truncate", "append", "random"]))
    if how == "flip":
        for _ in range(data.draw(st.integers(1, 3))):
            payload[data.draw(st.integers(0, len(payload) - 1))] = data.draw(st.integers(0, 255))
    elif how == "bits":
        i = data.draw(st.integers(0, len(payload) - 1))
        payload[i] ^= 1 << data.draw(st.integers(0, 7))
    elif how == "truncate":
        payload = payload[: data.draw(st.integers(0, len(payload) - 1))]
    elif how == "append":
        payload += data.draw(st.binary(min_size=1, max_size=8))
    else:
        payload = bytearray(data.draw(st.binary(max_size=80)))
    assert_agree(bytes(payload), capacity)


def test_decode_overwrites_the_whole_row():
    """A row filled with other values is fully rewritten, padding included."""
    payload = msgpack.packb([0, 1.0, 0.5, 2.0, 0.0, 0.0, 0.0, [9, 0.25]], use_single_float=False)
    c = garbage_rows(2, 3)
    buf = np.frombuffer(payload, np.uint8)
    assert decode_payload(buf, 0, len(payload), 3, 0, c.goal_known, c.goal_distance_m,
                          c.goal_angle_rad, c.goal_p_m, c.heard_ids, c.heard_bearing_rad)
    assert same(c.goal_known[0], np.array([False, False]))
    assert same(c.goal_distance_m[0], np.array([1.0, 0.0]))
    assert same(c.goal_angle_rad[0], np.array([0.5, 0.0]))
    assert same(c.goal_p_m[0], np.array([2.0, 0.0]))
    assert same(c.heard_ids[0], np.array([9, -1, -1]))
    assert same(c.heard_bearing_rad[0], np.array([0.25, 0.0, 0.0]))


def test_decode_refuses_what_the_arrays_cannot_hold():
    payload = msgpack.packb([0, 1.0, 0.5, 2.0, 0.0, 0.0, 0.0, []])
    buf = np.frombuffer(payload, np.uint8)
    c = garbage_rows(2, 3)
    args = (c.goal_known, c.goal_distance_m, c.goal_angle_rad, c.goal_p_m, c.heard_ids,
            c.heard_bearing_rad)
    assert decode_payload(buf, 0, len(payload), 3, 1, *args)
    assert not decode_payload(buf, 0, len(payload), 3, 2, *args)  # no row 2
    assert not decode_payload(buf, 0, len(payload), 3, -1, *args)
    assert not decode_payload(buf, 0, len(payload), 4, 0, *args)  # heard arrays too narrow
    # Python slice semantics: negative indices count from the end, out of range clamps.
    assert decode_payload(buf, -len(payload), 1000, 3, 0, *args)
    assert not decode_payload(buf, 1, len(payload), 3, 0, *args)
