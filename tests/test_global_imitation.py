"""Global imitation (seed 001 §5): the central average of the whole group's estimates."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.agents.epuck.global_imitation import (
    imitate_globally,
    to_arena_frame,
    to_robot_frames,
    transfer,
)
from swarmloc.deploy.cli import main
from swarmloc.deploy.lab.epuck.batch import run_batch, swarm_brain
from swarmloc.deploy.scenario import load_scenario
from swarmloc.world.epuck.foraging import ForagingWorld


def _state(n):
    return (np.zeros((n, 2, 2)), np.zeros((n, 2), bool), np.zeros((n, 2)), np.full(n, -1),
            np.ones(n, bool))


def test_hand_worked_average_reaches_a_robot_that_knew_nothing():
    # Robot 0 believes it is at the origin facing +x but really stands at (1, 2) facing +y: the
    # goal it believes 1 m ahead is really at (1, 3). Robot 1 is where it believes it is and puts
    # the goal at (3, 3). The mean is (2, 3). Robot 2 believes (0, 0, 0) but stands at (2, 0)
    # facing -x: (2, 3) is 3 m to its right, i.e. (0, -3) in its frame.
    goal_xy, known, p, target, searching = _state(3)
    goal_xy[0, 0] = (1.0, 0.0)
    goal_xy[1, 0] = (3.0, 3.0)
    known[:2, 0] = True
    p[0, 0], p[1, 0] = 0.4, 0.2
    believed = np.zeros((3, 3))
    true = np.array([[1.0, 2.0, math.pi / 2], [0.0, 0.0, 0.0], [2.0, 0.0, math.pi]])
    imitate_globally(goal_xy, known, p, target, searching, believed, true)
    np.testing.assert_allclose(goal_xy[1, 0], (2.0, 3.0), atol=1e-12)
    np.testing.assert_allclose(goal_xy[2, 0], (0.0, -3.0), atol=1e-12)
    # robot 0: (2, 3) is 1 m ahead (+y) and 1 m to the right (+x) of (1, 2) facing +y
    np.testing.assert_allclose(goal_xy[0, 0], (1.0, -1.0), atol=1e-12)
    assert known[:, 0].all() and not known[:, 1].any()
    np.testing.assert_allclose(p[:, 0], 0.3)
    # robot 2 learnt goal 0 and heads for it; 0 and 1 learnt nothing and go on looking for goal 1
    assert target.tolist() == [-1, -1, 0]
    assert searching.tolist() == [True, True, False]
    assert goal_xy[:, 1].tolist() == [[0.0, 0.0]] * 3


def test_wanderer_heads_for_the_nearer_goal_and_others_keep_their_target():
    goal_xy, known, p, target, searching = _state(2)
    # robot 0 knows both: nest 1 m east, prey 4 m north of where both robots really are
    goal_xy[0, 0] = (1.0, 0.0)
    goal_xy[0, 1] = (0.0, 4.0)
    known[0] = True
    target[0] = 1
    pose = np.zeros((2, 3))
    imitate_globally(goal_xy, known, p, target, searching, pose, pose.copy())
    assert target.tolist() == [1, 0]  # robot 1 learnt both and takes the nearer, the nest


def test_frames_round_trip_for_random_poses():
    rng = np.random.default_rng(3)
    believed = np.column_stack([rng.uniform(-5, 5, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    true = np.column_stack([rng.uniform(-5, 5, (50, 2)), rng.uniform(-np.pi, np.pi, 50)])
    points = rng.uniform(-3, 3, (50, 2, 2))
    arena = to_arena_frame(points, believed, true)
    for i in range(50):  # back into robot i's frame, one robot at a time
        back = to_robot_frames(arena[i], believed, true)[i]
        np.testing.assert_allclose(back, points[i], atol=1e-9)
        # distances from the robot are kept: a rigid change of frame
        d_own = np.linalg.norm(points[i] - believed[i, :2], axis=1)
        d_arena = np.linalg.norm(arena[i] - true[i, :2], axis=1)
        np.testing.assert_allclose(d_own, d_arena, atol=1e-9)


def _random_poses(rng, n):
    return np.column_stack([rng.uniform(-3, 3, (n, 2)), rng.uniform(-np.pi, np.pi, n)])


def test_noise_free_transfer_by_eq27_equals_the_change_of_frames():
    # eq. 27 over true ranges and bearings vs carrying each estimate through the arena frame
    rng = np.random.default_rng(11)
    n = 7
    believed, true = _random_poses(rng, n), _random_poses(rng, n)
    goals = rng.uniform(-4, 4, (n, 2, 2))
    heard = transfer(goals, believed, true)
    arena = to_arena_frame(goals, believed, true)
    for j in range(n):
        np.testing.assert_allclose(heard[:, j], to_robot_frames(arena[j], believed, true), atol=1e-9)


def test_board_noise_moves_a_goal_within_the_bound_of_its_range_and_bearing_errors():
    # A range error dr and bearing errors dgi, dgj move the received goal by at most
    # |dr| + (r + d) |dgi| + d |dgj| (r: range, d: goal distance from the sender); the noise is
    # applied (errors are not all zero) and grows with the range between robots.
    rng = np.random.default_rng(5)
    rn, bn = 0.025, math.radians(20)
    believed = np.zeros((2, 3))
    errors = {}
    for r in (0.1, 3.0):
        true = np.array([[0.0, 0.0, 0.3], [r, 0.0, -1.0]])
        goals = np.zeros((2, 2, 2))
        goals[1, 0] = (1.0, 0.0)  # 1 m ahead of the sender
        exact = transfer(goals, believed, true)[0, 1, 0]
        samples = np.array([transfer(goals, believed, true, rng, rn, bn)[0, 1, 0] for _ in range(2000)])
        dev = np.linalg.norm(samples - exact, axis=1)
        assert dev.max() <= rn + (r + 1.0) * bn + 1.0 * bn + 1e-9
        assert dev.min() < dev.max()
        errors[r] = dev.mean()
    assert errors[3.0] > 2 * errors[0.1]


def test_in_the_batch_engine_every_robot_holds_the_same_arena_point_each_tick():
    sc = load_scenario("SO-3.0x3.0", ["world.robots=12", "agent.strategy=GLOBAL", "world.duration_s=400.0",
                                      "world.seed=4"])
    world, brain = ForagingWorld(sc.world), swarm_brain(sc)
    from swarmloc.agents.epuck.foraging import on_path
    from swarmloc.deploy.lab.epuck.batch import inbox_from

    sent, checked = None, 0
    while not world.done:
        obs = world.observe()
        out = brain.step(obs.encoder_steps, obs.ir, obs.ground, inbox_from(obs, sent, brain.robot_ids))
        # noise-free boards: every robot must end up holding the same arena point
        imitate_globally(brain.goal_xy, brain.known, brain.goal_p_m, brain.target, brain.searching,
                         brain.pose, world.pose)
        for goal in range(2):
            if brain.known[:, goal].any():
                assert brain.known[:, goal].all()
                arena = to_arena_frame(brain.goal_xy, brain.pose, world.pose)[:, goal]
                np.testing.assert_allclose(arena, np.broadcast_to(arena[0], arena.shape), atol=1e-9)
                checked += 1
        world.step(out.wheel_speed_steps_s, out.sending, on_path(out.state))
        sent = out
    assert checked > 100, "no robot found a goal: the test checked nothing"


def test_global_imitation_recruits_faster_than_no_imitation():
    # Every robot learns a goal as soon as one robot finds it, so all visit both areas sooner.
    nc, gl = [], []
    for seed in (1, 2, 3):
        base = ["world.robots=15", "world.duration_s=900.0", f"world.seed={seed}"]
        nc.append(run_batch(load_scenario("SO-3.0x3.0", base + ["agent.strategy=NC"])).metrics)
        gl.append(run_batch(load_scenario("SO-3.0x3.0", base + ["agent.strategy=GLOBAL"])).metrics)
    found = lambda ms: sum(m["robots_found_both"] for m in ms)
    assert found(gl) > found(nc)


@pytest.mark.parametrize("command", ["run", "world"])
def test_processes_refuse_the_central_strategy_before_starting(command, capsys, monkeypatch):
    from swarmloc.deploy import launch
    from swarmloc.protocol import session

    def boom(*args, **kwargs):
        raise AssertionError("something was started despite the refused strategy")

    monkeypatch.setattr(launch, "start_router", boom)
    monkeypatch.setattr(session, "open_session", boom)
    code = main([command, "SO-3.0x3.0", "--strategy", "GLOBAL"])
    err = capsys.readouterr().err
    assert code == 2
    assert "GLOBAL" in err and "batch engine" in err


def test_world_service_refuses_the_central_strategy():
    from swarmloc.world.epuck.service import _foraging

    with pytest.raises(ValueError, match="GLOBAL"):
        _foraging(load_scenario("ES1", ["agent.strategy=GLOBAL"]))


def test_boards_average_what_each_robot_received_and_the_system_the_exact_mean():
    # The same state through both means: without noise they agree; with the boards' noise each
    # robot's estimate is the mean of its received copies (its own exact), not the exact mean.
    rng = np.random.default_rng(2)
    n = 6
    believed, true = _random_poses(rng, n), _random_poses(rng, n)
    goal_xy = rng.uniform(-4, 4, (n, 2, 2))
    known = np.zeros((n, 2), bool)
    known[:4, 0] = True

    def run(noise, seed):
        g, k, p = goal_xy.copy(), known.copy(), np.ones((n, 2))
        imitate_globally(g, k, p, np.full(n, -1), np.zeros(n, bool), believed, true,
                         np.random.default_rng(seed), *noise)
        return g

    exact = run((0.0, 0.0), 0)
    heard = transfer(goal_xy, believed, true)
    np.testing.assert_allclose(exact[:, 0], heard[:, :4, 0].mean(axis=1), atol=1e-9)
    noisy = run((0.025, math.radians(20)), 7)
    expected = transfer(goal_xy, believed, true, np.random.default_rng(7), 0.025, math.radians(20))
    np.testing.assert_allclose(noisy[:, 0], expected[:, :4, 0].mean(axis=1), atol=1e-12)
    assert np.abs(noisy[:, 0] - exact[:, 0]).max() > 0.01
