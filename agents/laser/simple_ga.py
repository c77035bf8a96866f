"""The simple genetic algorithm that seed 002 compares MR-SSGA against (table 3).

Seed ``/work/shared/seeds/002_fe2ac635ba0eab3e.txt`` §2.1 describes the simple GA (SGA): random
initialisation over the whole search space, fitness-based selection of an intermediate population
"such as the roulette wheel", and reproduction where crossover takes two elements and makes a
convex combination of them with probability ``p_chi`` and mutation modifies an element,
"inversely proportional to its fitness", with probability ``p_mu``; "some individuals, likely
having high fitness, will be exactly copied in the new population (elitism)". The population is
panmictic: any individual may mate with any other (no network, the difference from MR-SSGA that
§2.1 stresses).

Everything else is MR-SSGA's (``swarmloc.agents.laser.ssga``): the fitness (eq. 1, and eq. 2 with the
teammates' scans and sightings), the kinematic update (eq. 3), the best-individual estimate, the
radio payload. ``p_chi``, ``p_mu`` and the number of elites are not given in 002; the defaults are
ordinary values (Goldberg's ``p_chi`` ~ 0.6-0.9).

Reproduction (:func:`simple_ga_reproduction`):

1. the ``elite_count`` fittest individuals are copied unchanged;
2. ``N - elite_count`` parents are selected, by roulette wheel (probability proportional to
   fitness; uniform if every fitness is 0) or by tournaments of ``tournament_size`` (the fittest
   of that many drawn uniformly with replacement);
3. consecutive parents pair up; with probability ``crossover_prob`` a pair is replaced by its two
   convex combinations ``w a + (1 - w) b`` and ``(1 - w) a + w b``, ``w ~ U(0, 1)``;
4. each of these individuals is mutated with probability ``mutation_prob``, with the standard
   deviation of :func:`~swarmloc.agents.laser.ssga.mutation_std` for its selected parent's fitness.

Draws per step (fixed order): selection (``rng.random(M)`` for the roulette,
``rng.integers(size=(M, k))`` for tournaments), ``rng.random(M // 2)`` crossover decisions,
``rng.random(M // 2)`` weights, ``rng.random(M)`` mutation decisions, ``rng.normal(size=(M, 3))``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmloc.agents.laser.ssga import (
    GeneticLocalizer,
    GeneticParams,
    _positive_int,
    _real,
    crossover,
    mutate,
    mutation_std,
)
from swarmloc.config import did_you_mean

SELECTIONS = ("roulette", "tournament")


@dataclass(frozen=True)
class SimpleGAParams(GeneticParams):
    """Simple GA parameters (see the module docstring); the shared ones are
    :class:`~swarmloc.agents.laser.ssga.GeneticParams`."""

    selection: str = "roulette"
    tournament_size: int = 2
    crossover_prob: float = 0.7
    mutation_prob: float = 0.5
    elite_count: int = 1

    def __post_init__(self) -> None:
        super().__post_init__()
        if self.selection not in SELECTIONS:
            hint = did_you_mean(str(self.selection), SELECTIONS, 0.6)
            raise ValueError(
                f"selection: unknown selection {self.selection!r}{hint} (known: {SELECTIONS})"
            )
        _positive_int(self.tournament_size, "tournament_size")
        _real(self.crossover_prob, "crossover_prob", hi=1.0)
        _real(self.mutation_prob, "mutation_prob", hi=1.0)
        elite = _positive_int(self.elite_count, "elite_count", minimum=0)
        if elite >= self.population_size:
            raise ValueError(
                f"elite_count: must be < population_size ({self.population_size}), got {elite}"
            )


def roulette_selection(fitness: np.ndarray, count: int, rng: np.random.Generator) -> np.ndarray:
    """``count`` indices drawn with probability proportional to ``fitness`` (>= 0); uniform when
    the total is 0. One ``rng.random(count)`` draw."""
    cumulative = np.cumsum(np.maximum(fitness, 0.0))
    draws = rng.random(count)
    total = cumulative[-1]
    if not total > 0.0:
        return np.minimum((draws * fitness.size).astype(np.int64), fitness.size - 1)
    picks = np.searchsorted(cumulative, draws * total, side="right")
    return np.minimum(picks, fitness.size - 1)


def tournament_selection(
    fitness: np.ndarray, count: int, size: int, rng: np.random.Generator
) -> np.ndarray:
    """``count`` winners of tournaments among ``size`` individuals drawn uniformly with
    replacement. One ``rng.integers`` draw of shape ``(count, size)``."""
    entrants = rng.integers(0, fitness.size, size=(count, size))
    winner = np.argmax(fitness[entrants], axis=1)
    return entrants[np.arange(count), winner]


def simple_ga_reproduction(
    population_m: np.ndarray,
    fitness: np.ndarray,
    fitness_peak: float,
    params: SimpleGAParams,
    rng: np.random.Generator,
) -> np.ndarray:
    """One generation of the simple GA (module docstring, steps 1-4): ``(N, 3)`` -> ``(N, 3)``;
    the first ``elite_count`` rows of the result are the elites, fittest first."""
    population = np.asarray(population_m, dtype=np.float64)
    fitness = np.asarray(fitness, dtype=np.float64)
    n = population.shape[0]
    elite = np.argsort(-fitness, kind="stable")[: params.elite_count]
    count = n - elite.size
    if params.selection == "roulette":
        parents = roulette_selection(fitness, count, rng)
    else:
        parents = tournament_selection(fitness, count, params.tournament_size, rng)
    offspring = population[parents].copy()

    n_pairs = count // 2
    first, second = np.arange(0, 2 * n_pairs, 2), np.arange(1, 2 * n_pairs, 2)
    do_cross = rng.random(n_pairs) < params.crossover_prob
    weights = rng.random(n_pairs)
    a, b = offspring[first[do_cross]], offspring[second[do_cross]]
    w = weights[do_cross]
    offspring[first[do_cross]] = crossover(a, b, w)
    offspring[second[do_cross]] = crossover(a, b, 1.0 - w)

    do_mutate = rng.random(count) < params.mutation_prob
    std_m, std_rad = mutation_std(fitness[parents] / fitness_peak, params)
    mutated = mutate(offspring, std_m, std_rad, rng)
    offspring[do_mutate] = mutated[do_mutate]
    return np.concatenate([population[elite], offspring], axis=0)


class SimpleGALocalizer(GeneticLocalizer):
    """The simple GA baseline of 002 table 3: panmictic population, same fitness as MR-SSGA.

    ``SimpleGALocalizer(setup, SimpleGAParams(...), rng)`` or
    ``SimpleGALocalizer.from_config(setup, {"selection": "tournament"}, rng)``.
    """

    params_type = SimpleGAParams

    def _reproduce(self, population_m: np.ndarray, fitness: np.ndarray, peak: float):
        return simple_ga_reproduction(population_m, fitness, peak, self.params, self.rng)
