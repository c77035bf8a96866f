"""The SIKF strategies ("covariance knowledge", seed 001 §5; seed 000 eq. 9-11, 18-22)."""

from __future__ import annotations

import numpy as np
import pytest

from swarmloc.agents.epuck.foraging import AgentConfig, ForagingBrain, Inbox, agent_rng
from swarmloc.agents.epuck.social_odometry import STRATEGIES
from swarmloc.protocol.epuck import EpuckBody

BODY = EpuckBody()
K_M = 1.37e-4


def _brain(strategy="SSIKF"):
    # give_up_factor 0: the robots these tests build by hand have goal estimates without the trip
    # that set them out, which the default give-up rule (factor 2) would abandon at once.
    # one message per encounter: eq. 20-22 on the one message a test sends
    config = AgentConfig(strategy=strategy, odometry_k_m=K_M, give_up_factor=0.0, encounter_messages=1)
    return ForagingBrain(config, BODY, [0], [agent_rng(1, 0)], 0.1)


def _covariance_by_hand(steps_left, steps_right, n):
    """eq. 9-11 written out for a robot starting at heading 0, P_0 = 0."""
    b, m = BODY.wheelbase_m, BODY.metres_per_step
    x = np.zeros(3)
    p = np.zeros((3, 3))
    for _ in range(n):
        ul, ur = steps_left * m, steps_right * m
        rho, dth = (ur + ul) / 2, (ur - ul) / b
        z = x[2] + dth / 2
        a = np.array([[1, 0, -rho * np.sin(z)], [0, 1, rho * np.cos(z)], [0, 0, 1]])
        w = np.array([
            [0.5 * np.cos(z) - rho / (2 * b) * np.sin(z), 0.5 * np.cos(z) + rho / (2 * b) * np.sin(z)],
            [0.5 * np.sin(z) + rho / (2 * b) * np.cos(z), 0.5 * np.sin(z) - rho / (2 * b) * np.cos(z)],
            [1 / b, -1 / b],
        ])
        q = np.diag([K_M * abs(ur), K_M * abs(ul)])
        p = a @ p @ a.T + w @ q @ w.T
        x = x + np.array([rho * np.cos(z), rho * np.sin(z), dth])
    return p


def test_registry_has_the_sikf_strategies():
    assert STRATEGIES["SSIKF"].confidence == "covariance" and not STRATEGIES["SSIKF"].double
    assert STRATEGIES["DSIKF"].double and STRATEGIES["DSIKF"].gain == "kalman"
    assert all(STRATEGIES[s].confidence == "distance" for s in ("NC", "SSGIKF", "DSGIFF"))


@pytest.mark.parametrize("left, right", [(80.0, 80.0), (60.0, 90.0)])
def test_p_is_the_spectral_norm_of_the_covariance_since_the_area(left, right):
    brain = _brain()
    white, black = np.ones((1, 3)), np.full((1, 3), 0.1)
    no_ir, mail = np.zeros((1, 8)), Inbox.empty(3)
    brain.step(np.zeros((1, 2)), no_ir, black, mail)  # at the nest: P = 0, p = 0
    assert brain.goal_p_m[0, 0] == 0.0
    n = 40
    for _ in range(n):
        brain.step(np.array([[left, right]]), no_ir, white, mail)
    expected = np.linalg.eigvalsh(_covariance_by_hand(left, right, n)[:2, :2]).max()
    assert brain.goal_p_m[0, 0] == pytest.approx(expected, rel=1e-9)
    # It grows with the distance travelled, faster than linearly once the heading error acts.
    assert expected > 0


def test_fusion_scales_the_covariance_by_one_minus_the_gain():
    from swarmloc.agents.epuck.foraging import SocialMessages

    brain = _brain()
    brain.known[0, 0] = True
    brain.target[0] = 0  # heading for the nest: a single filter fuses the nest
    brain.goal_xy[0, 0] = [1.0, 0.0]
    cov = np.diag([4e-4, 1e-4, 1e-3])
    brain.goal_cov[0, 0] = cov
    brain.goal_p_m[0, 0] = 4e-4
    # Last tick we heard robot 5 straight ahead at 10 cm; it heard us behind it.
    brain.heard_ids[0, 0], brain.heard_bearing_rad[0, 0], brain.heard_range_m[0, 0] = 5, 0.0, 0.1
    brain._heard_clear = False
    msg = SocialMessages.empty(1, 3)
    msg.goal_known[0, 0] = True
    msg.goal_distance_m[0, 0], msg.goal_angle_rad[0, 0], msg.goal_p_m[0, 0] = 0.9, 0.0, 1e-4
    msg.heard_ids[0, 0], msg.heard_bearing_rad[0, 0] = 0, np.pi
    inbox = Inbox(np.zeros(1, np.int64), np.array([5]), np.array([0.1]), np.array([0.0]), msg)
    brain.step(np.zeros((1, 2)), np.zeros((1, 8)), np.ones((1, 3)), inbox)
    g = 4e-4 / (4e-4 + 1e-4)  # eq. 20
    assert brain.goal_p_m[0, 0] == pytest.approx((1 - g) * 4e-4)  # eq. 22
    np.testing.assert_allclose(brain.goal_cov[0, 0], (1 - g) * cov, rtol=1e-12)
    # The neighbour (10 cm ahead of us, facing away: it hears us at pi) sees the nest 0.9 m
    # straight ahead of itself: at (0.1 + 0.9, 0) = (1.0, 0) for us, where we already had it.
    np.testing.assert_allclose(brain.goal_xy[0, 0], [1.0, 0.0], atol=1e-6)
