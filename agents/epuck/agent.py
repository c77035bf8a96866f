"""The e-puck family's agents as the agent-node shell runs them (family ``foraging``).

:class:`ForagingAgent` wraps the foraging brain with social odometry (seeds 000/001,
:mod:`~swarmloc.agents.epuck.foraging`) for one robot; :class:`StandstillAgent` is the transport
benchmarks' stand-in (``swarmloc agent --null-brain``). :data:`swarmloc.families.FAMILIES`
names :meth:`ForagingAgent.from_welcome`.
"""

from __future__ import annotations

import numpy as np

from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.messages import MAX_RECEIVED, EpuckAct, EpuckSense, Welcome, encode


class ForagingAgent:
    """The e-puck foraging controller with social odometry (seeds 000/001) for one robot."""

    sense_type = EpuckSense
    #: A tick costs tens of microseconds (benchmarks/bench_agent_tick.py): the shell may run it
    #: on Zenoh's receiving thread (agents/node.py: AgentNode.declare).
    SENSE_ON_NETWORK_THREAD = True

    def __init__(self, brain, robot_id: int, *, packed: bool = True) -> None:
        """``packed``: step the brain as one compiled call per tick (agents/epuck/agent_tick.py) when it
        qualifies; else, or if False, through ``ForagingBrain.step``. Both give the same Acts."""
        from swarmloc.agents.epuck.agent_tick import PackedForagingTick
        from swarmloc.agents.epuck.foraging import Inbox

        self.brain = brain
        brain.reuse_outputs = True  # act() encodes each answer before the next tick
        self.robot_id = robot_id
        self._capacity = brain.config.heard_capacity
        self._no_mail = Inbox.empty(self._capacity)
        self._packed = (PackedForagingTick(brain, MAX_RECEIVED)
                        if packed and PackedForagingTick.supports(brain) else None)

    @classmethod
    def from_welcome(cls, welcome: Welcome, scenario) -> ForagingAgent:
        from swarmloc.agents.epuck.foraging import ForagingBrain, agent_rng

        rid, world = welcome.robot_id, scenario.world
        brain = ForagingBrain(scenario.agent, world.body, [rid], [agent_rng(welcome.seed, rid)], world.tick_s)
        return cls(brain, rid)

    def _inbox(self, sense: EpuckSense, errors: ErrorCounter):
        from swarmloc.agents.epuck.foraging import Inbox, SocialMessages

        if not sense.received:
            return self._no_mail
        rows = sense.received
        try:  # the common case: every message decodes, all at once
            content = SocialMessages.decode([msg.payload for msg in rows], self._capacity)
        except ValueError:
            rows, content = self._good_messages(sense, errors)
            if not rows:
                return self._no_mail
        return Inbox(
            receiver=np.zeros(len(rows), np.int64),
            sender_id=np.array([m.sender_id for m in rows], np.int64),
            range_m=np.array([m.range_m for m in rows]),
            bearing_rad=np.array([m.bearing_rad for m in rows]),
            content=content,
        )

    def _good_messages(self, sense: EpuckSense, errors: ErrorCounter):
        """The messages whose payload decodes, and their content; each bad one is counted."""
        from swarmloc.agents.epuck.foraging import SocialMessages

        rows, contents = [], []
        for msg in sense.received:
            try:
                contents.append(SocialMessages.decode([msg.payload], self._capacity))
                rows.append(msg)
            except ValueError as exc:
                errors.record(f"robot {msg.sender_id}", "payload", exc)
        if not rows:
            return rows, None
        return rows, SocialMessages(
            *(np.concatenate([getattr(c, f) for c in contents]) for f in SocialMessages.__dataclass_fields__)
        )

    def act(self, sense: EpuckSense, errors: ErrorCounter) -> EpuckAct:
        if self._packed is not None:
            return self._act_packed(sense, errors)
        out = self.brain.step(
            np.array([sense.encoder_steps]),
            np.array([sense.ir]),
            np.array([sense.ground]),
            self._inbox(sense, errors),
        )
        return EpuckAct(
            tick=sense.tick,
            robot_id=self.robot_id,
            wheel_speed_steps_s=tuple(out.wheel_speed_steps_s[0].tolist()),
            payload=out.messages.encode(0) if out.sending[0] else None,
            state=int(out.state[0]),
            pose_estimate=tuple(out.pose_estimate[0].tolist()),
        )

    def _act_packed(self, sense: EpuckSense, errors: ErrorCounter) -> EpuckAct:
        """``act`` as one compiled call (agents/epuck/agent_tick.py); the few Python operations here
        are the whole per-tick cost around it, so they are kept few."""
        t = self._packed
        f = t.f
        f[t.percepts:t.percepts + t.N_PERCEPTS] = (*sense.encoder_steps, *sense.ir, *sense.ground)
        rows = sense.received
        m = len(rows)
        if m:
            f[t.range_bearing:t.range_bearing + 2 * m] = [x for r in rows for x in (r.range_m, r.bearing_rad)]
            t.i[t.sender_len:t.sender_len + 2 * m] = [x for r in rows for x in (r.sender_id, len(r.payload))]
            blob = np.frombuffer(b"".join([r.payload for r in rows]), np.uint8)
        else:
            blob = t.no_payloads
        n = t.step(blob, m)
        for j in t.rejected():
            self._reject(rows[j].sender_id, rows[j].payload, errors)
        return self._packed_act(sense.tick, n)

    def _packed_act(self, tick: int, n: int) -> EpuckAct:
        """The Act of the packed tick just run, whose payload length is ``n`` (-1: none)."""
        t = self._packed
        if n < -1:  # as SocialMessages.encode raises: a float32 overflow
            raise ValueError(f"payload: this robot's own message does not encode (code {n + 1})")
        answer = t.f[t.answer:t.answer + 5].tolist()
        return EpuckAct(
            tick=tick,
            robot_id=self.robot_id,
            wheel_speed_steps_s=(answer[0], answer[1]),
            payload=t.payload_out[:n].tobytes() if n >= 0 else None,
            state=int(t.i[t.state]),
            pose_estimate=(answer[2], answer[3], answer[4]),
        )

    def act_wire(self, data: bytes, errors: ErrorCounter) -> bytes | None:
        """The encoded Act answering the encoded Sense ``data``, in one compiled call
        (agents/epuck/agent_tick.py: agent_tick_wire), or None when ``data`` is not in the world's
        canonical form (or this brain is not packed): the shell then decodes it with the protocol
        codec and calls :meth:`act`, which also reports what is wrong with it. The Act is the
        one :meth:`act` would give, byte for byte (tests/test_agent_tick.py)."""
        t = self._packed
        if t is None:
            return None
        n = t.step_wire(np.frombuffer(data, np.uint8))
        if n == t.USE_CODEC:
            return None
        for j in t.rejected():
            start, (sender, size) = int(t.view["msg_start"][j]), t.view["msg_sender_len"][j].tolist()
            self._reject(sender, data[start:start + size], errors)
        if n == t.ACT_INVALID:  # the codec names the problem (raises)
            return encode(self._packed_act(t.sense_tick, t.payload_length))
        return t.act_out[:n].tobytes()

    def _reject(self, sender_id: int, payload: bytes, errors: ErrorCounter) -> None:
        """Count a teammate's payload the compiled decoder rejected, with the reference decoder's
        reason (agents/epuck/foraging.py: SocialMessages.decode, which the compiled one agrees with)."""
        from swarmloc.agents.epuck.foraging import SocialMessages

        try:
            SocialMessages.decode([payload], self._capacity)
        except ValueError as exc:
            errors.record(f"robot {sender_id}", "payload", exc)
        else:  # cannot happen while the two decoders agree (tests/test_social_codec.py)
            errors.record(f"robot {sender_id}", "payload", ValueError("payload: rejected by the compiled decoder"))


class StandstillAgent:
    """A transport benchmark's stand-in for an e-puck brain (``swarmloc agent --null-brain``):
    answers every Sense at once with an Act that holds the wheels still and sends nothing. The
    shell still decodes each Sense and encodes each Act, so a swarm of these measures what an
    agent process costs without its brain (benchmarks/bench_lockstep.py --null-brain)."""

    sense_type = EpuckSense
    SENSE_ON_NETWORK_THREAD = True

    def __init__(self, robot_id: int) -> None:
        self.robot_id = robot_id

    def act(self, sense: EpuckSense, errors: ErrorCounter) -> EpuckAct:
        return EpuckAct(tick=sense.tick, robot_id=self.robot_id, wheel_speed_steps_s=(0.0, 0.0),
                        payload=None, state=0, pose_estimate=(0.0, 0.0, 0.0))
