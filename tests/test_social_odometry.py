"""Social odometry filters (seed 000 §4.2, eq. 17, 20-26) and the frame transform of eq. 27.

Expected values are hand numbers or plain-trig geometry, never produced by the code under test:

- SGIKF: g = p_i / (p_i + p_j) (20); x_i <- (1-g) x_i + g x_j (21); p_i <- (1-g) p_i (22);
- SGIFF: g = 1 / (1 + exp(-beta (p_i - p_j))) (24); x as (25); p_i <- (1-g) p_i + g p_j (26);
- eq. 27: alpha = phi^i - gamma^i, phi^j = gamma^j + alpha - pi,
  x~ = lambda cos(gamma^j) + dy cos(phi^j), y~ = lambda sin(gamma^j) + dy sin(phi^j).
"""

from __future__ import annotations

import math
import warnings

import numpy as np
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from swarmloc.agents.epuck.social_odometry import (
    STRATEGIES,
    fermi_gain,
    fuse,
    kalman_gain,
    sgiff_update,
    sgikf_update,
    transform_received,
)

PROPERTY = settings(max_examples=200, deadline=None)


def _a(*values) -> np.ndarray:
    return np.array(values, dtype=float)


# ---------------------------------------------------------------------------------------------
# Registry
# ---------------------------------------------------------------------------------------------


def test_registry_has_the_five_strategies_of_the_paper_the_sikf_pair_and_global_imitation():
    # Seed 000 §6.1's five, the SIKF of eq. 18-22 (seed 001's "covariance knowledge") and seed
    # 001's global imitation by a central system and by long-range boards.
    assert set(STRATEGIES) == {"NC", "SSGIKF", "DSGIKF", "SSGIFF", "DSGIFF", "SSIKF", "DSIKF",
                               "GLOBAL", "GLOBAL_RB"}
    assert {n for n, s in STRATEGIES.items() if s.central} == {"GLOBAL", "GLOBAL_RB"}


@pytest.mark.parametrize(
    "name, communicates, double, gain",
    [
        ("NC", False, False, "none"),
        ("SSGIKF", True, False, "kalman"),
        ("DSGIKF", True, True, "kalman"),
        ("SSGIFF", True, False, "fermi"),
        ("DSGIFF", True, True, "fermi"),
        ("SSIKF", True, False, "kalman"),
        ("DSIKF", True, True, "kalman"),
    ],
)
def test_registry_flags(name, communicates, double, gain):
    s = STRATEGIES[name]
    assert s.name == name
    assert s.communicates is communicates
    assert s.double is double
    assert s.gain == gain


def test_fuse_picks_the_filter_and_refuses_nc():
    x_own, x_other = _a(0.0, 0.0)[None], _a(1.0, 0.0)[None]
    # Kalman: p 3 vs 1 -> g 0.75
    x, p = fuse(STRATEGIES["SSGIKF"], beta=0.01)(x_own, _a(3.0), x_other, _a(1.0))
    assert x[0, 0] == pytest.approx(0.75)
    assert p[0] == pytest.approx(0.75)
    # Fermi, beta = 0: g 0.5, p = 0.5 * 3 + 0.5 * 1 = 2
    x, p = fuse(STRATEGIES["DSGIFF"], beta=0.0)(x_own, _a(3.0), x_other, _a(1.0))
    assert x[0, 0] == pytest.approx(0.5)
    assert p[0] == pytest.approx(2.0)
    with pytest.raises(ValueError, match="NC"):
        fuse(STRATEGIES["NC"], beta=0.01)


# ---------------------------------------------------------------------------------------------
# SGIKF, eq. 20-22
# ---------------------------------------------------------------------------------------------


def test_kalman_gain_hand_values():
    g = kalman_gain(_a(3.0, 1.0, 2.0, 0.0), _a(1.0, 3.0, 2.0, 5.0))
    assert g == pytest.approx([0.75, 0.25, 0.5, 0.0])


def test_sgikf_update_hand_values():
    # p_own = 3 m, p_other = 1 m: g = 0.75; x = 0.25 x_i + 0.75 x_j; p = 0.25 * 3 = 0.75 m
    x, p = sgikf_update(_a(0.0, 4.0)[None], _a(3.0), _a(4.0, 0.0)[None], _a(1.0))
    assert x[0] == pytest.approx([3.0, 1.0])
    assert p[0] == pytest.approx(0.75)


def test_sgikf_batch_rows_are_independent():
    x_own = np.array([[0.0, 0.0], [1.0, 1.0], [2.0, -2.0]])
    x_other = np.array([[1.0, 0.0], [3.0, 1.0], [2.0, 2.0]])
    p_own, p_other = _a(1.0, 1.0, 6.0), _a(1.0, 3.0, 2.0)
    x, p = sgikf_update(x_own, p_own, x_other, p_other)
    # g = 0.5, 0.25, 0.75
    np.testing.assert_allclose(x, [[0.5, 0.0], [1.5, 1.0], [2.0, 1.0]])
    np.testing.assert_allclose(p, [0.5, 0.75, 1.5])


def test_sgikf_both_perfect_average():
    # p = 0 for both: 0/0, the two perfect estimates are averaged (g = 0.5), p stays 0.
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        g = kalman_gain(_a(0.0), _a(0.0))
        x, p = sgikf_update(_a(0.0, 0.0)[None], _a(0.0), _a(2.0, -4.0)[None], _a(0.0))
    assert g[0] == 0.5
    assert x[0] == pytest.approx([1.0, -2.0])
    assert p[0] == 0.0


def test_sgikf_perfect_own_estimate_is_kept():
    x, p = sgikf_update(_a(1.0, 1.0)[None], _a(0.0), _a(5.0, 5.0)[None], _a(2.0))
    assert x[0] == pytest.approx([1.0, 1.0])
    assert p[0] == 0.0


def test_sgikf_perfect_other_estimate_is_adopted():
    x, p = sgikf_update(_a(1.0, 1.0)[None], _a(2.0), _a(5.0, 5.0)[None], _a(0.0))
    assert x[0] == pytest.approx([5.0, 5.0])
    assert p[0] == 0.0


# No subnormals: with p_i = 5e-324 the hand formula's own p_i * x_j rounds to a multiple of the
# smallest subnormal (5e-324 * 1.5 == 1e-323), so it, not the filter, is wrong there.
_coord = st.floats(-10.0, 10.0, allow_nan=False, allow_subnormal=False)
_p = st.floats(0.0, 50.0, allow_nan=False, allow_subnormal=False)


@PROPERTY
@given(xi=st.tuples(_coord, _coord), xj=st.tuples(_coord, _coord), pi=_p, pj=_p)
def test_sgikf_eq_17_both_robots_end_with_identical_estimates(xi, xj, pi, pj):
    """Robot i updates with j's prior and j with i's prior: same x and same p (eq. 17).

    By hand: x' = (p_j x_i + p_i x_j) / (p_i + p_j) and p' = p_i p_j / (p_i + p_j)."""
    xi_a, xj_a = np.array([xi]), np.array([xj])
    x_i, p_i = sgikf_update(xi_a, _a(pi), xj_a, _a(pj))
    x_j, p_j = sgikf_update(xj_a, _a(pj), xi_a, _a(pi))
    np.testing.assert_allclose(x_i, x_j, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(p_i, p_j, rtol=1e-12, atol=1e-12)
    if pi + pj > 0:
        expected_x = (pj * np.array(xi) + pi * np.array(xj)) / (pi + pj)
        np.testing.assert_allclose(x_i[0], expected_x, rtol=1e-9, atol=1e-9)
        assert p_i[0] == pytest.approx(pi * pj / (pi + pj), rel=1e-9, abs=1e-12)
        # Fusion never makes the estimate worse than the better of the two.
        assert p_i[0] <= min(pi, pj) + 1e-12


# ---------------------------------------------------------------------------------------------
# SGIFF, eq. 24-26
# ---------------------------------------------------------------------------------------------


def test_fermi_gain_beta_zero_is_one_half():
    g = fermi_gain(_a(0.0, 100.0, 3.0), _a(100.0, 0.0, 3.0), beta=0.0)
    assert g == pytest.approx([0.5, 0.5, 0.5])


def test_fermi_gain_beta_0_01_dp_100_hand_value():
    # 1 / (1 + e^-1) = 0.7310585786300049
    g = fermi_gain(_a(150.0), _a(50.0), beta=0.01)
    assert g[0] == pytest.approx(1.0 / (1.0 + math.exp(-1.0)), rel=1e-12)
    assert g[0] == pytest.approx(0.7310585786300049, rel=1e-12)
    g_rev = fermi_gain(_a(50.0), _a(150.0), beta=0.01)
    assert g_rev[0] == pytest.approx(1.0 / (1.0 + math.e), rel=1e-12)


def test_fermi_gain_large_beta_is_a_step_without_overflow():
    with warnings.catch_warnings():
        warnings.simplefilter("error")  # no overflow warnings from exp
        g = fermi_gain(_a(2.0, 1.0, 1.0, 1e6, 0.0), _a(1.0, 2.0, 1.0, 0.0, 1e6), beta=1e6)
    assert g[0] == pytest.approx(1.0, abs=1e-12)  # own worse: take the other's
    assert g[1] == pytest.approx(0.0, abs=1e-12)  # own better: keep own
    assert g[2] == pytest.approx(0.5)
    assert g[3] == pytest.approx(1.0, abs=1e-12)
    assert g[4] == pytest.approx(0.0, abs=1e-12)


def test_sgiff_update_hand_values_eq_25_26():
    # p_i = 3, p_j = 1, beta = 0.5: g = 1/(1+e^-1) = 0.7310585786300049
    g = 0.7310585786300049
    x, p = sgiff_update(_a(0.0, 2.0)[None], _a(3.0), _a(4.0, 0.0)[None], _a(1.0), beta=0.5)
    assert x[0] == pytest.approx([g * 4.0, (1 - g) * 2.0], rel=1e-12)
    # eq. 26: p = (1 - g) 3 + g 1 = 3 - 2 g = 1.5378828427399902
    assert p[0] == pytest.approx(3.0 - 2.0 * g, rel=1e-12)
    assert p[0] == pytest.approx(1.5378828427399902, rel=1e-12)


def test_sgiff_p_is_a_middle_point_unlike_sgikf():
    # eq. 26: the robot with the better confidence *loses* some of it (seed 000 §4.2.2).
    _, p_better = sgiff_update(_a(0.0, 0.0)[None], _a(1.0), _a(1.0, 0.0)[None], _a(3.0), 0.5)
    assert 1.0 < p_better[0] < 3.0
    # beta = 0: plain average of the two p
    _, p_avg = sgiff_update(_a(0.0, 0.0)[None], _a(1.0), _a(1.0, 0.0)[None], _a(3.0), 0.0)
    assert p_avg[0] == pytest.approx(2.0)


@PROPERTY
@given(
    xi=st.tuples(_coord, _coord),
    xj=st.tuples(_coord, _coord),
    pi=_p,
    pj=_p,
    beta=st.floats(0.0, 5.0, allow_nan=False),
)
def test_sgiff_eq_17_both_robots_end_with_identical_estimates(xi, xj, pi, pj, beta):
    xi_a, xj_a = np.array([xi]), np.array([xj])
    x_i, p_i = sgiff_update(xi_a, _a(pi), xj_a, _a(pj), beta)
    x_j, p_j = sgiff_update(xj_a, _a(pj), xi_a, _a(pi), beta)
    np.testing.assert_allclose(x_i, x_j, rtol=1e-9, atol=1e-9)
    np.testing.assert_allclose(p_i, p_j, rtol=1e-9, atol=1e-9)
    g = 1.0 / (1.0 + math.exp(-beta * (pi - pj)))
    assert p_i[0] == pytest.approx((1 - g) * pi + g * pj, rel=1e-9, abs=1e-12)


# ---------------------------------------------------------------------------------------------
# Eq. 27: the neighbour's goal in the receiver's frame
# ---------------------------------------------------------------------------------------------


def _wrap(a: float) -> float:
    return (a + math.pi) % (2 * math.pi) - math.pi


def _geometry(sender, receiver, goal):
    """True board measurements and goal-in-receiver-frame for world poses, by plain trig."""
    xi, yi, ti = sender
    xj, yj, tj = receiver
    gx, gy = goal
    range_m = math.hypot(xi - xj, yi - yj)
    gamma_j = _wrap(math.atan2(yi - yj, xi - xj) - tj)  # sender seen from the receiver
    gamma_i = _wrap(math.atan2(yj - yi, xj - xi) - ti)  # receiver seen from the sender
    dy_i = math.hypot(gx - xi, gy - yi)
    phi_i = _wrap(math.atan2(gy - yi, gx - xi) - ti)  # goal in the sender's frame
    # goal in the receiver's frame: rotate (G - p_j) by -theta_j
    dx, dyw = gx - xj, gy - yj
    local = (math.cos(tj) * dx + math.sin(tj) * dyw, -math.sin(tj) * dx + math.cos(tj) * dyw)
    return range_m, gamma_j, gamma_i, dy_i, phi_i, local


def test_transform_received_simple_hand_case():
    # Sender at (1, 0) facing +y, receiver at origin facing +x, goal at (1, 2).
    # gamma^j = 0 (sender straight ahead), gamma^i = pi/2... receiver is at -x of the sender,
    # i.e. at angle pi in the world, pi - pi/2 = pi/2 in the sender's frame.
    # Goal in the sender's frame: 2 m straight ahead (phi^i = 0, dy = 2).
    # alpha = 0 - pi/2 = -pi/2; phi^j = 0 - pi/2 - pi = -3 pi/2 (== +pi/2):
    # x~ = 1 + 2 cos(-3pi/2) = 1, y~ = 0 + 2 sin(-3pi/2) = 2.
    out = transform_received(_a(1.0), _a(0.0), _a(math.pi / 2), _a(2.0), _a(0.0))
    assert out[0] == pytest.approx([1.0, 2.0], abs=1e-12)


def test_transform_received_matches_exact_geometry_for_random_poses():
    rng = np.random.default_rng(20240601)
    m = 500
    rows = []
    for _ in range(m):
        receiver = (rng.uniform(-2, 2), rng.uniform(-2, 2), rng.uniform(-math.pi, math.pi))
        bearing = rng.uniform(-math.pi, math.pi)
        dist = rng.uniform(0.01, 0.15)
        sender = (
            receiver[0] + dist * math.cos(bearing),
            receiver[1] + dist * math.sin(bearing),
            rng.uniform(-math.pi, math.pi),
        )
        goal = (rng.uniform(-3, 3), rng.uniform(-3, 3))
        rows.append(_geometry(sender, receiver, goal))
    range_m, gamma_j, gamma_i, dy_i, phi_i, local = (np.array(c) for c in zip(*rows))
    out = transform_received(range_m, gamma_j, gamma_i, dy_i, phi_i)
    assert out.shape == (m, 2)
    np.testing.assert_allclose(out, local, rtol=0, atol=1e-9)


@PROPERTY
@given(
    receiver=st.tuples(
        st.floats(-5, 5), st.floats(-5, 5), st.floats(-math.pi, math.pi, exclude_max=True)
    ),
    rel_bearing=st.floats(-math.pi, math.pi),
    dist=st.floats(0.001, 0.8),
    sender_heading=st.floats(-math.pi, math.pi),
    goal=st.tuples(st.floats(-5, 5), st.floats(-5, 5)),
)
def test_transform_received_property(receiver, rel_bearing, dist, sender_heading, goal):
    sender = (
        receiver[0] + dist * math.cos(rel_bearing),
        receiver[1] + dist * math.sin(rel_bearing),
        sender_heading,
    )
    range_m, gamma_j, gamma_i, dy_i, phi_i, local = _geometry(sender, receiver, goal)
    out = transform_received(_a(range_m), _a(gamma_j), _a(gamma_i), _a(dy_i), _a(phi_i))
    assert out[0] == pytest.approx(local, abs=1e-9)


def test_transform_received_goal_at_sender_is_the_sender_position():
    # dy = 0: the goal is where the sender is, lambda along gamma^j.
    out = transform_received(_a(0.1), _a(0.4), _a(-2.0), _a(0.0), _a(1.3))
    assert out[0] == pytest.approx([0.1 * math.cos(0.4), 0.1 * math.sin(0.4)], abs=1e-15)
