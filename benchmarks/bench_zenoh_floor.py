"""The transport floor on this machine: a lockstep world and N robot processes in plain Zenoh.

The reference point of the core swarm's tick-rate target (issue 2: "half the measured floor of
Zenoh itself"; ZENOH.md measured 97.5 ticks/s for 100 robots on its machine). Nothing of swarmloc
runs here: each tick the world puts one 100-byte message per robot on ``floor/<run>/<i>/sense``;
each robot process answers with 100 bytes on ``floor/<run>/<i>/act``; the world waits for all N
answers, then starts the next tick. Congestion control BLOCK on both sides, multicast scouting off.

Two topologies: ``direct`` (the world's session is a router and the robots connect straight to
it, as ``swarmloc run`` does) and ``router`` (a separate Python router process in between, as
ZENOH.md's pieces on several hosts). Compare the figures with `benchmarks/bench_lockstep.py`, the
same swarm sizes with the real world-server and e-puck agents. ``--codec`` adds swarmloc's codec
and nothing else: each robot also decodes an e-puck Sense of 389 bytes (two received
messages; a recorded ES3 Sense averages 312 bytes) and builds and encodes an Act, every tick.
The default is Zenoh's own settings (bar scouting), the floor the issue names. Three flags give
the robots the settings swarmloc's e-puck agents run with, one at a time: ``--one-thread-robots``
(the Zenoh runtime of ``deploy/launch.py: ONE_THREAD_ZENOH_RUNTIME``), ``--direct-callbacks``
(the Sense callback on Zenoh's receiving thread, ``indirect=False``, agents/node.py),
``--shm-off`` (the shared-memory transport off, for the world too, protocol/session.py);
``--as-agents`` sets all three, the robots at nice 5 as ``swarmloc run`` starts agents that
outnumber the cores, and the world's Zenoh runtime as the world-server's
(``deploy/launch.py: WORLD_ZENOH_RUNTIME``): plain Zenoh configured as swarmloc configures it.
``--json`` prints each size's figures as one JSON line (benchmarks/bench_scale.py reads them).

``--realtime`` ticks at 10 Hz on the wall clock, as the world-server's real-time mode does (a
tick waits for the answers until its period is over; an answer that comes later is dropped),
and prints ticks/s, p50/p99 tick and overruns (after the first second) as
``benchmarks/bench_scale.py --realtime`` prints them for swarmloc (which runs this with
``--floor``). ``--idle`` measures what a robot process costs doing nothing: N connected robots,
no ticks, their CPU and wake-ups per second. Usage:

    python benchmarks/bench_zenoh_floor.py [--robots 10 50 100] [--duration-s 20] [--topology direct] [--codec]
    python benchmarks/bench_zenoh_floor.py --robots 100 --one-thread-robots
    python benchmarks/bench_zenoh_floor.py --robots 100 200 300 --realtime --as-agents
    python benchmarks/bench_zenoh_floor.py --robots 20 --idle [--shm-off]
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import signal
import socket
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass

import zenoh

from swarmloc.deploy.launch import ONE_THREAD_ZENOH_RUNTIME, WORLD_ZENOH_RUNTIME

PAYLOAD_BYTES = 100
#: The user's own ZENOH_RUNTIME, if any: it reaches the robots too (main sets the world's own
#: in this process's environment, which the robots must not inherit).
_USER_RUNTIME = os.environ.get("ZENOH_RUNTIME")
#: The real-time period (the e-puck controller's 10 Hz).
PERIOD_S = 0.1


@dataclass(frozen=True)
class Settings:
    """How the floor's processes use Zenoh (the module docstring says what each flag is)."""

    codec: bool = False
    one_thread: bool = False
    direct: bool = False
    shm_off: bool = False
    #: the robots' CPU priority (``swarmloc run`` starts agents at nice 5 when they outnumber
    #: the cores: on a machine shared with other work, a floor at nice 0 would be favoured)
    nice: int = 0

    def robot_flags(self) -> list[str]:
        return [flag for flag, on in (("--codec", self.codec), ("--direct-callbacks", self.direct),
                                      ("--shm-off", self.shm_off)) if on] + \
            (["--nice", str(self.nice)] if self.nice else [])

    def describe(self) -> str:
        parts = [("robots decode a Sense and encode an Act", self.codec),
                 ("robots on a one-thread Zenoh runtime", self.one_thread),
                 ("direct Sense callbacks", self.direct), ("shared memory off", self.shm_off),
                 (f"robots at nice {self.nice}", self.nice)]
        return "".join(f", {text}" for text, on in parts if on)


#: Plain Zenoh configured, and its robots prioritised, as ``swarmloc run`` does for its e-puck
#: agents and world when the agents outnumber the cores (deploy/run.py: start_swarm).
AS_AGENTS = Settings(one_thread=True, direct=True, shm_off=True, nice=5)


def _config(mode: str, *, listen: str | None = None, connect: str | None = None,
            shm_off: bool = False) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", f'"{mode}"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
    if shm_off:
        conf.insert_json5("transport/shared_memory/enabled", "false")
    if listen:
        conf.insert_json5("listen/endpoints", f'["{listen}"]')
    if connect:
        conf.insert_json5("connect/endpoints", f'["{connect}"]')
        conf.insert_json5("connect/timeout_ms", "-1")
    return conf


def _free_endpoint() -> str:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return f"tcp/127.0.0.1:{s.getsockname()[1]}"


def _cpu_s() -> float:
    """User + system CPU of the whole process (all its threads, Zenoh's included)."""
    r = resource.getrusage(resource.RUSAGE_SELF)
    return r.ru_utime + r.ru_stime


def _sense_bytes(robot_id: int) -> bytes:
    """An encoded e-puck Sense of 389 bytes: eight IR and three ground readings, two messages
    heard (a recorded ES3 Sense averages 312 bytes)."""
    from swarmloc.protocol.messages import EpuckSense, RabMessage, encode

    heard = tuple(RabMessage(sender_id=i, range_m=0.1 + 0.01 * i, bearing_rad=0.5 * i - 1.0,
                             payload=bytes(range(40))) for i in range(2))
    return encode(EpuckSense(tick=1, robot_id=robot_id, encoder_steps=(12.0, 13.0),
                             ir=tuple(0.1 * k for k in range(8)), ground=(0.9, 0.9, 0.9),
                             received=heard))


def robot(endpoint: str, run: str, robot_id: int, codec: bool = False, direct: bool = False,
          shm_off: bool = False) -> int:
    """One robot: answer every sense at once with 100 bytes, until the world says the end;
    with ``codec``, also decode a Sense and encode an Act each time."""
    if codec:
        from swarmloc.protocol.messages import EpuckAct, EpuckSense, decode, encode

        sense_bytes = _sense_bytes(robot_id)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    with zenoh.open(_config("client", connect=endpoint, shm_off=shm_off)) as session:
        pub = session.declare_publisher(f"floor/{run}/{robot_id}/act",
                                        congestion_control=zenoh.CongestionControl.BLOCK)
        answer = bytearray(PAYLOAD_BYTES)
        cpu = {"first": 0.0, "ticks": 0}

        def on_sense(sample: zenoh.Sample) -> None:
            if not cpu["ticks"]:
                cpu["first"] = _cpu_s()
            cpu["ticks"] += 1
            if codec:
                sense = decode(sense_bytes, EpuckSense)
                encode(EpuckAct(tick=sense.tick, robot_id=robot_id, wheel_speed_steps_s=(0.0, 0.0),
                                payload=None, state=0, pose_estimate=(0.0, 0.0, 0.0)))
            answer[:8] = sample.payload.to_bytes()[:8]  # echo the tick number
            pub.put(bytes(answer))

        handler = zenoh.handlers.Callback(on_sense, indirect=False) if direct else on_sense
        subs = [session.declare_subscriber(f"floor/{run}/{robot_id}/sense", handler),
                session.declare_subscriber(f"floor/{run}/end", lambda _s: done.set())]
        token = session.liveliness().declare_token(f"floor/{run}/alive/{robot_id}")
        done.wait(600)
        # CPU of every thread of this process from the first tick on, for the world to sum.
        print(f"cpu {_cpu_s() - cpu['first']:.6f} {cpu['ticks']}", flush=True)
        token.undeclare()
        for s in subs:
            s.undeclare()
    return 0


@contextmanager
def _swarm(n: int, topology: str, settings: Settings):
    """A world session and ``n`` robot processes, all joined: yields (session, run, robots, the
    seconds they took to join); the robots are told to end (``floor/<run>/end``) and reaped on the way out."""
    run = f"r{os.getpid()}x{n}"
    procs: list[subprocess.Popen] = []
    try:
        if topology == "router":
            router_ep = _free_endpoint()
            procs.append(subprocess.Popen([sys.executable, __file__, "--serve-router", router_ep],
                                          start_new_session=True))
            conf, robot_ep = _config("client", connect=router_ep, shm_off=settings.shm_off), router_ep
        else:
            robot_ep = _free_endpoint()
            conf = _config("router", listen=robot_ep, shm_off=settings.shm_off)
        with zenoh.open(conf) as session:
            alive: set[str] = set()
            joined = threading.Event()

            def on_alive(sample: zenoh.Sample) -> None:
                if sample.kind == zenoh.SampleKind.PUT:
                    alive.add(str(sample.key_expr))
                    if len(alive) == n:
                        joined.set()

            live = session.liveliness().declare_subscriber(f"floor/{run}/alive/*", on_alive, history=True)
            t0 = time.perf_counter()
            runtime = ONE_THREAD_ZENOH_RUNTIME if settings.one_thread else _USER_RUNTIME
            env = {k: v for k, v in os.environ.items() if k != "ZENOH_RUNTIME"}
            if runtime:
                env["ZENOH_RUNTIME"] = runtime
            robots = [subprocess.Popen([sys.executable, __file__, "--robot", str(i), "--connect", robot_ep,
                                        "--run", run, *settings.robot_flags()],
                                       start_new_session=True, stdout=subprocess.PIPE, text=True, env=env)
                      for i in range(n)]
            procs.extend(robots)
            if not joined.wait(180):
                raise RuntimeError(f"only {len(alive)} of {n} robots joined within 180 s")
            yield session, run, robots, time.perf_counter() - t0
            session.put(f"floor/{run}/end", b"")
            live.undeclare()
        if topology == "router":
            procs[0].terminate()
            procs[0].wait(30)
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()


def world(n: int, duration_s: float, topology: str, settings: Settings = Settings(),
          realtime: bool = False) -> dict:
    """Tick ``n`` robots for ``duration_s`` (lockstep, or at 10 Hz with ``realtime``); the
    figures: ticks/s, tick p50/p99, CPU of the world and of the robots, and in real time the
    overruns (ticks that ended after the next one was due) and late answers."""
    with _swarm(n, topology, settings) as (session, run, robots, joined_s):
        pubs = [session.declare_publisher(f"floor/{run}/{i}/sense",
                                          congestion_control=zenoh.CongestionControl.BLOCK)
                for i in range(n)]
        lock = threading.Lock()
        state = {"tick": 0, "acts": 0}
        tick_done = threading.Event()

        def on_act(sample: zenoh.Sample) -> None:
            tick = int.from_bytes(sample.payload.to_bytes()[:8], "little")
            with lock:
                if tick != state["tick"]:
                    return  # an answer to a tick already closed (real time)
                state["acts"] += 1
                if state["acts"] == n:
                    tick_done.set()

        acts = session.declare_subscriber(f"floor/{run}/*/act", on_act)
        payload = bytearray(PAYLOAD_BYTES)
        tick_s: list[float] = []
        late = overruns = overruns_after_1s = 0
        cpu0 = time.process_time()
        started = next_tick_at = time.perf_counter()
        t_end = started + duration_s
        while time.perf_counter() < t_end:
            with lock:
                state["tick"] += 1
                state["acts"] = 0
                tick_done.clear()
            payload[:8] = state["tick"].to_bytes(8, "little")
            t0 = time.perf_counter()
            for p in pubs:
                p.put(bytes(payload))
            if realtime:
                if not tick_done.wait(max(0.0, t0 + PERIOD_S - time.perf_counter())):
                    with lock:
                        late += n - state["acts"]
                        state["tick"] = -1  # answers from now on are late
            elif not tick_done.wait(10):
                raise RuntimeError(f"tick {state['tick']}: {state['acts']} of {n} answers in 10 s")
            tick_s.append(time.perf_counter() - t0)
            if realtime:  # as the world-server's real-time loop (world/server.py: WorldServer.run)
                next_tick_at += PERIOD_S
                pause = next_tick_at - time.perf_counter()
                if pause > 0:
                    time.sleep(pause)
                else:
                    overruns += 1
                    overruns_after_1s += time.perf_counter() - started > 1.0
        wall_s = time.perf_counter() - started
        world_cpu_s = time.process_time() - cpu0
        for d in (acts, *pubs):
            d.undeclare()
    robot_cpu_s = robot_ticks = 0.0
    for p in robots:  # they ended on floor/end and printed their CPU
        out, _ = p.communicate(timeout=30)
        _, cpu_s, ticks = out.split()
        robot_cpu_s += float(cpu_s)
        robot_ticks += int(ticks)
    tick_s.sort()
    return {"robots": n, "ticks": len(tick_s), "joined_s": joined_s,
            "ticks_per_s": len(tick_s) / (wall_s if realtime else sum(tick_s)),
            "p50_ms": tick_s[len(tick_s) // 2] * 1e3, "p99_ms": tick_s[int(len(tick_s) * 0.99)] * 1e3,
            "late_acts": late, "overruns": overruns, "overruns_after_1s": overruns_after_1s,
            "world_cpu_ms_per_tick": world_cpu_s / len(tick_s) * 1e3,
            "robot_cpu_us_per_tick": robot_cpu_s / robot_ticks * 1e6,
            "cores_robots": robot_cpu_s / wall_s, "cores_world": world_cpu_s / wall_s}


def _cpu_and_wakeups(pid: int) -> tuple[float, int]:
    """CPU seconds and voluntary context switches (wake-ups) of every thread of ``pid``."""
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    wakeups = 0
    for tid in os.listdir(f"/proc/{pid}/task"):
        with open(f"/proc/{pid}/task/{tid}/status", encoding="ascii") as f:
            wakeups += sum(int(line.split()[1]) for line in f if line.startswith("voluntary_ctxt"))
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK"), wakeups


def idle(n: int, window_s: float, settings: Settings) -> dict:
    """What ``n`` connected robots cost doing nothing: CPU (µs/s) and wake-ups per second each."""
    with _swarm(n, "direct", settings) as (_session, _run, robots, _joined_s):
        time.sleep(2.0)  # a measurement's start, not a readiness wait: every robot has joined
        before = [_cpu_and_wakeups(p.pid) for p in robots]
        t0 = time.perf_counter()
        time.sleep(window_s)
        after = [_cpu_and_wakeups(p.pid) for p in robots]
        dt = time.perf_counter() - t0
        threads = len(os.listdir(f"/proc/{robots[0].pid}/task"))
    for p in robots:
        p.communicate(timeout=30)
    cpu = sum(a[0] - b[0] for a, b in zip(after, before))
    wakeups = sum(a[1] - b[1] for a, b in zip(after, before))
    return {"robots": n, "cpu_us_per_s": cpu / dt / n * 1e6, "wakeups_per_s": wakeups / dt / n,
            "threads": threads}


def serve_router(endpoint: str) -> int:
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    with zenoh.open(_config("router", listen=endpoint)):
        done.wait()
    return 0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 50, 100])
    parser.add_argument("--duration-s", type=float, default=20.0)
    parser.add_argument("--topology", choices=("direct", "router"), default="direct")
    parser.add_argument("--robot", type=int, help=argparse.SUPPRESS)
    parser.add_argument("--connect", help=argparse.SUPPRESS)
    parser.add_argument("--run", help=argparse.SUPPRESS)
    parser.add_argument("--serve-router", help=argparse.SUPPRESS)
    parser.add_argument("--codec", action="store_true",
                        help="robots also decode an e-puck Sense and encode an Act every tick")
    parser.add_argument("--one-thread-robots", action="store_true",
                        help="robots run Zenoh's pools on one thread, as swarmloc's e-puck agents do")
    parser.add_argument("--direct-callbacks", action="store_true",
                        help="robots answer on Zenoh's receiving thread (indirect=False), as e-puck agents do")
    parser.add_argument("--shm-off", action="store_true",
                        help="the shared-memory transport off (world and robots), as swarmloc's sessions")
    parser.add_argument("--as-agents", action="store_true",
                        help="all three: plain Zenoh configured as swarmloc's e-puck agents")
    parser.add_argument("--nice", type=int, default=0, help="the robots' nice value (--as-agents: 5)")
    parser.add_argument("--realtime", action="store_true", help="tick at 10 Hz on the wall clock")
    parser.add_argument("--idle", action="store_true", help="robots' CPU and wake-ups with no ticks")
    parser.add_argument("--json", action="store_true", help="each size's figures as one JSON line")
    args = parser.parse_args()
    if args.serve_router:
        return serve_router(args.serve_router)
    if args.robot is not None:
        if args.nice:
            os.nice(args.nice)
        return robot(args.connect, args.run, args.robot, args.codec, args.direct_callbacks, args.shm_off)
    if args.as_agents:  # before this process opens its first session, when Zenoh reads it
        os.environ.setdefault("ZENOH_RUNTIME", WORLD_ZENOH_RUNTIME)
    settings = Settings(codec=args.codec, one_thread=args.one_thread_robots or args.as_agents,
                        direct=args.direct_callbacks or args.as_agents, shm_off=args.shm_off or args.as_agents,
                        nice=args.nice or (AS_AGENTS.nice if args.as_agents else 0))
    if args.idle:
        print(f"plain Zenoh robot processes, connected and idle{settings.describe()}")
        print(f"{'robots':>6} {'CPU us/s each':>14} {'wake-ups/s each':>16} {'threads':>8}")
        for n in args.robots:
            r = idle(n, args.duration_s, settings)
            print(f"{n:>6} {r['cpu_us_per_s']:>14.0f} {r['wakeups_per_s']:>16.1f} {r['threads']:>8}", flush=True)
        return 0
    if args.json:
        for n in args.robots:
            print(json.dumps(world(n, args.duration_s, args.topology, settings, args.realtime)), flush=True)
        return 0
    print(f"plain Zenoh {'real-time (10 Hz)' if args.realtime else 'lockstep'} floor, topology "
          f"{args.topology}, {PAYLOAD_BYTES}-byte messages{settings.describe()}  ({load()})")
    print(f"{'robots':>6} {'ticks':>6} {'ticks/s':>8} {'p50 ms':>7} {'p99 ms':>7} {'overruns>1s':>11} "
          f"{'late':>5} {'world CPU ms/tick':>18} {'robot CPU us/tick':>18}")
    for n in args.robots:
        r = world(n, args.duration_s, args.topology, settings, args.realtime)
        print(f"{r['robots']:>6} {r['ticks']:>6} {r['ticks_per_s']:>8.1f} {r['p50_ms']:>7.2f} {r['p99_ms']:>7.2f} "
              f"{r['overruns_after_1s']:>11} {r['late_acts']:>5} "
              f"{r['world_cpu_ms_per_tick']:>18.2f} {r['robot_cpu_us_per_tick']:>18.0f}  ({load()})", flush=True)
    return 0


def load() -> str:
    return "load " + " ".join(f"{x:.1f}" for x in os.getloadavg())


if __name__ == "__main__":
    raise SystemExit(main())
