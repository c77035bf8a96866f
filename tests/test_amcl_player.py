"""Player's AMCL (agents/laser/amcl_player.py, issue 43): the pieces read from Player's sources."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.agents.laser.amcl_player import (
    PlayerAMCLLocalizer,
    PlayerAMCLParams,
    resample_limit,
)
from swarmloc.agents.laser.localizer import LaserObservation, LocalizerSetup
from swarmloc.deploy.lab.laser.runner import ALGORITHMS, load_laser_scenario, run_laser
from swarmloc.world.laser.laser import cast_rays
from swarmloc.world.laser.maps import build_map


def _setup(n_beams=18, map_name="office"):
    return LocalizerSetup(robot_id=0, map_name=map_name, n_beams=n_beams, max_range_m=8.0,
                          laser_noise_std_m=0.1, speed_std_mps=0.05, turn_rate_std_rad_s=0.1,
                          relative_distance_std_m=0.2, relative_orientation_std_rad=0.1,
                          dt_s=0.5, cooperative=False)


def _player_limit(k, err=0.01, z=3.0, lo=1000, hi=10000):
    """pf_resample_limit, written out scalar by scalar as Player's C does it."""
    if k <= 1:
        return lo
    b = 2 / (9 * (k - 1))
    x = 1 - b + math.sqrt(b) * z
    n = math.ceil((k - 1) / (2 * err) * x * x * x)
    return min(max(n, lo), hi)


def test_resample_limit_is_players_formula_with_its_defaults():
    params = PlayerAMCLParams()
    assert (params.pop_err, params.pop_z) == (0.01, 3.0)
    ks = np.array([0, 1, 2, 5, 20, 60, 200, 2000])
    assert resample_limit(ks, params).tolist() == [_player_limit(int(k)) for k in ks]
    assert resample_limit(np.array([2]), PlayerAMCLParams(min_particles=1))[0] == \
        _player_limit(2, lo=1)


def test_uses_every_third_of_18_beams_and_all_of_8_as_players_step_does():
    rng = np.random.default_rng(0)
    assert PlayerAMCLLocalizer(_setup(18), PlayerAMCLParams(max_particles=2000), rng)\
        .used_beams.tolist() == [0, 3, 6, 9, 12, 15]
    assert PlayerAMCLLocalizer(_setup(8), PlayerAMCLParams(max_particles=2000), rng)\
        .used_beams.tolist() == list(range(8))


def test_beam_model_scores_the_true_pose_above_a_shifted_one():
    localizer = PlayerAMCLLocalizer(_setup(), PlayerAMCLParams(max_particles=1000),
                                    np.random.default_rng(1))
    true = np.array([[3.0, 6.0, 0.3]])
    ranges = cast_rays(build_map("office"), true, np.arange(18) * (2 * math.pi / 18), 8.0)[0]
    poses = np.array([[3.0, 6.0, 0.3], [3.3, 6.0, 0.3]])
    log_p = localizer.sensor_log_likelihood(poses, ranges)
    assert log_p[0] == pytest.approx(0.0, abs=1e-9)  # every pz = 1 at the exact pose
    # 0.3 m off along x: beams 0 and 9 (along the heading) change by about 0.3 m = 3 sigma.
    assert log_p[1] < 2 * math.log(0.1 + 0.9 * math.exp(-0.5 * 2.5**2))


def test_action_noise_follows_players_drift_model():
    localizer = PlayerAMCLLocalizer(_setup(), PlayerAMCLParams(min_particles=1000,
                                                               max_particles=10000),
                                    np.random.default_rng(2))
    localizer._particles = np.zeros((10000, 3))
    localizer.action_update(np.array([0.5, 0.0, 0.1]))
    moved = localizer.particles
    assert moved[:, 0].mean() == pytest.approx(0.5, abs=0.01)
    assert moved[:, 0].std() == pytest.approx(0.2 * 0.5, rel=0.05)
    assert moved[:, 2].std() == pytest.approx(0.2 * 0.5 + 0.2 * 0.1, rel=0.05)
    assert moved[:, 1].std() == pytest.approx(0.0, abs=1e-12)  # uy = 0.2 * dy = 0


def test_filter_updates_only_past_the_update_threshold():
    localizer = PlayerAMCLLocalizer(_setup(), PlayerAMCLParams(max_particles=2000),
                                    np.random.default_rng(3))
    ranges = np.full(18, 4.0)
    localizer.step(LaserObservation(0, 0.0, 0.0, ranges))
    assert localizer.updates == 1  # the first scan is always used
    before = localizer.estimate()
    localizer.step(LaserObservation(1, 0.15, 0.0, ranges))
    assert localizer.updates == 1  # 0.15 m < 0.2 m: no update, odometry composed
    after = localizer.estimate()
    assert math.hypot(*(after[:2] - before[:2])) == pytest.approx(0.15, abs=1e-9)
    localizer.step(LaserObservation(2, 0.1, 0.0, ranges))
    assert localizer.updates == 2


def test_population_shrinks_from_10000_and_injection_is_a_named_reading():
    scenario = load_laser_scenario("laser-robust-office", ['algorithm.name="amcl-player"',
                                                           "world.steps=6", "world.seed=3",
                                                           "algorithm.params.min_particles=1000",
                                                           "algorithm.params.max_particles=10000"])
    entry = ALGORITHMS.get("amcl-player")
    assert entry.population_text(scenario.algorithm.resolved_params()) == "1000-10000"
    assert not entry.communicates
    setup = _setup()
    fixed = PlayerAMCLLocalizer(setup, PlayerAMCLParams(injection="fixed", injected_samples=50),
                                np.random.default_rng(4))
    none = PlayerAMCLLocalizer(setup, PlayerAMCLParams(), np.random.default_rng(4))
    ranges = cast_rays(build_map("office"), np.array([[3.0, 6.0, 0.3]]),
                       np.arange(18) * (2 * math.pi / 18), 8.0)[0]
    for localizer in (fixed, none):
        assert localizer.n_particles == 10000  # uniform over free space at the start
        localizer.step(LaserObservation(0, 0.0, 0.0, ranges))
        assert 1000 <= localizer.n_particles <= 10000
    # A belief in one bin resamples to the smallest population plus one: Player stops once the
    # count *exceeds* pf_resample_limit (k = 1: min_particles).
    none._particles = np.tile([[3.1, 6.1, 0.05]], (5000, 1))
    assert none.resample(np.full(5000, 1 / 5000)).shape == (1001, 3)
    assert (fixed.last_injected, none.last_injected) == (50, 0)
    with pytest.raises(ValueError, match="injection"):
        PlayerAMCLParams(injection="adaptive")
    with pytest.raises(ValueError, match="did you mean 'injection'"):
        PlayerAMCLParams.from_dict({"injections": "none"})


def test_same_seed_same_run():
    scenario = load_laser_scenario("laser-robust-three-rooms", ['algorithm.name="amcl-player"',
                                                                "world.steps=40", "world.seed=5"])
    a, b = run_laser(scenario), run_laser(scenario)
    np.testing.assert_array_equal(a.estimates, b.estimates)
