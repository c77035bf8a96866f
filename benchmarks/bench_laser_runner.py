"""Speed of the laser world alone (world/laser/world.py): steps per second for 3 and 30 robots.

One world step is what the runner and a world-server do per tick besides the robots' brains:
the driver's pure-pursuit commands, noisy unicycle motion with the wall check, 18-beam scans,
sightings of teammates (range + line of sight) and the radio (every robot broadcasts a 1 kB
payload, delivered within 4 m and line of sight). Robots drive to random goals in the office
floor (table I of seed 003 for the sensors). CPU time (``time.process_time``) over whole runs
after a warm-up, so that other load on the machine does not count; one BLAS thread.

Usage: python benchmarks/bench_laser_runner.py
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import time

from swarmloc.world.laser.world import LaserWorld, LaserWorldConfig

STEPS = 400
PAYLOAD = bytes(1024)


def steps_per_s(robots: int, map_name: str = "office", seed: int = 1) -> tuple[float, float]:
    """(steps/s, robot-steps/s) of one run of ``STEPS`` steps, CPU time, after a warm-up run."""
    config = LaserWorldConfig(map=map_name, robots=robots, steps=STEPS, seed=seed)
    outgoing = [PAYLOAD] * robots
    LaserWorld(config)  # warm-up: builds (and caches) the planner of the map
    world = LaserWorld(config)
    t0 = time.process_time()
    while not world.done:
        world.observe()
        world.step(outgoing)
    cpu_s = time.process_time() - t0
    return STEPS / cpu_s, STEPS * robots / cpu_s


def main() -> int:
    print(f"LaserWorld alone, office map, random goals, {STEPS} steps, every robot broadcasting "
          f"{len(PAYLOAD)} B, CPU time")
    for robots in (3, 30):
        rate, robot_rate = steps_per_s(robots)
        print(f"  {robots:3d} robots: {rate:8.0f} steps/s  ({robot_rate:8.0f} robot-steps/s, "
              f"{1e3 / rate:.2f} ms per step)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
