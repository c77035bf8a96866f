"""Batch engine speed: robot-steps per second for swarms of 10 to 100,000 e-pucks on one core.

The swarm runs the ``ES3-tiled`` family, which keeps ES3's density at any size (one 6 x 8.5 m
tile with its nest, prey and start disc per 100 robots). Each size runs in a process of its own
and prints the CPU time per tick (``time.process_time``: wall time is noisy on a shared machine;
the best and the median of several rounds, since other work on the machine also takes the
caches), the cost per robot-step, robot-steps per second, how that compares with real time (the
e-puck controller runs at 10 Hz), the process's peak memory, the memory per robot (peak minus
the process before the world was built) and the set-up time (world, brains, first tick). Ticks
are measured after a warm-up round, so that the robots have left the dense start discs; they are
the batch engine's (deploy/lab/epuck/batch.py: CompiledTicks, as run_batch steps them). Usage:

    python benchmarks/bench_batch.py [--robots 10 100 1000 10000] [--ticks 100] [--rounds 5]
    python benchmarks/bench_batch.py --robots 1000 10000 100000
    python benchmarks/bench_batch.py --replication ES1 ES3   # whole seeded replications, CPU s
    python benchmarks/bench_batch.py --compile                # first-call compile / load time
    python benchmarks/bench_batch.py --estimate social-odometry-000  # a whole experiment's CPU time

``--compile`` runs two fresh interpreters against an empty numba cache directory: the first
compiles every kernel, the second loads them from that cache (what an experiment worker pays).

``--estimate`` runs one replication (the spec's first seed) of every setting of an experiment
spec and scales by its replications: the CPU time the whole experiment needs, and the wall time
on ``--workers`` cores (each worker also pays the start-up that ``--compile`` measures warm).
"""

from __future__ import annotations

import argparse
import os
import subprocess
import sys
import tempfile
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core, as the figure claims

_FIRST_TICK = """
import time
t0 = time.perf_counter()
from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.scenario import load_scenario
for strategy in ("SSGIKF", "DSGIFF", "NC", "SSIKF"):
    run_batch(load_scenario("ES1", [f"agent.strategy={strategy}", "world.duration_s=5"]))
print(f"{time.perf_counter() - t0:.2f}")
"""


def _scenario(n: int, ticks: int, strategy: str):
    """ES3's density at any size: the ``ES3-tiled`` family (one 6 x 8.5 m ES3 tile per 100 robots)."""
    from swarmloc.deploy.scenario import load_scenario

    return load_scenario("ES3-tiled", [f"world.robots={n}", f"world.duration_s={ticks / 10}",
                                       f"agent.strategy={strategy}"])


def _rss_mib() -> float:
    with open("/proc/self/status") as f:
        for line in f:
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    return float("nan")


def one_size(args) -> None:
    """One swarm size in this process (a fresh one per size, so that its peak memory is its own):
    one JSON line."""
    import json
    import resource

    from swarmloc.deploy.lab.epuck.batch import CompiledTicks, run_batch, swarm_brain
    from swarmloc.world.epuck.foraging import ForagingWorld

    n = args.one
    run_batch(_scenario(10, 2, args.strategy))  # load the kernels before the baseline
    base_mib = _rss_mib()
    t0 = time.process_time()
    scenario = _scenario(n, (args.rounds + 1) * args.ticks + 1, args.strategy)
    world = ForagingWorld(scenario.world)
    ticks = CompiledTicks(world, swarm_brain(scenario))  # what run_batch does
    ticks.think()
    setup_s = time.process_time() - t0
    rounds = []
    for _ in range(args.rounds + 1):  # the first round is the warm-up
        t0 = time.process_time()
        for _ in range(args.ticks):
            ticks.step_and_think()
        rounds.append((time.process_time() - t0) / args.ticks)
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    cols, rows = scenario.world.tiles
    print(json.dumps({"robots": n, "tick_s": sorted(rounds[1:]), "setup_s": setup_s, "peak_mib": peak_mib,
                      "base_mib": base_mib, "arena": f"{cols}x{rows} tiles"}))


def per_tick(args) -> None:
    import json

    print(f"{'robots':>7} {'ms/tick':>9} {'ns/robot-step':>14} {'robot-steps/s':>14} {'x real time':>12} "
          f"{'peak MiB':>9} {'KiB/robot':>10} {'setup s':>8}  arena   (CPU time, one core; best / median of "
          f"{args.rounds} rounds of {args.ticks} ticks)")
    first = None
    for n in args.robots:
        out = subprocess.run([sys.executable, __file__, "--one", str(n), "--ticks", str(args.ticks),
                              "--rounds", str(args.rounds), "--strategy", args.strategy],
                             capture_output=True, text=True, check=True)
        r = json.loads(out.stdout.strip().splitlines()[-1])
        best, median = r["tick_s"][0], r["tick_s"][len(r["tick_s"]) // 2]
        per_step_ns = best / n * 1e9
        first = first or per_step_ns
        print(f"{n:>7} {best * 1e3:>9.3f} {per_step_ns:>8.0f} / {median / n * 1e9:<4.0f} {n / best:>14,.0f} "
              f"{0.1 / best:>12.2f} {r['peak_mib']:>9.0f} {(r['peak_mib'] - r['base_mib']) * 1024 / n:>10.2f} "
              f"{r['setup_s']:>8.2f}  {r['arena']}   ({per_step_ns / first:.2f}x the first size's cost per "
              f"robot-step)", flush=True)


def replications(args) -> None:
    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.scenario import load_scenario

    run_batch(load_scenario("ES1", [f"agent.strategy={args.strategy}", "world.duration_s=10"]))  # load kernels
    print(f"{'scenario':>8} {'robots':>7} {'ticks':>7} {'CPU s':>8} {'us/tick':>8}   (strategy {args.strategy})")
    for name in args.replication:
        scenario = load_scenario(name, [f"agent.strategy={args.strategy}"])
        t0 = time.process_time()
        run_batch(scenario)
        cpu_s = time.process_time() - t0
        w = scenario.world
        print(f"{name:>8} {w.robots:>7} {w.n_ticks:>7} {cpu_s:>8.2f} {cpu_s / w.n_ticks * 1e6:>8.1f}", flush=True)


def estimate(args) -> None:
    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.lab.experiment import load_spec, settings
    from swarmloc.deploy.scenario import load_scenario

    spec = load_spec(args.estimate)
    run_batch(load_scenario("ES1", ["world.duration_s=10"]))  # load kernels
    by_scenario: dict[str, float] = {}
    total_s = 0.0
    for s in settings(spec):
        scenario = load_scenario(s.scenario, [*s.overrides, f"world.seed={spec.seed}"])
        t0 = time.process_time()
        run_batch(scenario)
        cpu_s = time.process_time() - t0
        total_s += cpu_s * spec.replications
        by_scenario[s.scenario] = by_scenario.get(s.scenario, 0.0) + cpu_s
        print(f"{s.id:<60} {cpu_s:7.2f} CPU s", flush=True)
    for name, cpu_s in by_scenario.items():
        print(f"{name}: {cpu_s * spec.replications:8.0f} CPU s for {spec.replications} replications of each setting")
    start_s = 1.0  # a spawned worker's imports and kernel loading (see --compile, warm)
    wall_s = total_s / args.workers + start_s
    print(f"total {total_s:.0f} CPU s: about {wall_s / 60:.1f} min on {args.workers} workers")


def compile_time() -> None:
    with tempfile.TemporaryDirectory() as cache:
        env = dict(os.environ, NUMBA_CACHE_DIR=cache)
        for label in ("cold cache (compile)", "warm cache (load)"):
            out = subprocess.run([sys.executable, "-c", _FIRST_TICK], env=env, capture_output=True, text=True, check=True)
            print(f"{label:>22}: {out.stdout.strip()} s wall from import to 4 short ES1 runs")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 100, 1000, 10000, 100000])
    parser.add_argument("--ticks", type=int, default=100, help="ticks per round")
    parser.add_argument("--rounds", type=int, default=5, help="measured rounds (after one warm-up round)")
    parser.add_argument("--one", type=int, help=argparse.SUPPRESS)  # one size, in a child process
    parser.add_argument("--strategy", default="SSGIKF")
    parser.add_argument("--replication", nargs="+", metavar="SCENARIO")
    parser.add_argument("--compile", action="store_true")
    parser.add_argument("--estimate", metavar="SPEC", help="an experiment spec (name or path)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if args.one:
        one_size(args)
    elif args.compile:
        compile_time()
    elif args.estimate:
        estimate(args)
    elif args.replication:
        replications(args)
    else:
        per_tick(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
