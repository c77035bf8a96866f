"""``swarmloc run``: a whole swarm of processes on this machine, with progress and results.

Starts a router (its bound port is its readiness signal), the world-server and one agent process
per robot, all as clients of the router on loopback; follows the world's state for progress;
waits for the world to finish; prints the metrics; stops every process it started.
"""

from __future__ import annotations

import json
import os
import secrets
import signal
import subprocess
import sys
import threading
import time
from dataclasses import dataclass
from pathlib import Path

from swarmloc.config import ConfigError
from swarmloc.deploy.fork.server import ForkedAgent, ForkedAgents
from swarmloc.deploy.launch import (
    ONE_THREAD_ZENOH_RUNTIME,
    Supervisor,
    start_announcing,
    start_router,
    supervised,
)
from swarmloc.deploy.scenario import AnyScenario, family_of, scenario_data


def _progress_follower(endpoint: str, run: str, total_ticks: int, quiet: bool):
    """Follow the world's state stream and show a progress bar; returns a stop function."""
    from swarmloc.protocol.keys import Keys
    from swarmloc.protocol.messages import ProtocolError, WorldState, decode
    from swarmloc.protocol.session import open_session, session_config

    session = open_session(session_config(mode="client", connect=[endpoint]))
    latest = {"tick": 0, "round_trips": 0, "alive": 0}

    def on_state(sample):
        try:
            s = decode(sample.payload.to_bytes(), WorldState)
        except ProtocolError:
            return
        latest.update(tick=s.tick, round_trips=s.round_trips, alive=sum(s.alive))

    sub = session.declare_subscriber(Keys(run).world_state, on_state)
    done = threading.Event()
    thread = None
    if not quiet and sys.stderr.isatty():
        from rich.progress import BarColumn, Progress, TextColumn, TimeRemainingColumn

        def show():
            with Progress(TextColumn("[bold]{task.description}"), BarColumn(),
                          TextColumn("{task.completed}/{task.total} ticks"),
                          TextColumn("{task.fields[info]}"), TimeRemainingColumn(),
                          transient=True) as bar:
                task = bar.add_task("swarm", total=total_ticks, info="waiting for agents")
                while not done.wait(0.25):
                    bar.update(task, completed=latest["tick"],
                               info=f"{latest['alive']} alive, {latest['round_trips']} round trips")

        thread = threading.Thread(target=show, daemon=True)
        thread.start()

    def stop():
        done.set()
        if thread:
            thread.join(2)
        sub.undeclare()
        session.close()

    return stop


@dataclass
class LocalSwarm:
    """The processes of one local run, as :func:`start_swarm` started them."""

    router_endpoint: str  # where observers and remote pieces connect
    world: subprocess.Popen
    world_endpoint: str  # where the agents connect
    #: one per robot: a ``Popen``, or for e-puck agents a :class:`ForkedAgent` (same ``pid``,
    #: ``poll()``, ``wait()``)
    agents: list[subprocess.Popen | ForkedAgent]


def start_swarm(sup: Supervisor, scenario_file: Path, *, run: str, robots: int, out: Path,
                log_dir: Path, realtime: bool = False, join_timeout_s: float = 180.0,
                world_args: tuple[str, ...] = (), agent_nice: int | None = None,
                agent_args: tuple[str, ...] = ()) -> LocalSwarm:
    """Start a router, the world-server and ``robots`` agents under ``sup``.

    The world's own session is a router that the agents reach directly (one hop less for each of
    the 2N lockstep messages of a tick); it links to the standalone router, where observers and
    pieces on other hosts connect. Every piece that listens announces its endpoint: readiness.

    With more agents than cores, agents run at a lower CPU priority (``agent_nice``, default 5
    then): the world-server is the serial part of every lockstep tick, and an agent that preempts
    it delays all the others. E-puck agents are forked from one warm agent server
    (deploy/fork/server.py) and run Zenoh on one thread (launch.py: ONE_THREAD_ZENOH_RUNTIME);
    the other families' agents are one ``swarmloc agent`` each.
    """
    if agent_nice is None:
        agent_nice = 5 if robots > (os.cpu_count() or 1) else 0
    _, endpoint = start_router(sup)
    args = ["world", str(scenario_file), "-m", "router", "-l", "tcp/127.0.0.1:0",
            "-e", endpoint, "--run", run, "--out", str(out), "--announce",
            "--join-timeout-s", str(join_timeout_s), *world_args]
    if realtime:
        args.append("--realtime")
    world, world_endpoint = start_announcing(sup, args, log_path=log_dir / "world.log")
    common = ["-m", "client", "-e", world_endpoint, "--run", run, "--join-timeout-s",
              str(join_timeout_s), "--nice", str(agent_nice), *agent_args]
    if family_of(scenario_data(str(scenario_file))) == "foraging":
        # Forked from one warm server (deploy/fork/server.py), each its own process and session.
        server = sup.start(["agents", "--robots", f"0-{robots - 1}", *common, "--log-dir", str(log_dir),
                            "--announce", "--die-with-parent", str(os.getpid())], stdout=subprocess.PIPE,
                           log_path=log_dir / "agent-server.log",
                           env={"ZENOH_RUNTIME": ONE_THREAD_ZENOH_RUNTIME})
        agents = ForkedAgents(server, list(range(robots))).wait_forked(join_timeout_s)
    else:
        family = family_of(scenario_data(str(scenario_file)))
        agents = [sup.start(["agent", "--robot", str(i), "--family", family, *common],
                            log_path=log_dir / f"agent-{i}.log") for i in range(robots)]
    return LocalSwarm(endpoint, world, world_endpoint, agents)


#: What one robot of a local run costs in memory, by how its agent runs (MiB, proportional set
#: size, measured with benchmarks/bench_scale.py --memory 100 on the project's machine): an e-puck
#: agent forked from the agent server, 6.9 (rounded up with its share of the world-server's
#: per-robot state); any other agent is a process of its own, 57 for an e-puck agent started so.
AGENT_MIB = {"forked": 10.0, "process": 60.0}
#: The pieces of a run whatever its size: router, world-server, agent server, this launcher.
BASE_MIB = 600.0


def memory_estimate_mib(robots: int, family: str) -> tuple[float, float]:
    """(MiB per agent, MiB of the whole run) that ``swarmloc run`` of ``robots`` needs."""
    per_agent = AGENT_MIB["forked" if family == "foraging" else "process"]
    return per_agent, BASE_MIB + per_agent * robots


def mem_available_mib(meminfo: str = "/proc/meminfo") -> float | None:
    """The kernel's estimate of memory available for new processes (MemAvailable), in MiB."""
    try:
        with open(meminfo, encoding="ascii") as f:
            for line in f:
                if line.startswith("MemAvailable:"):
                    return int(line.split()[1]) / 1024
    except (OSError, ValueError):
        return None
    return None


def check_memory(robots: int, family: str, available_mib: float | None) -> None:
    """Refuse (ConfigError) a swarm whose estimated memory exceeds what is available: started
    anyway, it would swap or meet the OOM killer part way through, with pieces half-started."""
    if available_mib is None:
        return
    per_agent, total = memory_estimate_mib(robots, family)
    if total > available_mib:
        fits = max(0, int((available_mib - BASE_MIB) // per_agent))
        raise ConfigError(
            f"--robots {robots}: this machine cannot hold that swarm: about {total / 1024:.1f} GiB "
            f"needed ({robots} agents x {per_agent:.0f} MiB + {BASE_MIB:.0f} MiB for the router, "
            f"world-server and launcher), {available_mib / 1024:.1f} GiB available (MemAvailable "
            f"in /proc/meminfo); at most about {fits} robots fit")


def print_metrics(summary: dict) -> None:
    """The foraging metrics of seed 000 §6, as the end of a run prints them."""
    m = summary["metrics"]
    n = summary["robots"]
    recruit = m.get("recruitment_time_s")
    print(f"scenario {summary['scenario']}  strategy {summary['strategy']}  seed {summary['seed']}  robots {n}")
    print(f"  robots that found both areas : {m['robots_found_both']}/{n}")
    print(f"  recruitment time (all robots): {f'{recruit:.1f} s' if recruit is not None else 'not reached'}")
    print(f"  round trips nest-prey-nest   : {m['round_trips_total']}")
    frac = m.get("on_path_fraction_mean")
    print(f"  robots on the path (2nd half): {'%.0f %%' % (100 * frac) if frac is not None else '-'}")


#: Open files the world-server needs beside one connection per agent (its Zenoh runtime, the
#: recording, logs), with room to spare.
FD_BASE = 256


def ensure_open_files(robots: int) -> int:
    """Make room for a swarm's connections before anything starts: the world-server holds one
    per agent, and a system's default soft limit (often 1,024) stopped a 1,000-agent world
    after start-up with agents missing. Raises this process's soft limit of open files (the
    pieces inherit it) up to the hard limit; ConfigError, naming the largest swarm that fits,
    if even the hard limit is too low. Returns the soft limit now in force."""
    import resource

    need = robots + FD_BASE
    soft, hard = resource.getrlimit(resource.RLIMIT_NOFILE)
    if soft == resource.RLIM_INFINITY or soft >= need:
        return soft
    if hard != resource.RLIM_INFINITY and hard < need:
        raise ConfigError(
            f"--robots {robots}: the world-server holds a connection per agent, about {need} open "
            f"files, but this system allows {hard} (ulimit -Hn); at most about {max(0, hard - FD_BASE)} "
            f"robots fit. Raise the hard limit (/etc/security/limits.conf, or LimitNOFILE= in a "
            f"systemd unit)")
    new = hard if hard == resource.RLIM_INFINITY else max(need, min(hard, 1 << 20))
    resource.setrlimit(resource.RLIMIT_NOFILE, (new, hard))
    return new


def run_local(scenario: AnyScenario, *, run_name: str | None, out_root: Path, realtime: bool,
              quiet: bool, join_timeout_s: float = 180.0, null_brains: bool = False,
              view: bool = False, view_http: str = "127.0.0.1:8765", record: str | None = None,
              record_messages: bool = False, particles: int = 0) -> int:
    check_memory(scenario.robots, scenario.family, mem_available_mib())  # before anything starts
    ensure_open_files(scenario.robots)
    run = run_name or f"{scenario.name}-{scenario.label}-s{scenario.seed}-{secrets.token_hex(3)}".replace(".", "_")
    out = out_root / run
    out.mkdir(parents=True, exist_ok=True)
    scenario_file = out / "scenario.json"
    scenario_file.write_text(json.dumps(scenario.to_dict(), indent=2))
    log_dir = out / "logs"
    log_dir.mkdir(exist_ok=True)
    say = (lambda *a: None) if quiet else (lambda *a: print(*a, file=sys.stderr, flush=True))
    t0 = time.perf_counter()

    def terminated(signum, frame):
        # Python's default SIGTERM ends the process without running `finally`: the pieces would
        # be orphaned. Unwind instead, so that the supervisor stops every one of them.
        raise SystemExit(128 + signum)

    signal.signal(signal.SIGTERM, terminated)
    # Compile the kernels in this one process before any piece starts (deploy/warm.py): left
    # to the pieces, a cold machine's world and agents compiled them all at once.
    from swarmloc.deploy.warm import ensure_compiled
    from swarmloc.families import needs_kernels

    # Said even with --quiet (which only drops the progress bar): it explains a minute's wait.
    if needs_kernels(scenario.family):
        ensure_compiled(lambda line: print(line, file=sys.stderr, flush=True))
    with supervised() as sup:
        from swarmloc.deploy.observe.cli import record_world_args, start_view

        swarm = start_swarm(sup, scenario_file, run=run, robots=scenario.robots, out=out,
                            log_dir=log_dir, realtime=realtime, join_timeout_s=join_timeout_s,
                            agent_args=("--null-brain",) if null_brains else (),
                            world_args=record_world_args(record, record_messages, particles))
        if view:  # an observer like any other, on the standalone router
            _, url = start_view(sup, swarm.router_endpoint, run, view_http, log_dir / "view.log")
            print(f"view: {url}", file=sys.stderr, flush=True)
        say(f"router on {swarm.router_endpoint}; run '{run}': {scenario.robots} {scenario.family} robots, "
            f"{scenario.label}, seed {scenario.seed}, {scenario.n_ticks} ticks "
            f"({'real time' if realtime else 'lockstep'})")
        stop_progress = _progress_follower(swarm.router_endpoint, run, scenario.n_ticks, quiet)
        try:
            code = swarm.world.wait()
        finally:
            stop_progress()
    results_file = out / "results.json"
    if code != 0 or not results_file.exists():
        print(f"swarmloc: the world-server failed (exit {code}); see {log_dir / 'world.log'}", file=sys.stderr)
        return 1
    result = json.loads(results_file.read_text())
    if scenario.family == "foraging":
        print_metrics(result)
    else:
        print(f"scenario {scenario.name}  {scenario.label}  seed {scenario.seed}  robots {scenario.robots}")
        for key, value in result["metrics"].items():
            print(f"  {key:29s}: {value}")
    t = result["transport"]
    print(f"  transport                    : {t['ticks']} ticks in {t['wall_s']} s = {t['ticks_per_s']} ticks/s "
          f"(tick p50 {t['tick_ms_p50']} ms, p99 {t['tick_ms_p99']} ms)")
    print(f"  rejected messages            : {sum(result['rejected'].values())}")
    print(f"run folder: {out}  ({time.perf_counter() - t0:.0f} s)")
    return 0
