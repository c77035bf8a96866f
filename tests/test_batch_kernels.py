"""Tests of the compiled kernels behind the batch engine (world/kernels.py, agents/kernels.py).

The kernels must give exactly what the models specify, whatever the swarm's layout: their
neighbour search is checked against brute force, the collision kernel against the KD-tree version
it stands in for (bit for bit), merged random draws against numpy's own, the Fermi fusion (whose
exp is numpy's) against the pure filter functions, and a swarm brain against per-robot brains fed
through the wire format, which is what the world-server and agent processes do.
"""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.agents.foraging import AgentConfig, ForagingBrain, Inbox, SocialMessages, agent_rng
from swarmloc.agents.social_odometry import sgiff_update
from swarmloc.deploy.batch import inbox_from, swarm_brain
from swarmloc.deploy.scenario import load_scenario
from swarmloc.protocol.epuck import EpuckBody, on_path
from swarmloc.world import kernels
from swarmloc.world.arena import Arena, Disc, _resolve_collisions_kdtree, resolve_collisions
from swarmloc.world.foraging import ForagingWorld

R = 0.035


def brute_pairs(xy: np.ndarray, radius_m: float) -> set[tuple[int, int]]:
    """Ordered pairs (s, r), s != r, with hypot distance <= radius_m, by brute force."""
    d = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
    s, r = np.nonzero((d <= radius_m) & ~np.eye(len(xy), dtype=bool))
    return set(zip(s.tolist(), r.tolist()))


@pytest.mark.parametrize(
    "layout",
    ["uniform", "one_cell", "outside_walls", "far_apart", "on_the_cell_edges", "thousands"],
)
def test_grid_neighbour_search_finds_exactly_the_brute_force_pairs(layout):
    rng = np.random.default_rng(7)
    n, range_m = 400, 0.15
    if layout == "uniform":
        xy = rng.uniform(0, 3.0, (n, 2))
    elif layout == "one_cell":  # everybody within one 0.15 m cell
        xy = 1.0 + rng.uniform(0, 0.1, (n, 2))
    elif layout == "outside_walls":  # negative and far positive coordinates
        xy = rng.uniform(-1.0, 1.0, (n, 2)) * np.array([1.0, 30.0])
    elif layout == "far_apart":  # beyond the grid's extent clamp (1e4 cells): border cells
        xy = np.concatenate([rng.uniform(0, 0.5, (n // 2, 2)), rng.uniform(5e3, 5e3 + 0.5, (n // 2, 2))])
    elif layout == "on_the_cell_edges":  # a lattice of pairs exactly one range apart
        range_m = 0.125  # exact in binary, so are the lattice and its distances
        g = np.arange(20) * range_m
        xy = np.stack(np.meshgrid(g, g), axis=-1).reshape(-1, 2)
    else:
        n = 3000
        xy = rng.uniform(0, 12.0, (n, 2))
    pose = np.column_stack([xy, rng.uniform(-np.pi, np.pi, len(xy))])
    sending = np.ones(len(xy), bool)
    sender, receiver, dist_m, rel_x, rel_y = kernels.rab_candidates(pose, sending, range_m)
    assert set(zip(sender.tolist(), receiver.tolist())) == brute_pairs(xy, range_m)
    # (receiver, sender) order, and the measured geometry is the true one
    key = receiver * len(xy) + sender
    assert (np.diff(key) > 0).all()
    np.testing.assert_array_equal(rel_x, xy[sender, 0] - xy[receiver, 0])
    np.testing.assert_array_equal(dist_m, np.hypot(rel_x, rel_y))
    if layout == "on_the_cell_edges":
        assert len(sender) == 2 * 2 * 19 * 20  # each lattice neighbour, both ways, in range


def test_only_senders_send():
    rng = np.random.default_rng(3)
    xy = rng.uniform(0, 1.0, (200, 2))
    pose = np.column_stack([xy, np.zeros(200)])
    sending = rng.random(200) < 0.3
    sender, receiver, *_ = kernels.rab_candidates(pose, sending, 0.15)
    expected = {(s, r) for s, r in brute_pairs(xy, 0.15) if sending[s]}
    assert set(zip(sender.tolist(), receiver.tolist())) == expected


def _arena(side_m: float) -> Arena:
    return Arena(side_m, side_m, nest=Disc((0.2, 0.2), 0.1), prey=Disc((side_m - 0.2, side_m - 0.2), 0.1))


@pytest.mark.parametrize("seed", range(6))
def test_collision_kernel_is_bit_identical_to_the_kdtree_version(seed):
    # Sparse enough that no body touches three others: the kernel's own path is taken.
    rng = np.random.default_rng(seed)
    arena = _arena(3.0)
    xy = rng.uniform(-0.1, 3.1, (120, 2))  # some outside the walls: the clamp
    for iterations in (0, 1, 2, 5):
        fast = xy.copy()
        ok = kernels.separate_bodies(fast, R, arena.width_m, arena.height_m, iterations)
        reference = _resolve_collisions_kdtree(xy, R, arena, None, iterations)
        if iterations <= 2:  # later, bodies clamped onto a wall pile up: the fallback's case
            assert ok
            np.testing.assert_array_equal(fast, reference)
        np.testing.assert_array_equal(resolve_collisions(xy, R, arena, iterations=iterations), reference)


def test_crowds_fall_back_to_the_kdtree_version():
    # A body touching three or more others at once: the pushes' sum depends on the KD-tree's pair
    # order, so the kernel declines and resolve_collisions runs the KD-tree version.
    rng = np.random.default_rng(11)
    arena = _arena(1.0)
    xy = 0.5 + rng.uniform(-0.06, 0.06, (40, 2))
    assert not kernels.separate_bodies(xy.copy(), R, 1.0, 1.0, 2)
    np.testing.assert_array_equal(
        resolve_collisions(xy, R, arena), _resolve_collisions_kdtree(xy, R, arena, None, 2)
    )


def test_merged_uniform_draws_are_numpys_uniform():
    # Generator.uniform(lo, hi) computes lo + (hi - lo) * random(): one random(a + b) call split
    # in two gives the numbers of two uniform() calls, which is how the world merges its draws.
    for lo, hi in ((-0.2, 0.2), (-0.025, 0.025), (-math.radians(20), math.radians(20)), (-math.pi, math.pi), (2.0, 8.0)):
        expected = np.random.default_rng(5).uniform(lo, hi, 3000)
        u = np.random.default_rng(5).random(3000)
        got = np.array([kernels.uniform(lo, hi - lo, v) for v in u])
        np.testing.assert_array_equal(got, expected)
    a, b = np.random.default_rng(9), np.random.default_rng(9)
    split = np.concatenate([a.uniform(-0.3, 0.3, 700), a.uniform(-0.1, 0.1, 50)])
    merged = b.random(750)
    merged[:700] = -0.3 + 0.6 * merged[:700]
    merged[700:] = -0.1 + 0.2 * merged[700:]
    np.testing.assert_array_equal(split, merged)


def _fermi_brain(beta: float) -> ForagingBrain:
    config = AgentConfig(strategy="DSGIFF", beta=beta)
    return ForagingBrain(config, EpuckBody(), [0], [agent_rng(1, 0)], 0.1)


def test_several_fermi_fusions_in_one_tick_match_the_filter_functions():
    # Two fresh neighbours, each knowing both goals: four Fermi fusions in one tick, each needing
    # numpy's exp (the kernel stops and resumes for each), applied in (sender, goal) order.
    beta = 0.01
    brain = _fermi_brain(beta)
    brain.known[0] = True
    brain.target[0] = 0
    brain.goal_xy[0] = [[1.0, 0.0], [0.0, 2.0]]
    brain.goal_p_m[0] = [3.0, 5.0]
    # Last tick we heard robot 5 straight ahead at 10 cm and robot 7 to the left at 12 cm.
    brain.heard_ids[0, :2] = [5, 7]
    brain.heard_bearing_rad[0, :2] = [0.0, np.pi / 2]
    brain.heard_range_m[0, :2] = [0.10, 0.12]
    msg = SocialMessages.empty(2, 3)
    msg.goal_known[:] = True
    msg.goal_distance_m[:] = [[0.9, 1.5], [0.7, 2.0]]
    msg.goal_angle_rad[:] = [[0.0, 1.0], [-0.5, 0.3]]
    msg.goal_p_m[:] = [[1.0, 9.0], [2.0, 0.5]]
    msg.heard_ids[:, 0] = 0
    msg.heard_bearing_rad[:, 0] = [np.pi, -np.pi / 2]
    inbox = Inbox(np.zeros(2, np.int64), np.array([5, 7]), np.array([0.10, 0.12]), np.array([0.0, 1.6]), msg)

    # Expected: the pure numpy filter (social_odometry.sgiff_update), message by message, in the
    # receiver's frame of the crossing (the pose of two ticks ago: the origin here).
    x = brain.goal_xy[0].copy()
    p = brain.goal_p_m[0] / brain.config.confidence_unit_m
    unit = brain.config.confidence_unit_m
    for m, (range_m, gamma_own) in enumerate(((0.10, 0.0), (0.12, np.pi / 2))):
        for goal in (0, 1):
            alpha = msg.goal_angle_rad[m, goal] - msg.heard_bearing_rad[m, 0]
            phi = gamma_own + alpha - np.pi
            d = msg.goal_distance_m[m, goal]
            other = np.array([range_m * np.cos(gamma_own) + d * np.cos(phi), range_m * np.sin(gamma_own) + d * np.sin(phi)])
            x_new, p_new = sgiff_update(x[None, goal], p[None, goal], other[None], np.array([msg.goal_p_m[m, goal] / unit]), beta)
            x[goal], p[goal] = x_new[0], p_new[0]
    brain.step(np.zeros((1, 2)), np.zeros((1, 8)), np.ones((1, 3)), inbox)
    # The brain moved by 0 (no encoder counts) and p grew by 0: the fusions alone changed it.
    np.testing.assert_allclose(brain.goal_xy[0], x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(brain.goal_p_m[0] / unit, p, rtol=1e-15)
    assert not np.allclose(x, [[1.0, 0.0], [0.0, 2.0]])  # the test did exercise fusion


def test_swarm_brain_equals_brains_of_one_over_the_wire():
    # The batch engine steps one brain holding the whole swarm; agent processes each step a
    # brain of one, with messages that crossed the wire as msgpack payloads. Same seeded run,
    # same trajectories, bit for bit: the kernels do not depend on the batch size.
    scenario = load_scenario("ES1", ["agent.strategy=DSGIFF", "world.duration_s=40", "world.seed=3"])
    worlds = [ForagingWorld(scenario.world), ForagingWorld(scenario.world)]
    swarm = swarm_brain(scenario)
    ids = swarm.robot_ids
    singles = [swarm_brain(scenario, [i]) for i in ids]
    capacity = swarm.config.heard_capacity
    sent, payloads = None, [None] * len(ids)
    exchanged = 0
    while not worlds[0].done:
        obs = [w.observe() for w in worlds]
        out = swarm.step(obs[0].encoder_steps, obs[0].ir, obs[0].ground, inbox_from(obs[0], sent, ids))
        d = obs[1].deliveries
        acts = []
        for i, brain in enumerate(singles):
            rows = np.flatnonzero(d.receiver == i)
            heard = [payloads[s] for s in d.sender[rows]]
            inbox = Inbox.empty(capacity)
            if heard:
                inbox = Inbox(np.zeros(len(rows), np.int64), d.sender[rows], d.range_m[rows], d.bearing_rad[rows],
                              SocialMessages.decode(heard, capacity))
                exchanged += len(rows)
            acts.append(brain.step(obs[1].encoder_steps[i : i + 1], obs[1].ir[i : i + 1], obs[1].ground[i : i + 1], inbox))
        cmd = np.concatenate([a.wheel_speed_steps_s for a in acts])
        state = np.concatenate([a.state for a in acts])
        np.testing.assert_array_equal(cmd, out.wheel_speed_steps_s)
        np.testing.assert_array_equal(state, out.state)
        payloads = [a.messages.encode(0) for a in acts]
        worlds[0].step(out.wheel_speed_steps_s, out.sending, on_path(out.state))
        worlds[1].step(cmd, np.concatenate([a.sending for a in acts]), on_path(state))
        sent = out
    np.testing.assert_array_equal(worlds[0].pose, worlds[1].pose)
    np.testing.assert_array_equal(swarm.pose, np.concatenate([b.pose for b in singles]))
    assert exchanged > 50  # messages did cross


def test_collisions_from_the_sensing_pairs_equal_a_fresh_search():
    # The world resolves collisions among the pairs it found when sensing, as long as nobody
    # moved far enough for a new overlap to come from outside them; else it searches the grid.
    rng = np.random.default_rng(4)
    ref = rng.uniform(0, 3.0, (150, 2))
    compared = 0
    for step_m in (0.005, 0.02, 0.2):  # the last is beyond the pairs' reach: grid search
        pos = ref + rng.uniform(-step_m, step_m, ref.shape)
        pairs = kernels.neighbour_pairs(ref[:, 0], ref[:, 1], 0.15, 0.0, 0.0, 3.0, 3.0)
        near, fresh = pos.copy(), pos.copy()
        ok_near = kernels.separate_bodies_near(near, R, 3.0, 3.0, 2, ref, pairs[0], pairs[1], 0.15)
        ok_fresh = kernels.separate_bodies(fresh, R, 3.0, 3.0, 2)
        assert ok_near == ok_fresh
        if ok_fresh:
            np.testing.assert_array_equal(near, fresh)
            np.testing.assert_array_equal(fresh, _resolve_collisions_kdtree(pos, R, _arena(3.0), None, 2))
            compared += 1
    assert compared == 3
