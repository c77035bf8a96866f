"""Batch engine speed: robot-steps per second for swarms of 10 to 10,000 e-pucks on one core.

The arena grows with the swarm so that density stays that of ES3 (100 robots on 6 x 8.5 m).
Prints, per size, the wall time per tick, robot-steps per second, and how that compares with
real time (the e-puck controller runs at 10 Hz). Usage:

    python benchmarks/bench_batch.py [--robots 10 100 1000 10000] [--ticks 200]
"""

from __future__ import annotations

import argparse
import math
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # one core, as the figure claims


def main() -> int:
    from swarmloc.agents.foraging import on_path
    from swarmloc.deploy.batch import inbox_from, swarm_brain
    from swarmloc.deploy.scenario import load_scenario
    from swarmloc.world.foraging import ForagingWorld

    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 100, 1000, 10000])
    parser.add_argument("--ticks", type=int, default=200)
    parser.add_argument("--strategy", default="SSGIKF")
    args = parser.parse_args()
    print(f"{'robots':>7} {'ms/tick':>9} {'robot-steps/s':>14} {'x real time':>12}")
    for n in args.robots:
        k = math.sqrt(n / 100)
        w, h = 6.0 * k, 8.5 * k
        scenario = load_scenario("ES3", [
            f"world.robots={n}", f"world.duration_s={args.ticks / 10}", f"agent.strategy={args.strategy}",
            f"world.arena.width_m={w}", f"world.arena.height_m={h}",
            f"world.arena.nest_centre_m=[{w / 2}, {0.15 * h}]", f"world.arena.prey_centre_m=[{w / 2}, {0.85 * h}]",
            f"world.arena.initial_radius_m={min(0.5 * k, w / 2 - 0.2)}",
        ])
        world = ForagingWorld(scenario.world)
        brain = swarm_brain(scenario)
        ids = brain.robot_ids
        sent = None
        t0 = time.perf_counter()
        while not world.done:
            obs = world.observe()
            out = brain.step(obs.encoder_steps, obs.ir, obs.ground, inbox_from(obs, sent, ids))
            world.step(out.wheel_speed_steps_s, out.sending, on_path(out.state))
            sent = out
        per_tick = (time.perf_counter() - t0) / args.ticks
        print(f"{n:>7} {per_tick * 1e3:>9.2f} {n / per_tick:>14,.0f} {0.1 / per_tick:>12.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
