"""One e-puck agent's whole tick in one compiled call: the foraging brain with its state packed.

An agent process steps a :class:`~swarmloc.agents.epuck.foraging.ForagingBrain` of one robot. Through
``ForagingBrain.step`` a tick is some thirty numpy and Python operations around the compiled
:func:`~swarmloc.agents.epuck.kernels.brain_tick`, whose 58 array arguments numba checks and unboxes one
by one. Warm, that is 26 µs; in a swarm of 100 processes taking turns on 2 cores every tick starts
with cold caches, and the same tick costs about 180 µs: most of an agent's CPU beyond the bare
transport (issue 2's tick-rate target).

:class:`PackedForagingTick` keeps every array of that brain (state, constants, scratch, the inbox,
the answer) as views into three buffers (float64, int64, bool), laid out by :func:`_views`, and
runs a tick with one call of :func:`agent_tick` of six arguments: it decodes the teammates'
payloads (:mod:`.social_codec`), calls ``brain_tick`` on the views, rotates the poses, and encodes
the robot's own payload. The numbers are ``ForagingBrain.step``'s, bit for bit: the same
``brain_tick`` runs on the same values, and the codec agrees with ``SocialMessages`` byte for byte
(tests/test_agent_tick.py holds the two paths to each other tick by tick).

It covers what an agent runs in practice: strategies whose confidence is the distance travelled
(all but SSIKF and DSIKF, whose covariance odometry is numpy code outside the kernel), with the
brain's own motor layers. :meth:`PackedForagingTick.supports` says whether a brain qualifies;
the agent shell (agents/epuck/agent.py: ForagingAgent) falls back to ``ForagingBrain.step`` otherwise.
"""

from __future__ import annotations

import numpy as np
from numba import njit

from swarmloc import numerics
from swarmloc.agents.epuck import kernels
from swarmloc.agents.epuck.foraging import _COS_IR, _SIN_IR
from swarmloc.agents.epuck.social_codec import decode_payload, encode_payload
from swarmloc.agents.epuck.wire import N_PERCEPTS, encode_act, parse_sense

#: Header slots of the int buffer: robots, heard capacity, encounter memory, inbox capacity, the
#: tick count, how many payloads the last tick rejected, how many messages it received, the
#: tick number of the last Sense parsed by :func:`agent_tick_wire`, and what :func:`_tick`
#: returned (the robot's payload length, -1 for none, below -1 an encoding error).
H_N, H_K, H_E, H_M, H_TICK, H_BAD, H_MESSAGES, H_SENSE_TICK, H_PAYLOAD, N_HEADER = range(10)
#: :func:`agent_tick_wire`'s answers besides an Act's length: the Sense is not in the form the
#: compiled parser takes (nothing done: decode it with the protocol codec instead); the tick ran
#: but its Act or payload does not encode (build it from the outputs: the codec says why).
WIRE_USE_CODEC, WIRE_ACT_INVALID = -1, -2

#: Names of :func:`_views`' arrays, in its order.
VIEWS = (
    # float64: percepts (encoder, IR and ground readings of a robot are contiguous, in that order)
    "encoder_steps", "ir", "ground",
    # poses: before the tick, of the tick before (the frame of messages heard now), after the tick
    "pose", "frame_pose", "new_pose",
    "goal_xy", "goal_p_m", "goal_cov", "search_left_m", "turn_dir", "heard_bearing_rad", "heard_range_m",
    "encounter_acc", "params", "cos_ir", "sin_ir", "geometry", "atan",
    # the inbox as received: (range, bearing) per message; the accepted messages and their content
    "msg_range_bearing", "in_range_m", "in_bearing_rad", "c_distance", "c_angle", "c_p", "c_heard_bearing",
    # the answer: wheel speeds then pose (contiguous), the message fields
    "cmd", "pose_out", "distance", "angle", "p", "heard_bearing_out",
    # int64
    "header", "robot_ids", "target", "lost_count", "visit_ticks", "turn_ticks", "straight_ticks", "heard_ids",
    "partner_ids", "partner_until", "settings", "math_fns", "rng_fn", "rng_state", "need", "n_need",
    "msg_sender_len", "msg_start", "receiver", "in_sender_id", "content_row", "c_heard_ids", "heard_ids_out", "state",
    # bool
    "known", "searching", "adopted", "c_known", "msg_bad", "known_out", "on_path",
)

#: Positions in :func:`_views`' float and int tuples of the arrays the entry points pick out.
_N_FLOAT_VIEWS = VIEWS.index("header")
F_RANGE_BEARING, F_CMD, F_POSE_OUT = (VIEWS.index(x) for x in ("msg_range_bearing", "cmd", "pose_out"))
I_HEADER, I_ROBOT_IDS, I_SENDER_LEN, I_START, I_STATE = (
    VIEWS.index(x) - _N_FLOAT_VIEWS for x in ("header", "robot_ids", "msg_sender_len", "msg_start", "state"))


# numba keys a cached kernel by its own source file only: a kernel of another file it calls
# (world/epuck/kernels.py: step_tick, agents/epuck/kernels.py: brain_tick) can change without
# invalidating it: edit this file too when one does (issue 18 changed both), so that it recompiles.
@njit(cache=True, error_model="numpy")
def _take(buf, o, size):
    """``size`` items of the buffer ``buf`` from offset ``o``, and the offset after them."""
    return buf[o:o + size], o + size


@njit(cache=True, error_model="numpy")
def _take2(buf, o, a, b):
    """As :func:`_take`, shaped ``(a, b)``."""
    return buf[o:o + a * b].reshape((a, b)), o + a * b


@njit(cache=True, error_model="numpy")
def _take3(buf, o, a, b, c):
    """As :func:`_take`, shaped ``(a, b, c)``."""
    return buf[o:o + a * b * c].reshape((a, b, c)), o + a * b * c


@njit(cache=True, error_model="numpy")
def _take4(buf, o, a, b, c, d):
    """As :func:`_take`, shaped ``(a, b, c, d)``."""
    return buf[o:o + a * b * c * d].reshape((a, b, c, d)), o + a * b * c * d


@njit(cache=True, error_model="numpy")
def _views(f, i, b):
    """The arrays of a packed brain, as views into its buffers ``f`` (float64), ``i`` (int64) and
    ``b`` (bool), sized by the header ``i[:N_HEADER]``; then the extent used of each buffer."""
    n, k, e, mm = i[H_N], i[H_K], i[H_E], i[H_M]
    o = 0
    encoder_steps, o = _take2(f, o, n, 2)
    ir, o = _take2(f, o, n, 8)
    ground, o = _take2(f, o, n, 3)
    pose, o = _take2(f, o, n, 3)
    frame_pose, o = _take2(f, o, n, 3)
    new_pose, o = _take2(f, o, n, 3)
    goal_xy, o = _take3(f, o, n, 2, 2)
    goal_p_m, o = _take2(f, o, n, 2)
    goal_cov, o = _take4(f, o, n, 2, 3, 3)
    search_left_m, o = _take(f, o, n)
    turn_dir, o = _take(f, o, n)
    heard_bearing_rad, o = _take2(f, o, n, k)
    heard_range_m, o = _take2(f, o, n, k)
    encounter_acc, o = _take3(f, o, n, e, kernels.N_ENCOUNTER)
    params, o = _take(f, o, kernels.N_BRAIN_PARAMS)
    cos_ir, o = _take(f, o, 8)
    sin_ir, o = _take(f, o, 8)
    geometry, o = _take3(f, o, 2, n, 3)
    atan, o = _take2(f, o, n, 3)
    msg_range_bearing, o = _take2(f, o, mm, 2)
    in_range_m, o = _take(f, o, mm)
    in_bearing_rad, o = _take(f, o, mm)
    c_distance, o = _take2(f, o, mm, 2)
    c_angle, o = _take2(f, o, mm, 2)
    c_p, o = _take2(f, o, mm, 2)
    c_heard_bearing, o = _take2(f, o, mm, k)
    cmd, o = _take2(f, o, n, 2)
    pose_out, o = _take2(f, o, n, 3)
    distance, o = _take2(f, o, n, 2)
    angle, o = _take2(f, o, n, 2)
    p, o = _take2(f, o, n, 2)
    heard_bearing_out, o = _take2(f, o, n, k)
    f_extent = o

    o = 0
    header, o = _take(i, o, N_HEADER)
    robot_ids, o = _take(i, o, n)
    target, o = _take(i, o, n)
    lost_count, o = _take(i, o, n)
    visit_ticks, o = _take2(i, o, n, 2)
    turn_ticks, o = _take(i, o, n)
    straight_ticks, o = _take(i, o, n)
    heard_ids, o = _take2(i, o, n, k)
    partner_ids, o = _take2(i, o, n, e)
    partner_until, o = _take2(i, o, n, e)
    settings, o = _take(i, o, kernels.N_SETTINGS)
    math_fns, o = _take(i, o, numerics.N_MATH_FNS)
    rng_fn, o = _take(i, o, n)
    rng_state, o = _take(i, o, n)
    need, o = _take(i, o, n)
    n_need, o = _take(i, o, 1)
    msg_sender_len, o = _take2(i, o, mm, 2)
    msg_start, o = _take(i, o, mm)
    receiver, o = _take(i, o, mm)
    in_sender_id, o = _take(i, o, mm)
    content_row, o = _take(i, o, mm)
    c_heard_ids, o = _take2(i, o, mm, k)
    heard_ids_out, o = _take2(i, o, n, k)
    state, o = _take(i, o, n)
    i_extent = o

    o = 0
    known, o = _take2(b, o, n, 2)
    searching, o = _take(b, o, n)
    adopted, o = _take2(b, o, n, 2)
    c_known, o = _take2(b, o, mm, 2)
    msg_bad, o = _take(b, o, mm)
    known_out, o = _take2(b, o, n, 2)
    on_path, o = _take(b, o, n)
    b_extent = o
    return (
        (encoder_steps, ir, ground, pose, frame_pose, new_pose, goal_xy, goal_p_m, goal_cov, search_left_m,
         turn_dir, heard_bearing_rad, heard_range_m, encounter_acc, params, cos_ir, sin_ir, geometry, atan, msg_range_bearing,
         in_range_m, in_bearing_rad, c_distance, c_angle, c_p, c_heard_bearing, cmd, pose_out, distance, angle, p,
         heard_bearing_out),
        (header, robot_ids, target, lost_count, visit_ticks, turn_ticks, straight_ticks, heard_ids, partner_ids,
         partner_until, settings, math_fns, rng_fn, rng_state, need, n_need, msg_sender_len, msg_start, receiver,
         in_sender_id, content_row, c_heard_ids, heard_ids_out, state),
        (known, searching, adopted, c_known, msg_bad, known_out, on_path),
        (f_extent, i_extent, b_extent),
    )


@njit(cache=True, error_model="numpy")
def _tick(f, i, b, buf, payload_out):
    """The tick of a packed brain whose percepts are in place and whose ``header[H_MESSAGES]``
    received messages are described by ``msg_sender_len``, ``msg_range_bearing`` and
    ``msg_start`` (each payload's offset in ``buf``, uint8).

    Each payload is decoded (:func:`.social_codec.decode_payload`); a payload that does not
    decode is flagged in ``msg_bad`` and its message dropped, the others kept in order, as
    ``ForagingAgent`` does. Then ``brain_tick`` (every layer, the robot's own motors), the pose
    rotation of ``ForagingBrain._commit_tick``, and the robot's payload into ``payload_out``.
    Returns the payload's length, -1 for none (a strategy that does not communicate), or an
    ``encode_payload`` error code below -1."""
    fv, iv, bv, _ = _views(f, i, b)
    (encoder_steps, ir, ground, pose, frame_pose, new_pose, goal_xy, goal_p_m, goal_cov, search_left_m,
     turn_dir, heard_bearing_rad, heard_range_m, encounter_acc, params, cos_ir, sin_ir, geometry, atan, msg_range_bearing,
     in_range_m, in_bearing_rad, c_distance, c_angle, c_p, c_heard_bearing, cmd, pose_out, distance, angle, p,
     heard_bearing_out) = fv
    (header, robot_ids, target, lost_count, visit_ticks, turn_ticks, straight_ticks, heard_ids, partner_ids,
     partner_until, settings, math_fns, rng_fn, rng_state, need, n_need, msg_sender_len, msg_start, receiver,
     in_sender_id, content_row, c_heard_ids, heard_ids_out, state) = iv
    (known, searching, adopted, c_known, msg_bad, known_out, on_path) = bv
    k = header[H_K]
    m = 0
    bad = 0
    for j in range(header[H_MESSAGES]):
        start = msg_start[j]
        if decode_payload(buf, start, start + msg_sender_len[j, 1], k, m, c_known, c_distance, c_angle, c_p,
                          c_heard_ids, c_heard_bearing):
            msg_bad[j] = False
            in_sender_id[m] = msg_sender_len[j, 0]
            in_range_m[m] = msg_range_bearing[j, 0]
            in_bearing_rad[m] = msg_range_bearing[j, 1]
            m += 1
        else:
            msg_bad[j] = True
            bad += 1
    header[H_BAD] = bad
    tick = header[H_TICK] + 1
    kernels.brain_tick(
        encoder_steps, ir, ground, tick,
        pose, new_pose, frame_pose, robot_ids, known, goal_xy, goal_p_m, goal_cov, target, searching,
        search_left_m, lost_count, visit_ticks, turn_ticks, straight_ticks, turn_dir, heard_ids, heard_bearing_rad,
        heard_range_m, partner_ids, partner_until, encounter_acc, adopted,
        receiver[:m], in_sender_id[:m], in_range_m[:m], in_bearing_rad[:m], content_row[:m], c_known[:m],
        c_distance[:m], c_angle[:m], c_p[:m], c_heard_ids[:m], c_heard_bearing[:m],
        params, settings, math_fns, rng_fn, rng_state, cos_ir, sin_ir,
        geometry, atan, need, n_need,
        cmd, known_out, distance, angle, p, heard_ids_out, heard_bearing_out, state, pose_out, on_path,
    )
    header[H_TICK] = tick
    # ForagingBrain._commit_tick: the frame of next tick's messages is this tick's starting pose
    frame_pose[:] = pose
    pose[:] = new_pose
    if settings[kernels.S_COMMUNICATES] == 0:
        header[H_PAYLOAD] = -1
        return -1
    n = encode_payload(known_out[0], distance[0], angle[0], p[0], heard_ids_out[0], heard_bearing_out[0],
                       payload_out)
    header[H_PAYLOAD] = n if n >= 0 else n - 1
    return header[H_PAYLOAD]


@njit(cache=True, error_model="numpy")
def agent_tick(f, i, b, blob, n_messages, payload_out):
    """One tick of a packed brain (:func:`_views`) whose percepts the caller wrote, and the
    payloads of its ``n_messages`` messages back to back in ``blob`` (uint8; their sender ids
    and lengths in ``msg_sender_len``, range and bearing in ``msg_range_bearing``): see
    :func:`_tick`, whose answer this is."""
    _, iv, _, _ = _views(f, i, b)
    header, msg_sender_len, msg_start = iv[I_HEADER], iv[I_SENDER_LEN], iv[I_START]
    header[H_MESSAGES] = n_messages
    start = 0
    for j in range(n_messages):
        msg_start[j] = start
        start += msg_sender_len[j, 1]
    return _tick(f, i, b, blob, payload_out)


@njit(cache=True, error_model="numpy")
def agent_tick_wire(f, i, b, sense, payload_out, act_out):
    """One tick from the Sense's bytes to the Act's: :func:`.wire.parse_sense` (the
    world-server's canonical form only; else ``WIRE_USE_CODEC``, nothing done), :func:`_tick`,
    then :func:`.wire.encode_act` into ``act_out``. Returns the Act's length, or
    ``WIRE_ACT_INVALID`` if the payload or the Act does not encode."""
    fv, iv, _, _ = _views(f, i, b)
    header, robot_ids, msg_sender_len, msg_start = iv[I_HEADER], iv[I_ROBOT_IDS], iv[I_SENDER_LEN], iv[I_START]
    n = parse_sense(sense, robot_ids[0], f[:N_PERCEPTS], fv[F_RANGE_BEARING], msg_sender_len, msg_start,
                    header[H_SENSE_TICK:H_SENSE_TICK + 1])
    if n < 0:
        return WIRE_USE_CODEC
    header[H_MESSAGES] = n
    payload_n = _tick(f, i, b, sense, payload_out)
    if payload_n < -1:
        return WIRE_ACT_INVALID
    size = encode_act(header[H_SENSE_TICK], robot_ids[0], fv[F_CMD][0], payload_out, payload_n,
                      iv[I_STATE][0], fv[F_POSE_OUT][0], act_out)
    return size if size >= 0 else WIRE_ACT_INVALID


_loaded = False


def _load_kernel(brain) -> None:
    """Load (or compile) :func:`agent_tick` now, once per process, by stepping a throwaway
    packed brain with its own generator: as ``foraging._load_kernels``, so that the first tick of
    a run does not load it (100 agents loading it at once at tick 1 cost seconds)."""
    global _loaded
    if _loaded:
        return
    _loaded = True
    throwaway = type(brain)(brain.config, brain.body, [0], [np.random.default_rng(0)], brain.tick_s)
    packed = PackedForagingTick(throwaway, 1)
    packed.step(packed.no_payloads, 0)
    if packed.step_wire(packed.no_payloads) != WIRE_USE_CODEC:  # an empty Sense: nothing done
        raise AssertionError("agent_tick_wire took an empty Sense")


class PackedForagingTick:
    """A one-robot :class:`~swarmloc.agents.epuck.foraging.ForagingBrain`, moved into packed buffers and
    stepped by :func:`agent_tick`. The brain's arrays are copied at construction; the brain
    itself must not be stepped afterwards (its generator, which the kernel draws from, must live:
    the caller keeps the brain)."""

    def __init__(self, brain, max_messages: int):
        if not self.supports(brain):
            raise ValueError("PackedForagingTick: a one-robot brain with distance confidence and its own motors only")
        _load_kernel(brain)
        n, k, e = 1, brain.config.heard_capacity, brain.config.encounter_memory
        size = 256 + 64 * k + kernels.N_ENCOUNTER * e + max_messages * (16 + 8 * k)
        self.f, self.i, self.b = np.zeros(size), np.zeros(size, np.int64), np.zeros(size, bool)
        self.i[:N_HEADER] = (n, k, e, max_messages, brain.tick, 0, 0, 0, -1)
        fv, iv, bv, extents = _views(self.f, self.i, self.b)
        if not all(x <= size for x in extents):  # the buffers' sizes are generous; check they are enough
            raise AssertionError(f"packed brain needs {extents}, buffers have {size}")
        self.view = dict(zip(VIEWS, (*fv, *iv, *bv), strict=True))
        v = self.view
        for name in ("known", "goal_xy", "goal_p_m", "target", "searching", "search_left_m", "lost_count",
                     "visit_ticks", "turn_ticks", "straight_ticks", "turn_dir", "heard_ids", "heard_bearing_rad",
                     "heard_range_m", "partner_ids", "partner_until", "encounter_acc", "robot_ids"):
            v[name][...] = getattr(brain, name)
        v["adopted"][...] = brain._adopted
        v["pose"][...] = brain.pose
        v["frame_pose"][...] = brain.pose_history[1]
        v["params"][...] = brain._params
        v["settings"][...] = brain._settings
        v["settings"][kernels.S_MOTORS] = 1
        fn, rng_state = brain._rng_addresses()
        v["rng_fn"][...], v["rng_state"][...] = fn, rng_state
        v["math_fns"][...] = brain._math
        v["cos_ir"][...], v["sin_ir"][...] = _COS_IR, _SIN_IR
        v["content_row"][...] = np.arange(max_messages)
        self.payload_out = np.zeros(64, np.uint8)
        self.act_out = np.zeros(256, np.uint8)
        # Read-only, as np.frombuffer(bytes) makes the inbox's: one type, one compiled agent_tick.
        self.no_payloads = np.frombuffer(b"", np.uint8)
        # Offsets (in items) of what the agent shell reads and writes each tick.
        self.percepts = _offset(v["encoder_steps"], self.f)  # encoder, ir, ground: N_PERCEPTS floats
        if self.percepts != 0:  # agent_tick_wire has the parser write them to f[:N_PERCEPTS]
            raise AssertionError("the percepts must open the float buffer")
        self.range_bearing = _offset(v["msg_range_bearing"], self.f)
        self.sender_len = _offset(v["msg_sender_len"], self.i)
        self.answer = _offset(v["cmd"], self.f)  # wheel speeds then pose: 5 floats
        self.state = _offset(v["state"], self.i)

    USE_CODEC, ACT_INVALID = WIRE_USE_CODEC, WIRE_ACT_INVALID
    N_PERCEPTS = N_PERCEPTS

    @staticmethod
    def supports(brain) -> bool:
        return brain.n == 1 and brain.goal_cov is None and brain._motors is None

    def step(self, blob: np.ndarray, n_messages: int) -> int:
        """One tick, percepts and messages written by the caller (:func:`agent_tick`)."""
        return agent_tick(self.f, self.i, self.b, blob, n_messages, self.payload_out)

    def step_wire(self, sense: np.ndarray) -> int:
        """One tick from a Sense's bytes (uint8, read-only) to the Act's in ``act_out``
        (:func:`agent_tick_wire`)."""
        return agent_tick_wire(self.f, self.i, self.b, sense, self.payload_out, self.act_out)

    @property
    def tick(self) -> int:
        return int(self.i[H_TICK])

    @property
    def payload_length(self) -> int:
        """What the last tick's payload encoding gave: its length, -1 for none, below -1 the
        code of an encoding error."""
        return int(self.i[H_PAYLOAD])

    @property
    def sense_tick(self) -> int:
        """The tick number of the last Sense :meth:`step_wire` parsed."""
        return int(self.i[H_SENSE_TICK])

    def rejected(self) -> list[int]:
        """Indices of the messages whose payload the last tick rejected."""
        if not self.i[H_BAD]:
            return []
        return np.flatnonzero(self.view["msg_bad"][: self.i[H_MESSAGES]]).tolist()


def _offset(view: np.ndarray, base: np.ndarray) -> int:
    return (view.ctypes.data - base.ctypes.data) // base.itemsize
