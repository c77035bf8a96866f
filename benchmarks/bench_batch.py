"""Batch engine speed: robot-steps per second for swarms of 10 to 10,000 e-pucks on one core.

The arena grows with the swarm so that density stays that of ES3 (100 robots on 6 x 8.5 m).
Prints, per size, the CPU time per tick (``time.process_time``: wall time is noisy on a shared
machine), robot-steps per second, and how that compares with real time (the e-puck controller
runs at 10 Hz). Ticks are measured after a warm-up of the same length, so that the robots have
left the dense start disc and the compiled kernels are loaded. Usage:

    python benchmarks/bench_batch.py [--robots 10 100 1000 10000] [--ticks 200]
    python benchmarks/bench_batch.py --replication ES1 ES3   # whole seeded replications, CPU s
    python benchmarks/bench_batch.py --compile                # first-call compile / load time

``--compile`` runs two fresh interpreters against an empty numba cache directory: the first
compiles every kernel, the second loads them from that cache (what an experiment worker pays).
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
from swarmloc.deploy.batch import run_batch
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
    from swarmloc.agents.foraging import on_path
    from swarmloc.deploy.batch import inbox_from, swarm_brain
    from swarmloc.world.foraging import ForagingWorld

    print(f"{'robots':>7} {'ms/tick':>9} {'robot-steps/s':>14} {'x real time':>12}   (CPU time, one core)")
    for n in args.robots:
        scenario = _scenario(n, 2 * args.ticks, args.strategy)
        world = ForagingWorld(scenario.world)
        brain = swarm_brain(scenario)
        ids = brain.robot_ids
        sent = None
        for measured in (False, True):
            t0 = time.process_time()
            for _ in range(args.ticks):
                obs = world.observe()
                out = brain.step(obs.encoder_steps, obs.ir, obs.ground, inbox_from(obs, sent, ids))
                world.step(out.wheel_speed_steps_s, out.sending, on_path(out.state))
                sent = out
        tick_s = (time.process_time() - t0) / args.ticks
        print(f"{n:>7} {tick_s * 1e3:>9.3f} {n / tick_s:>14,.0f} {0.1 / tick_s:>12.2f}", flush=True)


def replications(args) -> None:
    from swarmloc.deploy.batch import run_batch
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
    args = parser.parse_args()
    if args.compile:
        compile_time()
    elif args.replication:
        replications(args)
    else:
        per_tick(args)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
