"""Timing of the vectorised world models (world/epuck/arena.py, world/epuck/sensors.py, world/epuck/medium.py).

Prints milliseconds per call of ir_proximity, ground_sensors, deliver and resolve_collisions for
N = 100, 1000, 10000 e-pucks placed uniformly at random in a square arena at a density of about
one robot per 0.05 m^2 (collisions resolved first, as in a running world). One core, no Zenoh.

Usage: python benchmarks/bench_world_models.py
"""

from __future__ import annotations

import math

import numpy as np
from _timing import median_ms

from swarmloc.protocol.epuck import EpuckBody
from swarmloc.world.epuck.arena import Arena, Disc, area_at, resolve_collisions
from swarmloc.world.epuck.medium import RabMedium, deliver
from swarmloc.world.epuck.sensors import SensorParams, ground_sensors, ir_proximity

AREA_PER_ROBOT_M2 = 0.05
QUICK = {"min_time_s": 0.3, "min_calls": 5}  # measuring time per call


def main() -> None:
    body = EpuckBody()
    r_m = body.body_radius_m
    params = SensorParams()
    medium = RabMedium()
    print(
        f"{'N':>6} {'side_m':>7} {'ir_proximity':>13} {'ground':>8} {'deliver':>8} "
        f"{'collisions':>11} {'area_at':>8} {'total':>8}   (median ms per call)"
    )
    for n in (100, 1000, 10000):
        side_m = math.sqrt(n * AREA_PER_ROBOT_M2)
        arena = Arena(
            side_m,
            side_m,
            nest=Disc((0.3 * side_m, 0.5 * side_m), 0.1),
            prey=Disc((0.7 * side_m, 0.5 * side_m), 0.1),
        )
        rng = np.random.default_rng(1)
        pose = np.column_stack(
            [rng.uniform(0, side_m, n), rng.uniform(0, side_m, n), rng.uniform(-np.pi, np.pi, n)]
        )
        pose[:, :2] = resolve_collisions(pose[:, :2], r_m, arena, iterations=4)
        sending = np.ones(n, dtype=bool)
        xy = pose[:, :2].copy()
        t_ir = median_ms(lambda p=pose, a=arena, g=rng: ir_proximity(p, r_m, a, params, g), **QUICK)
        t_gr = median_ms(lambda p=pose, a=arena, g=rng: ground_sensors(p, a, params, g), **QUICK)
        t_rab = median_ms(lambda p=pose, s=sending, g=rng: deliver(p, s, medium, g), **QUICK)
        t_col = median_ms(lambda q=xy, a=arena: resolve_collisions(q, r_m, a), **QUICK)
        t_area = median_ms(lambda q=xy, a=arena: area_at(q, a), **QUICK)
        total = t_ir + t_gr + t_rab + t_col + t_area
        print(
            f"{n:>6} {side_m:>7.2f} {t_ir:>13.3f} {t_gr:>8.3f} {t_rab:>8.3f} {t_col:>11.3f} "
            f"{t_area:>8.3f} {total:>8.3f}"
        )


if __name__ == "__main__":
    main()
