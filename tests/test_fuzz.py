"""Fuzzing a real run: 100,000 malformed, truncated, oversized and type-confused messages.

A seeded generator (:class:`Fuzzer`) derives every message from a valid one (an act, a sense, a
join) by one mutation: random bytes, truncation, trailing bytes, bit flips, a message over the
256 KiB limit, a field of the wrong type or out of range, a missing or extra field, a bad
version or type tag, a message of another type, a valid message for another robot (or, for a
join, a robot the run does not have). Mutants that the receiving shell would accept (a bit flip
can leave a valid message) are discarded: *every* message sent must be refused, so that the run
cannot change, and each refusal is counted by the receiver.

During a lockstep run (router, world and agents as separate processes, ``start_swarm``):

- act keys of the world-server (``robot/*/act``, also ids that are not canonical or not in the
  run): the world's result must count exactly that many ``act`` rejections;
- the world's ``join`` queryable: exactly that many ``join`` rejections, and an ErrorReport
  reply to every query;
- the sense key of one agent: that agent's exit log must count exactly that many ``sense``
  rejections (it is started with ``-v``: agents log their counts at INFO when they end);
- the run's metrics equal the same seeded run's without fuzz (the batch engine's: a process run
  equals it, test_integration), with no late and no stale act.

Everything is sent before a marker; the marker's arrival (on a second session) proves that the
world's router had handed all fuzz to the world's act queue and to the agent's link, which both
process in order, and the run must still have ticks to go at that point (asserted). To make sure it
has, whatever the machine's load, the test holds the run while the fuzz goes in: it stops another
agent's process (SIGSTOP) once the run ticks, and the lockstep world waits for that robot's act
until the marker has arrived (SIGCONT). Every piece gets a Zenoh lease, an act timeout and a
world timeout longer than that hold can last. (Without the hold, a loaded machine once finished
the 12,000 ticks while half the join queries were still to be sent.)
"""

from __future__ import annotations

import ast
import contextlib
import json
import os
import random
import re
import signal
import threading
import time
import uuid
from collections import Counter

import msgpack
import numpy as np
import pytest
import zenoh

from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.lab.netns import write_lease_config
from swarmloc.deploy.launch import supervised
from swarmloc.deploy.run import start_swarm
from swarmloc.deploy.scenario import load_scenario
from swarmloc.protocol.keys import Keys
from swarmloc.protocol.messages import (
    MAX_MESSAGE_BYTES,
    EpuckAct,
    EpuckSense,
    ErrorReport,
    Join,
    ProtocolError,
    RabMessage,
    RunEnd,
    Welcome,
    WorldState,
    decode,
    encode,
)
from swarmloc.protocol.session import open_session, session_config

TOTAL = 100_000
SHARES = {"act": 0.6, "sense": 0.3, "join": 0.1}
ROBOTS = 3
FUZZED_AGENT = ROBOTS - 1
SEED = 20_250_607

CONFUSERS = ("x", b"\x00\x01", None, True, False, [], {}, [1.0, 2.0, 3.0, 4.0], {"a": 1},
             2**64 - 1, -(2**63), 1.5, -1, float("nan"), float("inf"), -float("inf"), 10**6,
             "1.0", [None], [[1.0]], b"")


# -- what the receiving shells accept (world/server.py, agents/node.py) -------------------------


def world_accepts_act(key: str, payload: bytes, robots: int) -> bool:
    try:
        robot = Keys.robot_id_from_key(key)
        act = decode(payload, EpuckAct)
    except (ProtocolError, ValueError):
        return False
    return act.robot_id == robot and robot < robots


def agent_accepts_sense(payload: bytes, robot_id: int) -> bool:
    try:
        return decode(payload, EpuckSense).robot_id == robot_id
    except ProtocolError:
        return False


def world_accepts_join(payload: bytes, robots: int) -> bool:
    try:
        return decode(payload, Join).robot_id < robots
    except ProtocolError:
        return False


# -- the generator -------------------------------------------------------------------------------


class Fuzzer:
    """Seeded bad messages for a run with ``robots`` robots (same generator state, same messages).

    Valid messages are drawn once into a pool per robot; each bad message is one mutation of a
    pooled message. Scalar draws come from a ``random.Random`` seeded from ``rng`` (much cheaper
    per call than numpy's, and as reproducible)."""

    POOL = 64

    def __init__(self, keys: Keys, robots: int, rng: np.random.Generator):
        self.keys, self.robots = keys, robots
        self.r = random.Random(int(rng.integers(0, 2**63)))
        self.kinds: Counter = Counter()
        self._pools: dict = {}
        self._others = [
            WorldState(tick=3, time_s=0.3, poses=((0.1, 0.2, 0.3),), alive=(True,), round_trips=0),
            RunEnd(tick=5, reason="completed", metrics={"a": 1}),
            ErrorReport("protocol", "x", "y"),
            Welcome(robot_id=0, run=keys.run, seed=1, scenario={"world": {}}),
        ]

    # valid messages to start from
    def _u(self, lo, hi, n):
        return tuple(self.r.uniform(lo, hi) for _ in range(n))

    def act(self, robot_id: int) -> EpuckAct:
        r = self.r
        payload = bytes(r.getrandbits(8) for _ in range(r.randrange(0, 65)))
        return EpuckAct(tick=r.randrange(0, 4000), robot_id=robot_id,
                        wheel_speed_steps_s=self._u(-1000, 1000, 2),
                        payload=payload if r.random() < 0.5 else None, state=r.randrange(0, 256),
                        pose_estimate=self._u(-2, 2, 3))

    def sense(self, robot_id: int) -> EpuckSense:
        r = self.r
        received = tuple(RabMessage(r.randrange(0, self.robots), r.uniform(0, 0.15), r.uniform(-3.14, 3.14),
                                    bytes(r.randrange(0, 65))) for _ in range(r.randrange(0, 4)))
        return EpuckSense(tick=r.randrange(0, 4000), robot_id=robot_id, encoder_steps=self._u(-20, 20, 2),
                          ir=self._u(0, 1, 8), ground=self._u(0, 2, 3), received=received)

    def join(self, robot_id: int) -> Join:
        return Join(robot_id=robot_id, brain="foraging", pid=self.r.randrange(1, 2**22))

    def _pooled(self, make, robot_id: int):
        """(message, its encoding, its wire map) from the pool of ``make`` for ``robot_id``."""
        pool = self._pools.get((make, robot_id))
        if pool is None:
            pool = []
            for _ in range(self.POOL):
                msg = make(robot_id)
                raw = encode(msg)
                pool.append((msg, raw, msgpack.unpackb(raw)))
            self._pools[(make, robot_id)] = pool
        return pool[self.r.randrange(self.POOL)]

    # mutations of one valid message
    KINDS = ("random", "truncated", "trailing", "flip", "oversized", "wrong_type", "out_of_range",
             "missing", "extra", "version", "tag", "other_type", "not_a_map", "nested")
    WEIGHTS = (11, 10, 5, 10, 0.2, 24, 10, 5, 5, 5, 5, 5, 2.8, 2)

    def mutate(self, make, robot_id: int) -> bytes:
        r = self.r
        _, raw, wire = self._pooled(make, robot_id)
        wire = dict(wire)
        fields = [f for f in wire if f not in ("v", "t")]
        kind = r.choices(self.KINDS, self.WEIGHTS)[0]
        self.kinds[kind] += 1
        if kind == "random":
            return r.randbytes(r.randrange(0, 200))
        if kind == "truncated":
            return raw[: r.randrange(0, len(raw))]
        if kind == "trailing":
            return raw + r.randbytes(r.randrange(1, 9))
        if kind == "flip":
            data = bytearray(raw)
            for _ in range(r.randrange(1, 4)):
                data[r.randrange(len(data))] ^= 1 << r.randrange(8)
            return bytes(data)
        if kind == "oversized":
            return msgpack.packb({**wire, "pad": bytes(MAX_MESSAGE_BYTES + r.randrange(1, 4096))})
        if kind in ("wrong_type", "out_of_range"):
            field = r.choice(fields)
            value = r.choice(CONFUSERS)
            if kind == "out_of_range":
                value = r.choice((-1.0, 1.0)) * 10.0 ** r.randrange(3, 25)
                if isinstance(wire[field], list) and wire[field]:
                    items = list(wire[field])
                    items[r.randrange(len(items))] = value
                    value = items
            wire[field] = value
            return msgpack.packb(wire)
        if kind == "missing":
            del wire[r.choice(fields)]
            return msgpack.packb(wire)
        if kind == "extra":
            wire[f"x{r.randrange(100)}"] = 1
            return msgpack.packb(wire)
        if kind == "version":
            wire["v"] = r.choice((0, 2, "1", None, 1.0, True, 255))
            if r.random() < 0.2:
                del wire["v"]
            return msgpack.packb(wire)
        if kind == "tag":
            wire["t"] = r.choice(("", "act2", 1, None, "ACT", "sense ", "join\x00"))
            return msgpack.packb(wire)
        if kind == "other_type":
            other = r.choice((self.act, self.sense, self.join, None))
            return encode(r.choice(self._others)) if other is None else self._pooled(other, robot_id)[1]
        if kind == "not_a_map":
            return msgpack.packb(r.choice((list(wire.values()), 7, "act", None, 1.5)))
        # nested: a bad entry inside a list field (received messages, tuples)
        field = r.choice([f for f in fields if isinstance(wire[f], list)] or fields)
        bad = {"sender_id": -1, "range_m": "far", "bearing_rad": None, "payload": bytes(65)}
        wire[field] = [bad] * r.randrange(1, 18)
        return msgpack.packb(wire)

    def act_key(self) -> tuple[str, int]:
        r, robots = self.r, self.robots
        i = r.randrange(robots)
        u = r.random()
        if u < 0.9:
            return self.keys.act(i), i
        if u < 0.95:
            return self.keys.act(robots + i), robots + i  # not a robot of the run
        odd = f"0{i}" if u < 0.975 else f"x{i}"  # not a canonical id
        return f"{self.keys.prefix}/robot/{odd}/act", i

    def bad_act(self) -> tuple[str, bytes]:
        while True:
            key, i = self.act_key()
            if self.r.random() < 0.05:  # a valid act of robot i on another robot's key
                other = (i + 1 + self.r.randrange(self.robots - 1)) % self.robots
                key, payload = self.keys.act(other), self._pooled(self.act, i % self.robots)[1]
            else:
                payload = self.mutate(self.act, i)
            if not world_accepts_act(key, payload, self.robots):
                return key, payload

    def bad_sense(self, robot_id: int) -> bytes:
        while True:
            if self.r.random() < 0.05:  # a valid sense of another robot
                payload = self._pooled(self.sense, (robot_id + 1) % self.robots)[1]
            else:
                payload = self.mutate(self.sense, robot_id)
            if not agent_accepts_sense(payload, robot_id):
                return payload

    def bad_join(self) -> bytes:
        while True:
            if self.r.random() < 0.05:  # a robot the run does not have
                payload = encode(self.join(self.robots + self.r.randrange(1000)))
            else:
                payload = self.mutate(self.join, self.r.randrange(self.robots))
            if not world_accepts_join(payload, self.robots):
                return payload


def test_generator_is_seeded_and_every_message_is_refused():
    keys = Keys("fuzzcheck")
    a, b = Fuzzer(keys, ROBOTS, np.random.default_rng(1)), Fuzzer(keys, ROBOTS, np.random.default_rng(1))
    batch_a = [a.bad_act() for _ in range(300)] + [(keys.sense(1), a.bad_sense(1)) for _ in range(300)]
    batch_b = [b.bad_act() for _ in range(300)] + [(keys.sense(1), b.bad_sense(1)) for _ in range(300)]
    assert batch_a == batch_b
    assert len(set(batch_a)) > 550, "the messages vary"
    assert len({len(p) for _, p in batch_a}) > 50, "of many sizes"
    for key, payload in batch_a[:300]:
        assert not world_accepts_act(key, payload, ROBOTS)
    # The oracle is not vacuous: the valid messages the mutants start from are accepted.
    f = Fuzzer(keys, ROBOTS, np.random.default_rng(2))
    assert world_accepts_act(keys.act(1), encode(f.act(1)), ROBOTS)
    assert not world_accepts_act(keys.act(2), encode(f.act(1)), ROBOTS)
    assert agent_accepts_sense(encode(f.sense(2)), 2)
    assert world_accepts_join(encode(f.join(0)), ROBOTS)
    assert not world_accepts_join(encode(f.join(ROBOTS)), ROBOTS)


# -- the run ----------------------------------------------------------------------------------


class Observer:
    """A second session: the world's states and the fuzzer's marker."""

    def __init__(self, endpoint: str, keys: Keys, marker_key: str):
        self.session = open_session(session_config(mode="client", connect=[endpoint]))
        self.tick = -1
        self.started = threading.Event()
        self.marker = threading.Event()
        self.tick_at_marker = None

        def on_state(sample):
            self.tick = decode(sample.payload.to_bytes(), WorldState).tick
            self.started.set()

        def on_marker(sample):
            self.tick_at_marker = self.tick
            self.marker.set()

        self.session.declare_subscriber(keys.world_state, on_state)
        self.session.declare_subscriber(marker_key, on_marker)


def _send_joins(session, keys: Keys, payloads: list[bytes], in_flight: int = 64) -> Counter:
    """One query per payload, at most ``in_flight`` outstanding; count the replies by type."""
    replies: Counter = Counter()
    lock = threading.Lock()
    slots = threading.BoundedSemaphore(in_flight)

    def on_reply(reply):
        kind = "no reply"
        if reply.ok is not None:
            try:
                kind = type(decode(reply.ok.payload.to_bytes(), (ErrorReport, Welcome))).__name__
            except ProtocolError:
                kind = "undecodable"
        with lock:
            replies[kind] += 1

    for payload in payloads:
        assert slots.acquire(timeout=60), "join queries stopped being answered"
        session.get(keys.join, zenoh.handlers.Callback(on_reply, slots.release), payload=payload,
                    timeout=30.0, congestion_control=zenoh.CongestionControl.BLOCK)
    for _ in range(in_flight):  # every query finished
        assert slots.acquire(timeout=60)
    return replies


@pytest.mark.integration
def test_a_real_run_refuses_and_counts_100k_bad_messages_and_is_unchanged(tmp_path):
    # 12,000 ticks: long enough for the robots to forage, so that metrics equal to the batch
    # engine's say something (the hold below, not the length, keeps the run ticking past the fuzz).
    scenario = load_scenario("ES1", [f"world.robots={ROBOTS}", "world.duration_s=1200.0", "world.seed=11"])
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(scenario.to_dict()))
    expected = json.loads(json.dumps(run_batch(scenario).metrics))
    run = "fz" + uuid.uuid4().hex[:10]
    keys = Keys(run)
    fuzzer = Fuzzer(keys, ROBOTS, np.random.default_rng(SEED))
    n_act, n_sense = int(TOTAL * SHARES["act"]), int(TOTAL * SHARES["sense"])
    n_join = TOTAL - n_act - n_sense
    t0 = time.perf_counter()
    acts = [fuzzer.bad_act() for _ in range(n_act)]
    senses = [fuzzer.bad_sense(FUZZED_AGENT) for _ in range(n_sense)]
    joins = [fuzzer.bad_join() for _ in range(n_join)]
    generated_s = time.perf_counter() - t0
    assert min(fuzzer.kinds.values()) > 0 and len(fuzzer.kinds) == 14, fuzzer.kinds

    marker_key = f"{keys.prefix}/fuzz/marker"
    out = tmp_path / "out"
    # Longer than the hold below can last, however loaded the machine: the held agent's link, the
    # world's wait for its act, and the other agents' wait for their next Sense.
    hold_s = "600"
    lease = ("-c", str(write_lease_config(tmp_path / "zenoh-lease.json5", float(hold_s))))
    agent_args = ("--world-timeout-s", hold_s, *lease)
    with supervised() as sup:
        # The agents of robots 0..N-2 as `swarmloc run` starts them; the fuzzed one with -v, so
        # that it logs its rejection counts when it ends. The world waits for all of them.
        swarm = start_swarm(sup, path, run=run, robots=ROBOTS - 1, out=out, log_dir=tmp_path,
                            join_timeout_s=60, world_args=("--act-timeout-s", hold_s, *lease),
                            agent_args=agent_args)
        fuzzed = sup.start(["-v", "agent", "--robot", str(FUZZED_AGENT), "-m", "client", "-e",
                            swarm.world_endpoint, "--run", run, "--join-timeout-s", "60", *agent_args],
                           log_path=tmp_path / f"agent-{FUZZED_AGENT}.log")
        observer = Observer(swarm.world_endpoint, keys, marker_key)
        fuzz = open_session(session_config(mode="client", connect=[swarm.world_endpoint]))
        held = swarm.agents[0]
        try:
            assert observer.started.wait(60), "the run never started"
            os.kill(held.pid, signal.SIGSTOP)  # the run waits for robot 0's act from here
            t1 = time.perf_counter()
            block = zenoh.CongestionControl.BLOCK
            sense_key = keys.sense(FUZZED_AGENT)
            for i in range(0, max(n_act, n_sense), 1000):  # interleaved, in chunks
                for key, payload in acts[i:i + 1000]:
                    fuzz.put(key, payload, congestion_control=block)
                for payload in senses[i:i + 1000]:
                    fuzz.put(sense_key, payload, congestion_control=block)
            replies = _send_joins(fuzz, keys, joins)
            fuzz.put(marker_key, b"done", congestion_control=block)
            assert observer.marker.wait(60), "the marker never arrived"
            sent_s = time.perf_counter() - t1
            os.kill(held.pid, signal.SIGCONT)
            assert swarm.world.wait(timeout=180) == 0
            assert fuzzed.wait(timeout=30) in (0, 3)
        finally:
            with contextlib.suppress(ProcessLookupError):  # gone already: let the first error show
                os.kill(held.pid, signal.SIGCONT)  # a stopped process would not see the supervisor's SIGTERM
            fuzz.close()
            observer.session.close()
    result = json.loads((out / "results.json").read_text())
    n_ticks = result["transport"]["ticks"]
    print(f"fuzz: {TOTAL} messages generated in {generated_s:.1f} s, sent in {sent_s:.1f} s; marker at "
          f"tick {observer.tick_at_marker} of {n_ticks}; kinds {dict(fuzzer.kinds)}; "
          f"world transport {result['transport']}")
    # The fuzz was all in the receivers' queues with ticks to go (states come every 10 ticks).
    assert observer.tick_at_marker is not None and observer.tick_at_marker + 20 < n_ticks, (
        "the run ended too soon after the fuzz for the counts to be complete: lengthen it")
    assert result["reason"] == "completed"
    assert result["rejected"] == {"act": n_act, "join": n_join}
    assert replies == Counter({"ErrorReport": n_join}), "every join query got a refusal"
    assert result["transport"]["late_acts"] == 0 and result["transport"]["stale_acts"] == 0
    assert result["metrics"] == expected, "the fuzz changed the run"
    log = (tmp_path / f"agent-{FUZZED_AGENT}.log").read_text()
    counts = re.findall(r"robot \d+: .* after \d+ ticks; rejected (\{.*\})", log)
    assert len(counts) == 1, log[-2000:]
    assert ast.literal_eval(counts[0]) == {"sense": n_sense}
