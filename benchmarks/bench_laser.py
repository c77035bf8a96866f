"""Timing of the laser observation model (world/laser/laser.py ``cast_rays``, eq. 4 of seed 002).

Prints milliseconds per call of ``cast_rays`` on the office map (world/laser/maps.py) for the batch
sizes the laser agents need: CFS-GA evaluates 300 individuals x 18 beams per iteration (table I of
seed 003; >= 100 iterations/s per robot leaves 10 ms per iteration for everything), the particle
filter 5,000 particles x 18 or 36 beams per update (>= 20 updates/s leaves 50 ms). Poses are
drawn in free space with a fixed seed; the figure is the median over repetitions. One core: run it
with ``OMP_NUM_THREADS=1`` (set below before numpy loads) so that BLAS uses a single thread.

Usage: python benchmarks/bench_laser.py
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")


import numpy as np
from _timing import median_ms

from swarmloc.world.laser.laser import cast_rays
from swarmloc.world.laser.maps import free_space_sample, office_map

CASES = ((300, 18), (5000, 18), (5000, 36))
MAX_RANGE_M = 8.0


def main() -> int:
    world = office_map()
    rng = np.random.default_rng(0)
    print(
        f"cast_rays on map {world.name!r}: {world.n_segments} segments, "
        f"{world.width_m:g} x {world.height_m:g} m, max range {MAX_RANGE_M:g} m"
    )
    for n_poses, n_beams in CASES:
        poses = free_space_sample(world, n_poses, rng)
        beams = np.arange(n_beams) * (2.0 * np.pi / n_beams)
        ms = median_ms(lambda p=poses, b=beams: cast_rays(world, p, b, MAX_RANGE_M))
        rate = 1e3 / ms
        print(
            f"  {n_poses:5d} poses x {n_beams:2d} beams = {n_poses * n_beams:7d} rays: "
            f"{ms:7.2f} ms  ({rate:6.0f} calls/s, {ms * 1e6 / (n_poses * n_beams):5.1f} ns/ray)"
        )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
