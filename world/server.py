"""The world-server: serves a world model over Zenoh to agent processes.

A thin shell: decode, call the model, encode, publish. It knows no robot family: it serves a
:class:`~swarmloc.world.service.ServedWorld` (the e-puck foraging world, the laser world, the
vision world, a replay of recorded data). Per tick ``k`` it publishes ``Sense(k)`` to every live
robot, waits for ``Act(k)`` from each, then steps the world with the Acts it got.

- *Lockstep* (default): waits for every live robot's Act, up to ``act_timeout_s``; a robot that
  misses it keeps its previous wheel command for that tick and sends nothing. Given a seed, the run
  is deterministic.
- *Real time*: ticks at ``tick_s`` on the wall clock; a late Act means the previous command.

Agents join through a query on ``world/join`` (answered with the scenario) and stay alive through a
liveliness token: a robot whose token disappears stands still and the run goes on; a token that
comes back revives it. A malformed, oversized or out-of-range message is rejected by the protocol,
counted, logged once per sender, and changes nothing.
"""

from __future__ import annotations

import gc
import logging
import threading
import time
from array import array
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np
import zenoh

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
from swarmloc.world.service import ServedWorld

log = logging.getLogger("swarmloc.world")

#: Overruns whose details a run keeps (:attr:`TickStats.overrun_ticks`).
MAX_OVERRUNS_KEPT = 20
#: In real time the collection of Acts ends before the tick's slot does by the time the step
#: will take, estimated as the 90th percentile of the last :data:`STEP_RESERVE_TICKS` steps (one
#: step preempted for 180 ms, seen at 600 agents, must not cut the next ticks' collection to
#: nothing), at most :data:`MAX_STEP_RESERVE_SHARE` of the period, plus :data:`WAKE_MARGIN_S` for
#: the world's thread to wake on a loaded machine (:meth:`WorldServer._collect`).
STEP_RESERVE_TICKS = 20
MAX_STEP_RESERVE_SHARE = 0.25
WAKE_MARGIN_S = 0.002


@dataclass
class TickStats:
    ticks: int = 0
    started_s: float = 0.0
    cpu_started_s: float = 0.0  # process CPU time (every thread, Zenoh's too) when ticking began
    tap_cpu_s: float = 0.0  # the world thread's CPU time inside the observer tap's calls
    #: Every tick's duration and phases, 8 bytes each (``array('d')``): a run of an hour keeps
    #: 36,000 ticks, 1.2 MB in all; as lists of floats they took four times that, a steady
    #: growth the soak benchmark saw in the world's memory (benchmarks/bench_soak.py, issue 47).
    tick_durations_s: array = field(default_factory=lambda: array("d"))
    late_acts: int = 0  # live robots whose act missed its tick (deadline or lockstep timeout)
    stale_acts: int = 0  # acts that arrived after their tick was closed
    overruns: int = 0
    overruns_after_1s: int = 0  # those of ticks after the run's first wall second (start-up)
    #: real-time stalls: the clock found more than one period late (the process was stopped,
    #: the machine swapped, no agent was alive) and restarted from now instead of catching up
    stalls: int = 0
    stalled_s: float = 0.0  # the real time those stalls skipped
    join_s: float | None = None  # from the world's declaration to the last agent's join
    rejoins: int = 0  # agents that came back after their liveliness token went
    rejoin_away_s: list = field(default_factory=list)  # how long each was gone
    #: the first overruns, where the time went: tick, the tick's phases (ms) and how late the
    #: next tick started (ms), for diagnosis (results.json: transport.overrun_ticks)
    overrun_ticks: list = field(default_factory=list)
    #: where each tick went: computing and putting the Senses, waiting for the Acts, stepping
    phases_s: dict = field(default_factory=lambda: {p: array("d") for p in ("sense_put", "collect", "step")})

    def summary(self) -> dict:
        d = np.array(self.tick_durations_s) if self.tick_durations_s else np.zeros(1)
        wall = time.perf_counter() - self.started_s if self.started_s else 0.0
        cpu = time.process_time() - self.cpu_started_s if self.started_s else 0.0
        return {
            "ticks": self.ticks,
            "wall_s": round(wall, 3),
            "ticks_per_s": round(self.ticks / wall, 2) if wall > 0 else None,
            **dict(zip(("tick_ms_p50", "tick_ms_p99"), _p50_p99_ms(d))),
            "tick_ms_max": round(float(d.max()) * 1e3, 3),
            "tick_ms_sum": round(float(d.sum()) * 1e3, 1),
            # The world process's CPU time while ticking: far less noisy on a shared machine
            # than wall-clock rates (benchmarks/bench_observers.py compares it per tick).
            "cpu_s": round(cpu, 3),
            "cpu_ms_per_tick": round(cpu / self.ticks * 1e3, 4) if self.ticks else None,
            "tap_cpu_ms_per_tick": round(self.tap_cpu_s / self.ticks * 1e3, 4) if self.ticks else None,
            "late_acts": self.late_acts,
            "stale_acts": self.stale_acts,
            "overruns": self.overruns,
            "overruns_after_1s": self.overruns_after_1s,
            "stalls": self.stalls,
            "stalled_s": round(self.stalled_s, 3),
            "join_s": round(self.join_s, 3) if self.join_s is not None else None,
            "rejoins": self.rejoins,
            "rejoin_away_s_max": round(max(self.rejoin_away_s), 3) if self.rejoin_away_s else None,
            "overrun_ticks": self.overrun_ticks,
            **{f"{phase}_ms_p{q}": ms for phase, v in self.phases_s.items()
               for q, ms in zip((50, 99), _p50_p99_ms(v) if v else (None, None))},
        }


def _p50_p99_ms(seconds) -> tuple[float, float]:
    """The median and 99th percentile of ``seconds`` (a sequence of durations), in ms to 3
    decimals: one sort for both."""
    return tuple(round(float(x) * 1e3, 3) for x in np.percentile(np.array(seconds), (50, 99)))


class WorldServer:
    """Serve one run of a world to agent processes."""

    def __init__(
        self,
        session: zenoh.Session,
        keys: Keys,
        world: ServedWorld,
        scenario: dict,
        *,
        realtime: bool = False,
        act_timeout_s: float = 10.0,
        join_timeout_s: float = 120.0,
        state_every_ticks: int = 10,
        checkpoint: Callable[[dict], None] | None = None,
        checkpoint_every_s: float = 5.0,
        tap=None,
        samples: int = 0,
    ):
        self.session = session
        self.keys = keys
        self.world = world
        self.scenario = scenario
        self.realtime = realtime
        self.act_timeout_s = act_timeout_s
        self.join_timeout_s = join_timeout_s
        self.state_every_ticks = max(1, state_every_ticks)
        # Called with the figures so far every checkpoint_every_s of wall time, so that a
        # world-server that dies leaves what it had recorded.
        self.checkpoint = checkpoint
        self.checkpoint_every_s = checkpoint_every_s
        # An observer tap (deploy/observe/tap.py: WorldTap): gets every tick's Senses and Acts
        # to record them, and streams frames at a bounded wall-clock rate.
        self.tap = tap
        # Observers' request, passed to every agent in its Welcome: log up to this many poses of
        # the belief's population in each Act (drawn by the view, recorded; 0: none).
        self.samples = samples
        n = world.n_robots
        self.errors = ErrorCounter()
        self.stats = TickStats()
        self._cond = threading.Condition()
        self._live = np.zeros(n, bool)  # liveliness tokens present
        self._joined = np.zeros(n, bool)
        self._gone_at: dict[int, float] = {}  # robots whose agent went, since when (monotonic)
        self._current_tick = -1
        self._awaited = 0
        self._got = np.zeros(n, bool)
        self._acts: list = [None] * n
        self._stop = threading.Event()
        self._decls = []

    # -- Zenoh callbacks (run on Zenoh's threads) --------------------------------------------

    def _on_join(self, query: zenoh.Query) -> None:
        sender = f"join query on {query.key_expr}"
        try:
            payload = query.payload.to_bytes() if query.payload is not None else b""
            join = decode(payload, Join)
            if join.robot_id >= self.world.n_robots:
                raise ProtocolError(
                    "robot_id", f"{join.robot_id} is not a robot of this run (0..{self.world.n_robots - 1})"
                )
        except ProtocolError as exc:
            self.errors.record(sender, "join", exc)
            query.reply(self.keys.join, encode(ErrorReport.from_protocol_error(exc, "join")))
            return
        with self._cond:
            self._joined[join.robot_id] = True
        welcome = Welcome(
            robot_id=join.robot_id, run=self.keys.run, seed=self.world.seed,
            scenario=self.scenario, samples=self.samples,
        )
        query.reply(self.keys.join, encode(welcome))

    def _on_alive(self, sample: zenoh.Sample) -> None:
        try:
            robot = Keys.robot_id_from_key(str(sample.key_expr))
        except ValueError:
            return  # the world's own token, or an observer's
        if robot >= self.world.n_robots:
            return
        with self._cond:
            if sample.kind == zenoh.SampleKind.PUT:
                self._live[robot] = True
                gone_at = self._gone_at.pop(robot, None)
                if gone_at is not None:  # a rejoin: logged and timed (docs/deploy.md, Faults)
                    away_s = time.monotonic() - gone_at
                    self.stats.rejoins += 1
                    self.stats.rejoin_away_s.append(away_s)
                    log.warning("robot %d: agent back after %.2f s, the robot moves again", robot, away_s)
                else:
                    log.debug("robot %d: agent alive", robot)
            else:
                self._live[robot] = False
                self._gone_at[robot] = time.monotonic()
                log.warning("robot %d: agent gone, the robot stands still", robot)
            self._cond.notify_all()

    def _on_act(self, sample: zenoh.Sample) -> None:
        key = str(sample.key_expr)
        try:
            robot = Keys.robot_id_from_key(key)
            act = decode(sample.payload.to_bytes(), self.world.act_type)
            if act.robot_id != robot:
                raise ProtocolError("robot_id", f"{act.robot_id} published on the key of robot {robot}")
            if robot >= self.world.n_robots:
                raise ProtocolError("robot_id", f"{robot} is not a robot of this run")
        except (ProtocolError, ValueError) as exc:
            self.errors.record(key, "act", exc)
            return
        with self._cond:
            if act.tick != self._current_tick:
                self.stats.stale_acts += 1
                return
            if self._got[robot]:
                self.errors.record(key, "duplicate act", ValueError(f"second act for tick {act.tick}"))
                return
            self._got[robot] = True
            self._acts[robot] = act
            self._awaited -= 1
            if self._awaited <= 0:  # wake the loop once, when the last awaited act is in
                self._cond.notify_all()

    # -- the loop ----------------------------------------------------------------------------

    def declare(self) -> None:
        s, k = self.session, self.keys
        self._decls.append(s.declare_queryable(k.join, self._on_join))
        # The Acts are decoded on Zenoh's two receiving workers (deploy/launch.py:
        # WORLD_ZENOH_RUNTIME), not handed to a Python thread one by one: at 400 real-time
        # agents the world's CPU went from 436-441 to 318-366 ms a second, tick p99 from 95 to
        # 72-80 ms, and 100 lockstep agents from 59-72 to 82-100 ticks/s (issue 47). Two workers,
        # not one: on Zenoh's one-thread runtime tests/test_fuzz.py's flood stalled the world
        # behind a slow agent's link (docs/design.md, "600 agents"); on two it passes.
        self._decls.append(s.declare_subscriber(k.act_all, direct_callback(self._on_act)))
        self._decls.append(s.liveliness().declare_subscriber(k.alive_all, self._on_alive, history=True))
        self._sense_pub = [
            s.declare_publisher(k.sense(i), congestion_control=zenoh.CongestionControl.BLOCK)
            for i in range(self.world.n_robots)
        ]
        self._state_pub = s.declare_publisher(k.world_state)
        self._end_pub = s.declare_publisher(k.run_end, congestion_control=zenoh.CongestionControl.BLOCK)
        self._token = s.liveliness().declare_token(k.world_alive)

    def wait_for_agents(self) -> bool:
        """Block until every robot has joined and holds a liveliness token. ``join_timeout_s`` is
        the longest wait *without progress*: while agents keep arriving the world waits for the
        rest (a thousand agents on two cores take minutes to start, and a fixed deadline failed
        such runs after start-up, issue 47); it logs how many are in every 10 s. The time to the
        last one is ``join_s`` in the results."""
        started = time.monotonic()
        deadline = started + self.join_timeout_s
        last_count, next_log = -1, started + 10.0
        with self._cond:
            while not (self._live.all() and self._joined.all()):
                now = time.monotonic()
                count = int((self._live & self._joined).sum())
                if count > last_count:
                    last_count, deadline = count, now + self.join_timeout_s
                if now >= next_log:
                    log.warning("%d of %d agents joined after %.0f s; waiting for the rest", count,
                                self.world.n_robots, now - started)
                    next_log = now + 10.0
                left = deadline - now
                if left <= 0 or self._stop.is_set():
                    missing = np.flatnonzero(~(self._live & self._joined)).tolist()
                    log.error("agents missing: no new agent for %.0f s (%d of %d joined in %.0f s); robots %s",
                              self.join_timeout_s, count, self.world.n_robots, now - started, missing)
                    return False
                self._cond.wait(min(left, 0.5))
        self.stats.join_s = time.monotonic() - started
        return True

    def stop(self) -> None:
        self._stop.set()
        with self._cond:
            self._cond.notify_all()

    def _collect(self, slot_started: float) -> None:
        """Wait for this tick's acts; return when all live robots answered or time is up.

        In real time the tick must end inside its slot (ARCHITECTURE.md, Clock: "ticks at the
        controller rate on the wall clock; a late Act means the robot keeps its previous
        command"), so the wait ends when the slot does, less the step's recent time and
        :data:`WAKE_MARGIN_S` (:data:`STEP_RESERVE_TICKS` says how). Before issue 47 it lasted
        a whole period from the moment the Senses were out, so a tick whose agents were slow
        lasted the Senses' time, a period and the step: an overrun by construction, which the
        plain-Zenoh floor (whose wait ends a period after its tick starts,
        benchmarks/bench_zenoh_floor.py) never had."""
        if self.realtime:
            period = self.world.tick_s
            recent_steps = self.stats.phases_s["step"][-STEP_RESERVE_TICKS:]
            step_s = float(np.percentile(recent_steps, 90)) if len(recent_steps) else 0.0
            deadline = slot_started + period - min(step_s, MAX_STEP_RESERVE_SHARE * period) - WAKE_MARGIN_S
        else:
            deadline = time.monotonic() + self.act_timeout_s
        with self._cond:
            while True:
                waiting = self.world.alive & self._live & ~self._got
                if not waiting.any() or self._stop.is_set():
                    break
                left = deadline - time.monotonic()
                if left <= 0:
                    if not self.realtime:
                        log.warning("tick %d: no act from robots %s", self._current_tick, np.flatnonzero(waiting).tolist())
                    break
                self._cond.wait(left)

    def _await_any_agent(self) -> bool:
        """With no live agent nothing can happen in the run: pause (e.g. while the router
        restarts) until one is back, up to ``join_timeout_s``; False if none came back."""
        with self._cond:
            if self._live.any() or self._stop.is_set():
                return True
            log.warning("no agent alive: the world waits for agents (up to %.0f s)", self.join_timeout_s)
            deadline = time.monotonic() + self.join_timeout_s
            while not self._live.any() and not self._stop.is_set():
                left = deadline - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(min(left, 0.5))
            log.warning("agents are back; the run goes on")
            return True

    def run(self) -> dict:
        """Run the whole scenario; return the metrics and the run's figures."""
        # Everything built so far (modules, numba's dispatchers, the world's arrays, the
        # scenario) lives as long as the run: move it out of the collector's view. A full
        # collection otherwise walked it all, 20-55 ms each, several times a run at 300
        # robots, each one an overrun of the 100 ms real-time tick (benchmarks/bench_scale.py).
        # Unfrozen when the run ends: a process may serve more runs (tests do).
        gc.collect()
        gc.freeze()
        try:
            return self._run()
        finally:
            gc.unfreeze()

    def _run(self) -> dict:
        world = self.world
        n = world.n_robots
        self.stats.started_s = time.perf_counter()
        self.stats.cpu_started_s = time.process_time()
        period = world.tick_s
        next_tick_at = time.monotonic()
        next_checkpoint_at = time.monotonic() + self.checkpoint_every_s
        while not world.done and not self._stop.is_set():
            if not self._await_any_agent():
                return self.finish("agents gone")
            if self.realtime:
                next_tick_at = self._pace(next_tick_at, period)
            t0 = time.perf_counter()
            with self._cond:
                # A robot whose agent died stands still; one whose agent came back moves again.
                dead = world.alive & ~self._live
                for i in np.flatnonzero(dead).tolist():
                    world.kill(i)
                for i in np.flatnonzero(~world.alive & self._live).tolist():
                    world.revive(i)
                self._current_tick = world.tick
                self._got[:] = False
                self._acts = [None] * n
                self._awaited = int((world.alive & self._live).sum())
            senses = world.senses()
            for robot, sense in senses:
                self._sense_pub[robot].put(sense)
            if self.tap is not None:
                c0 = time.thread_time()
                self.tap.sensed(senses)
                self.stats.tap_cpu_s += time.thread_time() - c0
            t_sensed = time.perf_counter()
            # the slot's start on the wall clock (real time: where _pace put it; a tick that
            # starts late has the rest of its slot, so the next one starts on time)
            self._collect(next_tick_at)
            t_collected = time.perf_counter()
            with self._cond:
                self._current_tick = -1  # acts arriving now are late
                self.stats.late_acts += int((~self._got & world.alive & self._live).sum())
                acts = self._acts  # None where no act came: the world keeps that robot's command
                self._acts = [None] * n
            world.step(acts)
            if self.tap is not None:
                c0 = time.thread_time()
                self.tap.stepped(acts)
                self.stats.tap_cpu_s += time.thread_time() - c0
            self.stats.ticks += 1
            t_end = time.perf_counter()
            self.stats.tick_durations_s.append(t_end - t0)
            phases = self.stats.phases_s
            phases["sense_put"].append(t_sensed - t0)
            phases["collect"].append(t_collected - t_sensed)
            phases["step"].append(t_end - t_collected)
            if world.tick % self.state_every_ticks == 0 or world.done:
                self._publish_state()
            if self.checkpoint is not None and time.monotonic() >= next_checkpoint_at:
                self.checkpoint(self.snapshot("running"))
                next_checkpoint_at = time.monotonic() + self.checkpoint_every_s
            if self.realtime:
                next_tick_at += period
                pause = next_tick_at - time.monotonic()
                if pause > 0:
                    self._stop.wait(pause)
                else:
                    self.stats.overruns += 1
                    if len(self.stats.overrun_ticks) < MAX_OVERRUNS_KEPT:
                        self.stats.overrun_ticks.append({
                            "tick": world.tick - 1, "late_ms": round(-pause * 1e3, 2),
                            **{p: round(v[-1] * 1e3, 2) for p, v in phases.items()}})
                    if time.perf_counter() - self.stats.started_s > 1.0:
                        self.stats.overruns_after_1s += 1
        return self.finish("completed" if world.done else "stopped")

    def _pace(self, next_tick_at: float, period: float) -> float:
        """The real-time clock's one rule after any pause (docs/deploy.md, "Real time"): a tick
        that starts late by at most one period starts at once (an overrun, made up by the next
        ticks' slack); found later than that, whatever the cause (the world SIGSTOPped, a swap,
        a wait for agents, a long collection), the clock restarts from now: the missed slots
        are dropped and counted (``stalls``, ``stalled_s``), never run back to back."""
        now = time.monotonic()
        late = now - next_tick_at
        if late > period:
            self.stats.stalls += 1
            self.stats.stalled_s += late
            log.warning("real-time clock: %.2f s late (the world was paused?); resuming from now, "
                        "no catch-up", late)
            return now
        return next_tick_at

    def _publish_state(self) -> None:
        self._state_pub.put(encode(self.world.state()))

    def snapshot(self, reason: str) -> dict:
        """The run's figures so far."""
        return {
            "reason": reason,
            "tick": self.world.tick,
            "family": self.world.family,
            "metrics": self.world.summary(),
            "transport": self.stats.summary(),
            "rejected": dict(self.errors.counts),
            "dead_robots": np.flatnonzero(~self.world.alive).tolist(),
        }

    def finish(self, reason: str) -> dict:
        result = self.snapshot(reason)
        self._end_pub.put(encode(RunEnd(tick=self.world.tick, reason=reason, metrics=_plain(result))))
        return result

    def close(self) -> None:
        for d in self._decls:
            try:
                d.undeclare()
            except Exception as exc:  # noqa: BLE001 -- gone with the session already
                log.debug("undeclare: %s", exc)


def _plain(value):
    """JSON/msgpack-friendly copy (no None inside lists is fine; tuples to lists)."""
    if isinstance(value, dict):
        return {str(k): _plain(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_plain(v) for v in value]
    return value
