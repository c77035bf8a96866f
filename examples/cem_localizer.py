"""A cross-entropy-method (CEM) localizer for the laser robots: a worked example of a plugin.

This file is the whole of a new cooperative-localization algorithm (``docs/extending.md`` walks
through it). It registers itself as ``cem``, so that once swarmloc imports it (``--plugin
examples/cem_localizer.py``, or an entry point of an installed package) it is chosen like the
built-in localizers: ``--algorithm cem``, ``algorithm.name = "cem"`` in a scenario, or a grid
value of an experiment spec.

The method (Rubinstein's cross-entropy method, applied to global localization): each step, the
robot's hypotheses are moved by the odometry and scored with the same fitness as MR-SSGA and
CFS-GA (seed 002 eq. 1; eq. 2 with the teammates' scans and sightings when cooperative, which is
what makes it a cooperative localizer); the ``elite_fraction`` fittest are kept, a Gaussian is
fitted to them (x and y, and the heading as a wrapped angle), and the rest of the population is
drawn from that Gaussian, widened by ``min_std_m``/``min_std_rad`` so it never collapses; a
``restart_fraction`` is drawn uniformly over the free space again, so that a robot that is wrong
(or kidnapped) can recover. Everything else, the motion update, the estimate (the fittest
hypothesis) and the radio payload, is the genetic localizers' (``GeneticLocalizer``).

Like every localizer it is a pure model: no Zenoh, no clock, and every random draw comes from the
generator it is built with. Draws per step, in order: ``rng.normal(size=(M, 3))`` for the
Gaussian's draws, then the restarts' ``free_space_sample``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmloc.agents.laser.registry import ALGORITHMS, AlgorithmEntry
from swarmloc.agents.laser.ssga import GeneticLocalizer, GeneticParams
from swarmloc.world.laser.laser import wrap_angle
from swarmloc.world.laser.maps import free_space_sample


@dataclass(frozen=True)
class CEMParams(GeneticParams):
    """The population, fitness and motion parameters of the genetic localizers, and CEM's own."""

    elite_fraction: float = 0.1
    restart_fraction: float = 0.05
    min_std_m: float = 0.03
    min_std_rad: float = 0.03

    def __post_init__(self) -> None:
        super().__post_init__()
        if not 0.0 < self.elite_fraction < 1.0:
            raise ValueError(f"elite_fraction: must be in (0, 1), got {self.elite_fraction!r}")
        if not 0.0 <= self.restart_fraction < 1.0 - self.elite_fraction:
            raise ValueError(f"restart_fraction: must be in [0, 1 - elite_fraction), got {self.restart_fraction!r}")
        for name in ("min_std_m", "min_std_rad"):
            if not getattr(self, name) > 0.0:
                raise ValueError(f"{name}: must be > 0, got {getattr(self, name)!r}")


class CEMLocalizer(GeneticLocalizer):
    """One robot's CEM localizer: ``CEMLocalizer.from_config(setup, {"elite_fraction": 0.2}, rng)``."""

    params_type = CEMParams

    def _reproduce(self, population_m: np.ndarray, fitness: np.ndarray, peak: float) -> np.ndarray:
        p: CEMParams = self.params
        n = population_m.shape[0]
        n_elite = max(2, round(p.elite_fraction * n))
        n_restart = round(p.restart_fraction * n)
        elite = population_m[np.argsort(-fitness, kind="stable")[:n_elite]]
        # The elites' Gaussian; the heading's mean and spread as a wrapped angle.
        mean_xy = elite[:, :2].mean(axis=0)
        mean_th = np.arctan2(np.sin(elite[:, 2]).mean(), np.cos(elite[:, 2]).mean())
        std_xy = np.maximum(elite[:, :2].std(axis=0), p.min_std_m)
        std_th = max(float(np.sqrt(np.mean(wrap_angle(elite[:, 2] - mean_th) ** 2))), p.min_std_rad)
        n_drawn = n - n_elite - n_restart
        noise = self.rng.normal(size=(n_drawn, 3))
        drawn = np.empty((n_drawn, 3))
        drawn[:, :2] = mean_xy + noise[:, :2] * std_xy
        drawn[:, 2] = wrap_angle(mean_th + noise[:, 2] * std_th)
        parts = [elite, drawn]
        if n_restart:
            parts.append(free_space_sample(self.world_map, n_restart, self.rng,
                                           clearance_m=p.init_clearance_m))
        return np.concatenate(parts, axis=0)


# The one registry entry: name, label in reports, the localizer, its parameters, and which of
# them `population` (a scenario's algorithm.population, a spec's grid value) sets.
ALGORITHMS.register(AlgorithmEntry("cem", "CEM", CEMLocalizer, CEMParams, ("population_size",)))
