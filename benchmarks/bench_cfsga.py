"""Iterations per second of CFS-GA (agents/laser/cfsga.py; seed 003, table I) on one core.

Issue 4 asks for at least 100 iterations/s per robot with 300 individuals and 18 beams. One
iteration is a full :meth:`CFSGALocalizer.step`: kinematic update, raw fitness (300 x 18 rays cast
on the office map, 47 walls), shared fitness (O(m^2) niche counts), and one generation; the
"collaborative" column adds one teammate's payload and sighting, i.e. decoding, roto-translation
and the O(m m_v) virtual niche counts (003 §IV-C). Figures are CPU time (``time.process_time``,
user + system) over at least 1 s and 30 iterations per case; the robot drives along a straight
stretch of the office corridor with fresh noisy scans (precomputed, so the world's cost is not
counted).

Usage: python benchmarks/bench_cfsga.py
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import time

import numpy as np

from swarmloc.agents.laser.cfsga import CFSGALocalizer, CFSGAParams, encode_individuals
from swarmloc.agents.laser.localizer import (
    LaserObservation,
    LocalizerSetup,
    RadioMessage,
    Sighting,
)
from swarmloc.world.laser.laser import LaserParams, MotionNoise, RelativeNoise, scan
from swarmloc.world.laser.maps import build_map

POPULATIONS = (100, 300, 1000)
N_OBSERVATIONS = 50
STEP_M = 0.06


def make_observations(world, laser, cooperative: bool, rng) -> list[LaserObservation]:
    """A robot driving east along the corridor (y = 6 m); a teammate 2 m behind it."""
    observations = []
    for k in range(N_OBSERVATIONS):
        pose = np.array([[3.0 + STEP_M * k, 6.0, 0.0]])
        ranges = scan(world, pose, laser, rng)[0]
        received, sightings = (), ()
        if cooperative:
            team = pose[0] + np.array([-2.0, 0.0, 0.0]) + rng.normal(0.0, 0.3, size=(150, 3))
            received = (RadioMessage(1, encode_individuals(team)),)
            sightings = (Sighting(1, 2.0, np.pi, 0.0),)
        observations.append(LaserObservation(k, STEP_M, 0.0, ranges, sightings, received))
    return observations


def iterations_per_s(population: int, cooperative: bool, min_time_s: float = 1.0) -> float:
    world = build_map("office")
    laser, motion, relative = LaserParams.cfs_ga(), MotionNoise.cfs_ga(), RelativeNoise.cfs_ga()
    setup = LocalizerSetup(
        robot_id=0,
        map_name="office",
        n_beams=laser.n_beams,
        max_range_m=laser.max_range_m,
        laser_noise_std_m=laser.noise_std_m,
        speed_std_mps=motion.speed_std_mps,
        turn_rate_std_rad_s=motion.turn_rate_std_rad_s,
        relative_distance_std_m=relative.distance_std_m,
        relative_orientation_std_rad=relative.orientation_std_rad,
        dt_s=0.2,
        cooperative=cooperative,
    )
    rng = np.random.default_rng(0)
    observations = make_observations(world, laser, cooperative, rng)
    loc = CFSGALocalizer(setup, CFSGAParams(population_size=population), np.random.default_rng(1))
    loc.step(observations[0])  # warm-up
    steps, t0 = 0, time.process_time()
    while steps < 30 or time.process_time() - t0 < min_time_s:
        loc.step(observations[steps % N_OBSERVATIONS])
        steps += 1
    return steps / (time.process_time() - t0)


def main() -> int:
    print("CFS-GA step on map 'office', 18 beams, table I parameters, CPU time, one thread")
    print(f"  {'individuals':>11}  {'autonomous it/s':>15}  {'collaborative it/s':>18}")
    for population in POPULATIONS:
        solo = iterations_per_s(population, cooperative=False)
        team = iterations_per_s(population, cooperative=True)
        print(f"  {population:11d}  {solo:15.0f}  {team:18.0f}")
    print("  target (issue 4): >= 100 it/s with 300 individuals")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
