"""The in-process runner of the laser robots: one :class:`LaserWorld` and one localizer per robot,
stepped in one process with no transport (seeds ``002_fe2ac635ba0eab3e.txt`` and
``003_5278cbbbf8cc61de.txt`` in ``/work/shared/seeds/``).

A **laser scenario** (TOML; shipped ones in ``deploy/scenarios/laser/``) has a name, a
description, a ``[world]`` table (:class:`~swarmloc.world.laser.world.LaserWorldConfig`: map,
robots, steps, sensors, radio, driver, paths, kidnaps), an ``[algorithm]`` table
(:class:`AlgorithmConfig`: which localizer, collaborative or not, its population, its own
parameters) and a ``[metrics]`` table (:class:`MetricsConfig`: the thresholds of the summary).
Unknown keys and impossible values are refused with a message naming them before anything runs.

Per step ``k`` (the lockstep of ARCHITECTURE.md): ``world.observe()`` -> each robot's
``localizer.step(obs)`` -> ``localizer.estimate()`` is compared with the true pose of that
observation -> ``localizer.outgoing()`` -> ``world.step(outgoing)``. Each robot's localizer gets
its own generator derived from (seed, robot id) (:func:`~swarmloc.agents.epuck.foraging.agent_rng`);
the world's is ``default_rng([seed, 0])``. So a run is a function of the scenario and its seed.

Errors, as the papers measure them: 003 §V "at each iteration of a given trial, a pose error was
computed (using the Euclidean metric) with respect to the best hypothesis": the position error
``|xy_est - xy_true|`` of every robot at every step, plus the heading error. The summary
(:func:`summarize`):

- ``final_error_m``: per robot, the mean position error over the last ``final_window_steps``;
  averaged over robots (``final_error_max_m``: the worst robot). Seed 002 §6 takes "minimum,
  maximum and average error" over "100 trials for each configuration" without saying over which
  steps; its fig. 9 shows the error falling once the robots have met, and every index of its
  table 3 is below 0.21 m, so they are errors after convergence. Our reading: each trial's
  team error after the last meeting, i.e. this per-trial final error (the table-3 scenario's
  window is the last 50 of 400 steps, after the third robot joins), and min / max / mean over
  trials of it (``deploy/lab/laser/report.py``, :func:`~swarmloc.deploy.lab.laser.report.table3_indexes`).
- ``settle_step``: the step from which every robot's error stays below ``settle_error_m``
  (0.15 m, 003 §V fig. 4) to the end, for at least the final window; empty if some robot never
  settles. Kidnapped robots count from their last kidnap.
- ``localized``: every robot's final error below ``localized_error_m`` (robustness, 003 §V).
- kidnap runs: ``settled_before_kidnap``, ``recovered`` (final error of the kidnapped robot below
  ``localized_error_m``) and ``recover_steps`` (steps from the kidnap to settling under
  ``settle_error_m``).
- ``first_contact_step``: the first step at which some robot sighted a teammate.
- ``final_error_sym_m``: as ``final_error_m``, but against the nearest of the true pose's images
  under the map's rotational symmetries (:func:`map_rotations`; the ``symmetric_rooms`` floor is
  invariant under a half turn, ``symmetric`` under quarter turns). No sensor can tell those
  images apart, so this separates "found the right room" from "found a room like it"; it is a
  diagnostic, never the papers' error.

Algorithms are chosen by name from :data:`ALGORITHMS` (a registry that rejects duplicates):
``ssga`` (MR-SSGA, 002), ``simple_ga`` (the simple GA of 002 table 3), ``cfsga`` (CFS-GA, 003),
``amcl`` (the modern, ROS-amcl-like particle filter with KLD sampling and recovery: the
collaborative PF of 002 table 3 with a fixed population, and the stronger baseline of 003),
``amcl-player`` (Player's ``amcl`` driver as 003 ran it, :mod:`swarmloc.agents.laser.amcl_player`). ``python -m swarmloc.deploy.lab.laser.runner SCENARIO`` runs one.
"""

from __future__ import annotations

import argparse
import dataclasses
import functools
import json
import math
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from swarmloc.agents.epuck.foraging import agent_rng
from swarmloc.agents.laser.localizer import Localizer, LocalizerSetup
from swarmloc.agents.laser.registry import (
    ALGORITHMS,
    AlgorithmEntry,
    AlgorithmRegistry,
    default_algorithms,
)
from swarmloc.config import (
    ConfigError,
    apply_overrides,
)
from swarmloc.world.laser.maps import MAPS, SegmentMap

# The scenario classes live with the family (world/laser/scenario.py); the runner's names stay
# for the modules and notebooks that import them from here.
from swarmloc.world.laser.scenario import AlgorithmConfig, LaserScenario
from swarmloc.world.laser.scoring import MetricsConfig, pose_errors, summarize
from swarmloc.world.laser.world import WORLD_STREAM, LaserWorld


def laser_scenario_names() -> list[str]:
    """The shipped laser scenarios (``deploy/scenarios/laser/*.toml``)."""
    from swarmloc.deploy.scenario import builtin_names

    return builtin_names("laser")


def load_laser_scenario(name_or_path: str | Path, overrides: list[str] = ()) -> LaserScenario:
    """Load and validate a laser scenario (a shipped name, or a .toml/.json path), with
    ``section.key=value`` overrides applied, through the one scenario loader
    (:func:`swarmloc.deploy.scenario.scenario_data`). Errors are ConfigError naming the key."""
    from swarmloc.deploy.scenario import scenario_data

    data = scenario_data(str(name_or_path))
    family = data.pop("family", "laser")
    if family != "laser":
        raise ConfigError(f"laser scenario '{name_or_path}': a {family} scenario, not a laser one")
    data = apply_overrides(data, list(overrides))
    try:
        return LaserScenario.from_dict(data)
    except ConfigError as exc:
        raise ConfigError(f"laser scenario '{name_or_path}': {exc}") from None


# -- one run ----------------------------------------------------------------------------------

#: A localizer factory ``(setup, params, rng) -> Localizer`` (what ``from_config`` is).
LocalizerFactory = Callable[[LocalizerSetup, dict, np.random.Generator], Localizer]


@dataclass
class LaserRunResult:
    """Per-step errors and poses of one run, and its summary (:func:`summarize`)."""

    position_error_m: np.ndarray  #: (T, N) |xy_est - xy_true| after step k
    heading_error_rad: np.ndarray  #: (T, N) |wrap(theta_est - theta_true)|
    true_poses: np.ndarray  #: (T, N, 3) the poses each step's observation was taken at
    estimates: np.ndarray  #: (T, N, 3)
    sightings: np.ndarray  #: (T,) how many (observer, teammate) sightings each step had
    summary: dict


def _canonical_segments(segments_m: np.ndarray) -> set:
    ends = np.round(segments_m.reshape(-1, 2, 2), 6) + 0.0  # + 0.0 turns -0.0 into 0.0
    flip = (ends[:, 0, 0] > ends[:, 1, 0]) | ((ends[:, 0, 0] == ends[:, 1, 0])
                                             & (ends[:, 0, 1] > ends[:, 1, 1]))
    ends[flip] = ends[flip][:, ::-1]
    return {tuple(row) for row in ends.reshape(-1, 4).tolist()}


def map_rotations(world_map: SegmentMap) -> tuple[float, ...]:
    """Angles (quarter, half, three-quarter turns) of the rotations about the centre of the map's
    bounds that carry its wall segments onto themselves: the map's rigid symmetries, which make
    poses indistinguishable to any sensor. Segments are compared to 1e-6 m."""
    x_min, y_min, x_max, y_max = world_map.bounds_m
    centre = np.array([(x_min + x_max) / 2.0, (y_min + y_max) / 2.0])
    base = _canonical_segments(world_map.segments_m)
    out = []
    for quarter in (1, 2, 3):
        angle = quarter * math.pi / 2.0
        c, s = round(math.cos(angle)), round(math.sin(angle))
        ends = world_map.segments_m.reshape(-1, 2) - centre
        turned = np.column_stack([c * ends[:, 0] - s * ends[:, 1], s * ends[:, 0] + c * ends[:, 1]])
        if _canonical_segments((turned + centre).reshape(-1, 4)) == base:
            out.append(angle)
    return tuple(out)


@functools.lru_cache(maxsize=16)
def _rotations_of(map_name: str) -> tuple[np.ndarray, tuple[float, ...]]:
    world_map = MAPS.build(map_name)
    x_min, y_min, x_max, y_max = world_map.bounds_m
    return np.array([(x_min + x_max) / 2.0, (y_min + y_max) / 2.0]), map_rotations(world_map)


def symmetric_position_error(estimates: np.ndarray, true_poses: np.ndarray,
                             map_name: str) -> np.ndarray:
    """``|xy_est - g(xy_true)|`` minimised over the map's rotations ``g`` (identity included):
    ``(...,)`` for poses ``(..., 3)``."""
    centre, angles = _rotations_of(map_name)
    est, true = estimates[..., :2], true_poses[..., :2]
    best = np.hypot(*(est - true).reshape(-1, 2).T).reshape(est.shape[:-1])
    for angle in angles:
        c, s = math.cos(angle), math.sin(angle)
        rel = true - centre
        image = np.stack([c * rel[..., 0] - s * rel[..., 1], s * rel[..., 0] + c * rel[..., 1]],
                         axis=-1) + centre
        best = np.minimum(best, np.hypot(est[..., 0] - image[..., 0], est[..., 1] - image[..., 1]))
    return best


def _check_estimate(value, robot: int) -> np.ndarray:
    estimate = np.asarray(value, dtype=np.float64)
    if estimate.shape != (3,) or not np.all(np.isfinite(estimate)):
        raise ValueError(f"robot {robot}: estimate() must return 3 finite numbers "
                         f"(x_m, y_m, theta_rad), got {value!r}")
    return estimate


def run_laser(
    scenario: LaserScenario,
    algorithm: str | LocalizerFactory | None = None,
    params: dict | None = None,
    seed: int | None = None,
    *,
    cooperative: bool | None = None,
) -> LaserRunResult:
    """Run one seeded replication of ``scenario`` to the end.

    ``algorithm``: a registered name (default: the scenario's) or a factory
    ``(setup, params, rng) -> Localizer``; ``params``: the localizer's parameters (default: the
    scenario's, with its population); ``seed``: the run seed (default: the scenario's);
    ``cooperative``: overrides the scenario's ``algorithm.cooperative``.
    """
    if not isinstance(scenario, LaserScenario):
        raise TypeError(f"scenario: expected a LaserScenario, got {type(scenario).__name__}")
    config = scenario.world
    if seed is not None:
        config = dataclasses.replace(config, seed=seed)
    algo = scenario.algorithm
    if algorithm is None or isinstance(algorithm, str):
        entry = ALGORITHMS.get(algorithm or algo.name)
        if params is None:
            params = (algo.resolved_params() if entry.name == algo.name
                      else entry.params(algo.population, {}))
        entry.check(params)
        factory: LocalizerFactory = entry.build
    elif callable(algorithm):
        factory, params = algorithm, dict(params or {})
    else:
        raise TypeError(f"algorithm: expected a name or a factory, got {algorithm!r}")
    coop = algo.cooperative if cooperative is None else bool(cooperative)

    world = LaserWorld(config, np.random.default_rng([config.seed, WORLD_STREAM]))
    n, steps = config.robots, config.steps
    localizers = [factory(world.localizer_setup(r, coop), dict(params), agent_rng(config.seed, r))
                  for r in range(n)]
    true_poses = np.empty((steps, n, 3))
    estimates = np.empty((steps, n, 3))
    sightings = np.zeros(steps, dtype=np.int64)
    while not world.done:
        k = world.step_index
        observations = world.observe()
        true_poses[k] = world.true_poses
        sightings[k] = sum(len(o.sightings) for o in observations)
        outgoing = []
        for r, (localizer, obs) in enumerate(zip(localizers, observations)):
            localizer.step(obs)
            estimates[k, r] = _check_estimate(localizer.estimate(), r)
            outgoing.append(localizer.outgoing())
        world.step(outgoing)
    position_error, heading_error = pose_errors(estimates, true_poses)
    kidnaps = [(k.robot, k.step) for k in config.kidnaps]
    summary = summarize(position_error, heading_error, kidnaps, scenario.metrics, sightings)
    window = min(scenario.metrics.final_window_steps, steps)
    sym_error = symmetric_position_error(estimates[-window:], true_poses[-window:], config.map)
    summary["final_error_sym_m"] = float(sym_error.mean(axis=0).mean())
    summary["bumps"] = int(world.bumps.sum())
    return LaserRunResult(position_error, heading_error, true_poses, estimates, sightings, summary)


def encode_series_mm(position_error_m: np.ndarray) -> str:
    """Per-step errors ``(T, N)`` as text for one CSV cell: robots separated by ``;``, steps by
    spaces, whole millimetres."""
    mm = np.rint(np.asarray(position_error_m) * 1000.0).astype(np.int64)
    return ";".join(" ".join(map(str, mm[:, r])) for r in range(mm.shape[1]))


def decode_series_mm(text: str) -> np.ndarray:
    """Inverse of :func:`encode_series_mm`: errors in metres ``(T, N)``."""
    try:
        robots = [np.array(part.split(), dtype=np.int64) for part in text.split(";")]
    except ValueError:
        raise ValueError(f"position_error_mm: not a series of integers: {text[:40]!r}") from None
    if not robots or len({r.shape[0] for r in robots}) != 1 or robots[0].shape[0] == 0:
        raise ValueError("position_error_mm: robots' series are empty or of different lengths")
    return np.stack(robots, axis=1) / 1000.0


# -- command line -----------------------------------------------------------------------------


def main(argv: list[str] | None = None) -> int:
    """``python -m swarmloc.deploy.lab.laser.runner SCENARIO``: one run, its summary as JSON."""
    parser = argparse.ArgumentParser(prog="python -m swarmloc.deploy.lab.laser.runner",
                                     description=main.__doc__)
    parser.add_argument("scenario", help=f"shipped ({', '.join(laser_scenario_names())}) "
                                         f"or a .toml file")
    parser.add_argument("--algorithm", default=None, help=f"one of {', '.join(ALGORITHMS.names())}")
    parser.add_argument("--seed", type=int, default=None)
    parser.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                        help="any scenario value, e.g. --set algorithm.population=50")
    args = parser.parse_args(argv)
    overrides = list(args.set)
    if args.algorithm:
        overrides.append(f"algorithm.name={json.dumps(args.algorithm)}")
    if args.seed is not None:
        overrides.append(f"world.seed={args.seed}")
    try:
        scenario = load_laser_scenario(args.scenario, overrides)
    except ConfigError as exc:
        print(f"error: {exc}", file=sys.stderr)
        return 2
    t0, c0 = time.perf_counter(), time.process_time()
    result = run_laser(scenario)
    print(json.dumps({"scenario": scenario.name, "algorithm": scenario.algorithm.name,
                      "seed": scenario.world.seed, **result.summary,
                      "cpu_s": round(time.process_time() - c0, 2),
                      "wall_s": round(time.perf_counter() - t0, 2)}))
    return 0


# ALGORITHMS, AlgorithmEntry, AlgorithmRegistry (agents/laser/registry.py) and MetricsConfig,
# pose_errors, summarize (world/laser/scoring.py) live beside the code that uses them, below
# deploy/ (issue 48: nothing in agents/ or world/ imports deploy/); re-exported here.
__all__ = [
    "ALGORITHMS",
    "AlgorithmConfig",
    "AlgorithmEntry",
    "AlgorithmRegistry",
    "LaserRunResult",
    "LaserScenario",
    "MetricsConfig",
    "decode_series_mm",
    "default_algorithms",
    "encode_series_mm",
    "laser_scenario_names",
    "load_laser_scenario",
    "map_rotations",
    "pose_errors",
    "run_laser",
    "summarize",
    "symmetric_position_error",
]

if __name__ == "__main__":
    raise SystemExit(main())
