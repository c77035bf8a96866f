"""Batch engine speed: robot-steps per second for swarms of 10 to 10,000 e-pucks on one core.

The arena grows with the swarm so that density stays that of ES3 (100 robots on 6 x 8.5 m).
Prints, per size, the CPU time per tick (``time.process_time``: wall time is noisy on a shared
machine), robot-steps per second, and how that compares with real time (the e-puck controller
runs at 10 Hz). Ticks are measured after a warm-up of the same length, so that the robots have
left the dense start disc and the compiled kernels are loaded; they are the batch engine's
(deploy/lab/epuck/batch.py: CompiledTicks, as run_batch steps them). Usage:

    python benchmarks/bench_batch.py [--robots 10 100 1000 10000] [--ticks 200]
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
import math
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
    from swarmloc.deploy.scenario import load_scenario

    k = math.sqrt(n / 100)
    w, h = 6.0 * k, 8.5 * k
    return load_scenario("ES3", [
        f"world.robots={n}", f"world.duration_s={ticks / 10}", f"agent.strategy={strategy}",
        f"world.arena.width_m={w}", f"world.arena.height_m={h}",
        f"world.arena.nest_centre_m=[{w / 2}, {0.15 * h}]", f"world.arena.prey_centre_m=[{w / 2}, {0.85 * h}]",
        f"world.arena.initial_radius_m={min(0.5 * k, w / 2 - 0.2)}",
    ])


def per_tick(args) -> None:
    from swarmloc.deploy.lab.epuck.batch import CompiledTicks, swarm_brain
    from swarmloc.world.epuck.foraging import ForagingWorld

    print(f"{'robots':>7} {'ms/tick':>9} {'robot-steps/s':>14} {'x real time':>12}   (CPU time, one core)")
    for n in args.robots:
        scenario = _scenario(n, 2 * args.ticks + 1, args.strategy)
        world = ForagingWorld(scenario.world)
        ticks = CompiledTicks(world, swarm_brain(scenario))  # what run_batch does
        ticks.think()
        for measured in (False, True):
            t0 = time.process_time()
            for _ in range(args.ticks):
                ticks.step_and_think()
        tick_s = (time.process_time() - t0) / args.ticks
        print(f"{n:>7} {tick_s * 1e3:>9.3f} {n / tick_s:>14,.0f} {0.1 / tick_s:>12.2f}", flush=True)


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
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 100, 1000, 10000])
    parser.add_argument("--ticks", type=int, default=200)
    parser.add_argument("--strategy", default="SSGIKF")
    parser.add_argument("--replication", nargs="+", metavar="SCENARIO")
    parser.add_argument("--compile", action="store_true")
    parser.add_argument("--estimate", metavar="SPEC", help="an experiment spec (name or path)")
    parser.add_argument("--workers", type=int, default=2)
    args = parser.parse_args()
    if args.compile:
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
