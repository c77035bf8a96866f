"""The world-server's compiled Sense encoder (issue 47) against the protocol codec: every live
robot's Sense byte-equal to ``encode(EpuckSense(...))`` over whole runs and over random worlds
(Hypothesis), and where the codec refuses, the served world raises the codec's own error."""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmloc.agents.epuck.wire import RAB_MAX_BYTES, SENSE_BASE_MAX_BYTES, encode_senses
from swarmloc.deploy.scenario import load_any
from swarmloc.protocol.messages import (
    MAX_RECEIVED,
    EpuckAct,
    EpuckSense,
    ProtocolError,
    RabMessage,
    decode,
    encode,
)
from swarmloc.world.service import served_world


def _acts(world, tick: int, rng: np.random.Generator) -> list:
    """Acts as agents send them: wheel commands, payloads of every length or none, some robots
    silent (None)."""
    acts = []
    for r in range(world.n_robots):
        if rng.random() < 0.1:
            acts.append(None)
            continue
        size = int(rng.integers(-1, 65))
        payload = None if size < 0 else rng.integers(0, 256, size, dtype=np.uint8).tobytes()
        acts.append(EpuckAct(tick, r, tuple(rng.uniform(-500, 500, 2).tolist()), payload,
                             int(rng.integers(0, 4)), (0.0, 0.0, 0.0)))
    return acts


@pytest.mark.parametrize("scenario,robots", [("ES1", 10), ("ES3-tiled", 60)])
def test_every_sense_of_a_run_equals_the_codecs_bytes(scenario, robots):
    world = served_world(load_any(scenario, {"seed": 4, "robots": robots}))
    rng = np.random.default_rng(1)
    received = 0
    for tick in range(150):
        if tick == 40:
            world.kill(3)  # a dead robot gets no Sense, on both paths
        if tick == 90:
            world.revive(3)
        obs = world.world.observe()  # one observation (it draws the sensors' noise), both paths
        fast = world.encode_senses(obs)
        assert fast == world.encode_senses_reference(obs), f"tick {tick}"
        received += sum(len(decode(data, EpuckSense).received) for _, data in fast)
        world.step(_acts(world, tick, rng))
    assert received > 100  # the medium delivered messages: the received section was exercised


def test_a_sense_the_codec_refuses_raises_the_codecs_error():
    world = served_world(load_any("ES1", {"seed": 4, "robots": 4}))
    world.world.encoder_steps[2, 0] = np.nan  # a broken odometer: not finite
    with pytest.raises(ProtocolError) as caught:
        world.senses()
    assert caught.value.field == "encoder_steps[0]"


@settings(max_examples=150, deadline=None)
@given(data=st.data())
def test_random_worlds_encode_like_the_codec_or_are_refused_where_it_raises(data):
    n = data.draw(st.integers(1, 6))
    finite = st.floats(-1e6, 1e6, allow_nan=False)
    unit = st.floats(-0.5, 1.5, allow_nan=False)  # ir bounds [0, 1]: some out
    encoder = np.array(data.draw(st.lists(st.lists(finite, min_size=2, max_size=2), min_size=n, max_size=n)))
    ir = np.array(data.draw(st.lists(st.lists(unit, min_size=8, max_size=8), min_size=n, max_size=n)))
    ground = np.array(data.draw(st.lists(st.lists(st.floats(0, 2.5), min_size=3, max_size=3),
                                         min_size=n, max_size=n)))
    m = data.draw(st.integers(0, 3 * MAX_RECEIVED))
    receiver = np.array(data.draw(st.lists(st.integers(0, n - 1), min_size=m, max_size=m)), np.int64)
    sender = np.array(data.draw(st.lists(st.integers(0, n - 1), min_size=m, max_size=m)), np.int64)
    range_m = np.array(data.draw(st.lists(st.floats(-0.1, 0.3), min_size=m, max_size=m)), float)
    bearing = np.array(data.draw(st.lists(st.floats(-3.2, 3.2), min_size=m, max_size=m)), float)
    lengths = data.draw(st.lists(st.integers(-1, 66), min_size=n, max_size=n))
    payloads = np.zeros((n, 64), np.uint8)
    raw = []
    for s, length in enumerate(lengths):
        body = bytes(data.draw(st.binary(min_size=max(length, 0), max_size=max(length, 0))))
        raw.append(None if length < 0 else body)
        payloads[s, :min(len(body), 64)] = np.frombuffer(body[:64], np.uint8)
    robots = np.array(sorted(data.draw(st.sets(st.integers(0, n - 1)))), np.int64)
    tick = data.draw(st.integers(0, 2**40))
    out = np.zeros(len(robots) * SENSE_BASE_MAX_BYTES + m * RAB_MAX_BYTES, np.uint8)
    offsets = np.empty(len(robots) + 1, np.int64)
    total = encode_senses(tick, robots, encoder, ir, ground, sender, receiver, range_m, bearing,
                          payloads, np.array(lengths, np.int64), out, offsets)
    try:
        expected = []
        for r in robots.tolist():
            received = tuple(RabMessage(int(s), float(rg), float(b), raw[s])
                             for s, rv, rg, b in zip(sender, receiver, range_m, bearing)
                             if rv == r and raw[s] is not None)
            expected.append(encode(EpuckSense(tick, r, tuple(encoder[r].tolist()), tuple(ir[r].tolist()),
                                              tuple(ground[r].tolist()), received)))
    except ProtocolError:
        assert total == -1  # the codec raises: the compiled encoder refuses
        return
    assert total >= 0
    got = [out[offsets[i]:offsets[i + 1]].tobytes() for i in range(len(robots))]
    assert got == expected
