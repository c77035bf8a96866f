"""The e-puck agent's inbox: received payloads decoded together, a bad one dropped and counted."""

from __future__ import annotations

import msgpack
import numpy as np

from swarmloc.agents.epuck.agent import ForagingAgent
from swarmloc.agents.epuck.foraging import ForagingBrain, agent_rng
from swarmloc.deploy.scenario import load_scenario
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.messages import EpuckSense, RabMessage


def _agent() -> ForagingAgent:
    sc = load_scenario("ES1", [])
    brain = ForagingBrain(sc.agent, sc.world.body, [0], [agent_rng(1, 0)], sc.world.tick_s)
    return ForagingAgent(brain, 0)


def _payload(flags, goals, heard):
    # The wire layout of seed 000's message, written out by hand: flags, (d, angle, p) per goal,
    # then the (id, bearing) pairs the sender heard.
    return msgpack.packb([flags, *goals, heard], use_single_float=True)


GOOD_A = _payload(1, [0.5, 0.25, 2.0, 0.0, 0.0, 0.0], [0, -1.5])
GOOD_B = _payload(3, [1.0, -0.5, 0.125, 2.5, 3.0, 4.0], [])
BAD = b"\xc1not msgpack"


def _sense(*payloads):
    msgs = tuple(RabMessage(sender_id=10 + i, range_m=0.05 + 0.01 * i, bearing_rad=0.1 * i, payload=p)
                 for i, p in enumerate(payloads))
    return EpuckSense(tick=1, robot_id=0, encoder_steps=(0.0, 0.0), ir=(0.0,) * 8, ground=(1.0,) * 3,
                      received=msgs)


def test_all_good_messages_arrive_in_order_with_their_content():
    errors = ErrorCounter()
    inbox = _agent()._inbox(_sense(GOOD_A, GOOD_B), errors)
    assert inbox.sender_id.tolist() == [10, 11]
    np.testing.assert_allclose(inbox.range_m, [0.05, 0.06])
    c = inbox.content
    assert c.goal_known.tolist() == [[True, False], [True, True]]
    np.testing.assert_allclose(c.goal_distance_m, [[0.5, 0.0], [1.0, 2.5]])
    np.testing.assert_allclose(c.goal_angle_rad, [[0.25, 0.0], [-0.5, 3.0]])
    np.testing.assert_allclose(c.goal_p_m, [[2.0, 0.0], [0.125, 4.0]])
    assert c.heard_ids[0, 0] == 0 and c.heard_ids[1].tolist() == [-1, -1, -1]
    assert not errors.counts


def test_a_bad_payload_is_dropped_and_counted_and_the_others_kept():
    errors = ErrorCounter()
    inbox = _agent()._inbox(_sense(GOOD_A, BAD, GOOD_B), errors)
    assert inbox.sender_id.tolist() == [10, 12]
    np.testing.assert_allclose(inbox.bearing_rad, [0.0, 0.2])
    assert inbox.content.goal_known.tolist() == [[True, False], [True, True]]
    assert sum(errors.counts.values()) == 1


def test_only_bad_payloads_give_an_empty_inbox():
    errors = ErrorCounter()
    inbox = _agent()._inbox(_sense(BAD, BAD), errors)
    assert inbox.receiver.shape == (0,)
    assert sum(errors.counts.values()) == 2
