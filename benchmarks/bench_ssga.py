"""Speed of MR-SSGA and the simple GA (agents/laser/ssga.py, agents/laser/simple_ga.py; seed 002).

Prints iterations per second per robot (one ``step``: eq. 3 kinematic update, eq. 1 or eq. 2
fitness through ``cast_rays``, reproduction, estimate) for populations of 50, 100 and 300 with the
laser of table 2 of 002 (8 beams, 6 m), on the symmetric multi-room map of table 3. Two cases:
autonomous (eq. 1) and collaborating with two teammates both seen and heard (eq. 2, as the three
robots of table 3 when they meet; each teammate costs one more ray cast of the population).

CPU time from ``time.process_time()`` (wall time is noisy on a shared machine) over at least one
second of steps, fed with pre-computed observations of a robot driving through the corridor. One
core: BLAS threads are pinned to 1 before numpy loads.

``--cooperation`` instead checks that eq. 2 pays (not a speed figure): two robots shuttle along
the office corridor (2 m apart at the start, in sight), 20 seeds x 150 steps with population 300, once
autonomous and once cooperating; it prints the share of robots whose median error over the last
10 steps is below 0.3 m and the median of those errors per robot. About 25 s of CPU.

Usage: python benchmarks/bench_ssga.py [--cooperation]
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import math
import sys
import time

import numpy as np

from swarmloc.agents.laser.localizer import (
    LaserObservation,
    LocalizerSetup,
    RadioMessage,
    Sighting,
)
from swarmloc.agents.laser.simple_ga import SimpleGALocalizer
from swarmloc.agents.laser.ssga import SSGALocalizer, encode_scan_payload
from swarmloc.world.laser.laser import (
    LaserParams,
    MotionNoise,
    RelativeNoise,
    relative_observation,
    scan,
    unicycle_step,
    wrap_angle,
)
from swarmloc.world.laser.maps import build_map

MAP_NAME = "symmetric_rooms"
POPULATIONS = (50, 100, 300)
N_OBSERVATIONS = 200
MIN_CPU_S = 1.0


def observations(cooperative: bool, rng: np.random.Generator) -> list[LaserObservation]:
    """Robot 0 drives east along the corridor; teammates 1 and 2 follow 1 m and 2 m behind."""
    world = build_map(MAP_NAME)
    laser, motion = LaserParams.mr_ssga(), MotionNoise.mr_ssga()
    poses = np.array([[3.0, 5.0, 0.0], [2.0, 5.0, 0.0], [1.0, 5.0, 0.0]])
    out, delta_s, delta_phi, previous = [], 0.0, 0.0, ()
    for k in range(N_OBSERVATIONS):
        ranges = scan(world, poses, laser, rng)
        sightings, received = (), ()
        if cooperative:
            sightings = tuple(
                Sighting(
                    j,
                    math.hypot(*(poses[j, :2] - poses[0, :2])),
                    math.atan2(*(poses[j, :2] - poses[0, :2])[::-1]) - poses[0, 2],
                    poses[j, 2] - poses[0, 2],
                )
                for j in (1, 2)
            )
            received = previous
            previous = tuple(
                RadioMessage(j, encode_scan_payload(k, ranges[j], laser.max_range_m))
                for j in (1, 2)
            )
        out.append(LaserObservation(k, delta_s, delta_phi, ranges[0], sightings, received))
        turn = 0.3 * math.sin(k / 10.0)
        moved = unicycle_step(poses, 0.05, turn * 0.1, 1.0, motion, rng)
        poses = moved.poses_m
        poses[:, 1] = np.clip(poses[:, 1], 4.3, 5.7)  # stay in the corridor
        poses[:, 0] = np.clip(poses[:, 0], 0.5, 17.5)
        delta_s = float(moved.odometry_delta_s_m[0])
        delta_phi = float(moved.odometry_delta_phi_rad[0])
    return out


def iterations_per_s(cls, population_size: int, obs: list[LaserObservation]) -> float:
    laser, motion, relative = LaserParams.mr_ssga(), MotionNoise.mr_ssga(), RelativeNoise.mr_ssga()
    setup = LocalizerSetup(
        robot_id=0,
        map_name=MAP_NAME,
        n_beams=laser.n_beams,
        max_range_m=laser.max_range_m,
        laser_noise_std_m=laser.noise_std_m,
        speed_std_mps=motion.speed_std_mps,
        turn_rate_std_rad_s=motion.turn_rate_std_rad_s,
        relative_distance_std_m=relative.distance_std_m,
        relative_orientation_std_rad=relative.orientation_std_rad,
    )
    loc = cls.from_config(setup, {"population_size": population_size}, np.random.default_rng(1))
    for o in obs[:5]:  # warm-up
        loc.step(o)
    steps, start = 0, time.process_time()
    while True:
        for o in obs:
            loc.step(o)
        steps += len(obs)
        elapsed = time.process_time() - start
        if elapsed >= MIN_CPU_S:
            return steps / elapsed


def two_robots_in_the_office(seed: int, cooperative: bool, n: int, steps: int) -> np.ndarray:
    """Errors ``(steps, 2)`` of two robots shuttling along the office corridor. Sightings from
    the world's relative observation (table 2 noises, 8 m); a message sent at step ``k`` arrives
    at ``k + 1`` when the robots are within 8 m (no loss)."""
    map_name = "office"
    world = build_map(map_name)
    laser, motion, relative = LaserParams.mr_ssga(), MotionNoise.mr_ssga(), RelativeNoise.mr_ssga()
    robots = []
    for r in range(2):
        setup = LocalizerSetup(
            robot_id=r,
            map_name=map_name,
            n_beams=laser.n_beams,
            max_range_m=laser.max_range_m,
            laser_noise_std_m=laser.noise_std_m,
            speed_std_mps=motion.speed_std_mps,
            turn_rate_std_rad_s=motion.turn_rate_std_rad_s,
            relative_distance_std_m=relative.distance_std_m,
            relative_orientation_std_rad=relative.orientation_std_rad,
            cooperative=cooperative,
        )
        robots.append(
            SSGALocalizer.from_config(
                setup, {"population_size": n}, np.random.default_rng([seed, r])
            )
        )
    rng = np.random.default_rng(seed)
    poses = np.array([[3.0, 6.0, 0.0], [5.0, 6.0, 0.0]])
    routes = [[(8.0, 6.0), (3.0, 6.0)], [(10.0, 6.0), (5.0, 6.0)]]
    leg = [0, 0]
    delta_s, delta_phi = np.zeros(2), np.zeros(2)
    inbox: list[tuple] = [(), ()]
    pair_i, pair_j = np.array([0, 1]), np.array([1, 0])
    errors = np.zeros((steps, 2))
    for k in range(steps):
        ranges = scan(world, poses, laser, rng)
        seen = relative_observation(poses, pair_i, pair_j, world, relative.range_m, relative, rng)
        sent = []
        for r in range(2):
            sightings = ()
            if seen.visible[r]:
                sightings = (
                    Sighting(
                        1 - r,
                        float(seen.distance_m[r]),
                        float(seen.bearing_rad[r]),
                        float(seen.relative_heading_rad[r]),
                    ),
                )
            robots[r].step(
                LaserObservation(
                    k, float(delta_s[r]), float(delta_phi[r]), ranges[r], sightings, inbox[r]
                )
            )
            errors[k, r] = math.hypot(*(robots[r].estimate()[:2] - poses[r, :2]))
            sent.append(robots[r].outgoing())
        in_range = math.hypot(*(poses[0, :2] - poses[1, :2])) <= relative.range_m
        inbox = [
            (RadioMessage(1 - r, sent[1 - r]),) if in_range and sent[1 - r] else ()
            for r in range(2)
        ]
        speed, turn = np.zeros(2), np.zeros(2)
        for r in range(2):
            target = np.array(routes[r][leg[r]])
            if np.hypot(*(target - poses[r, :2])) < 0.3:
                leg[r] = (leg[r] + 1) % len(routes[r])
                target = np.array(routes[r][leg[r]])
            heading_error = wrap_angle(math.atan2(*(target - poses[r, :2])[::-1]) - poses[r, 2])
            turn[r] = np.clip(heading_error, -0.8, 0.8)
            speed[r] = 0.2 if abs(heading_error) < 0.5 else 0.0
        moved = unicycle_step(poses, speed, turn, 1.0, motion, rng)
        poses, delta_s, delta_phi = (
            moved.poses_m,
            moved.odometry_delta_s_m,
            moved.odometry_delta_phi_rad,
        )
    return errors


def cooperation_check(n: int = 300, steps: int = 150, seeds: int = 20) -> None:
    print(f"Two MR-SSGA robots in the office, population {n}, {steps} steps, {seeds} seeds")
    for cooperative in (False, True):
        final = np.array(
            [
                np.median(two_robots_in_the_office(seed, cooperative, n, steps)[-10:], axis=0)
                for seed in range(seeds)
            ]
        )
        label = "cooperating (eq. 2)" if cooperative else "autonomous (eq. 1) "
        print(
            f"  {label}: localized (< 0.3 m) {np.mean(final < 0.3):4.0%}, "
            f"median final error per robot {np.round(np.median(final, axis=0), 3).tolist()} m"
        )


def main() -> int:
    if "--cooperation" in sys.argv[1:]:
        cooperation_check()
        return 0
    rng = np.random.default_rng(0)
    cases = {
        "autonomous (eq. 1)": observations(False, rng),
        "2 teammates (eq. 2)": observations(True, rng),
    }
    print(
        f"MR-SSGA and simple GA on map {MAP_NAME!r}, {LaserParams.mr_ssga().n_beams} beams, "
        "iterations per second per robot (CPU time, one core)"
    )
    for label, obs in cases.items():
        print(f"  {label}:")
        for n in POPULATIONS:
            ssga = iterations_per_s(SSGALocalizer, n, obs)
            ga = iterations_per_s(SimpleGALocalizer, n, obs)
            print(
                f"    population {n:3d}: MR-SSGA {ssga:7.0f} it/s ({1e3 / ssga:5.2f} ms)   "
                f"simple GA {ga:7.0f} it/s ({1e3 / ga:5.2f} ms)"
            )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
