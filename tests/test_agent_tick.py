"""The packed agent tick (agents/epuck/agent_tick.py) against ForagingBrain.step, Act for Act.

Two agents per robot, built alike from the same seed: one steps its brain as one compiled call
(the agent process's path), the other through ForagingBrain.step (the reference, also the batch
engine's code). Both answer every Sense of a real served world; the Acts, the payload bytes and the
rejection counts must be equal, tick after tick. Equality is exact: the packed path runs the same
kernel on the same values.
"""

from __future__ import annotations

import dataclasses
import math

import msgpack
import numpy as np
import pytest
from readings import COMM, COMM_EACH, READINGS

from swarmloc.agents.epuck.agent import ForagingAgent
from swarmloc.agents.epuck.agent_tick import PackedForagingTick
from swarmloc.agents.epuck.foraging import ForagingBrain, agent_rng
from swarmloc.agents.epuck.social_odometry import STRATEGIES
from swarmloc.deploy.scenario import load_any
from swarmloc.protocol.epuck import STATE_KNOWS_BOTH
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.messages import EpuckSense, RabMessage, decode, encode
from swarmloc.world.service import served_world


def _agents(sc, packed: bool) -> list[ForagingAgent]:
    return [
        ForagingAgent(ForagingBrain(sc.agent, sc.world.body, [rid], [agent_rng(sc.world.seed, rid)], sc.world.tick_s),
                      rid, packed=packed)
        for rid in range(sc.world.robots)
    ]


def _corrupt(sense: EpuckSense, tick: int) -> EpuckSense:
    """Every 7th tick, spoil the payload of the first message: bad flags, or a truncated body."""
    if tick % 7 or not sense.received:
        return sense
    first = sense.received[0]
    bad = msgpack.packb([9, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, []]) if tick % 14 else first.payload[:-3]
    return dataclasses.replace(sense, received=(dataclasses.replace(first, payload=bad), *sense.received[1:]))




@pytest.mark.parametrize(
    ("strategy", "readings"),
    [(s, ()) for s, v in STRATEGIES.items() if v.confidence == "distance" and not v.central]
    + [("SSGIKF", READINGS), ("DSGIFF", READINGS), ("SSGIKF", COMM), ("DSGIFF", COMM_EACH)],
)
def test_packed_tick_gives_the_reference_acts(strategy, readings):
    loaded = load_any("ES1", {"seed": 3}, [f'agent.strategy="{strategy}"', "world.robots=10", *readings])
    sc = loaded.scenario
    world = served_world(loaded)
    packed, wire, reference = _agents(sc, True), _agents(sc, True), _agents(sc, False)
    assert all(a._packed is not None for a in packed) and all(a._packed is None for a in reference)
    errors_packed, errors_wire, errors_reference = ErrorCounter(), ErrorCounter(), ErrorCounter()
    heard = sent = 0
    for tick in range(600):
        acts = []
        for rid, data in world.senses():
            sense = _corrupt(decode(data, EpuckSense), tick)
            act = packed[rid].act(sense, errors_packed)
            assert act == reference[rid].act(sense, errors_reference), f"robot {rid}, tick {tick}"
            # bytes to bytes: the Sense as the world encodes it, the Act as the codec would
            assert wire[rid].act_wire(encode(sense), errors_wire) == encode(act), f"robot {rid}, tick {tick}"
            heard += len(sense.received)
            sent += act.payload is not None
            acts.append(act)
        world.step(acts)
    assert dict(errors_packed.counts) == dict(errors_reference.counts) == dict(errors_wire.counts)
    # the run exercised what it is meant to: messages heard, some of them spoilt and rejected
    if STRATEGIES[strategy].communicates:
        assert heard > 100 and sum(errors_packed.counts.values()) > 5 and sent == 600 * 10
    else:
        assert heard == sent == 0


def test_covariance_strategies_and_motor_overrides_take_the_reference_path():
    loaded = load_any("ES1", {"seed": 1}, ['agent.strategy="SSIKF"', "world.robots=2"])
    (agent, _) = _agents(loaded.scenario, True)
    assert agent._packed is None
    loaded = load_any("ES1", {"seed": 1}, ["world.robots=1"])
    sc = loaded.scenario
    brain = ForagingBrain(sc.agent, sc.world.body, [0], [np.random.default_rng(0)], sc.world.tick_s)
    assert PackedForagingTick.supports(brain)
    brain._motors = lambda ir: np.zeros((1, 2))
    assert not PackedForagingTick.supports(brain)
    with pytest.raises(ValueError, match="PackedForagingTick"):
        PackedForagingTick(brain, 16)


def test_a_full_inbox_of_sixteen_messages_is_decoded():
    """The most a Sense carries (MAX_RECEIVED): every message reaches the brain's fusion."""
    # one message per encounter: each of the 16 is fused the tick after its sender was heard
    loaded = load_any("ES1", {"seed": 5}, ["world.robots=1", "agent.encounter_messages=1"])
    sc = loaded.scenario
    (packed,), (reference,) = _agents(sc, True), _agents(sc, False)
    # both goals known; the sender heard us (robot 0) at bearing 0.5 rad: eq. 27 has all it needs
    payload = msgpack.packb([3, 0.5, 0.25, 40.0, 0.75, -0.5, 10.0, [0, 0.5]], use_single_float=True)
    received = tuple(RabMessage(sender_id=100 + j, range_m=0.05 + 0.005 * j, bearing_rad=-1.0 + 0.1 * j,
                                payload=payload) for j in range(16))
    sense = EpuckSense(tick=0, robot_id=0, encoder_steps=(0.0, 0.0), ir=(0.0,) * 8, ground=(1.0, 1.0, 1.0),
                       received=received)
    errors = ErrorCounter()
    for tick in range(3):  # a message is fused once its sender was heard the tick before
        act = packed.act(dataclasses.replace(sense, tick=tick), errors)
        assert act == reference.act(dataclasses.replace(sense, tick=tick), ErrorCounter())
    assert not errors.counts
    # the robot adopted a neighbour's goals: it now knows both and says so in its state code
    assert act.state & STATE_KNOWS_BOTH


def test_a_sense_the_wire_path_does_not_take_is_left_to_the_codec_untouched():
    """A final Sense, or one addressed to another robot, is not answered by act_wire (None) and
    changes nothing: the shell then decodes it and calls act, which still matches the reference."""
    loaded = load_any("ES1", {"seed": 2}, ["world.robots=1"])
    sc = loaded.scenario
    (agent,), (reference,) = _agents(sc, True), _agents(sc, False)
    sense = EpuckSense(tick=0, robot_id=0, encoder_steps=(3.0, 4.0), ir=(0.1,) * 8, ground=(1.0, 1.0, 1.0),
                       received=())
    errors = ErrorCounter()
    for other in (dataclasses.replace(sense, final=True), dataclasses.replace(sense, robot_id=1), b"\x93\x01"):
        assert agent.act_wire(other if isinstance(other, bytes) else encode(other), errors) is None
    assert agent._packed.tick == 0 and not errors.counts
    assert agent.act(sense, errors) == reference.act(sense, ErrorCounter())
    assert agent.act_wire(encode(dataclasses.replace(sense, tick=1)), errors) == encode(
        reference.act(dataclasses.replace(sense, tick=1), ErrorCounter()))



def test_estimates_beyond_float32_still_give_an_act_on_every_path():
    """Why no Act of a brain fails to encode: the brain rounds what it sends to float32 itself
    (agents/epuck/kernels.py: report_into), infinity where a value overflows, and the heard bearings it
    sends back are ones the codec bounded to [-pi, pi]. Goals at 1e39 m (a state no run reaches)
    go out as infinite distances, the same bytes on the packed, wire and reference paths."""
    loaded = load_any("ES1", {"seed": 4}, ['agent.strategy="SSGIKF"', "world.robots=1"])
    sc = loaded.scenario
    agents = []
    for packed in (True, True, False):
        brain = ForagingBrain(sc.agent, sc.world.body, [0], [agent_rng(sc.world.seed, 0)], sc.world.tick_s)
        brain.known[0] = True
        brain.goal_xy[0] = [[1e39, 0.0], [0.0, -1e39]]
        agents.append(ForagingAgent(brain, 0, packed=packed))
    packed, wire, reference = agents
    assert packed._packed is not None and reference._packed is None
    errors = ErrorCounter()
    sense = EpuckSense(tick=0, robot_id=0, encoder_steps=(3.0, 4.0), ir=(0.1,) * 8, ground=(1.0, 1.0, 1.0),
                       received=())
    for tick in range(5):
        this = dataclasses.replace(sense, tick=tick)
        act = reference.act(this, errors)
        assert packed.act(this, errors) == act
        assert wire.act_wire(encode(this), errors) == encode(act)
        flags, nest_m, _, _, prey_m, _, _, heard = msgpack.unpackb(act.payload)
        assert (flags, nest_m, prey_m, heard) == (3, math.inf, math.inf, [])
    assert not errors.counts
