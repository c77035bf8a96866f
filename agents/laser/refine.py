"""Local refinement of the genetic localizers' best individuals: a compass (pattern) search on the
scan match (issue 43).

Neither seed has it. Seed 002's MR-SSGA (``002_fe2ac635ba0eab3e.txt``) and seed 003's CFS-GA
(``003_5278cbbbf8cc61de.txt``) take the best individual as the estimate, so their accuracy is
bounded by how finely the population samples the fitness peak (the population's resolution) on
top of what one scan can tell (the single-scan Cramér-Rao bound,
:func:`swarmloc.world.laser.laser.single_scan_crb`). This option, off by default because the
papers' text has no such step, climbs the fitness of a few of the best individuals a few steps
uphill and puts them back into the population (Lamarckian: the refined individual replaces its
original, with its new fitness).

Compass search (Kolda, Lewis, Torczon 2003): each iteration scores the six neighbours
``pose +- step_m`` along x and y and ``+- step_rad`` in heading of every refined individual in one
batched call; an individual moves to its best neighbour if that scores higher, else its steps
halve. No random draw: the option changes a run only through the individuals it moves.
"""

from __future__ import annotations

from collections.abc import Callable

import numpy as np

from swarmloc.world.laser.laser import wrap_angle

#: ``score(poses (N, 3)) -> (N,)``, higher is better.
Score = Callable[[np.ndarray], np.ndarray]


def compass_search(
    score: Score,
    poses_m: np.ndarray,
    scores: np.ndarray,
    iterations: int,
    step_m: float,
    step_rad: float,
) -> tuple[np.ndarray, np.ndarray]:
    """``iterations`` compass-search iterations from each of ``poses_m`` ``(k, 3)`` whose current
    ``scores`` ``(k,)`` are known. Returns the refined poses and their scores (never lower)."""
    poses = np.array(poses_m, dtype=np.float64).reshape(-1, 3)
    best = np.array(scores, dtype=np.float64).reshape(-1)
    k = poses.shape[0]
    steps = np.tile([step_m, step_m, step_rad], (k, 1))
    directions = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]],
                          dtype=np.float64)
    for _ in range(iterations):
        candidates = poses[:, None, :] + directions[None, :, :] * steps[:, None, :]  # (k, 6, 3)
        candidates[..., 2] = wrap_angle(candidates[..., 2])
        values = np.asarray(score(candidates.reshape(-1, 3)), dtype=np.float64).reshape(k, 6)
        pick = np.argmax(values, axis=1)
        gain = values[np.arange(k), pick] > best
        poses[gain] = candidates[np.flatnonzero(gain), pick[gain]]
        best[gain] = values[np.flatnonzero(gain), pick[gain]]
        steps[~gain] *= 0.5
    return poses, best


def check_refine_options(iterations, individuals, step_m, step_rad) -> None:
    """ValueError naming the option that is not usable."""
    for name, value in (("refine_iterations", iterations), ("refine_individuals", individuals)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < 0:
            raise ValueError(f"{name}: must be an integer >= 0, got {value!r}")
    for name, value in (("refine_step_m", step_m), ("refine_step_rad", step_rad)):
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
            raise ValueError(f"{name}: must be a number > 0, got {value!r}")


__all__ = ["Score", "check_refine_options", "compass_search"]
