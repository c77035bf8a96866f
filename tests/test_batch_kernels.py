"""Tests of the compiled kernels behind the batch engine (world/epuck/kernels.py, agents/epuck/kernels.py).

The kernels must give exactly what the models specify, whatever the swarm's layout: their
neighbour search is checked against brute force, the collision kernel against the KD-tree version
it stands in for (bit for bit), merged random draws against numpy's own, the Fermi fusion (whose
exp is numpy's) against the pure filter functions, and a swarm brain against per-robot brains fed
through the wire format, which is what the world-server and agent processes do.

The per-tick kernels draw from numpy generators and evaluate numpy's ``exp`` and ``arctan2``
themselves: their numbers are checked against numpy's, and a world tick against the public model
functions it stands in for (sensors, medium, kinematics, collisions, metrics), including poses
changed between the calls and buffers too small for the swarm. The batch engine's compiled tick
(deploy/lab/epuck/batch.py) must leave the world and the brains as their methods do.
"""

from __future__ import annotations

import copy
import math

import numpy as np
import pytest
from numba import njit
from readings import COMM, COMM_EACH, READINGS

from swarmloc import numerics
from swarmloc.agents.epuck import kernels as agent_kernels
from swarmloc.agents.epuck.foraging import (
    AgentConfig,
    ForagingBrain,
    Inbox,
    SocialMessages,
    agent_rng,
)
from swarmloc.agents.epuck.social_odometry import sent_goals, sgiff_update, sgikf_update
from swarmloc.deploy.lab.epuck.batch import CompiledTicks, inbox_from, run_ticks, swarm_brain
from swarmloc.deploy.scenario import load_scenario
from swarmloc.protocol.epuck import (
    EpuckBody,
    ground_sensor_point,
    integrate_pose,
    on_path,
    wrap_angle,
)
from swarmloc.world.epuck import kernels
from swarmloc.world.epuck.arena import (
    Arena,
    Disc,
    _resolve_collisions_kdtree,
    area_at,
    resolve_collisions,
)
from swarmloc.world.epuck.foraging import ForagingWorld
from swarmloc.world.epuck.medium import deliver
from swarmloc.world.epuck.metrics import ForagingMetrics
from swarmloc.world.epuck.sensors import ground_sensors, ir_proximity

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


def _fusing_brain(strategy: str, beta: float, p_after_fusion: str) -> ForagingBrain:
    # give_up_factor 0: a robot built by hand with a goal 1 m away and 3 m travelled would give
    # up on it at once under the default rule (factor 2), and fuse nothing.
    # one message per encounter: each message fused at once, as the filter functions are
    config = AgentConfig(strategy=strategy, beta=beta, p_after_fusion=p_after_fusion, give_up_factor=0.0,
                         encounter_messages=1)
    return ForagingBrain(config, EpuckBody(), [0], [agent_rng(1, 0)], 0.1)


@pytest.mark.parametrize("p_after_fusion", ["fused", "distance"])
@pytest.mark.parametrize("strategy", ["DSGIFF", "DSGIKF"])
def test_several_fusions_in_one_tick_match_the_filter_functions(strategy, p_after_fusion):
    # Two fresh neighbours, each knowing both goals: four fusions in one tick (the Fermi ones each
    # needing numpy's exp: the kernel stops and resumes for each), applied in (sender, goal)
    # order; p after each as AgentConfig.p_after_fusion reads the seed (table 1 or eq. 23).
    beta = 0.01
    brain = _fusing_brain(strategy, beta, p_after_fusion)
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
            p_other = np.array([msg.goal_p_m[m, goal] / unit])
            if strategy == "DSGIFF":
                x_new, p_new = sgiff_update(x[None, goal], p[None, goal], other[None], p_other, beta, p_after_fusion)
            else:
                x_new, p_new = sgikf_update(x[None, goal], p[None, goal], other[None], p_other, p_after_fusion)
            x[goal], p[goal] = x_new[0], p_new[0]
    brain.step(np.zeros((1, 2)), np.zeros((1, 8)), np.ones((1, 3)), inbox)
    # The brain moved by 0 (no encoder counts) and p grew by 0: the fusions alone changed it.
    np.testing.assert_allclose(brain.goal_xy[0], x, rtol=0, atol=1e-15)
    np.testing.assert_allclose(brain.goal_p_m[0] / unit, p, rtol=1e-15)
    assert not np.allclose(x, [[1.0, 0.0], [0.0, 2.0]])  # the test did exercise fusion
    # By hand: eq. 23 leaves p at the distance travelled (3 m, 5 m); table 1 changed it.
    if p_after_fusion == "distance":
        np.testing.assert_array_equal(brain.goal_p_m[0], [3.0, 5.0])
    else:
        assert not np.allclose(brain.goal_p_m[0], [3.0, 5.0])


@pytest.mark.parametrize("sends", ["both", "last-visited"])
def test_the_goals_sent_are_the_reference_ones(sends):
    # Five robots, one per case: heading for the nest or the prey knowing both, heading for the
    # prey knowing only it (recruited), wandering knowing the nest, wandering knowing nothing.
    config = AgentConfig(strategy="SSGIKF", sends=sends, give_up_factor=0.0)  # as _fusing_brain
    brain = ForagingBrain(config, EpuckBody(), np.arange(5), [agent_rng(1, i) for i in range(5)], 0.1)
    brain.known[:] = [[True, True], [True, True], [False, True], [True, False], [False, False]]
    brain.target[:] = [0, 1, 1, -1, -1]
    brain.goal_xy[:] = 1.0
    out = brain.step(np.zeros((5, 2)), np.zeros((5, 8)), np.ones((5, 3)), Inbox.empty(3))
    expected = sent_goals(brain.known, brain.target, sends)
    np.testing.assert_array_equal(out.messages.goal_known, expected)
    # By hand (seed 001 §4.2, "the last visited area": the goal the robot is not heading to)
    by_hand = {"both": [[1, 1], [1, 1], [0, 1], [1, 0], [0, 0]],
               "last-visited": [[0, 1], [1, 0], [0, 0], [1, 0], [0, 0]]}[sends]
    np.testing.assert_array_equal(expected, np.array(by_hand, bool))
    # a goal not sent carries zeros, as an unknown one
    assert np.all(out.messages.goal_distance_m[~expected] == 0.0) and np.all(out.messages.goal_p_m[~expected] == 0.0)
    assert np.all(out.messages.goal_distance_m[expected] > 0.0)




@pytest.mark.parametrize("readings", [[], READINGS, COMM, COMM_EACH], ids=["defaults", "readings", "comm", "comm-each"])
def test_swarm_brain_equals_brains_of_one_over_the_wire(readings):
    # The batch engine steps one brain holding the whole swarm; agent processes each step a
    # brain of one, with messages that crossed the wire as msgpack payloads. Same seeded run,
    # same trajectories, bit for bit: the kernels do not depend on the batch size.
    scenario = load_scenario("ES1", ["agent.strategy=DSGIFF", "world.duration_s=40", "world.seed=3", *readings])
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


# ------------------------------------------------------------- the kernels' numbers are numpy's


def test_kernels_draw_numpys_numbers_and_advance_the_generator_as_numpy():
    for seed in ([3, 0], [3, 1, 7]):
        rng, twin = np.random.default_rng(seed), np.random.default_rng(seed)
        fn, state = numerics.generator_address(rng)
        out = np.empty(1000)
        kernels.fill_random(out[:5], fn, state)
        kernels.fill_random(out[5:], fn, state)
        np.testing.assert_array_equal(out, twin.random(1000))
        assert rng.random() == twin.random()  # the generator's own state moved on
    with pytest.raises(TypeError, match="rng"):
        numerics.generator_address(np.random.RandomState(1))


def test_wander_draws_are_each_robots_own_uniforms_rounded_half_to_even():
    brain = ForagingBrain(AgentConfig(), EpuckBody(), np.arange(5), [agent_rng(9, i) for i in range(5)], 0.1)
    twins = [agent_rng(9, i) for i in range(5)]
    fn, state = brain._rng_addresses()
    p = brain._params
    need = np.array([3, 0, 4, 0, 0])
    turn, turn_dir, straight = np.zeros(5, np.int64), np.zeros(5), np.zeros(5, np.int64)
    agent_kernels.wander_draws(need, 3, fn, state, p, turn, turn_dir, straight)
    lo, hi = AgentConfig().wander_straight_s
    for i in (3, 0, 4):
        # what each agent drew before the kernels: uniform((-pi, lo), (pi, hi)) of its generator
        angle, straight_s = twins[i].uniform((-math.pi, lo), (math.pi, hi))
        assert turn[i] == round(abs(angle) / p[agent_kernels.A_SPIN_PER_TICK])
        assert turn_dir[i] == (1.0 if angle >= 0 else -1.0)
        assert straight[i] == round(straight_s / p[agent_kernels.A_TICK])
    assert turn[1] == turn[2] == 0  # robots not in need draw nothing
    for rng, twin in zip(brain.rngs, twins):
        assert rng.random() == twin.random()
    # Python's round() sends halves to the even neighbour, and so must the kernel: a turn of
    # exactly 2.5 ticks and a run of exactly 3.5 ticks (powers of two: no rounding on the way).
    q = p.copy()
    q[agent_kernels.A_TURN_LO], q[agent_kernels.A_TURN_SPAN], q[agent_kernels.A_SPIN_PER_TICK] = -1.25, 0.0, 0.5
    q[agent_kernels.A_STRAIGHT_LO], q[agent_kernels.A_STRAIGHT_SPAN], q[agent_kernels.A_TICK] = 1.75, 0.0, 0.5
    agent_kernels.wander_draws(np.array([1]), 1, fn, state, q, turn, turn_dir, straight)
    assert (turn[1], turn_dir[1], straight[1]) == (2, -1.0, 4)


@njit
def _exp_each(module_np_exp, x, math_fns):
    out = np.empty_like(x)
    for q in range(x.shape[0]):
        out[q] = module_np_exp(x[q], math_fns)
    return out


def _bits(a):
    return np.asarray(a, float).view(np.int64)


def test_kernels_exp_and_arctan2_are_numpys_bit_for_bit():
    module = numerics
    rng = np.random.default_rng(11)
    x = np.concatenate([rng.uniform(-500.0, 500.0, 3000), rng.uniform(-2.0, 2.0, 3000), [0.0, -0.0, 1e-300]])
    y, z = rng.normal(size=(2, 4000)) * np.repeat([1.0, 1e-4, 1e4], [2000, 1000, 1000])
    y[:6], z[:6] = [0.0, -0.0, 0.0, -0.0, 1.0, -1.0], [0.0, 0.0, -0.0, -0.0, 0.0, -0.0]
    modes = [module.numpy_math(), np.array([module.MATH_NUMPY, 0, 0])]  # this machine's; numpy from the kernel
    for fns in modes:
        np.testing.assert_array_equal(_bits(_exp_each(module.np_exp, x, fns)), _bits(np.exp(x)))
        for n in (0, 1, 7, 8, 9, 17, 4000):  # whole vectors of 8 and zero-padded tails
            out = np.full(n, np.nan)
            module.np_arctan2(y[:n], z[:n], out, fns)
            np.testing.assert_array_equal(_bits(out), _bits(np.arctan2(y[:n], z[:n])))
        out = np.full(2000, np.nan)  # strided views
        module.np_arctan2(y[::2], z[::2], out, fns)
        np.testing.assert_array_equal(_bits(out), _bits(np.arctan2(y[::2], z[::2])))
    # The C library's branch gives the C library's numbers (used where they are numpy's).
    libm = np.array([module.MATH_LIBM, 0, 0])
    assert list(_exp_each(module.np_exp, x[:200], libm)) == [math.exp(v) for v in x[:200]]
    out = np.empty(200)
    module.np_arctan2(y[:200], z[:200], out, libm)
    assert list(out) == [math.atan2(a, b) for a, b in zip(y[:200], z[:200])]


def test_world_and_agents_kernels_share_one_numerics_module():
    # The world's and the agents' kernels take numpy's numbers from the one module, not copies.
    for name in ("call_next_double", "np_arctan2"):
        assert getattr(kernels, name) is getattr(numerics, name) is getattr(agent_kernels, name)
    assert agent_kernels.np_exp is numerics.np_exp


def test_wrap_skips_fmod_but_keeps_numpys_modulo():
    rng = np.random.default_rng(2)
    edges = [0.0, -0.0, math.pi, -math.pi, 2 * math.pi, -2 * math.pi, 3 * math.pi, -3 * math.pi, 1e300, -1e300]
    edges += [np.nextafter(v, d) for v in (math.pi, -math.pi, 3 * math.pi, -3 * math.pi) for d in (-10, 10)]
    a = np.concatenate([rng.uniform(-20.0, 20.0, 20000), edges])
    expected = _bits(wrap_angle(a))  # (a + pi) % (2 pi) - pi in numpy

    @njit
    def each(f, a):
        out = np.empty_like(a)
        for q in range(a.shape[0]):
            out[q] = f(a[q])
        return out

    np.testing.assert_array_equal(_bits(each(kernels.wrap, a)), expected)
    np.testing.assert_array_equal(_bits(each(agent_kernels._wrap, a)), expected)


# ------------------------------------------------------------------ a world tick, by its models


def _reference_observe(world, pose, rng):
    """What observe() must give, from the public model functions (numpy draws)."""
    cfg = world.config
    ir = ir_proximity(pose, cfg.body.body_radius_m, world.arena, cfg.sensors, rng)
    ground = ground_sensors(pose, world.arena, cfg.sensors, rng)
    return ir, ground


def _reference_step(world, pose, cmd, sending, rng):
    """What step() must do, from the public model functions: the medium (world/epuck/medium.py:
    deliver), the slip, the kinematics (protocol/epuck.py) and the collisions (world/epuck/arena.py)."""
    cfg, body = world.config, world.config.body
    alive = world.alive
    steps = np.where(alive[:, None], np.clip(cmd, -body.max_wheel_speed_steps_s, body.max_wheel_speed_steps_s)
                     * cfg.tick_s, 0.0)
    heard = deliver(pose, sending & alive, cfg.medium, rng)
    s, n_sub = cfg.odometry.slip_fraction, cfg.odometry.substeps
    slips = rng.uniform(-s, s, (n_sub, len(pose), 2))  # one slip per wheel and physics sub-step
    moved = pose
    for k in range(n_sub):
        du = steps / n_sub * body.metres_per_step * (1.0 + slips[k])
        moved = integrate_pose(moved, du[:, 0], du[:, 1], body.wheelbase_m)
    moved[:, :2] = resolve_collisions(moved[:, :2], body.body_radius_m, world.arena, iterations=2)
    return moved, steps, heard


@pytest.mark.parametrize("case", ["plain", "crowd", "moved_in_between", "small_buffers", "substeps"])
def test_world_ticks_are_the_model_functions(case):
    substeps = ["world.odometry.substeps=10"] if case == "substeps" else []
    scenario = load_scenario("ES1", ["world.robots=30", "agent.strategy=SSGIKF", "world.duration_s=12", *substeps])
    world = ForagingWorld(scenario.world)
    brain = swarm_brain(scenario)
    if case == "crowd":  # bodies on top of each other: the KD-tree collisions of arena.py
        world.pose[:, :2] = 0.6 + np.random.default_rng(1).uniform(-0.06, 0.06, (30, 2))
    reference = ForagingMetrics(30, scenario.world.tick_s)
    nudge = np.random.default_rng(5)
    sent, heard, delivered = None, None, 0
    while not world.done:
        if world.tick == 40:
            world.kill(3)
        if case == "small_buffers":  # the pairs and the messages do not fit: grown, or allocated
            world._pair_buffers(1)
            world._work_i, world._work_f = np.empty((5, 1), np.int64), np.empty((7, 1))
        if case == "moved_in_between" and world.tick % 3 == 1:  # in place, after the last step
            world.pose[::4, :2] += nudge.uniform(-0.02, 0.02, (8, 2))
        rng = copy.deepcopy(world.rng)
        pose = world.pose.copy()
        obs = world.observe()
        ir, ground = _reference_observe(world, pose, rng)
        np.testing.assert_array_equal(obs.ir, ir)
        np.testing.assert_array_equal(obs.ground, ground)
        if heard is not None:
            live = world.alive[heard.receiver]
            for got, want in zip((obs.deliveries.sender, obs.deliveries.receiver, obs.deliveries.range_m,
                                  obs.deliveries.bearing_rad),
                                 (heard.sender, heard.receiver, heard.range_m, heard.bearing_rad)):
                np.testing.assert_array_equal(got, want[live])
            delivered += len(obs.deliveries)
        out = brain.step(obs.encoder_steps, obs.ir, obs.ground, inbox_from(obs, sent, brain.robot_ids))
        np.testing.assert_array_equal(out.on_path, on_path(out.state))
        if case == "moved_in_between" and world.tick % 3 == 2:  # in place, after sensing
            world.pose[1::5, :2] += nudge.uniform(-0.02, 0.02, (6, 2))
        pose = world.pose.copy()
        moved, steps, heard = _reference_step(world, pose, out.wheel_speed_steps_s, out.sending, rng)
        world.step(out.wheel_speed_steps_s, out.sending, out.on_path)
        np.testing.assert_array_equal(world.pose, moved)
        np.testing.assert_array_equal(world.encoder_steps, steps)
        reference.update(world.tick, area_at(ground_sensor_point(moved), world.arena), out.on_path & world.alive)
        assert world.rng.random() == rng.random()  # no draw more, none less
        world.rng = rng  # the twin goes on (the kernels find its numbers' address anew)
        sent = out
    assert world.metrics.summary() == reference.summary()
    assert delivered > 100  # messages did cross


# --------------------------------------------------------- the batch engine's compiled ticks


def _swarm_state(world, brain):
    return [world.pose, world.encoder_steps, world.tick, world.metrics.summary(), world.rng.random(),
            brain.pose, *brain.pose_history, brain.tick, brain.known, brain.goal_xy, brain.goal_p_m, brain.target,
            brain.searching, brain.search_left_m, brain.lost_count, brain.visit_ticks, brain.turn_ticks,
            brain.straight_ticks, brain.turn_dir, brain.heard_ids, brain.heard_bearing_rad, brain.heard_range_m,
            brain.partner_ids, brain.partner_until, [g.random() for g in brain.rngs]]


@pytest.mark.parametrize("case", ["NC", "SSGIKF", "DSGIFF", "GLOBAL_RB", "crowd", "no_room", "readings", "comm",
                                  "comm-each"])
def test_compiled_ticks_leave_world_and_brains_as_their_methods_do(case):
    strategy = case if case in ("NC", "SSGIKF", "DSGIFF", "GLOBAL_RB") else "SSGIFF"
    readings = {"readings": READINGS, "comm": COMM, "comm-each": COMM_EACH}.get(case, ())
    scenario = load_scenario("ES1", ["world.robots=20", f"agent.strategy={strategy}", "world.duration_s=15", *readings])
    runs = []
    for compiled in (True, False):
        world, brain = ForagingWorld(scenario.world), swarm_brain(scenario)
        if case == "crowd":
            world.pose[:, :2] = 0.6 + np.random.default_rng(2).uniform(-0.05, 0.05, (20, 2))
        seen = []

        def between(world=world, brain=brain, seen=seen):
            # what a central system sees between the brains' step and the world's; it may also
            # change the brains (here: robot 0 forgets the nest every 40 ticks)
            seen.append((world.tick, brain.tick, world.pose.copy(), brain.pose.copy(), brain.goal_xy.copy()))
            if world.tick % 40 == 39:
                brain.known[0, 0] = False
            if case == "no_room" and world.tick % 7 == 0:
                world._pair_buffers(1)  # the pairs will not fit: found again, with room

        assert CompiledTicks.usable(world, brain)
        run_ticks(world, brain, between, compiled=compiled)
        runs.append((_swarm_state(world, brain), seen))
    (state, seen), (state_ref, seen_ref) = runs
    assert len(seen) == len(seen_ref) == scenario.world.n_ticks
    for a, b in zip(seen, seen_ref):
        for x, y in zip(a, b):
            np.testing.assert_array_equal(x, y)
    for x, y in zip(state, state_ref):
        np.testing.assert_array_equal(x, y)


def test_compiled_ticks_are_for_a_whole_swarm_in_index_order_without_covariances():
    scenario = load_scenario("ES1", ["world.duration_s=5"])
    world = ForagingWorld(scenario.world)
    assert not CompiledTicks.usable(world, swarm_brain(scenario, [0, 1]))
    assert not CompiledTicks.usable(world, swarm_brain(scenario, np.arange(10)[::-1]))
    sikf = load_scenario("ES1", ["world.duration_s=5", "agent.strategy=SSIKF"])
    assert not CompiledTicks.usable(world, swarm_brain(sikf))
    with pytest.raises(ValueError, match="brain"):
        CompiledTicks(world, swarm_brain(sikf))
