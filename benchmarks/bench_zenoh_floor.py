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
``--one-thread-robots`` runs the robots on the Zenoh runtime swarmloc's e-puck agents use
(``deploy/launch.py: ONE_THREAD_ZENOH_RUNTIME``); the default is Zenoh's own, the floor the issue
names. Usage:

    python benchmarks/bench_zenoh_floor.py [--robots 10 50 100] [--duration-s 20] [--topology direct] [--codec]
    python benchmarks/bench_zenoh_floor.py --robots 100 --one-thread-robots
"""

from __future__ import annotations

import argparse
import os
import resource
import signal
import socket
import subprocess
import sys
import threading
import time

import zenoh

from swarmloc.deploy.launch import ONE_THREAD_ZENOH_RUNTIME

PAYLOAD_BYTES = 100


def _config(mode: str, *, listen: str | None = None, connect: str | None = None) -> zenoh.Config:
    conf = zenoh.Config()
    conf.insert_json5("mode", f'"{mode}"')
    conf.insert_json5("scouting/multicast/enabled", "false")
    conf.insert_json5("scouting/gossip/enabled", "false")
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


def robot(endpoint: str, run: str, robot_id: int, codec: bool = False) -> int:
    """One robot: answer every sense at once with 100 bytes, until the world says the end;
    with ``codec``, also decode a Sense and encode an Act each time."""
    if codec:
        from swarmloc.protocol.messages import EpuckAct, EpuckSense, decode, encode

        sense_bytes = _sense_bytes(robot_id)
    done = threading.Event()
    signal.signal(signal.SIGTERM, lambda *_: done.set())
    with zenoh.open(_config("client", connect=endpoint)) as session:
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

        subs = [session.declare_subscriber(f"floor/{run}/{robot_id}/sense", on_sense),
                session.declare_subscriber(f"floor/{run}/end", lambda _s: done.set())]
        token = session.liveliness().declare_token(f"floor/{run}/alive/{robot_id}")
        done.wait(600)
        # CPU of every thread of this process from the first tick on, for the world to sum.
        print(f"cpu {_cpu_s() - cpu['first']:.6f} {cpu['ticks']}", flush=True)
        token.undeclare()
        for s in subs:
            s.undeclare()
    return 0


def world(n: int, duration_s: float, topology: str, codec: bool = False, one_thread: bool = False) -> dict:
    run = f"r{os.getpid()}x{n}"
    procs: list[subprocess.Popen] = []
    try:
        if topology == "router":
            router_ep = _free_endpoint()
            procs.append(subprocess.Popen([sys.executable, __file__, "--serve-router", router_ep],
                                          start_new_session=True))
            conf, robot_ep = _config("client", connect=router_ep), router_ep
        else:
            robot_ep = _free_endpoint()
            conf = _config("router", listen=robot_ep)
        with zenoh.open(conf) as session:
            alive: set[str] = set()
            joined = threading.Event()

            def on_alive(sample: zenoh.Sample) -> None:
                if sample.kind == zenoh.SampleKind.PUT:
                    alive.add(str(sample.key_expr))
                    if len(alive) == n:
                        joined.set()

            live = session.liveliness().declare_subscriber(f"floor/{run}/alive/*", on_alive, history=True)
            robots = [subprocess.Popen([sys.executable, __file__, "--robot", str(i), "--connect", robot_ep,
                                        "--run", run, *(["--codec"] if codec else [])],
                                       start_new_session=True, stdout=subprocess.PIPE, text=True,
                                       env={**os.environ, "ZENOH_RUNTIME": ONE_THREAD_ZENOH_RUNTIME}
                                       if one_thread else None)
                      for i in range(n)]
            procs.extend(robots)
            if not joined.wait(120):
                raise RuntimeError(f"only {len(alive)} of {n} robots joined within 120 s")
            pubs = [session.declare_publisher(f"floor/{run}/{i}/sense",
                                              congestion_control=zenoh.CongestionControl.BLOCK)
                    for i in range(n)]
            lock = threading.Lock()
            state = {"tick": 0, "acts": 0}
            tick_done = threading.Event()

            def on_act(sample: zenoh.Sample) -> None:
                if int.from_bytes(sample.payload.to_bytes()[:8], "little") != state["tick"]:
                    return
                with lock:
                    state["acts"] += 1
                    if state["acts"] == n:
                        tick_done.set()

            acts = session.declare_subscriber(f"floor/{run}/*/act", on_act)
            payload = bytearray(PAYLOAD_BYTES)
            tick_s: list[float] = []
            cpu0, t_end = time.process_time(), time.perf_counter() + duration_s
            while time.perf_counter() < t_end:
                state["tick"] += 1
                state["acts"] = 0
                tick_done.clear()
                payload[:8] = state["tick"].to_bytes(8, "little")
                t0 = time.perf_counter()
                for p in pubs:
                    p.put(bytes(payload))
                if not tick_done.wait(10):
                    raise RuntimeError(f"tick {state['tick']}: {state['acts']} of {n} answers in 10 s")
                tick_s.append(time.perf_counter() - t0)
            world_cpu_s = time.process_time() - cpu0
            session.put(f"floor/{run}/end", b"")
            for d in (acts, live, *pubs):
                d.undeclare()
        robot_cpu_s = robot_ticks = 0.0
        for p in robots:  # they end on floor/end and print their CPU
            out, _ = p.communicate(timeout=30)
            _, cpu_s, ticks = out.split()
            robot_cpu_s += float(cpu_s)
            robot_ticks += int(ticks)
        if topology == "router":
            procs[0].terminate()
            procs[0].wait(30)
    finally:
        for p in procs:
            if p.poll() is None:
                os.killpg(p.pid, signal.SIGKILL)
                p.wait()
    tick_s.sort()
    return {"robots": n, "ticks": len(tick_s), "ticks_per_s": len(tick_s) / sum(tick_s),
            "p50_ms": tick_s[len(tick_s) // 2] * 1e3, "p99_ms": tick_s[int(len(tick_s) * 0.99)] * 1e3,
            "world_cpu_ms_per_tick": world_cpu_s / len(tick_s) * 1e3,
            "robot_cpu_us_per_tick": robot_cpu_s / robot_ticks * 1e6}


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
    args = parser.parse_args()
    if args.serve_router:
        return serve_router(args.serve_router)
    if args.robot is not None:
        return robot(args.connect, args.run, args.robot, args.codec)
    print(f"plain Zenoh lockstep floor, topology {args.topology}, {PAYLOAD_BYTES}-byte messages"
          + (", robots decode a Sense and encode an Act" if args.codec else "")
          + (", robots on a one-thread Zenoh runtime" if args.one_thread_robots else ""))
    print(f"{'robots':>6} {'ticks':>6} {'ticks/s':>8} {'p50 ms':>7} {'p99 ms':>7} {'world CPU ms/tick':>18} {'robot CPU us/tick':>18}")
    for n in args.robots:
        r = world(n, args.duration_s, args.topology, args.codec, args.one_thread_robots)
        print(f"{r['robots']:>6} {r['ticks']:>6} {r['ticks_per_s']:>8.1f} {r['p50_ms']:>7.2f} {r['p99_ms']:>7.2f} "
              f"{r['world_cpu_ms_per_tick']:>18.2f} {r['robot_cpu_us_per_tick']:>18.0f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
