"""Chaos with accounting (issue 47): a real-time swarm deployed as on several hosts (a router,
the world-server and the agent server each a client of it), hit while it runs, then every tick of
every robot accounted for from the recording.

The faults, on a schedule of wall-clock seconds after the first tick:

- every ``--kill-every-s`` (default 60 s): SIGKILL a random 10 % of the agents (``--seed``); the
  agent server (``swarmloc agents --respawn``) forks each one again;
- once, half a period after the first kill: the router SIGKILLed and started again on its port;
- once, half a period after the second kill (or at 80 % of the run): the world SIGSTOPped for
  ``--pause-s`` (2 s) and SIGCONTed.

The world records with ``--record-messages``: every Sense it sent and every Act it stepped with.
Each (tick, robot) is then one of: **arrived** (its Act was in the step), **missing** (a Sense
went out, no Act came in time: the robot kept its previous wheel command) or **dead** (no Sense:
the robot's agent was gone and the robot stood still). The benchmark prints the totals, every
tick that was not all-arrived (or, with many, how many), each outage (a robot's run of ticks not
arrived) with its length, the rejoins the world logged with the time each agent was away, and
the checks: the results and the recording hold every tick once (frames 0..N, no duplicate), the
run completed, every robot's Act arrived on the last tick.

    python benchmarks/bench_chaos.py --robots 100 --duration-s 300
    python benchmarks/bench_chaos.py --robots 300 --duration-s 300
    python benchmarks/bench_chaos.py --robots 10 --duration-s 30 --kill-every-s 10   # a quick look

``--csv FILE`` writes every tick's counts (tick, arrived, missing, dead).
"""

from __future__ import annotations

import argparse
import collections
import json
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
import uuid
from dataclasses import dataclass, field
from pathlib import Path

#: The world's log line of a rejoin (world/server.py; docs/deploy.md, "Faults").
_REJOIN = re.compile(r"robot (\d+): agent back after ([0-9.]+) s")


@dataclass
class Chaos:
    robots: int
    duration_s: float
    tick_s: float
    n_ticks: int
    events: list = field(default_factory=list)  # (wall s after start, what)
    killed: list = field(default_factory=list)  # (round, robot)
    results: dict = field(default_factory=dict)
    recording: Path | None = None
    world_log: str = ""
    agent_server_code: int | None = None


def _wait_first_tick(results: Path, world: subprocess.Popen, timeout_s: float) -> None:
    """Until the world's first checkpoint shows a tick (it writes results.json every second here):
    polling a file the world writes, its readiness signal."""
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if world.poll() is not None:
            raise RuntimeError(f"the world-server exited ({world.returncode}) before its first tick")
        try:
            if json.loads(results.read_text()).get("transport", {}).get("ticks", 0) > 0:
                return
        except (OSError, ValueError):
            pass
        time.sleep(0.2)
    raise RuntimeError(f"no tick within {timeout_s:.0f} s")


def run_chaos(robots: int, duration_s: float, kill_every_s: float = 60.0, pause_s: float = 2.0,
              seed: int = 1, workdir: Path | None = None, join_timeout_s: float = 300.0) -> Chaos:
    """Deploy, hit and account one real-time run; every process it starts ends before it returns."""
    import numpy as np

    from swarmloc.deploy.fork.server import ForkedAgents
    from swarmloc.deploy.launch import (
        ONE_THREAD_ZENOH_RUNTIME,
        start_announcing,
        start_router,
        supervised,
    )
    from swarmloc.deploy.scenario import load_any

    rng = np.random.default_rng(seed)
    tmp = tempfile.TemporaryDirectory() if workdir is None else None
    folder = Path(tmp.name if tmp else workdir)
    scenario = load_any("ES3-tiled", {"robots": robots, "duration_s": duration_s, "seed": seed})
    path = folder / "scenario.json"
    path.write_text(json.dumps(scenario.to_dict()))
    chaos = Chaos(robots, duration_s, scenario.scenario.world.tick_s, scenario.n_ticks,
                  recording=folder / "chaos.mcap")
    run, out = "chaos" + uuid.uuid4().hex[:8], folder / "out"
    try:
        with supervised() as sup:
            router, endpoint = start_router(sup)
            port = endpoint.rsplit(":", 1)[1]
            world, _ = start_announcing(sup, [
                "world", str(path), "-m", "client", "-e", endpoint, "--run", run, "--out", str(out),
                "--realtime", "--record", str(chaos.recording), "--record-messages", "--checkpoint-s", "1",
                "--join-timeout-s", str(join_timeout_s), "--announce"], log_path=folder / "world.log")
            server = sup.start(["agents", "--robots", f"0-{robots - 1}", "-m", "client", "-e", endpoint,
                                "--run", run, "--respawn", "--announce", "--log-dir", str(folder),
                                "--join-timeout-s", str(join_timeout_s), "--die-with-parent", str(os.getpid())],
                               stdout=subprocess.PIPE, log_path=folder / "agent-server.log",
                               env={"ZENOH_RUNTIME": ONE_THREAD_ZENOH_RUNTIME})
            agents = ForkedAgents(server, list(range(robots)))
            agents.wait_forked(join_timeout_s)
            _wait_first_tick(out / "results.json", world, join_timeout_s)
            t0 = time.monotonic()
            kills = [kill_every_s * k for k in range(1, int(duration_s / kill_every_s) + 1)
                     if kill_every_s * k < duration_s - 2.0]
            router_at = (kills[0] if kills else 0.3 * duration_s) + 0.5 * kill_every_s
            pause_at = kills[1] + 0.5 * kill_every_s if len(kills) > 1 else 0.8 * duration_s
            schedule = sorted([(t, "kill", k) for k, t in enumerate(kills)]
                              + [(router_at, "router", None), (pause_at, "pause", None)])
            for at, what, k in schedule:
                left = t0 + at - time.monotonic()
                if left > 0:
                    time.sleep(left)  # the chaos schedule is wall time: not a readiness wait
                if world.poll() is not None:
                    break
                now = round(time.monotonic() - t0, 2)
                if what == "kill":
                    victims = sorted(rng.choice(robots, max(1, robots // 10), replace=False).tolist())
                    for robot in victims:
                        os.kill(agents._by_robot[robot].pid, signal.SIGKILL)
                        chaos.killed.append((k, robot))
                    chaos.events.append((now, f"SIGKILL agents {victims}"))
                elif what == "router":
                    router.kill()
                    router.wait(timeout=10)
                    router, _ = start_router(sup, f"tcp/127.0.0.1:{port}")
                    took_s = time.monotonic() - t0 - now
                    chaos.events.append((now, f"router SIGKILLed and restarted on port {port} ({took_s:.2f} s)"))
                else:
                    world.send_signal(signal.SIGSTOP)
                    time.sleep(pause_s)  # the pause itself
                    world.send_signal(signal.SIGCONT)
                    chaos.events.append((now, f"world SIGSTOPped for {pause_s:g} s"))
            world.wait(timeout=duration_s + 600)
            try:
                chaos.agent_server_code = server.wait(timeout=60)
            except subprocess.TimeoutExpired:
                server.terminate()
                chaos.agent_server_code = server.wait(timeout=30)
        chaos.results = json.loads((out / "results.json").read_text())
        chaos.world_log = (folder / "world.log").read_text(errors="replace")
        if tmp is not None:
            keep = Path(tempfile.mkdtemp(prefix="chaos-"))
            os.replace(chaos.recording, keep / "chaos.mcap")
            chaos.recording = keep / "chaos.mcap"
    finally:
        if tmp is not None:
            tmp.cleanup()
    return chaos


@dataclass
class Accounting:
    fate: dict  # tick -> (arrived, missing, dead)
    frames: list  # frame ticks in recording order
    outages: list  # (robot, first tick, ticks)
    rejoins: list  # (robot, away s) from the world's log
    rejected: int


def account(chaos: Chaos) -> Accounting:
    """Every (tick, robot) from the recording (read with the mcap library): arrived, missing, dead."""
    import msgpack
    from mcap.reader import make_reader

    from swarmloc.deploy.observe.record import ACT_TOPIC, FRAME_TOPIC, SENSE_TOPIC
    from swarmloc.protocol.messages import decode

    sensed, acted, frames = set(), set(), []
    with open(chaos.recording, "rb") as f:
        for _, channel, message in make_reader(f).iter_messages(topics=[SENSE_TOPIC, ACT_TOPIC, FRAME_TOPIC]):
            if channel.topic == FRAME_TOPIC:
                frames.append(msgpack.unpackb(message.data)["tick"])
                continue
            m = decode(message.data)
            (sensed if channel.topic == SENSE_TOPIC else acted).add((m.tick, m.robot_id))
    fate, outages, open_since = {}, [], {}
    for tick in range(chaos.n_ticks):
        counts = [0, 0, 0]
        for robot in range(chaos.robots):
            state = 0 if (tick, robot) in acted else 1 if (tick, robot) in sensed else 2
            counts[state] += 1
            if state and robot not in open_since:
                open_since[robot] = tick
            elif not state and robot in open_since:
                start = open_since.pop(robot)
                outages.append((robot, start, tick - start))
        fate[tick] = tuple(counts)
    outages += [(robot, start, chaos.n_ticks - start) for robot, start in open_since.items()]
    rejoins = [(int(r), float(s)) for r, s in _REJOIN.findall(chaos.world_log)]
    rejected = sum(chaos.results.get("rejected", {}).values())
    return Accounting(fate, frames, sorted(outages, key=lambda o: (o[1], o[0])), rejoins, rejected)


def checks(chaos: Chaos, acc: Accounting) -> dict[str, bool]:
    """What must hold whatever the faults did."""
    n = chaos.n_ticks
    return {
        "the run completed": chaos.results.get("reason") == "completed" and chaos.results.get("tick") == n,
        "the results count every tick": chaos.results.get("transport", {}).get("ticks") == n,
        "the recording has every tick's frame once": acc.frames == list(range(n + 1)),
        "every (tick, robot) accounted for": all(sum(c) == chaos.robots for c in acc.fate.values())
                                             and len(acc.fate) == n,
        "every robot's Act arrived on the last tick": acc.fate[n - 1][0] == chaos.robots,
        "every killed agent rejoined": len(acc.rejoins) >= len(chaos.killed),
        "no message rejected": acc.rejected == 0,
    }


def report(chaos: Chaos, acc: Accounting, csv_path: str | None = None, max_lines: int = 40) -> None:
    totals = [sum(c[i] for c in acc.fate.values()) for i in range(3)]
    cells = chaos.n_ticks * chaos.robots
    print(f"{chaos.robots} agents, {chaos.n_ticks} ticks of {chaos.tick_s:g} s in real time: "
          f"{cells} (tick, robot) cells")
    for at, what in chaos.events:
        print(f"  t+{at:7.2f} s  {what}")
    print(f"arrived {totals[0]} ({totals[0] / cells:.2%}), missing {totals[1]} (previous command kept), "
          f"dead {totals[2]} (agent gone, robot still)")
    t = chaos.results.get("transport", {})
    print(f"world: overruns {t.get('overruns')}, stalls {t.get('stalls')} ({t.get('stalled_s')} s), late Acts "
          f"{t.get('late_acts')}, rejoins {t.get('rejoins')} (longest away {t.get('rejoin_away_s_max')} s), "
          f"join {t.get('join_s')} s")
    bad = [(tick, c) for tick, c in acc.fate.items() if c[0] != chaos.robots]
    print(f"ticks not all-arrived: {len(bad)} of {chaos.n_ticks}")
    for tick, (a, m, d) in bad[:max_lines]:
        print(f"  tick {tick:6d}: arrived {a:4d}  missing {m:4d}  dead {d:4d}")
    if len(bad) > max_lines:
        print(f"  ... {len(bad) - max_lines} more (--csv FILE for every tick)")
    lengths = collections.Counter(length for _, _, length in acc.outages)
    print(f"outages (a robot's run of ticks without its Act): {len(acc.outages)}; by length in ticks: "
          + ", ".join(f"{k}: {v}" for k, v in sorted(lengths.items())))
    if acc.rejoins:
        away = sorted(s for _, s in acc.rejoins)
        print(f"rejoins logged by the world: {len(away)}; away s: min {away[0]:.2f}, median "
              f"{away[len(away) // 2]:.2f}, max {away[-1]:.2f}")
    for name, ok in checks(chaos, acc).items():
        print(f"  {'ok  ' if ok else 'FAIL'}  {name}")
    if csv_path:
        with open(csv_path, "w") as fh:
            fh.write("tick,arrived,missing,dead\n")
            for tick, (a, m, d) in acc.fate.items():
                fh.write(f"{tick},{a},{m},{d}\n")


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robots", type=int, default=100)
    p.add_argument("--duration-s", type=float, default=300.0)
    p.add_argument("--kill-every-s", type=float, default=60.0)
    p.add_argument("--pause-s", type=float, default=2.0)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--csv", default=None)
    args = p.parse_args(argv)
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # unwinds: the supervisor stops every piece
    chaos = run_chaos(args.robots, args.duration_s, args.kill_every_s, args.pause_s, args.seed)
    acc = account(chaos)
    report(chaos, acc, args.csv)
    print(f"recording: {chaos.recording}")
    return 0 if all(checks(chaos, acc).values()) else 1


if __name__ == "__main__":
    raise SystemExit(main())
