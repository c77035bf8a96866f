"""The agent node: one robot's brain in its own process, over Zenoh.

A thin shell around an :class:`~swarmloc.agents.brains.AgentBrain` (the e-puck foraging brain
with a batch of one, a laser localizer, ...), chosen by the scenario the world sends:

1. join: query ``world/join`` with a ``Join``; the world answers with the scenario and run seed;
2. subscribe to this robot's ``sense`` key, then declare its liveliness token (the world waits
   for it, so the first Sense never finds the agent deaf);
3. on each Sense: decode, step the brain, publish the Act (a brain with ``act_wire`` answers the
   Sense's bytes with the Act's itself, falling back to this for anything unusual);
4. stop on ``RunEnd``, on a final Sense, on SIGINT/SIGTERM, when the world's liveliness token has
   been gone for ``world_grace_s`` (a world restarting within that time is waited for), or when
   no Sense came for ``world_timeout_s``; close the session on the way out.

A malformed Sense, or a teammate's malformed payload inside a valid Sense, is rejected, counted
and logged once; the agent keeps running.
"""

from __future__ import annotations

import logging
import os
import threading
import time

import zenoh

from swarmloc.agents.brains import AgentBrain, BrainError, brain_from_welcome
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.keys import Keys
from swarmloc.protocol.messages import (
    ErrorReport,
    Join,
    ProtocolError,
    RunEnd,
    Welcome,
    decode,
    encode,
)
from swarmloc.protocol.session import direct_callback

log = logging.getLogger("swarmloc.agent")


WORLD_GONE = "the world-server is gone"
#: How long the world's liveliness may be gone before an agent warns: longer than its RunEnd
#: takes to follow at a normal end.
WORLD_GONE_WARN_S = 1.0
#: Exit code of an agent whose world died (and did not come back within the grace period).
EXIT_WORLD_GONE = 3
#: How often the main thread looks at the run's end and the world's health while the callbacks
#: work; a signal wakes it at once. Each look wakes the process: at 0.2 s that was about 20 µs
#: of CPU per 10 Hz tick, a tenth of what an agent costs (benchmarks/bench_scale.py --realtime).
WAIT_POLL_S = 1.0


class JoinError(RuntimeError):
    """The world refused us, or could not be reached."""


def join(session: zenoh.Session, keys: Keys, robot_id: int, timeout_s: float,
         stop: threading.Event | None = None) -> Welcome:
    """Ask the world for our scenario, retrying until ``timeout_s`` (the world may start later)
    or until ``stop`` is set (SIGINT/SIGTERM while waiting: JoinError at once)."""
    deadline = time.monotonic() + timeout_s
    stop = stop if stop is not None else threading.Event()
    request = encode(Join(robot_id=robot_id, brain="auto", pid=os.getpid()))
    while True:
        for reply in session.get(keys.join, payload=request, timeout=2.0):
            if reply.ok is None:
                continue
            msg = decode(reply.ok.payload.to_bytes(), (Welcome, ErrorReport))
            if isinstance(msg, ErrorReport):
                raise JoinError(f"the world refused robot {robot_id}: {msg.field}: {msg.detail}")
            return msg
        if time.monotonic() > deadline:
            raise JoinError(f"no world answered on {keys.join} within {timeout_s:.0f} s")
        if stop.wait(0.2):  # retry pacing for a world not started yet, cut short by a signal
            raise JoinError("stopped while waiting for the world")


class AgentNode:
    def __init__(self, session: zenoh.Session, keys: Keys, robot_id: int, brain: AgentBrain):
        self.session = session
        self.keys = keys
        self.robot_id = robot_id
        self.brain = brain
        self.errors = ErrorCounter()
        self.done = threading.Event()
        self.end_reason = ""
        self.last_sense_at = time.monotonic()
        self.world_lost_at: float | None = None
        self._world_warned = False  # warned that the world is gone (once per absence)
        self.ticks = 0
        self._decls = []
        #: ``act_wire(data, errors) -> bytes | None`` of brains that answer an encoded Sense with
        #: an encoded Act themselves (None: decode it and call ``act``); see ForagingAgent.
        self._act_wire = getattr(brain, "act_wire", None)

    def _on_sense(self, sample: zenoh.Sample) -> None:
        data = sample.payload.to_bytes()
        # bytes to bytes in one call, when the brain can; None: decode and step it here
        act = self._act_wire(data, self.errors) if self._act_wire is not None else None
        if act is None:
            try:
                sense = decode(data, self.brain.sense_type)
                if sense.robot_id != self.robot_id:
                    raise ProtocolError("robot_id", f"{sense.robot_id} sent on the key of robot {self.robot_id}")
            except ProtocolError as exc:
                self.errors.record(str(sample.key_expr), "sense", exc)
                return
            if getattr(sense, "final", False):
                self.last_sense_at = time.monotonic()
                self.end_reason = "final sense"
                self.done.set()
                return
            act = encode(self.brain.act(sense, self.errors))
        self.last_sense_at = time.monotonic()
        self._act_pub.put(act)
        self.ticks += 1

    def _on_end(self, sample: zenoh.Sample) -> None:
        try:
            end = decode(sample.payload.to_bytes(), RunEnd)
        except ProtocolError as exc:
            self.errors.record(str(sample.key_expr), "end", exc)
            return
        self.end_reason = f"run ended: {end.reason}"
        self.done.set()

    def _on_world_alive(self, sample: zenoh.Sample) -> None:
        if sample.kind == zenoh.SampleKind.PUT:
            if self.world_lost_at is not None and self._world_warned:
                log.warning("robot %d: the world-server is back", self.robot_id)
            self.world_lost_at = None
            self._world_warned = False
        else:
            # Not a warning yet: at a normal end the world's token goes at the same moment as
            # its RunEnd, on another key, and may arrive first (issue 47: 98 of 100 agents
            # warned at every normal end). wait() warns if the run has not ended by then.
            self.world_lost_at = time.monotonic()

    def declare(self) -> None:
        s, k = self.session, self.keys
        self._act_pub = s.declare_publisher(
            k.act(self.robot_id), congestion_control=zenoh.CongestionControl.BLOCK
        )
        # These two only set a flag: run on Zenoh's receiving thread (indirect=False), not on a
        # Python thread of their own each, which every callback subscriber otherwise gets.
        self._decls.append(s.declare_subscriber(k.run_end, direct_callback(self._on_end)))
        self._decls.append(
            s.liveliness().declare_subscriber(k.world_alive, direct_callback(self._on_world_alive), history=True)
        )
        declare = getattr(self.brain, "declare", None)
        if declare is not None:  # a brain with keys of its own (vision agents' team keys)
            self._decls.extend(declare(s, k, self.errors))
        # A brain whose step is bounded and short (SENSE_ON_NETWORK_THREAD) answers on Zenoh's
        # receiving thread too: no hand-over to a Python thread, two context switches fewer
        # per tick. A long step there would stall that thread's link (keep-alives included),
        # so the other brains keep a thread of their own.
        on_sense = self._on_sense
        if getattr(self.brain, "SENSE_ON_NETWORK_THREAD", False):
            on_sense = direct_callback(on_sense)
        self._decls.append(s.declare_subscriber(k.sense(self.robot_id), on_sense))
        # Declared last: the world sees us only once we can hear it.
        self._token = s.liveliness().declare_token(k.alive(self.robot_id))

    def wait(self, stop: threading.Event, world_timeout_s: float, world_grace_s: float) -> str:
        """Wait until the run ends, we are told to stop, or the world is gone or silent too long."""
        while not self.done.is_set():
            if stop.wait(WAIT_POLL_S):
                return "signal"
            now = time.monotonic()
            lost = self.world_lost_at
            if lost is not None and now - lost > world_grace_s:
                return WORLD_GONE
            if lost is not None and not self._world_warned and now - lost > WORLD_GONE_WARN_S:
                self._world_warned = True
                log.warning("robot %d: the world-server is gone; waiting for it (up to %.0f s)",
                            self.robot_id, world_grace_s)
            if now - self.last_sense_at > world_timeout_s:
                return f"no sense from the world for {world_timeout_s:.0f} s"
        return self.end_reason


def run_agent(
    session: zenoh.Session,
    keys: Keys,
    robot_id: int,
    stop: threading.Event,
    *,
    join_timeout_s: float = 120.0,
    world_timeout_s: float = 300.0,
    world_grace_s: float = 10.0,
    null_brain: bool = False,
) -> int:
    """Run one agent to the end of the run; returns a process exit code. ``null_brain``: answer
    with a standstill Act instead of running the brain (transport benchmarks)."""
    try:
        welcome = join(session, keys, robot_id, join_timeout_s, stop)
        brain = brain_from_welcome(welcome, null_brain=null_brain)
    except (JoinError, BrainError, ProtocolError) as exc:
        if stop.is_set():
            log.info("robot %d: stopped before joining", robot_id)
            return 0
        log.error("robot %d: %s", robot_id, exc)
        return 2
    node = AgentNode(session, keys, robot_id, brain)
    node.declare()
    reason = node.wait(stop, world_timeout_s, world_grace_s)
    log.info("robot %d: %s after %d ticks; rejected %s", robot_id, reason, node.ticks, dict(node.errors.counts))
    return EXIT_WORLD_GONE if reason == WORLD_GONE else 0
