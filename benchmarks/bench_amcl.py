"""Speed of the AMCL-style particle filter (agents/laser/amcl.py), the baseline of seeds 002 and 003.

Issue 4's target: at 5,000 particles, at least 20 updates per second on one core with the 18-beam
laser of seed 003 (table I: L = 18, l = 8 m). One update is ``AMCLLocalizer.step``: motion
(eq. 3 of 002), likelihood-field measurement, recovery averages, best-cluster estimate and
KLD-sized low-variance resampling with injection. The population is held at the given size
(``AMCLParams.fixed``: min = max) so that KLD-sampling cannot shrink it.

A robot wanders the office map (world/laser/maps.py) for a precomputed trajectory; only the filter's
steps are timed, in CPU time (``time.process_time``, robust to other load on the machine), over
at least ``MIN_CPU_S`` of work after a warm-up. The collaborative line adds one teammate sighting
with a 64-sample belief payload per step. BLAS and OpenMP are held to one thread.

Usage: python benchmarks/bench_amcl.py
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import math
import time

import numpy as np

from swarmloc.agents.laser.amcl import AMCLLocalizer, AMCLParams
from swarmloc.agents.laser.amcl_belief import BeliefSummary, encode_belief
from swarmloc.agents.laser.localizer import (
    LaserObservation,
    LocalizerSetup,
    RadioMessage,
    Sighting,
)
from swarmloc.world.laser.laser import (
    LaserParams,
    MotionNoise,
    RelativeNoise,
    cast_rays,
    scan,
    unicycle_step,
)
from swarmloc.world.laser.maps import build_map, free_space_sample

PARTICLES = (500, 5000, 20000)
MAP_NAME = "office"
TRAJECTORY_STEPS = 200
MIN_CPU_S = 1.0
TARGET_AT_5000 = 20.0


def trajectory(world, laser, motion, rng):
    """Observations of a robot wandering the map (straight, turning away from walls)."""
    pose = free_space_sample(world, 1, rng, clearance_m=0.5)[0]
    observations = []
    for k in range(TRAJECTORY_STEPS):
        front = cast_rays(world, pose[None], np.array([-0.4, 0.0, 0.4]), 8.0)[0]
        v, w = (0.0, 0.8 if front[0] < front[2] else -0.8) if front.min() < 0.8 else (0.3, 0.0)
        moved = unicycle_step(pose[None], v, w, 1.0, motion, rng)
        pose = moved.poses_m[0]
        ranges = scan(world, pose[None], laser, rng)[0]
        observations.append(
            LaserObservation(
                k,
                float(moved.odometry_delta_s_m[0]),
                float(moved.odometry_delta_phi_rad[0]),
                ranges,
            )
        )
    return observations


def updates_per_cpu_second(make_localizer, observations) -> float:
    loc = make_localizer()
    loc.step(observations[0])  # warm-up (and the likelihood field is cached by then)
    steps, cpu, k = 0, 0.0, 1
    while cpu < MIN_CPU_S:
        if k == len(observations):
            loc, k = make_localizer(), 0
        t0 = time.process_time()
        loc.step(observations[k])
        cpu += time.process_time() - t0
        steps, k = steps + 1, k + 1
    return steps / cpu


def main() -> int:
    world = build_map(MAP_NAME)
    laser, motion, relative = LaserParams.cfs_ga(), MotionNoise.cfs_ga(), RelativeNoise.cfs_ga()
    rng = np.random.default_rng(0)
    observations = trajectory(world, laser, motion, rng)
    teammate = BeliefSummary(
        robot_id=1,
        step=0,
        poses_m=free_space_sample(world, 64, rng),
        weights=np.ones(64),
        kernel_std_m=0.25,
        kernel_std_rad=0.15,
    )
    payload = encode_belief(teammate)
    with_teammate = [
        LaserObservation(
            o.step,
            o.odometry_delta_s_m,
            o.odometry_delta_phi_rad,
            o.ranges_m,
            (Sighting(1, 2.0, 0.5, 0.1),),
            (RadioMessage(1, payload),),
        )
        for o in observations
    ]

    def setup(cooperative: bool) -> LocalizerSetup:
        return LocalizerSetup(
            robot_id=0,
            map_name=MAP_NAME,
            n_beams=laser.n_beams,
            max_range_m=laser.max_range_m,
            laser_noise_std_m=laser.noise_std_m,
            speed_std_mps=motion.speed_std_mps,
            turn_rate_std_rad_s=motion.turn_rate_std_rad_s,
            relative_distance_std_m=relative.distance_std_m,
            relative_orientation_std_rad=relative.orientation_std_rad,
            cooperative=cooperative,
        )

    print(
        f"AMCLLocalizer.step on map {MAP_NAME!r} ({world.n_segments} segments), "
        f"{laser.n_beams} beams, max range {laser.max_range_m:g} m; CPU time, one thread"
    )
    results = {}
    for n in PARTICLES:
        params = AMCLParams.fixed(n)
        for cooperative, obs in ((False, observations), (True, with_teammate)):
            seed = np.random.default_rng(1)
            rate = updates_per_cpu_second(
                lambda c=cooperative, p=params, s=seed: AMCLLocalizer(setup(c), p, s), obs
            )
            results[n, cooperative] = rate
            label = "with 1 teammate sighting" if cooperative else "autonomous"
            print(
                f"  {n:6d} particles, {label:25s}: {rate:8.1f} updates/s "
                f"({1e3 / rate:6.2f} ms/update)"
            )
    rate = results[5000, False]
    verdict = "meets" if rate >= TARGET_AT_5000 else "MISSES"
    print(f"target: >= {TARGET_AT_5000:g} updates/s at 5000 particles: {verdict} ({rate:.1f})")
    return 0 if math.isfinite(rate) else 1


if __name__ == "__main__":
    raise SystemExit(main())
