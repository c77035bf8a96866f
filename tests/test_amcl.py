"""Tests of the AMCL-style particle filter (agents/laser/amcl.py; baseline of seeds 002 and 003).

Expected values come from closed forms computed here independently (scipy's chi-square and normal
quantiles, hand geometry on a box map, the Augmented_MCL averages by hand), statistics have stated
tolerances, and the closed-loop runs (global localization, kidnap) use fixed seeds and "most
seeds" thresholds, not values read off the code under test.
"""

from __future__ import annotations

import math

import msgpack
import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st
from scipy.stats import chi2, norm, vonmises

from swarmloc.agents.laser.amcl import AMCLLocalizer, AMCLParams, AugmentedMCL, build_distance_field
from swarmloc.agents.laser.amcl_belief import (
    MAX_SHARED_SAMPLES,
    BeliefSummary,
    decode_belief,
    encode_belief,
    poses_from_teammate,
    teammate_log_factor,
)
from swarmloc.agents.laser.amcl_sampling import (
    best_cluster_estimate,
    cluster_labels,
    kld_sample_count,
    kld_sample_size,
    low_variance_resample,
    recovery_probability,
)
from swarmloc.agents.laser.localizer import (
    MAX_RADIO_PAYLOAD_BYTES,
    LaserObservation,
    Localizer,
    LocalizerSetup,
    RadioMessage,
    Sighting,
)
from swarmloc.world.laser.laser import (
    LaserParams,
    MotionNoise,
    cast_rays,
    scan,
    unicycle_model,
    unicycle_step,
)
from swarmloc.world.laser.maps import SegmentMap, build_map, free_space_sample


def box_map(width_m: float = 4.0, height_m: float = 2.0) -> SegmentMap:
    w, h = width_m, height_m
    return SegmentMap(
        "test-box", np.array([[0, 0, w, 0], [w, 0, w, h], [w, h, 0, h], [0, h, 0, 0]])
    )


def make_setup(map_name: str = "office", cooperative: bool = False, robot_id: int = 0, **kw):
    laser, motion = LaserParams.cfs_ga(), MotionNoise.cfs_ga()
    values = {
        "robot_id": robot_id,
        "map_name": map_name,
        "n_beams": laser.n_beams,
        "max_range_m": laser.max_range_m,
        "laser_noise_std_m": laser.noise_std_m,
        "speed_std_mps": motion.speed_std_mps,
        "turn_rate_std_rad_s": motion.turn_rate_std_rad_s,
        "relative_distance_std_m": 0.2,
        "relative_orientation_std_rad": 0.1,
        "cooperative": cooperative,
    }
    values.update(kw)
    return LocalizerSetup(**values)


def wh_count(k: int, epsilon: float, delta: float) -> int:
    """Fox 2003's sample count, written out here from the paper with scipy's normal quantile."""
    z = norm.ppf(1.0 - delta)
    dof = k - 1
    return math.ceil(dof / (2 * epsilon) * (1 - 2 / (9 * dof) + math.sqrt(2 / (9 * dof)) * z) ** 3)


# --------------------------------------------------------------------------------------------
# KLD sample counts
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize("k", [2, 3, 5, 10, 20, 50, 200, 1000])
@pytest.mark.parametrize("epsilon,delta", [(0.05, 0.01), (0.01, 0.01), (0.1, 0.05)])
def test_kld_count_is_the_wilson_hilferty_chi_square_quantile(k, epsilon, delta):
    z = norm.ppf(1.0 - delta)
    count = int(kld_sample_count(k, epsilon, z))
    assert count == wh_count(k, epsilon, delta)
    exact = chi2.ppf(1.0 - delta, k - 1) / (2 * epsilon)  # what Wilson-Hilferty approximates
    assert abs(count - exact) <= 0.01 * exact + 1


def test_kld_count_vectorised_and_single_bin():
    params = AMCLParams()
    counts = kld_sample_count(np.array([0, 1, 2, 30]), params.kld_epsilon, params.kld_z)
    assert counts.tolist() == [0, 0, wh_count(2, 0.05, 0.01), wh_count(30, 0.05, 0.01)]
    assert params.kld_z == pytest.approx(norm.ppf(0.99), rel=1e-9)


def test_kld_size_is_clamped_to_min_and_max():
    params = AMCLParams(min_particles=150, max_particles=900)
    # k = 1 needs no sample (below min); k = 5 needs 133 < 150; k = 60 needs ~ 880; k = 100 > 900.
    sizes = kld_sample_size(np.array([1, 5, 60, 100, 10_000]), params)
    assert sizes.tolist() == [150, 150, wh_count(60, 0.05, 0.01), 900, 900]
    assert 150 < wh_count(60, 0.05, 0.01) < 900


def uniform_sampler(lo=(0.0, 0.0), hi=(10.0, 10.0)):
    def sample(n, rng):
        xy = rng.uniform(lo, hi, size=(n, 2))
        return np.column_stack([xy, rng.uniform(-math.pi, math.pi, size=n)])

    return sample


def test_kld_particle_count_from_the_filter():
    params = AMCLParams(min_particles=50, max_particles=3000)
    rng = np.random.default_rng(1)
    # All particles in one bin: the minimum.
    same = np.tile([[1.2, 1.2, 0.1]], (500, 1))
    core = AugmentedMCL(params, rng, uniform_sampler(), (0.0, 0.0), initial_particles=same)
    assert core.kld_particle_count() == 50
    # Exactly 20 equally weighted bins (centres of 0.5 m cells, same heading bin): all 20 are hit
    # within the first 362 draws except with probability < 20 (19/20)^362 ~ 2e-7, so the count is
    # n_chi(20) itself.
    centres = np.array([[0.25 + 0.5 * i, 0.25, 0.05] for i in range(20)])
    core.reset(np.repeat(centres, 10, axis=0))
    assert core.kld_particle_count() == wh_count(20, 0.05, 0.01)
    # Spread over far more bins than the maximum can fill: the maximum.
    core.reset(uniform_sampler((0, 0), (100, 100))(5000, rng))
    assert core.kld_particle_count() == 3000


# --------------------------------------------------------------------------------------------
# Low-variance resampling
# --------------------------------------------------------------------------------------------


def test_low_variance_resampling_counts_are_floor_or_ceil_of_n_w():
    rng = np.random.default_rng(2)
    for _ in range(50):
        weights = rng.dirichlet(np.full(30, 0.5))
        n = int(rng.integers(1, 500))
        counts = np.bincount(low_variance_resample(weights, n, rng), minlength=30)
        assert counts.sum() == n
        assert np.all(counts >= np.floor(n * weights) - 1e-9)
        assert np.all(counts <= np.ceil(n * weights) + 1e-9)


def test_low_variance_resampling_is_unbiased():
    # Each count is floor(n w) + Bernoulli(frac(n w)); over T trials the mean count has standard
    # error <= 0.5 / sqrt(T) = 0.011; 6 standard errors is 0.07.
    rng = np.random.default_rng(3)
    weights = np.array([0.013, 0.2, 0.0, 0.337, 0.05, 0.4])
    n, trials = 37, 2000
    total = np.zeros(weights.size)
    for _ in range(trials):
        total += np.bincount(low_variance_resample(weights, n, rng), minlength=weights.size)
    assert np.allclose(total / trials, n * weights, atol=0.07)
    assert total[2] == 0  # a zero weight is never drawn


def test_low_variance_resampling_rejects_bad_weights():
    rng = np.random.default_rng(0)
    for weights in ([], [0.0, 0.0], [1.0, np.nan], [1.0, -0.1]):
        with pytest.raises(ValueError):
            low_variance_resample(np.array(weights), 5, rng)


# --------------------------------------------------------------------------------------------
# Likelihood field
# --------------------------------------------------------------------------------------------


def test_distance_field_against_hand_geometry():
    world = box_map(4.0, 2.0)
    res, cap = 0.05, 2.0
    field = build_distance_field(world, res, cap)
    # Cell centres: the stored value is the exact distance there.
    xs, ys = field.cell_centres_m()
    i, j = np.searchsorted(xs, 1.0 + res / 2), np.searchsorted(ys, 0.5 + res / 2)
    x, y = xs[i], ys[j]  # a cell centre near (1, 0.5), inside the box
    assert field.distances_m[i, j] == pytest.approx(min(x, 4 - x, y, 2 - y), abs=1e-6)
    # Arbitrary points: within res / sqrt(2) of the true distance (1-Lipschitz, nearest cell).
    points = np.array([[1.0, 0.5], [3.7, 1.0], [2.0, 1.0], [-0.5, 1.0], [4.3, 2.4], [-5.0, 1.0]])
    # inside: nearest walls y = 0, x = 4, y = 0 or 2; outside: x = 0, corner (4, 2); far: capped.
    truth = np.array([0.5, 0.3, 1.0, 0.5, math.hypot(0.3, 0.4), cap])
    assert np.allclose(field.lookup(points), truth, atol=res / math.sqrt(2) + 1e-6)
    assert field.lookup(np.array([[-5.0, 1.0], [100.0, -100.0]])).tolist() == [cap, cap]


def test_laser_likelihood_against_hand_geometry():
    world = box_map(4.0, 2.0)
    setup = make_setup("test-box", n_beams=4, max_range_m=8.0)
    params = AMCLParams(min_particles=10, max_particles=10, sigma_hit_m=0.2)
    loc = AMCLLocalizer(setup, params, np.random.default_rng(0), world_map=world)
    tol = params.field_resolution_m / math.sqrt(2)  # nearest-cell lookup error bound

    def beam_score(d):
        return math.log(0.95 * norm.pdf(d, scale=0.2) + 0.05 / 8.0)

    def bounds(distances):  # the sum of beam scores for true distances within +-tol
        lo = sum(min(beam_score(max(d - tol, 0.0)), beam_score(d + tol)) for d in distances)
        hi = sum(beam_score(max(d - tol, 0.0)) for d in distances)
        return lo - 1e-6, hi + 1e-6

    # At (1.5, 0.7, 0) the 4 beams (0, 90, 180, 270 deg) hit walls at 2.5, 1.3, 1.5, 0.7 m.
    ranges = np.array([2.5, 1.3, 1.5, 0.7])
    poses = np.array([[1.5, 0.7, 0.0], [1.8, 0.7, 0.0], [1.5, 0.7, math.pi]])
    logl = loc.likelihood_field.log_likelihood(poses, ranges)
    # True pose: every end point on a wall (d = 0).
    # Shifted 0.3 m along x: beams 0 and 180 end 0.3 m from the side walls, 90 and 270 on walls.
    # Turned around: end points (-1, 0.7), (1.5, -0.6), (3, 0.7), (1.5, 1.4): d = 1, 0.6, 0.7, 0.6.
    for value, distances in zip(logl, ([0, 0, 0, 0], [0.3, 0, 0.3, 0], [1.0, 0.6, 0.7, 0.6])):
        lo, hi = bounds(distances)
        assert lo <= value <= hi
    assert logl[0] > logl[1] > logl[2]
    # A maximum-range reading carries no hit and is skipped.
    only_max = loc.likelihood_field.log_likelihood(poses, np.array([8.0, 8.0, 8.0, 8.0]))
    assert only_max.tolist() == [0.0, 0.0, 0.0]


# --------------------------------------------------------------------------------------------
# Recovery: slow and fast averages
# --------------------------------------------------------------------------------------------


def test_injection_rate_rises_when_w_fast_drops_below_w_slow():
    params = AMCLParams(min_particles=4000, max_particles=4000, alpha_slow=0.01, alpha_fast=0.2)
    rng = np.random.default_rng(5)
    core = AugmentedMCL(params, rng, uniform_sampler(), (0.01, 0.01))
    for _ in range(30):  # w_avg = 1: both averages settle at 1, nothing injected
        core.update(0.0, 0.0, lambda p: np.zeros(p.shape[0]))
        assert core.last_injected == 0
    assert core.injection_probability == 0.0
    # The likelihood drops to exp(-2): by hand, after n such steps
    # w = (1 - a)^n + (1 - (1 - a)^n) exp(-2) for each average.
    low = math.exp(-2.0)
    previous = 0.0
    for n in range(1, 9):
        core.predict(0.0, 0.0)
        core.correct(lambda p: np.full(p.shape[0], -2.0))
        w_slow = 0.99**n + (1 - 0.99**n) * low
        w_fast = 0.8**n + (1 - 0.8**n) * low
        expected = 1.0 - w_fast / w_slow
        assert core.injection_probability == pytest.approx(expected, rel=1e-9)
        assert expected > previous
        previous = expected
        injected = core.resample()
        sd = math.sqrt(4000 * expected * (1 - expected))
        assert abs(injected - 4000 * expected) <= 5 * sd + 1
    assert previous > 0.5


def test_recovery_probability_and_switch():
    assert recovery_probability(None, None) == 0.0
    assert recovery_probability(math.log(2.0), math.log(3.0)) == 0.0  # w_fast > w_slow
    assert recovery_probability(math.log(4.0), math.log(1.0)) == pytest.approx(0.75)
    params = AMCLParams(min_particles=100, max_particles=100, recovery=False)
    core = AugmentedMCL(params, np.random.default_rng(0), uniform_sampler(), (0.0, 0.0))
    core.correct(lambda p: np.zeros(p.shape[0]))
    for _ in range(10):
        core.correct(lambda p: np.full(p.shape[0], -5.0))
    assert core.injection_probability == 0.0 and core.resample() == 0


# --------------------------------------------------------------------------------------------
# Estimate
# --------------------------------------------------------------------------------------------


def test_estimate_is_the_heaviest_cluster_with_circular_mean():
    # Cluster A around (2, 2) with headings on both sides of +-pi; cluster B far away, lighter.
    a = np.array(
        [[2.0, 2.0, math.pi - 0.05], [2.1, 2.0, -math.pi + 0.05], [2.0, 2.1, math.pi - 0.1]]
    )
    b = np.array([[8.0, 8.0, 0.0], [8.1, 8.0, 0.0]])
    particles = np.vstack([a, b])
    weights = np.array([0.2, 0.2, 0.2, 0.2, 0.2])
    labels = cluster_labels(particles, 0.5, math.radians(10))
    assert labels[0] == labels[1] == labels[2] != labels[3] == labels[4]
    mean, share = best_cluster_estimate(particles, weights, labels)
    assert mean[0] == pytest.approx(6.1 / 3) and mean[1] == pytest.approx(6.1 / 3)
    # Headings pi - 0.05, pi + 0.05, pi - 0.1 average to pi - 1/30 (small angles: circular mean
    # is the arithmetic one up to O(0.1^3)).
    assert abs(math.remainder(mean[2] - (math.pi - 0.1 / 3), 2 * math.pi)) < 1e-3
    assert share == pytest.approx(0.6)
    heavier_b = np.array([0.1, 0.1, 0.1, 0.35, 0.35])
    mean_b, _ = best_cluster_estimate(particles, heavier_b, labels)
    assert mean_b == pytest.approx([8.05, 8.0, 0.0])


# --------------------------------------------------------------------------------------------
# Config
# --------------------------------------------------------------------------------------------


@pytest.mark.parametrize(
    "config,field",
    [
        ({"min_particles": 600, "max_particles": 500}, "min_particles"),
        ({"alpha_slow": 0.0}, "alpha_slow"),
        ({"alpha_fast": 1.0}, "alpha_fast"),
        ({"alpha_slow": 0.2, "alpha_fast": 0.1}, "alpha_slow"),
        ({"kld_epsilon": 0.0}, "kld_epsilon"),
        ({"kld_delta": 1.5}, "kld_delta"),
        ({"z_hit": 0.9, "z_rand": 0.2}, "z_hit"),
        ({"sigma_hit_m": -1.0}, "sigma_hit_m"),
        ({"min_particles": 0}, "min_particles"),
        ({"share_samples": MAX_SHARED_SAMPLES + 1}, "share_samples"),
        ({"likelihood_exponent": 2.0}, "likelihood_exponent"),
        ({"bin_size_m": math.nan}, "bin_size_m"),
    ],
)
def test_from_config_rejects_impossible_values(config, field):
    with pytest.raises(ValueError, match=field):
        AMCLLocalizer.from_config(make_setup(), config, np.random.default_rng(0))


def test_from_config_rejects_unknown_keys_and_wrong_types():
    with pytest.raises(ValueError, match="did you mean 'max_particles'"):
        AMCLParams.from_dict({"max_particle": 10})
    with pytest.raises(TypeError, match="min_particles"):
        AMCLParams.from_dict({"min_particles": 10.5})
    with pytest.raises(TypeError, match="recovery"):
        AMCLParams.from_dict({"recovery": "yes"})
    with pytest.raises(TypeError, match="alpha_fast"):
        AMCLParams.from_dict({"alpha_fast": "0.1"})
    params = AMCLParams.from_dict({"min_particles": 20, "max_particles": 30, "alpha_fast": 0.2})
    assert (params.min_particles, params.max_particles, params.alpha_fast) == (20, 30, 0.2)
    assert AMCLParams.seed_003().max_particles == 10000
    assert AMCLParams.fixed(50).min_particles == AMCLParams.fixed(50).max_particles == 50


# --------------------------------------------------------------------------------------------
# Belief payloads
# --------------------------------------------------------------------------------------------


def sample_summary(k: int = 5) -> BeliefSummary:
    rng = np.random.default_rng(7)
    return BeliefSummary(
        robot_id=3,
        step=41,
        poses_m=np.column_stack([rng.uniform(0, 10, (k, 2)), rng.uniform(-3, 3, k)]),
        weights=rng.uniform(0.1, 1.0, k),
        kernel_std_m=0.25,
        kernel_std_rad=0.15,
        odometry_delta_s_m=0.3,
        odometry_delta_phi_rad=-0.1,
    )


def test_payload_round_trip():
    summary = sample_summary()
    back = decode_belief(encode_belief(summary))
    assert (back.robot_id, back.step) == (3, 41)
    # Samples travel as float32: relative error <= 2^-24.
    assert np.allclose(back.poses_m, summary.poses_m, rtol=2**-23, atol=0)
    assert np.allclose(back.weights, summary.weights, rtol=2**-23, atol=0)
    assert (back.kernel_std_m, back.kernel_std_rad) == (0.25, 0.15)
    assert (back.odometry_delta_s_m, back.odometry_delta_phi_rad) == (0.3, -0.1)
    big = BeliefSummary(
        0, 0, np.zeros((MAX_SHARED_SAMPLES, 3)), np.ones(MAX_SHARED_SAMPLES), 1.0, 1.0
    )
    assert len(encode_belief(big)) <= MAX_RADIO_PAYLOAD_BYTES


def _wire(**changes):
    wire = msgpack.unpackb(encode_belief(sample_summary()), raw=False)
    for key, value in changes.items():
        if value is KeyError:
            del wire[key]
        else:
            wire[key] = value
    return msgpack.packb(wire, use_bin_type=True)


@pytest.mark.parametrize(
    "payload,field",
    [
        (b"", "msgpack"),
        (b"\xc1", "msgpack"),
        (msgpack.packb([1, 2, 3]), "map"),
        (_wire(kind="other"), "kind"),
        (_wire(v=2), "v"),
        (_wire(poses=KeyError), "missing"),
        (_wire(extra=1), "unknown"),
        (_wire(id="3"), "id"),
        (_wire(step=1.5), "step"),
        (_wire(poses=b"\x00" * 13), "poses"),
        (_wire(poses=[1, 2, 3]), "poses"),
        (_wire(weights=np.ones(4, "<f4").tobytes()), "weights"),
        (_wire(weights=np.array([1, -1, 1, 1, 1], "<f4").tobytes()), "weights"),
        (_wire(weights=np.zeros(5, "<f4").tobytes()), "weights"),
        (_wire(poses=np.full(15, np.nan, "<f4").tobytes()), "poses"),
        (_wire(poses=b"", weights=b""), "poses"),
        (_wire(kernel=[0.0, 0.1]), "kernel_std_m"),
        (_wire(kernel=[0.1]), "kernel"),
        (_wire(odom=[math.inf, 0.0]), "odometry_delta_s_m"),
        (b"\x00" * (MAX_RADIO_PAYLOAD_BYTES + 1), "exceeds"),
    ],
)
def test_payload_rejects_malformed_input(payload, field):
    with pytest.raises(ValueError, match=field):
        decode_belief(payload)


@settings(max_examples=300, deadline=None)
@given(st.binary(max_size=256))
def test_arbitrary_bytes_decode_or_raise_value_error(data):
    try:
        decode_belief(data)
    except ValueError:
        pass


# --------------------------------------------------------------------------------------------
# Closed loop: a simulated robot in a map
# --------------------------------------------------------------------------------------------


def drive_command(world, pose, rng):
    """Wander: straight at 0.3 m/s, turn in place away from walls closer than 0.8 m ahead."""
    front = cast_rays(world, pose[None], np.array([-0.4, 0.0, 0.4]), 8.0)[0]
    if front.min() < 0.8:
        return 0.0, (0.8 if front[0] < front[2] else -0.8)
    return 0.3, float(rng.normal(0.0, 0.1))


def run_robot(loc, world, seed, steps, start=None, kidnap_at=None):
    """Drive one robot for ``steps``; return the position errors of ``loc`` per step."""
    rng = np.random.default_rng([seed, 99])
    laser, motion = LaserParams.cfs_ga(), MotionNoise.cfs_ga()
    pose = free_space_sample(world, 1, rng, clearance_m=0.5)[0] if start is None else start
    errors = []
    for k in range(steps):
        if k == kidnap_at:
            pose = free_space_sample(world, 1, rng, clearance_m=0.5)[0]
        v, w = drive_command(world, pose, rng)
        moved = unicycle_step(pose[None], v, w, 1.0, motion, rng)
        pose = moved.poses_m[0]
        ranges = scan(world, pose[None], laser, rng)[0]
        loc.step(
            LaserObservation(
                k,
                float(moved.odometry_delta_s_m[0]),
                float(moved.odometry_delta_phi_rad[0]),
                ranges,
            )
        )
        errors.append(math.hypot(*(loc.estimate()[:2] - pose[:2])))
    return np.array(errors), pose


def test_global_localization_converges_for_most_seeds():
    world = build_map("office")
    params = AMCLParams(min_particles=500, max_particles=5000)
    settled = 0
    for seed in range(5):
        loc = AMCLLocalizer(make_setup("office"), params, np.random.default_rng(seed))
        errors, _ = run_robot(loc, world, seed, 150)
        settled += np.median(errors[-20:]) < 0.2
    assert settled >= 4


def _recording(resample, record):
    """Wrap ``AugmentedMCL.resample`` to record how many particles each call injects."""

    def wrapped():
        record.append(resample())
        return record[-1]

    return wrapped


def test_kidnapped_robot_recovers_within_120_steps_for_most_seeds():
    world = build_map("office")
    params = AMCLParams(min_particles=500, max_particles=5000)
    recovered, injected_after_kidnap = 0, 0
    for seed in range(5):
        start = free_space_sample(world, 1, np.random.default_rng([seed, 5]), clearance_m=0.5)[0]
        loc = AMCLLocalizer(make_setup("office"), params, np.random.default_rng(seed))
        loc.filter.reset_gaussian(start, [0.1, 0.1, 0.05])
        injections = []
        loc.filter.resample = _recording(loc.filter.resample, injections)
        errors, _ = run_robot(loc, world, seed, 20 + 120, start=start, kidnap_at=20)
        assert np.max(errors[5:20]) < 0.3  # tracking before the kidnap
        after = errors[20:] < 0.3
        # Recovered: ten consecutive steps under 0.3 m within the 120 steps after the kidnap.
        recovered += np.any(np.convolve(after, np.ones(10), "valid") == 10)
        injected_after_kidnap += sum(injections[20:]) > 0
    assert injected_after_kidnap == 5
    assert recovered >= 3


def test_same_seed_same_run():
    world = build_map("three_rooms_corridor")
    params = AMCLParams(min_particles=200, max_particles=1000)
    runs = []
    for _ in range(2):
        loc = AMCLLocalizer(make_setup("three_rooms_corridor"), params, np.random.default_rng(4))
        runs.append(run_robot(loc, world, 4, 15)[0])
    assert np.array_equal(runs[0], runs[1])


def test_core_takes_any_log_likelihood():
    """The sensor seam: a range-and-bearing landmark sensor, no laser, drives the same core."""
    landmarks = np.array([[2.0, 8.0], [9.0, 1.0], [5.0, 5.5]])

    def landmark_log_likelihood(ranges, bearings):
        def log_likelihood(particles):
            d = landmarks[None, :, :] - particles[:, None, :2]
            r = np.hypot(d[..., 0], d[..., 1])
            b = np.arctan2(d[..., 1], d[..., 0]) - particles[:, 2:3]
            db = np.remainder(b - bearings + np.pi, 2 * np.pi) - np.pi
            return (-0.5 * ((r - ranges) / 0.2) ** 2 - 0.5 * (db / 0.1) ** 2).sum(axis=1)

        return log_likelihood

    params = AMCLParams(min_particles=300, max_particles=3000)
    core = AugmentedMCL(params, np.random.default_rng(0), uniform_sampler(), (0.05, 0.02))
    true_pose = np.array([4.0, 3.0, 0.7])
    for _ in range(30):  # drive a circle of radius 1 m, exact odometry and measurements
        true_pose = unicycle_model(true_pose[None], 0.2, 0.2)[0]
        rel = landmarks - true_pose[:2]
        ranges = np.hypot(rel[:, 0], rel[:, 1])
        bearings = np.arctan2(rel[:, 1], rel[:, 0]) - true_pose[2]
        estimate = core.update(0.2, 0.2, landmark_log_likelihood(ranges, bearings))
    assert np.hypot(*(estimate[:2] - true_pose[:2])) < 0.1
    assert abs(math.remainder(estimate[2] - true_pose[2], 2 * math.pi)) < 0.05


def test_follows_the_localizer_protocol_and_validates_observations():
    loc = AMCLLocalizer(
        make_setup(), AMCLParams(min_particles=50, max_particles=100), np.random.default_rng(0)
    )
    assert isinstance(loc, Localizer)
    assert loc.estimate().shape == (3,)
    with pytest.raises(ValueError, match="ranges_m"):
        loc.step(LaserObservation(0, 0.1, 0.0, np.ones(5)))
    with pytest.raises(ValueError, match="odometry_delta_s_m"):
        loc.step(LaserObservation(0, math.nan, 0.0, np.ones(18)))
    with pytest.raises(TypeError, match="rng"):
        AMCLLocalizer(make_setup(), AMCLParams(), rng=None)


# --------------------------------------------------------------------------------------------
# Collaboration
# --------------------------------------------------------------------------------------------


def test_teammate_factor_against_the_density_by_hand():
    # Teammate belief: one sample at (5, 3, 0.5), zero odometry. Sighting from this robot:
    # distance 2, bearing pi/2, relative heading 0.5. A particle at (5, 1, 0) predicts the
    # teammate exactly at (5, 3, 0.5); one at (5, 0.8, 0) predicts it 0.2 m short along the line
    # of sight; one at (5.3, 1, 0) 0.3 m off across it. One at (5, 1, t) predicts it at
    # (5 - 2 sin t, 1 + 2 cos t, 0.5 + t): in the frame of its line of sight (-sin t, cos t) the
    # sample lies 2 cos t - 2 along, -2 sin t across, and -t in heading.
    t = 0.1
    summary = BeliefSummary(1, 0, np.array([[5.0, 3.0, 0.5]]), np.array([1.0]), 0.25, 0.15)
    sighting = Sighting(
        robot_id=1, distance_m=2.0, bearing_rad=math.pi / 2, relative_heading_rad=0.5
    )
    particles = np.array([[5.0, 1.0, 0.0], [5.0, 0.8, 0.0], [5.3, 1.0, 0.0], [5.0, 1.0, t]])
    offsets = [
        (0.0, 0.0, 0.0),
        (0.2, 0.0, 0.0),
        (0.0, 0.3, 0.0),
        (2 * math.cos(t) - 2, -2 * math.sin(t), -t),
    ]
    eps, log_u = 0.1, math.log(1 / 100.0)
    got = teammate_log_factor(particles, sighting, summary, 0.2, 0.1, eps, log_u)
    sd_along = math.sqrt(0.25**2 + 0.2**2)
    sd_across = math.sqrt(0.25**2 + (2 * 0.1) ** 2)
    kappa = 1.0 / (0.15**2 + 0.1**2)  # heading: von Mises with 1/kappa the summed variances
    for particle_index, (along, across, heading) in enumerate(offsets):
        density = (
            norm.pdf(along, scale=sd_along)
            * norm.pdf(across, scale=sd_across)
            * vonmises.pdf(heading, kappa)
        )
        expected = math.log((1 - eps) * density + eps / 100.0)
        assert got[particle_index] == pytest.approx(expected, rel=1e-9)


def test_a_seen_localized_teammate_breaks_a_symmetry():
    """Robot A believes two mirror poses in the symmetric map equally; teammate B, localized,
    broadcasts its belief; A sees B: A's estimate goes to the true pose."""
    world = build_map("symmetric")
    true_a = np.array([3.0, 2.5, 0.0])
    mirror_a = np.array([7.0, 7.5, math.pi])  # the 180-degree rotation about the centre (5, 5)
    true_b = np.array([3.0, 6.5, 0.0])  # 4 m north of A, in line of sight (west of the pillar)
    setup_a = make_setup(
        "symmetric", cooperative=True, robot_id=0, speed_std_mps=0.0, turn_rate_std_rad_s=0.0
    )
    params = AMCLParams(min_particles=400, max_particles=400, recovery=False)
    rng = np.random.default_rng(11)
    loc_a = AMCLLocalizer(setup_a, params, rng)
    cloud = rng.normal(0, 1, (200, 3)) * [0.05, 0.05, 0.02]
    loc_a.filter.reset(np.vstack([true_a + cloud, mirror_a + cloud]))
    loc_b = AMCLLocalizer(
        make_setup("symmetric", cooperative=True, robot_id=1), params, np.random.default_rng(12)
    )
    loc_b.filter.reset(true_b + cloud[:, :] * 0.5)
    laser = LaserParams.cfs_ga()
    scan_b = cast_rays(world, true_b[None], laser.beam_angles_rad, laser.max_range_m)[0]
    loc_b.step(LaserObservation(0, 0.0, 0.0, scan_b))
    payload = loc_b.outgoing()
    assert payload is not None and len(payload) <= MAX_RADIO_PAYLOAD_BYTES
    # A's scan is the same at both of its hypotheses (the map is symmetric): without B, a tie.
    scan_a = cast_rays(world, true_a[None], laser.beam_angles_rad, laser.max_range_m)[0]
    d = true_b[:2] - true_a[:2]
    sighting = Sighting(1, float(np.hypot(*d)), math.atan2(d[1], d[0]) - true_a[2], 0.0)
    loc_a.step(LaserObservation(0, 0.0, 0.0, scan_a, (sighting,), (RadioMessage(1, payload),)))
    assert np.hypot(*(loc_a.estimate()[:2] - true_a[:2])) < 0.2
    assert loc_a.main_cluster_weight > 0.95
    assert loc_a.teammate_updates == 1


def test_outgoing_only_when_cooperative_and_concentrated():
    params = AMCLParams(min_particles=200, max_particles=2000)
    spread = AMCLLocalizer(make_setup(cooperative=True), params, np.random.default_rng(0))
    assert spread.outgoing() is None  # before any step
    spread.step(LaserObservation(0, 0.0, 0.0, np.full(18, 8.0)))  # no information at all
    assert spread.main_cluster_weight < 0.5 and spread.outgoing() is None
    alone = AMCLLocalizer(make_setup(cooperative=False), params, np.random.default_rng(0))
    alone.filter.reset(np.tile([[3.0, 3.0, 0.0]], (50, 1)))
    alone.step(LaserObservation(0, 0.0, 0.0, np.full(18, 8.0)))
    assert alone.outgoing() is None


def test_bad_payloads_are_skipped_and_listed():
    params = AMCLParams(min_particles=100, max_particles=300)
    loc = AMCLLocalizer(make_setup(cooperative=True), params, np.random.default_rng(0))
    good = encode_belief(sample_summary())  # robot 3
    obs = LaserObservation(
        7,
        0.2,
        0.0,
        np.full(18, 8.0),
        (Sighting(3, 1.0, 0.0, 0.0),),
        (RadioMessage(5, b"garbage"), RadioMessage(4, good), RadioMessage(3, good)),
    )
    loc.step(obs)
    assert [sender for sender, _ in loc.rejected] == [5, 4]
    assert all(isinstance(error, ValueError) for _, error in loc.rejected)
    assert "id" in str(loc.rejected[1][1])
    assert loc.teammate_updates == 1  # robot 3's belief was used
    loc.step(LaserObservation(8, 0.2, 0.0, np.full(18, 8.0)))
    assert loc.rejected == ()


def test_poses_from_teammate_inverts_the_sighting():
    # Teammate at (5, 3, 0.5), seen at distance 2, bearing pi/2, relative heading 0.5: the
    # observer is at heading 0.5 - 0.5 = 0, 2 m south of it: (5, 1, 0).
    sighting = Sighting(
        robot_id=1, distance_m=2.0, bearing_rad=math.pi / 2, relative_heading_rad=0.5
    )
    exact = BeliefSummary(1, 0, np.array([[5.0, 3.0, 0.5]]), np.array([1.0]), 1e-12, 1e-12)
    poses = poses_from_teammate(exact, sighting, 10, np.random.default_rng(0), 0.0, 0.0)
    assert np.allclose(poses, [[5.0, 1.0, 0.0]] * 10, atol=1e-9)
    # With noise: the heading spread is sqrt(kernel_rad^2 + orientation_std^2) (sum of two
    # independent normals); 20000 samples estimate a std within 3 % (relative s.e. 0.5 %).
    noisy = BeliefSummary(1, 0, np.array([[5.0, 3.0, 0.5]]), np.array([1.0]), 0.1, 0.15)
    poses = poses_from_teammate(noisy, sighting, 20000, np.random.default_rng(1), 0.2, 0.1)
    assert np.std(poses[:, 2]) == pytest.approx(math.hypot(0.15, 0.1), rel=0.03)
    # The line of sight theta + b = pi/2 + e with e ~ N(0, 0.15^2 + 0.1^2 + 0.1^2) (kernel, relative
    # heading, bearing): E[y] = 3 - 2 E[cos e] = 3 - 2 exp(-var / 2), E[x] = 5 - 2 E[-sin e] = 5.
    # Standard errors are below 0.003 m; tolerance 0.01 m.
    var = 0.15**2 + 0.1**2 + 0.1**2
    assert np.allclose(poses.mean(axis=0), [5.0, 3.0 - 2.0 * math.exp(-var / 2), 0.0], atol=0.01)


@pytest.mark.parametrize("reset_fraction", [0.0, 0.2])
def test_teammate_reset_moves_a_confidently_wrong_belief(reset_fraction):
    """A sits at the true pose but believes only the mirror pose (the symmetric map's laser
    cannot tell them apart); localized B is seen every step. Reweighting alone cannot fix A;
    resetting from B's belief does."""
    world = build_map("symmetric")
    true_a, mirror_a = np.array([3.0, 2.5, 0.0]), np.array([7.0, 7.5, math.pi])
    true_b = np.array([3.0, 6.5, 0.0])
    params = AMCLParams(
        min_particles=300, max_particles=300, recovery=False, teammate_reset_fraction=reset_fraction
    )
    rng = np.random.default_rng(21)
    cloud = rng.normal(0, 1, (300, 3)) * [0.05, 0.05, 0.02]
    loc_a = AMCLLocalizer(make_setup("symmetric", cooperative=True), params, rng)
    loc_a.filter.reset(mirror_a + cloud)
    summary = BeliefSummary(1, 0, true_b + cloud[:64] * 0.5, np.ones(64), 0.25, 0.15)
    payload = encode_belief(summary)
    laser = LaserParams.cfs_ga()
    scan_a = cast_rays(world, true_a[None], laser.beam_angles_rad, laser.max_range_m)[0]
    sighting = Sighting(1, 4.0, math.pi / 2, 0.0)
    for k in range(5):
        loc_a.step(LaserObservation(k, 0.0, 0.0, scan_a, (sighting,), (RadioMessage(1, payload),)))
    error = np.hypot(*(loc_a.estimate()[:2] - true_a[:2]))
    assert loc_a.teammate_disagreements >= 1
    if reset_fraction == 0.0:
        assert error > 5.0 and loc_a.teammate_resets == 0
    else:
        assert error < 0.2 and loc_a.teammate_resets > 0
