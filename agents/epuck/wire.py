"""Compiled (numba) fast path for the e-puck Sense and Act wire messages (seed 000 §3.2, §4.3).

An e-puck agent process (seed 000's controller, one robot per process) spends much of its tick
decoding its :class:`~swarmloc.protocol.messages.EpuckSense` (the encoder, IR and ground readings
and the range-and-bearing messages of seed 000 §3.2) and encoding its
:class:`~swarmloc.protocol.messages.EpuckAct`. The two functions here do that from inside a
compiled tick, without Python objects or exceptions, on preallocated arrays:

- :func:`parse_sense` reads the raw Sense bytes. It is a FAST PATH: it accepts only the canonical
  form that ``protocol.messages.encode(EpuckSense(...))`` emits (msgpack
  ``Packer(use_bin_type=True)``, fields in dataclass order) and returns -1 for anything else (the
  caller then falls back to :func:`~swarmloc.protocol.messages.decode`). Whenever it accepts,
  ``decode(bytes, EpuckSense)`` accepts too, with the very same values (bit for bit).
- :func:`encode_act` writes exactly the bytes of ``encode(EpuckAct(...))``, and refuses (-1)
  exactly where ``encode`` raises :class:`~swarmloc.protocol.messages.ProtocolError`.
- :func:`encode_senses` is the world-server's side (issue 47): every live robot's Sense of one
  tick in one call, each exactly the bytes of ``encode(EpuckSense(...))``, refusing (-1) where
  ``encode`` would raise for any of them (the world then runs the reference, which raises the
  precise error).

The protocol codec (``protocol/messages.py``) stays the reference. Key names, lengths and bounds
are taken from its ``_FIELD_SPECS`` table at import, which also checks that the table still has
the layout this code was written for (a change there fails loudly at import, not silently here).
"""

from __future__ import annotations

import msgpack
import numpy as np
from numba import njit

from swarmloc.agents.epuck.social_codec import (
    _bits_of_f64,
    _f64_from_bits,
    _get_be,
    _put_be,
    _put_uint,
    _uint_size,
)
from swarmloc.protocol.messages import (
    _FIELD_SPECS,
    MAX_MESSAGE_BYTES,
    MAX_RAB_PAYLOAD_BYTES,
    MAX_RECEIVED,
    PROTOCOL_VERSION,
    EpuckAct,
    EpuckSense,
    RabMessage,
    _Bool,
    _Bytes,
    _Float,
    _FloatTuple,
    _Int,
    _Message,
    _Tuple,
)

#: Length of :func:`parse_sense`'s ``percepts``: encoder_steps (2), ir (8), ground (3).
N_PERCEPTS = 13
#: ``out`` size that always holds an EpuckAct (the largest is 162 bytes).
ACT_MAX_BYTES = 256

# ------------------------------------------------------------------ the layout, from the table

_SENSE_TAG, _SENSE = _FIELD_SPECS[EpuckSense]
_RAB_TAG, _RAB = _FIELD_SPECS[RabMessage]
_ACT_TAG, _ACT = _FIELD_SPECS[EpuckAct]


def _require(condition: bool, what: str) -> None:
    if not condition:
        raise RuntimeError(f"protocol/messages.py changed: {what}; update agents/epuck/wire.py")


_require(tuple(_SENSE) == ("tick", "robot_id", "encoder_steps", "ir", "ground", "received", "final"),
         "EpuckSense fields")
_require(tuple(_RAB) == ("sender_id", "range_m", "bearing_rad", "payload"), "RabMessage fields")
_require(tuple(_ACT) == ("tick", "robot_id", "wheel_speed_steps_s", "payload", "state",
                         "pose_estimate"), "EpuckAct fields")
_require(type(_SENSE["tick"]) is _Int and type(_SENSE["robot_id"]) is _Int, "Sense int fields")
_require(all(type(_SENSE[k]) is _FloatTuple for k in ("encoder_steps", "ir", "ground")),
         "Sense float tuples")
_require([_SENSE[k].length for k in ("encoder_steps", "ir", "ground")] == [2, 8, 3],
         "Sense tuple lengths")
_require(type(_SENSE["received"]) is _Tuple and type(_SENSE["received"].item) is _Message
         and _SENSE["received"].item.cls is RabMessage
         and _SENSE["received"].max_len == MAX_RECEIVED and _SENSE["received"].min_len == 0,
         "Sense received")
_require(type(_SENSE["final"]) is _Bool, "Sense final")
_require(type(_RAB["sender_id"]) is _Int and type(_RAB["range_m"]) is _Float
         and type(_RAB["bearing_rad"]) is _Float and type(_RAB["payload"]) is _Bytes
         and not _RAB["payload"].optional and _RAB["payload"].max_len == MAX_RAB_PAYLOAD_BYTES,
         "RabMessage specs")
_require(type(_ACT["tick"]) is _Int and type(_ACT["robot_id"]) is _Int
         and type(_ACT["state"]) is _Int and type(_ACT["wheel_speed_steps_s"]) is _FloatTuple
         and _ACT["wheel_speed_steps_s"].length == 2 and type(_ACT["pose_estimate"]) is _FloatTuple
         and _ACT["pose_estimate"].length == 3 and type(_ACT["payload"]) is _Bytes
         and _ACT["payload"].optional and _ACT["payload"].max_len == MAX_RAB_PAYLOAD_BYTES,
         "EpuckAct specs")
_require(0 <= PROTOCOL_VERSION <= 0x7F and MAX_RECEIVED <= 0xFFFF and MAX_RAB_PAYLOAD_BYTES <= 0xFF,
         "wire sizes")
_require(all(spec.lo >= 0 for spec in (_SENSE["tick"], _SENSE["robot_id"], _RAB["sender_id"],
                                       _ACT["tick"], _ACT["robot_id"], _ACT["state"])),
         "unsigned int fields")

# Bounds (Python values; numba freezes module globals as compile-time constants).
_S_TICK_LO, _S_TICK_HI = _SENSE["tick"].lo, _SENSE["tick"].hi
_S_ID_LO, _S_ID_HI = _SENSE["robot_id"].lo, _SENSE["robot_id"].hi
_ENC_LO, _ENC_HI = _SENSE["encoder_steps"].lo, _SENSE["encoder_steps"].hi
_IR_LO, _IR_HI = _SENSE["ir"].lo, _SENSE["ir"].hi
_GROUND_LO, _GROUND_HI = _SENSE["ground"].lo, _SENSE["ground"].hi
_SENDER_LO, _SENDER_HI = _RAB["sender_id"].lo, _RAB["sender_id"].hi
_RANGE_LO, _RANGE_HI = _RAB["range_m"].lo, _RAB["range_m"].hi
_BEARING_LO, _BEARING_HI = _RAB["bearing_rad"].lo, _RAB["bearing_rad"].hi
_A_TICK_LO, _A_TICK_HI = _ACT["tick"].lo, _ACT["tick"].hi
_A_ID_LO, _A_ID_HI = _ACT["robot_id"].lo, _ACT["robot_id"].hi
_WHEEL_LO, _WHEEL_HI = _ACT["wheel_speed_steps_s"].lo, _ACT["wheel_speed_steps_s"].hi
_POSE_LO, _POSE_HI = _ACT["pose_estimate"].lo, _ACT["pose_estimate"].hi
_STATE_LO, _STATE_HI = _ACT["state"].lo, _ACT["state"].hi


def _key(name: str) -> bytes:
    return msgpack.packb(name, use_bin_type=True)


def _map_header(n: int) -> bytes:
    _require(n <= 15, "a map of more than 15 entries")
    return bytes([0x80 | n])


def _array_header(n: int) -> bytes:
    _require(n <= 15, "a fixed tuple of more than 15 entries")
    return bytes([0x90 | n])


def _token(data: bytes) -> np.ndarray:
    return np.array(list(data), dtype=np.uint8)


# Fixed byte runs of the canonical Sense, between its variable values.
_T_SENSE_HEAD = _token(_map_header(2 + len(_SENSE)) + _key("v") + bytes([PROTOCOL_VERSION])
                       + _key("t") + _key(_SENSE_TAG) + _key("tick"))
_T_ROBOT_ID = _token(_key("robot_id"))
_T_ENCODER = _token(_key("encoder_steps") + _array_header(2))
_T_IR = _token(_key("ir") + _array_header(8))
_T_GROUND = _token(_key("ground") + _array_header(3))
_T_RECEIVED = _token(_key("received"))
_T_RAB_HEAD = _token(_map_header(len(_RAB)) + _key("sender_id"))
_T_RANGE = _token(_key("range_m"))
_T_BEARING = _token(_key("bearing_rad"))
_T_PAYLOAD = _token(_key("payload"))
_T_FINAL = _token(_key("final"))
# ... and of the canonical Act.
_T_ACT_HEAD = _token(_map_header(2 + len(_ACT)) + _key("v") + bytes([PROTOCOL_VERSION])
                     + _key("t") + _key(_ACT_TAG) + _key("tick"))
_T_WHEEL = _token(_key("wheel_speed_steps_s") + _array_header(2))
_T_STATE = _token(_key("state"))
_T_POSE = _token(_key("pose_estimate") + _array_header(3))

_NIL, _FALSE, _TRUE, _BIN8, _FLOAT64, _ARRAY16 = 0xC0, 0xC2, 0xC3, 0xC4, 0xCB, 0xDC


# ------------------------------------------------------------------------------------ parse


@njit(cache=True, inline="always", error_model="numpy")
def _expect(buf, pos, token):
    """Position after ``token`` if ``buf[pos:]`` starts with it, else -1."""
    n = token.shape[0]
    if pos < 0 or pos + n > buf.shape[0]:
        return -1
    for j in range(n):
        if buf[pos + j] != token[j]:
            return -1
    return pos + n


@njit(cache=True, inline="always", error_model="numpy")
def _get_uint(buf, pos):
    """A msgpack unsigned int (positive fixint, 0xcc..0xcf) at ``buf[pos]``: ``(value, next)``;
    next is -1 for anything else, a truncated value, or a value above 2**63 - 1."""
    if pos < 0 or pos >= buf.shape[0]:
        return 0, -1
    b = np.int64(buf[pos])
    if b <= 0x7F:
        return b, pos + 1
    if b < 0xCC or b > 0xCF:
        return 0, -1
    nbytes = 1 << (b - 0xCC)
    if pos + 1 + nbytes > buf.shape[0]:
        return 0, -1
    bits = _get_be(buf, pos + 1, nbytes)
    if bits > np.uint64(0x7FFFFFFFFFFFFFFF):
        return 0, -1
    return np.int64(bits), pos + 1 + nbytes


@njit(cache=True, inline="always", error_model="numpy")
def _get_f64(buf, pos, lo, hi):
    """A msgpack float64 (0xcb) at ``buf[pos]`` within ``[lo, hi]``: ``(value, next)``; next is
    -1 for any other form, a truncated value, NaN or a value out of range."""
    if pos < 0 or pos + 9 > buf.shape[0] or buf[pos] != _FLOAT64:
        return 0.0, -1
    value = _f64_from_bits(_get_be(buf, pos + 1, 8))
    if not (lo <= value <= hi):  # NaN fails too
        return 0.0, -1
    return value, pos + 9


@njit(cache=True, error_model="numpy")
def parse_sense(buf, robot_id, percepts, range_bearing, sender_len, payload_start, tick_out):
    """Parse the canonical msgpack of an EpuckSense for robot ``robot_id``.

    ``buf`` uint8 (n,), the whole message (may be read-only). On success writes ``percepts``
    float64 (>= 13,) = encoder_steps (2), ir (8), ground (3); per received message ``k``:
    ``range_bearing[k] = (range_m, bearing_rad)`` float64 (>= 16, 2),
    ``sender_len[k] = (sender_id, payload length)`` int64 (>= 16, 2), ``payload_start[k]`` int64
    (>= 16,) the offset of its payload in ``buf``; ``tick_out[0]`` the tick; and returns the
    number of received messages (0..16). Returns -1 (outputs then unspecified) for anything but
    the canonical form ``encode(EpuckSense(...))`` emits with ``final`` false and this robot's id,
    and for output arrays too small. Never reads outside ``buf``.
    """
    size = buf.shape[0]
    if size > MAX_MESSAGE_BYTES:
        return -1
    if (percepts.shape[0] < N_PERCEPTS or range_bearing.shape[0] < MAX_RECEIVED
            or range_bearing.shape[1] < 2 or sender_len.shape[0] < MAX_RECEIVED
            or sender_len.shape[1] < 2 or payload_start.shape[0] < MAX_RECEIVED
            or tick_out.shape[0] < 1):
        return -1
    pos = _expect(buf, 0, _T_SENSE_HEAD)
    tick, pos = _get_uint(buf, pos)
    if pos < 0 or not (_S_TICK_LO <= tick <= _S_TICK_HI):
        return -1
    pos = _expect(buf, pos, _T_ROBOT_ID)
    rid, pos = _get_uint(buf, pos)
    if pos < 0 or not (_S_ID_LO <= rid <= _S_ID_HI) or rid != robot_id:
        return -1
    pos = _expect(buf, pos, _T_ENCODER)
    for i in range(2):
        value, pos = _get_f64(buf, pos, _ENC_LO, _ENC_HI)
        percepts[i] = value
    pos = _expect(buf, pos, _T_IR)
    for i in range(8):
        value, pos = _get_f64(buf, pos, _IR_LO, _IR_HI)
        percepts[2 + i] = value
    pos = _expect(buf, pos, _T_GROUND)
    for i in range(3):
        value, pos = _get_f64(buf, pos, _GROUND_LO, _GROUND_HI)
        percepts[10 + i] = value
    pos = _expect(buf, pos, _T_RECEIVED)
    if pos < 0 or pos >= size:
        return -1
    head = np.int64(buf[pos])
    if 0x90 <= head <= 0x9F:  # fixarray
        count = head & 0x0F
        pos += 1
    elif head == _ARRAY16 and pos + 3 <= size:  # what msgpack emits for 16 and more
        count = np.int64(_get_be(buf, pos + 1, 2))
        pos += 3
    else:
        return -1
    if count > MAX_RECEIVED:
        return -1
    for k in range(count):
        pos = _expect(buf, pos, _T_RAB_HEAD)
        sender, pos = _get_uint(buf, pos)
        if pos < 0 or not (_SENDER_LO <= sender <= _SENDER_HI):
            return -1
        pos = _expect(buf, pos, _T_RANGE)
        range_m, pos = _get_f64(buf, pos, _RANGE_LO, _RANGE_HI)
        pos = _expect(buf, pos, _T_BEARING)
        bearing_rad, pos = _get_f64(buf, pos, _BEARING_LO, _BEARING_HI)
        pos = _expect(buf, pos, _T_PAYLOAD)
        if pos < 0 or pos + 2 > size or buf[pos] != _BIN8:
            return -1
        length = np.int64(buf[pos + 1])
        if length > MAX_RAB_PAYLOAD_BYTES or pos + 2 + length > size:
            return -1
        range_bearing[k, 0] = range_m
        range_bearing[k, 1] = bearing_rad
        sender_len[k, 0] = sender
        sender_len[k, 1] = length
        payload_start[k] = pos + 2
        pos += 2 + length
    pos = _expect(buf, pos, _T_FINAL)
    # final true: the caller must see it, through the reference decoder; no trailing bytes.
    if pos < 0 or pos + 1 != size or buf[pos] != _FALSE:
        return -1
    tick_out[0] = tick
    return count


# ----------------------------------------------------------------------------------- encode


@njit(cache=True, inline="always", error_model="numpy")
def _put_token(out, pos, token):
    for j in range(token.shape[0]):
        out[pos + j] = token[j]
    return pos + token.shape[0]


@njit(cache=True, inline="always", error_model="numpy")
def _put_f64(out, pos, value):
    out[pos] = np.uint8(_FLOAT64)
    return _put_be(out, pos + 1, _bits_of_f64(value), 8)


@njit(cache=True, error_model="numpy")
def encode_act(tick, robot_id, wheel, payload, payload_len, state, pose, out):
    """Write ``encode(EpuckAct(tick, robot_id, (wheel[0], wheel[1]), payload, state,
    (pose[0], pose[1], pose[2])))`` into ``out[:n]`` and return ``n``.

    ``wheel`` float64 (2,) steps/s, ``payload`` uint8 (>= payload_len,), ``payload_len`` -1 for
    None (msgpack nil) else the payload's length, ``state`` int, ``pose`` float64 (3,)
    (x_m, y_m, theta_rad), ``out`` uint8 (``ACT_MAX_BYTES`` always suffices). Returns -1 (nothing
    valid written) where ``encode`` raises ProtocolError (wheel speed beyond
    +-MAX_WHEEL_SPEED_STEPS_S or NaN, non-finite pose, state outside 0..255, payload longer than
    MAX_RAB_PAYLOAD_BYTES, tick or robot_id out of range), and for arrays too small.
    """
    if not (_A_TICK_LO <= tick <= _A_TICK_HI) or not (_A_ID_LO <= robot_id <= _A_ID_HI):
        return -1
    if not (_STATE_LO <= state <= _STATE_HI):
        return -1
    if wheel.shape[0] < 2 or pose.shape[0] < 3:
        return -1
    for i in range(2):
        if not (_WHEEL_LO <= wheel[i] <= _WHEEL_HI):
            return -1
    for i in range(3):
        if not (_POSE_LO <= pose[i] <= _POSE_HI):
            return -1
    if payload_len < -1 or payload_len > MAX_RAB_PAYLOAD_BYTES or payload_len > payload.shape[0]:
        return -1
    payload_size = 1 if payload_len < 0 else 2 + payload_len
    size = (_T_ACT_HEAD.shape[0] + _uint_size(tick) + _T_ROBOT_ID.shape[0] + _uint_size(robot_id)
            + _T_WHEEL.shape[0] + 2 * 9 + _T_PAYLOAD.shape[0] + payload_size
            + _T_STATE.shape[0] + _uint_size(state) + _T_POSE.shape[0] + 3 * 9)
    if out.shape[0] < size:
        return -1
    pos = _put_token(out, 0, _T_ACT_HEAD)
    pos = _put_uint(out, pos, tick)
    pos = _put_token(out, pos, _T_ROBOT_ID)
    pos = _put_uint(out, pos, robot_id)
    pos = _put_token(out, pos, _T_WHEEL)
    for i in range(2):
        pos = _put_f64(out, pos, wheel[i])
    pos = _put_token(out, pos, _T_PAYLOAD)
    if payload_len < 0:
        out[pos] = np.uint8(_NIL)
        pos += 1
    else:
        out[pos] = np.uint8(_BIN8)
        out[pos + 1] = np.uint8(payload_len)
        pos += 2
        for j in range(payload_len):
            out[pos + j] = payload[j]
        pos += payload_len
    pos = _put_token(out, pos, _T_STATE)
    pos = _put_uint(out, pos, state)
    pos = _put_token(out, pos, _T_POSE)
    for i in range(3):
        pos = _put_f64(out, pos, pose[i])
    return pos


#: Bytes of a Sense without received messages, at most (tick and robot id at their widest).
SENSE_BASE_MAX_BYTES = (_T_SENSE_HEAD.shape[0] + 9 + _T_ROBOT_ID.shape[0] + 9 + _T_ENCODER.shape[0]
                        + _T_IR.shape[0] + _T_GROUND.shape[0] + 13 * 9 + _T_RECEIVED.shape[0] + 3
                        + _T_FINAL.shape[0] + 1)
#: Bytes one received message adds, at most.
RAB_MAX_BYTES = (_T_RAB_HEAD.shape[0] + 9 + _T_RANGE.shape[0] + 9 + _T_BEARING.shape[0] + 9
                 + _T_PAYLOAD.shape[0] + 2 + MAX_RAB_PAYLOAD_BYTES)


@njit(cache=True, inline="always", error_model="numpy")
def _put_f64_row(out, pos, row, lo, hi):
    """Every value of ``row`` as msgpack float64 from ``out[pos]``; -1 if one is outside
    ``[lo, hi]`` or NaN."""
    for c in range(row.shape[0]):
        if not (lo <= row[c] <= hi):
            return -1
        pos = _put_f64(out, pos, row[c])
    return pos


@njit(cache=True, error_model="numpy")
def encode_senses(tick, robots, encoder, ir, ground, d_sender, d_receiver, d_range, d_bearing,
                  payloads, payload_len, out, offsets):
    """Write the Sense of every robot in ``robots`` (int64, ascending) for ``tick`` into ``out``:
    robot ``robots[i]``'s message is ``out[offsets[i]:offsets[i + 1]]``, byte for byte
    ``encode(EpuckSense(tick, r, tuple(encoder[r]), tuple(ir[r]), tuple(ground[r]), received,
    False))``, where ``received`` holds, in delivery order, a :class:`RabMessage` for each
    delivery ``j`` to ``r`` (``d_receiver[j] == r``) whose sender sends (``payload_len[s] >= 0``;
    its payload ``payloads[s, :payload_len[s]]``). What ``ForagingService`` built in Python.

    ``encoder`` (n, 2), ``ir`` (n, 8), ``ground`` (n, 3) float64; deliveries as the medium's
    arrays; ``payloads`` uint8 (n, >= 64); ``payload_len`` int64 (n,), -1 for no message;
    ``out`` uint8 (at least ``len(robots) * SENSE_BASE_MAX_BYTES + deliveries * RAB_MAX_BYTES``);
    ``offsets`` int64 (len(robots) + 1,). Returns the bytes written, or -1 where ``encode``
    raises for some robot (a reading out of its bounds or not finite, more than ``MAX_RECEIVED``
    messages, a payload too long, an id out of range) or the arrays do not fit.
    """
    n = encoder.shape[0]
    m = robots.shape[0]
    if offsets.shape[0] < m + 1 or not (_S_TICK_LO <= tick <= _S_TICK_HI):
        return -1
    if ir.shape[0] != n or ground.shape[0] != n or payload_len.shape[0] != n or payloads.shape[0] != n:
        return -1
    # deliveries grouped by receiver, in their order (a stable counting sort)
    count = np.zeros(n + 1, np.int64)
    for j in range(d_receiver.shape[0]):
        r = d_receiver[j]
        s = d_sender[j]
        if r < 0 or r >= n or s < 0 or s >= n:
            return -1
        if payload_len[s] >= 0:
            count[r + 1] += 1
    for r in range(n):
        count[r + 1] += count[r]
    order = np.empty(count[n], np.int64)
    fill = count[:n].copy()
    for j in range(d_receiver.shape[0]):
        if payload_len[d_sender[j]] >= 0:
            order[fill[d_receiver[j]]] = j
            fill[d_receiver[j]] += 1
    pos = 0
    for i in range(m):
        r = robots[i]
        offsets[i] = pos
        if r < 0 or r >= n or not (_S_ID_LO <= r <= _S_ID_HI):
            return -1
        k = count[r + 1] - count[r]
        if k > MAX_RECEIVED:
            return -1
        if pos + SENSE_BASE_MAX_BYTES + k * RAB_MAX_BYTES > out.shape[0]:
            return -1
        pos = _put_token(out, pos, _T_SENSE_HEAD)
        pos = _put_uint(out, pos, tick)
        pos = _put_token(out, pos, _T_ROBOT_ID)
        pos = _put_uint(out, pos, r)
        # a reading out of its bounds (or not finite): encode raises, so refuse
        pos = _put_f64_row(out, _put_token(out, pos, _T_ENCODER), encoder[r], _ENC_LO, _ENC_HI)
        if pos < 0:
            return -1
        pos = _put_f64_row(out, _put_token(out, pos, _T_IR), ir[r], _IR_LO, _IR_HI)
        if pos < 0:
            return -1
        pos = _put_f64_row(out, _put_token(out, pos, _T_GROUND), ground[r], _GROUND_LO, _GROUND_HI)
        if pos < 0:
            return -1
        pos = _put_token(out, pos, _T_RECEIVED)
        if k <= 15:
            out[pos] = np.uint8(0x90 | k)
            pos += 1
        else:
            out[pos] = np.uint8(_ARRAY16)
            pos = _put_be(out, pos + 1, np.uint64(k), 2)
        for q in range(count[r], count[r + 1]):
            j = order[q]
            s = d_sender[j]
            length = payload_len[s]
            if (not (_SENDER_LO <= s <= _SENDER_HI) or not (_RANGE_LO <= d_range[j] <= _RANGE_HI)
                    or not (_BEARING_LO <= d_bearing[j] <= _BEARING_HI)
                    or length > MAX_RAB_PAYLOAD_BYTES or length > payloads.shape[1]):
                return -1
            pos = _put_token(out, pos, _T_RAB_HEAD)
            pos = _put_uint(out, pos, s)
            pos = _put_token(out, pos, _T_RANGE)
            pos = _put_f64(out, pos, d_range[j])
            pos = _put_token(out, pos, _T_BEARING)
            pos = _put_f64(out, pos, d_bearing[j])
            pos = _put_token(out, pos, _T_PAYLOAD)
            out[pos] = np.uint8(_BIN8)
            out[pos + 1] = np.uint8(length)
            pos += 2
            for b in range(length):
                out[pos + b] = payloads[s, b]
            pos += length
        pos = _put_token(out, pos, _T_FINAL)
        out[pos] = np.uint8(_FALSE)
        pos += 1
    offsets[m] = pos
    return pos


__all__ = ["ACT_MAX_BYTES", "N_PERCEPTS", "RAB_MAX_BYTES", "SENSE_BASE_MAX_BYTES", "encode_act",
           "encode_senses", "parse_sense"]
