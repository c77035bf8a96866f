"""The refinement option of the genetic localizers and the single-scan bound (issue 43)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.agents.laser.cfsga import CFSGAParams, FitnessSharingGA
from swarmloc.agents.laser.refine import compass_search
from swarmloc.agents.laser.ssga import SSGAParams
from swarmloc.deploy.lab.laser.runner import load_laser_scenario, run_laser
from swarmloc.world.laser.laser import single_scan_crb
from swarmloc.world.laser.maps import SegmentMap, build_map

PEAK = np.array([2.0, 3.0, 0.5])


def _peaked(poses):
    d = poses - PEAK
    return np.exp(-(d[:, 0] ** 2 + d[:, 1] ** 2) / 0.1 - d[:, 2] ** 2 / 0.05)


def test_compass_search_climbs_to_the_peak_and_never_down():
    start = np.array([[2.12, 2.93, 0.46], [1.95, 3.04, 0.55], [2.0, 3.0, 0.5]])
    poses, values = compass_search(_peaked, start, _peaked(start), 12, 0.05, 0.02)
    assert np.all(values >= _peaked(start))
    assert np.all(np.abs(poses[:2] - PEAK) < 0.01)
    np.testing.assert_array_equal(poses[2], PEAK)  # already at the peak: stays


def test_cfsga_refine_moves_its_fittest_individuals_uphill_only():
    params = CFSGAParams(population_size=20, refine_iterations=8, refine_individuals=2)
    rng = np.random.default_rng(0)
    population = PEAK + rng.normal(0.0, 0.1, size=(20, 3))
    ga = FitnessSharingGA(params, 1.0, lambda n, g: g.uniform(0, 5, size=(n, 3)), rng, population)
    ga.evaluate(_peaked)
    before = ga.raw_fitness.copy()
    top = np.argsort(-before)[:2]
    ga.refine(_peaked)
    assert np.all(ga.raw_fitness[top] > before[top])
    np.testing.assert_array_equal(np.delete(ga.raw_fitness, top), np.delete(before, top))
    np.testing.assert_allclose(ga.raw_fitness, _peaked(ga.population))  # fitness follows poses
    assert np.all(np.isfinite(ga.shared_fitness))


def test_refine_options_are_checked_and_off_by_default():
    assert CFSGAParams().refine_iterations == 0 and SSGAParams().refine_iterations == 0
    with pytest.raises(ValueError, match="refine_iterations"):
        SSGAParams(refine_iterations=-1)
    with pytest.raises(ValueError, match="refine_step_m"):
        CFSGAParams(refine_step_m=0.0)


@pytest.mark.parametrize("algorithm", ["ssga", "cfsga"])
def test_refined_genetic_localizers_run_and_differ_from_the_plain_ones(algorithm):
    base = ["world.steps=12", "world.seed=2", f'algorithm.name="{algorithm}"',
            "algorithm.population=60"]
    plain = run_laser(load_laser_scenario("laser-robust-office", base))
    refined = run_laser(load_laser_scenario(
        "laser-robust-office", [*base, "algorithm.params.refine_iterations=3"]))
    np.testing.assert_array_equal(plain.true_poses, refined.true_poses)  # same world
    assert not np.array_equal(plain.estimates, refined.estimates)


def _box():
    segments = [(0, 0, 4, 0), (4, 0, 4, 4), (4, 4, 0, 4), (0, 4, 0, 0)]
    return SegmentMap("box", np.array(segments, dtype=float))


def test_single_scan_bound_scales_with_the_noise_and_needs_enough_beams():
    world = _box()
    beams = np.arange(8) * (2 * math.pi / 8)
    pose = np.array([[1.6, 2.2, 0.3]])
    b1 = single_scan_crb(world, pose, beams, 8.0, 0.1)[0]
    b2 = single_scan_crb(world, pose, beams, 8.0, 0.2)[0]
    assert b2 == pytest.approx(2 * b1, rel=1e-6)
    assert 0.0 < b1 < 0.1  # 8 beams of 0.1 m each fix the position better than one
    # With two beams along x only, y and heading are not fixed: the bound is infinite.
    along_x = np.array([0.0, math.pi])
    assert math.isinf(single_scan_crb(world, np.array([[1.6, 2.2, 0.0]]), along_x, 8.0, 0.1)[0])


def test_single_scan_bound_is_unbounded_along_a_long_corridor():
    world = build_map("three_corridors")
    beams = np.arange(8) * (2 * math.pi / 8)
    middle = np.array([[12.0, 2.0, 0.0]])  # south corridor, its ends 9 m away, laser 6 m
    assert single_scan_crb(world, middle, beams, 6.0, 0.1)[0] >= 1.0
