"""Compiled (numba) codec of the payload e-pucks send each other (social odometry, seed 000 §4.3).

What a robot broadcasts over its range-and-bearing board (seed 000 §3.2, §4.3, fig. 10): for each
goal (nest, prey) the distance ``dy^i`` and angle of its estimate in its own body frame and its
inverse confidence ``p`` (eq. 23), and the bearings it measured to the neighbours it heard last
tick, which the receiver needs for the frame transform of eq. 27. The wire format is the one of
:meth:`swarmloc.agents.epuck.foraging.SocialMessages.encode` (msgpack, floats as float32)::

    [flags, d_nest, a_nest, p_nest, d_prey, a_prey, p_prey, [id0, bearing0, id1, bearing1, ...]]

with ``flags = known_nest | known_prey << 1``. :class:`SocialMessages` (``encode`` / ``decode``)
stays the reference, and the source of the error messages; the two functions here do the same
from inside a compiled tick (no Python objects, no exceptions, preallocated arrays):

- :func:`encode_payload`: the very bytes ``SocialMessages.encode`` returns for the same row;
- :func:`decode_payload`: succeeds exactly when ``SocialMessages.decode`` would, for any byte
  string (any msgpack encoding of a valid message is accepted: fixarray/array16/array32 headers,
  every integer width, float32 or float64; anything else, truncation or trailing bytes is
  refused), and then writes the very row it would, padding included.

Caller errors that the Python reference cannot make (a row outside the arrays, arrays of the wrong
width, an output buffer too small) are refused with a return code, never written out of bounds.
"""

from __future__ import annotations

import math

import numpy as np
from llvmlite import ir as llvm_ir
from numba import njit, types
from numba.extending import intrinsic

#: Goal columns of the decoded arrays (as in ``agents/epuck/foraging.py``).
NEST, PREY = 0, 1
#: Output buffer size that always suffices for capacity <= 3 and ids <= 65535 (the board's payload).
PAYLOAD_MAX_BYTES = 64
#: ``encode_payload``'s return value when ``out`` is too small for the payload.
ENCODE_TOO_SMALL = -1
#: ``encode_payload``'s return value when a finite float overflows float32: msgpack's packer
#: (``PyFloat_Pack4``) raises ``OverflowError`` there, so ``SocialMessages.encode`` does too.
ENCODE_FLOAT_OVERFLOW = -2
#: msgpack's ``unpackb(max_array_len=16)`` of the reference decode: longer arrays are refused.
MAX_ARRAY_LEN = 16

# Range checks of SocialMessages.decode, the same constants.
_MAX_DISTANCE_M = 100.0
_MAX_ANGLE_RAD = math.pi + 1e-5
_MAX_P_M = 1e7
_MAX_ID = 65535

# What one msgpack scalar decoded to.
_BAD, _INT, _FLOAT = 0, 1, 2


# ---------------------------------------------------------------------------- bit reinterpretation


@intrinsic
def _f32_from_bits(typingctx, bits):
    """The float32 whose IEEE bits are the uint32 ``bits``."""
    if not (isinstance(bits, types.Integer) and bits.bitwidth == 32):
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvm_ir.FloatType())

    return types.float32(bits), codegen


@intrinsic
def _f64_from_bits(typingctx, bits):
    """The float64 whose IEEE bits are the uint64 ``bits``."""
    if not (isinstance(bits, types.Integer) and bits.bitwidth == 64):
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvm_ir.DoubleType())

    return types.float64(bits), codegen


@intrinsic
def _bits_of_f32(typingctx, value):
    """The IEEE bits of the float32 ``value``, as a uint32."""
    if value != types.float32:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvm_ir.IntType(32))

    return types.uint32(value), codegen


@intrinsic
def _bits_of_f64(typingctx, value):
    """The IEEE bits of the float64 ``value``, as a uint64."""
    if value != types.float64:
        return None

    def codegen(context, builder, signature, args):
        return builder.bitcast(args[0], llvm_ir.IntType(64))

    return types.uint64(value), codegen


# ----------------------------------------------------------------------------------------- encode


@njit(cache=True, inline="always", error_model="numpy")
def _uint_size(value):
    """Bytes msgpack's packer uses for the non-negative int ``value`` (Python int semantics)."""
    if value < 0x80:
        return 1
    if value < 0x100:
        return 2
    if value < 0x10000:
        return 3
    if value < 0x100000000:
        return 5
    return 9


@njit(cache=True, inline="always", error_model="numpy")
def _put_be(out, pos, value, nbytes):
    """Write the low ``nbytes`` of the uint64 ``value`` big-endian at ``out[pos]``."""
    for j in range(nbytes):
        out[pos + j] = np.uint8((value >> np.uint64(8 * (nbytes - 1 - j))) & np.uint64(0xFF))
    return pos + nbytes


@njit(cache=True, inline="always", error_model="numpy")
def _put_uint(out, pos, value):
    """msgpack of a non-negative int64 as msgpack packs a Python int: the shortest unsigned form."""
    u = np.uint64(value)
    if value < 0x80:
        out[pos] = np.uint8(value)
        return pos + 1
    if value < 0x100:
        out[pos] = np.uint8(0xCC)
        return _put_be(out, pos + 1, u, 1)
    if value < 0x10000:
        out[pos] = np.uint8(0xCD)
        return _put_be(out, pos + 1, u, 2)
    if value < 0x100000000:
        out[pos] = np.uint8(0xCE)
        return _put_be(out, pos + 1, u, 4)
    out[pos] = np.uint8(0xCF)
    return _put_be(out, pos + 1, u, 8)


@njit(cache=True, inline="always", error_model="numpy")
def _put_float32(out, pos, value):
    """msgpack float32 (0xca) of a float64, rounded as the C cast msgpack uses (nearest even);
    -1 where that cast overflows a finite value to infinity (msgpack raises there)."""
    single = np.float32(value)
    if math.isinf(single) and not math.isinf(value):
        return -1
    out[pos] = np.uint8(0xCA)
    return _put_be(out, pos + 1, np.uint64(_bits_of_f32(single)), 4)


@njit(cache=True, inline="always", error_model="numpy")
def _array_header_size(n):
    if n <= 15:
        return 1
    if n <= 0xFFFF:
        return 3
    return 5


@njit(cache=True, inline="always", error_model="numpy")
def _put_array_header(out, pos, n):
    if n <= 15:
        out[pos] = np.uint8(0x90 | n)
        return pos + 1
    if n <= 0xFFFF:
        out[pos] = np.uint8(0xDC)
        return _put_be(out, pos + 1, np.uint64(n), 2)
    out[pos] = np.uint8(0xDD)
    return _put_be(out, pos + 1, np.uint64(n), 4)


@njit(cache=True, error_model="numpy")
def encode_payload(known, distance, angle, p, heard_ids, heard_bearing, out):
    """Write the payload of one message into ``out[:n]`` and return ``n``.

    ``known`` bool (2,), ``distance`` (m), ``angle`` (rad), ``p`` (m) float64 (2,), indexed by
    ``NEST``/``PREY``; ``heard_ids`` int64 (K,) with -1 for no neighbour and ``heard_bearing``
    float64 (K,) (rad): every pair with id >= 0 is sent, in order. The bytes are those of
    ``SocialMessages.encode`` for the same row. Returns ``ENCODE_TOO_SMALL`` (and writes nothing)
    if ``out`` cannot hold them (``PAYLOAD_MAX_BYTES`` always can for K <= 3 and ids <= 65535),
    else ``ENCODE_FLOAT_OVERFLOW`` (``out`` then unspecified) where ``SocialMessages.encode``
    raises ``OverflowError``: a finite value beyond float32's range (|x| >= 2**128 - 2**103).
    """
    k_max = min(heard_ids.shape[0], heard_bearing.shape[0])
    pairs = 0
    ids_size = 0
    for k in range(k_max):
        if heard_ids[k] >= 0:
            pairs += 1
            ids_size += _uint_size(heard_ids[k])
    # array header, flags (fixint), 6 float32, heard header, pairs.
    size = 1 + 1 + 6 * 5 + _array_header_size(2 * pairs) + ids_size + 5 * pairs
    if out.shape[0] < size:
        return ENCODE_TOO_SMALL
    out[0] = np.uint8(0x98)
    out[1] = np.uint8((1 if known[NEST] else 0) | ((1 if known[PREY] else 0) << 1))
    pos = 2
    for g in range(2):
        for value in (distance[g], angle[g], p[g]):
            pos = _put_float32(out, pos, value)
            if pos < 0:
                return ENCODE_FLOAT_OVERFLOW
    pos = _put_array_header(out, pos, 2 * pairs)
    for k in range(k_max):
        if heard_ids[k] >= 0:
            pos = _put_uint(out, pos, heard_ids[k])
            pos = _put_float32(out, pos, heard_bearing[k])
            if pos < 0:
                return ENCODE_FLOAT_OVERFLOW
    return pos


# ----------------------------------------------------------------------------------------- decode


@njit(cache=True, inline="always", error_model="numpy")
def _get_be(buf, pos, nbytes):
    """The big-endian unsigned int of ``buf[pos:pos + nbytes]`` as a uint64."""
    value = np.uint64(0)
    for j in range(nbytes):
        value = (value << np.uint64(8)) | np.uint64(buf[pos + j])
    return value


@njit(cache=True, error_model="numpy")
def _get_scalar(buf, pos, stop):
    """One msgpack int or float at ``buf[pos]``: ``(kind, int_value, float_value, next_pos)``.

    ``kind`` is ``_BAD`` for anything else (nil, bool, str, bin, array, map, ext, 0xc1) or a
    truncated value. ``int_value`` is exact, except that a uint64 above 2**63 - 1 becomes -1:
    every int slot of the payload refuses both.
    """
    if pos >= stop:
        return _BAD, 0, 0.0, pos
    b = np.int64(buf[pos])
    if b <= 0x7F:
        return _INT, b, 0.0, pos + 1
    if b >= 0xE0:
        return _INT, b - 256, 0.0, pos + 1
    if b == 0xCA or b == 0xCB:
        nbytes = 4 if b == 0xCA else 8
        if pos + 1 + nbytes > stop:
            return _BAD, 0, 0.0, pos
        bits = _get_be(buf, pos + 1, nbytes)
        if nbytes == 4:
            value = np.float64(_f32_from_bits(np.uint32(bits)))
        else:
            value = _f64_from_bits(bits)
        return _FLOAT, 0, value, pos + 1 + nbytes
    if 0xCC <= b <= 0xD3:
        signed = b >= 0xD0
        nbytes = 1 << ((b - 0xD0) if signed else (b - 0xCC))
        if pos + 1 + nbytes > stop:
            return _BAD, 0, 0.0, pos
        bits = _get_be(buf, pos + 1, nbytes)
        top = np.uint64(1) << np.uint64(8 * nbytes - 1)
        if bits < top:
            value = np.int64(bits)
        elif not signed:
            value = np.int64(-1) if nbytes == 8 else np.int64(bits)
        elif nbytes == 8:
            value = -np.int64(~bits) - 1  # two's complement, without overflowing int64
        else:
            value = np.int64(bits) - (np.int64(1) << np.int64(8 * nbytes))
        return _INT, value, 0.0, pos + 1 + nbytes
    return _BAD, 0, 0.0, pos


@njit(cache=True, inline="always", error_model="numpy")
def _get_array_header(buf, pos, stop):
    """Length and next position of a msgpack array header at ``buf[pos]``; length -1: not one."""
    if pos >= stop:
        return -1, pos
    b = np.int64(buf[pos])
    if 0x90 <= b <= 0x9F:
        return b & 0x0F, pos + 1
    if b == 0xDC or b == 0xDD:
        nbytes = 2 if b == 0xDC else 4
        if pos + 1 + nbytes > stop:
            return -1, pos
        return np.int64(_get_be(buf, pos + 1, nbytes)), pos + 1 + nbytes
    return -1, pos


@njit(cache=True, error_model="numpy")
def decode_payload(buf, start, stop, capacity, row, c_known, c_distance, c_angle, c_p,
                   c_heard_ids, c_heard_bearing):
    """Decode ``buf[start:stop]`` (uint8, Python slice semantics) into row ``row`` of the ``c_*``.

    Returns True, having written the whole row (``c_known`` bool (M, 2); ``c_distance``,
    ``c_angle``, ``c_p`` float64 (M, 2); ``c_heard_ids`` int64 (M, >= capacity) padded with -1;
    ``c_heard_bearing`` float64 (M, >= capacity) padded with 0.0), exactly when
    ``SocialMessages.decode([bytes(buf[start:stop])], capacity)`` would succeed, with the values
    of its row 0. Returns False when it would raise ``ValueError`` (the row is then unspecified),
    and also when ``row`` or the arrays' shapes cannot hold the result.
    """
    n_buf = buf.shape[0]
    # Python slice semantics of buf[start:stop].
    if start < 0:
        start = max(start + n_buf, 0)
    if stop < 0:
        stop = max(stop + n_buf, 0)
    start = min(start, n_buf)
    stop = min(stop, n_buf)
    if capacity < 0 or not 0 <= row < c_known.shape[0]:
        return False
    for a in (c_known.shape, c_distance.shape, c_angle.shape, c_p.shape):
        if a[0] != c_known.shape[0] or a[1] != 2:
            return False
    width = c_heard_ids.shape[1]
    if (c_heard_ids.shape[0] != c_known.shape[0] or c_heard_bearing.shape[0] != c_known.shape[0]
            or c_heard_bearing.shape[1] != width or width < capacity):
        return False

    length, pos = _get_array_header(buf, start, stop)
    if length != 8:
        return False
    kind, flags, _, pos = _get_scalar(buf, pos, stop)
    if kind != _INT or not 0 <= flags <= 3:
        return False
    # The six goal floats: read now, checked and written once the whole payload has parsed.
    d0 = a0 = p0 = d1 = a1 = p1 = 0.0
    for i in range(6):
        kind, _, value, pos = _get_scalar(buf, pos, stop)
        if kind != _FLOAT or not math.isfinite(value):
            return False
        if i == 0:
            d0 = value
        elif i == 1:
            a0 = value
        elif i == 2:
            p0 = value
        elif i == 3:
            d1 = value
        elif i == 4:
            a1 = value
        else:
            p1 = value
    heard_len, pos = _get_array_header(buf, pos, stop)
    if heard_len < 0 or heard_len > MAX_ARRAY_LEN or heard_len % 2 or heard_len > 2 * capacity:
        return False
    pairs = heard_len // 2
    for k in range(pairs):
        kind, rid, _, pos = _get_scalar(buf, pos, stop)
        if kind != _INT or not 0 <= rid <= _MAX_ID:
            return False
        kind, _, bearing, pos = _get_scalar(buf, pos, stop)
        if kind != _FLOAT or not abs(bearing) <= _MAX_ANGLE_RAD:
            return False
        c_heard_ids[row, k] = rid
        c_heard_bearing[row, k] = bearing
    if pos != stop:  # msgpack's ExtraData
        return False
    if not (0.0 <= d0 <= _MAX_DISTANCE_M and abs(a0) <= _MAX_ANGLE_RAD and 0.0 <= p0 <= _MAX_P_M):
        return False
    if not (0.0 <= d1 <= _MAX_DISTANCE_M and abs(a1) <= _MAX_ANGLE_RAD and 0.0 <= p1 <= _MAX_P_M):
        return False
    for k in range(pairs, width):
        c_heard_ids[row, k] = -1
        c_heard_bearing[row, k] = 0.0
    c_known[row, NEST] = flags & 1 != 0
    c_known[row, PREY] = flags & 2 != 0
    c_distance[row, NEST] = d0
    c_angle[row, NEST] = a0
    c_p[row, NEST] = p0
    c_distance[row, PREY] = d1
    c_angle[row, PREY] = a1
    c_p[row, PREY] = p1
    return True
