"""Covariance intersection in the cooperative EKF (agents/replay/ekf.py: ci_position_update, the
algorithm ekf-ci, CoLo's LS-CI; issue 46), against properties derived by hand."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.agents.replay.ekf import ci_position_update, position_update
from swarmloc.agents.replay.localizers import ALGORITHMS
from swarmloc.deploy.lab.replay.mrclam import ReplayConfig, consistency, run_replay, score

POSE = np.array([1.0, 2.0, 0.3])
COV = np.array([[0.04, 0.01, 0.002], [0.01, 0.05, 0.001], [0.002, 0.001, 0.01]])


def _psd(m: np.ndarray) -> bool:
    return bool(np.all(np.linalg.eigvalsh(0.5 * (m + m.T)) >= -1e-12))


@pytest.mark.parametrize("fix_cov", [np.diag([0.03, 0.02]), np.array([[0.02, -0.008], [-0.008, 0.06]])])
def test_ci_never_claims_more_than_the_kalman_update_with_independence(fix_cov):
    fix = np.array([1.1, 1.9])
    _, kf_cov, ok = position_update(POSE, COV, fix, fix_cov, np.inf)
    _, ci_cov, accepted, w = ci_position_update(POSE, COV, fix, fix_cov, np.inf)
    assert ok and accepted and 0.0 < w < 1.0
    assert _psd(ci_cov - kf_cov)  # the KF, assuming independence, is the more confident
    # CI lowers the trace it minimises (not every direction's variance: with w < 1 a direction
    # the fix knows worse than the estimate may widen, the price of not knowing the correlation)
    assert np.trace(ci_cov[:2, :2]) < np.trace(COV[:2, :2])
    assert _psd(ci_cov)
    # the heading, which the fix does not observe, is not inflated (the full-state form
    # cov / w would multiply its variance by 1 / w)
    assert ci_cov[2, 2] <= COV[2, 2] + 1e-15


def test_a_fix_worse_in_every_direction_leaves_the_estimate_as_it_is():
    pose, cov, accepted, w = ci_position_update(POSE, COV, np.array([1.2, 2.1]), np.diag([0.5, 0.5]), np.inf)
    assert accepted and w == 1.0
    np.testing.assert_array_equal(pose, POSE)
    np.testing.assert_array_equal(cov, COV)


def test_isotropic_case_by_hand_takes_the_better_estimate():
    # P = a I, R = r I with r < a: the fused position covariance 1 / (w / a + (1 - w) / r) per axis
    # is smallest at the smallest w: the fix, all but whole (w at the search's bound 1e-3).
    a, r = 0.09, 0.01
    cov = np.diag([a, a, 0.02])
    fix = np.array([1.3, 1.8])
    pose, new_cov, accepted, w = ci_position_update(POSE, cov, fix, np.diag([r, r]), np.inf)
    assert accepted and w == pytest.approx(1e-3, abs=2e-4)
    expected = 1.0 / (w / a + (1.0 - w) / r)
    np.testing.assert_allclose(np.diag(new_cov)[:2], [expected, expected], rtol=1e-9)
    assert new_cov[2, 2] == pytest.approx(0.02)  # no correlation with the position: unchanged
    np.testing.assert_allclose(pose[:2], fix, atol=2e-3)


def test_the_gate_refuses_a_far_fix():
    pose, cov, accepted, _ = ci_position_update(POSE, COV, np.array([9.0, 9.0]), np.diag([0.01, 0.01]), 13.8)
    assert not accepted and pose is POSE and cov is COV


def test_ekf_ci_is_registered_and_runs_cooperatively(synthetic):
    assert "ekf-ci" in ALGORITHMS
    from swarmloc.agents.replay.ekf import EkfParams

    with pytest.raises(ValueError, match="fusion"):
        EkfParams(fusion="cii")
    result = run_replay(synthetic, ReplayConfig(algorithm="ekf-ci", cooperative=True, duration_s=20.0))
    scores = score(result)
    assert all(np.isfinite(s["position_rmse_m"]) and s["position_rmse_m"] < 0.5 for s in scores.values())


def test_position_nees_by_hand_and_on_data_the_filter_models():
    from swarmloc.deploy.lab.replay.mrclam import ReplayResult, position_nees

    cfg = ReplayConfig()
    est = np.zeros((2, 1, 3))
    truth = np.zeros((2, 1, 3))
    est[0, 0, :2] = [0.3, -0.4]
    cov = np.full((2, 1, 2, 2), np.nan)
    cov[0, 0] = np.diag([0.09, 0.16])
    result = ReplayResult(cfg, (1,), np.array([0.02, 0.04]), est, truth, 0.0, covariance_xy=cov)
    nees = position_nees(result)
    assert nees[0, 0] == pytest.approx(0.3**2 / 0.09 + 0.4**2 / 0.16) and np.isnan(nees[1, 0])


def test_the_ekf_alone_is_consistent_on_data_drawn_from_its_own_model(synthetic):
    # With the synthesizer's own noise models the EKF's position NEES should average about 2
    # (2 degrees of freedom) and fall within the chi-square 95 % bound about 95 % of the time;
    # measured 2.2 / 1.0 / 1.5 and 0.99-1.0 over the 40 s of 3 robots (tolerance: a factor 2,
    # and 0.9: the ticks are strongly correlated, so 2,000 of them are few samples).
    from mrclam_synthetic import synthetic_config

    result = run_replay(synthetic, synthetic_config(algorithm="ekf"))
    for s in consistency(result).values():
        assert 0.5 < s["position_nees_mean"] < 4.0, s
        assert s["position_nees_in_95"] > 0.9, s
    # its landmark innovations are as large as it expects: NIS about 2 (2 dof), 95 % inside the
    # band, over hundreds of readings per robot
    for nis in result.nis.values():
        assert nis["landmark_nis_count"] > 100, nis
        assert 1.0 < nis["landmark_nis_mean"] < 3.0 and nis["landmark_nis_in_95"] > 0.85, nis
    # a filter told its readings are 10x better than they are is overconfident, and it shows
    from dataclasses import replace

    from mrclam_synthetic import SYNTH_CAMERA
    tight = replace(SYNTH_CAMERA, range_std_m=SYNTH_CAMERA.range_std_m / 10, bearing_std_rad=SYNTH_CAMERA.bearing_std_rad / 10)
    over_result = run_replay(synthetic, synthetic_config(algorithm="ekf", camera=tight))
    over = consistency(over_result)
    assert all(s["position_nees_mean"] > 4.0 for s in over.values()), over
    # ... and in its innovations: readings 10x noisier than it believes (NIS ~ 100x)
    assert all(n["landmark_nis_mean"] > 20.0 for n in over_result.nis.values()), over_result.nis


def test_heading_nees_by_hand_and_in_its_band_on_a_linear_gaussian_case():
    from swarmloc.deploy.lab.replay.mrclam import ReplayResult
    from swarmloc.world.replay.evaluation import CHI2_1DOF_95, heading_nees

    # by hand: the error is wrapped (3.1 against -3.1 is 0.0832 rad off, not 6.2)
    cfg = ReplayConfig()
    est, truth = np.zeros((2, 1, 3)), np.zeros((2, 1, 3))
    est[0, 0, 2], truth[0, 0, 2] = 3.1, -3.1
    var = np.array([[0.01], [np.nan]])
    nees = heading_nees(ReplayResult(cfg, (1,), np.array([0.02, 0.04]), est, truth, 0.0, heading_variance=var))
    assert nees[0, 0] == pytest.approx((2 * np.pi - 6.2) ** 2 / 0.01) and np.isnan(nees[1, 0])

    # a consistent heading estimate (errors drawn from the variance it states): mean NEES 1 and
    # 95 % inside the 1-dof bound, within 4 standard errors of 20,000 independent samples; the
    # same errors with a variance stated 4x too small (overconfident) fall outside both
    rng = np.random.default_rng(5)
    n = 20_000
    var_rad2 = rng.uniform(0.001, 0.05, (n, 1))
    truth = np.zeros((n, 1, 3))
    truth[:, 0, 2] = rng.uniform(-np.pi, np.pi, n)
    est = truth.copy()
    est[:, 0, 2] += rng.normal(0.0, np.sqrt(var_rad2[:, 0]))
    for stated, consistent in ((var_rad2, True), (var_rad2 / 4, False)):
        result = ReplayResult(cfg, (1,), np.arange(n) * 0.02, est, truth, 0.0, heading_variance=stated)
        c = consistency(result)[1]
        inside = c["heading_nees_in_95"]
        assert bool(abs(c["heading_nees_mean"] - 1.0) < 4 * np.sqrt(2 / n)) is consistent, c
        assert bool(abs(inside - 0.95) < 4 * np.sqrt(0.95 * 0.05 / n)) is consistent, c
        assert np.mean(heading_nees(result) <= CHI2_1DOF_95) == inside
