"""Global imitation (seed 001 §5): every robot averages the whole group's estimates, every tick.

Seed 001 compares social odometry (local imitation: pairwise, 15 cm, weighted by confidence)
with *global imitation*: "robots learn from all robots present in the arena. Each robot updates
its estimate by averaging the knowledge of the whole group" -- the good estimates and those of
robots already lost alike, which is why the paper finds it worse than the best local imitation.
It "would additionally require either more expensive devices or a central system" (§6).

swarmloc models that central system: it knows every robot's true pose and believed (dead-reckoned)
pose, so it can carry each robot's estimate of a goal, kept in that robot's own odometric frame,
into the arena frame (``w = t_xy + R(t_theta - b_theta) (e - b_xy)``), average the estimates of
the robots that know the goal, and carry the mean back into each robot's frame
(``e_i = b_xy_i + R(b_theta_i - t_theta_i) (m - t_xy_i)``). Every robot then knows every goal any
robot knows; its confidence ``p`` becomes the knowers' mean ``p``. As in the receive layer of
social odometry (seed 000 §6.1.1), a wandering robot that has thereby learnt a goal heads for the
nearer one.

The central system needs the true poses, which only the world has: it runs in the batch engine
(:mod:`swarmloc.deploy.batch`), between the brains' step and the world's. The world-server and the
agent processes refuse the strategy (``Strategy.central``) rather than run something else.
"""

from __future__ import annotations

import numpy as np


def _rotate(xy: np.ndarray, angle_rad: np.ndarray) -> np.ndarray:
    """Rotate points ``xy`` (..., 2) by ``angle_rad`` (...)."""
    c, s = np.cos(angle_rad), np.sin(angle_rad)
    return np.stack([c * xy[..., 0] - s * xy[..., 1], s * xy[..., 0] + c * xy[..., 1]], axis=-1)


def to_arena_frame(points_xy: np.ndarray, believed_pose: np.ndarray, true_pose: np.ndarray) -> np.ndarray:
    """Points (N, G, 2) in each robot's odometric frame -> the arena frame, from its believed and
    true poses (N, 3) (x_m, y_m, theta_rad)."""
    rel = points_xy - believed_pose[:, None, :2]
    turn = (true_pose[:, 2] - believed_pose[:, 2])[:, None]
    return true_pose[:, None, :2] + _rotate(rel, turn)


def to_robot_frames(points_xy: np.ndarray, believed_pose: np.ndarray, true_pose: np.ndarray) -> np.ndarray:
    """Arena points (G, 2) -> every robot's odometric frame: (N, G, 2). Inverse of
    :func:`to_arena_frame`."""
    rel = points_xy[None, :, :] - true_pose[:, None, :2]
    turn = (believed_pose[:, 2] - true_pose[:, 2])[:, None]
    return believed_pose[:, None, :2] + _rotate(rel, turn)


def imitate_globally(
    goal_xy: np.ndarray,
    known: np.ndarray,
    goal_p_m: np.ndarray,
    target: np.ndarray,
    searching: np.ndarray,
    believed_pose: np.ndarray,
    true_pose: np.ndarray,
) -> None:
    """One tick of global imitation, in place on the brains' state.

    ``goal_xy`` (N, 2, 2) estimates in each robot's odometric frame, ``known`` (N, 2),
    ``goal_p_m`` (N, 2) the inverse confidences, ``target`` (N,) the goal each robot heads to
    (-1: none), ``searching`` (N,), ``believed_pose``/``true_pose`` (N, 3).
    """
    n_goals = known.shape[1]
    if not known.any():
        return
    arena = to_arena_frame(goal_xy, believed_pose, true_pose)
    learnt = np.zeros_like(known)
    for goal in range(n_goals):
        who = known[:, goal]
        if not who.any():
            continue
        mean_xy = arena[who, goal].mean(axis=0)
        goal_xy[:, goal] = to_robot_frames(mean_xy[None, :], believed_pose, true_pose)[:, 0]
        goal_p_m[:, goal] = goal_p_m[who, goal].mean()
        learnt[:, goal] = ~who
        known[:, goal] = True
    # A wandering robot that has just learnt a goal heads for the nearer goal it learnt.
    wandering = (target < 0) & learnt.any(axis=1)
    if wandering.any():
        dist = np.linalg.norm(goal_xy[wandering] - believed_pose[wandering, None, :2], axis=2)
        dist = np.where(learnt[wandering], dist, np.inf)
        target[wandering] = np.argmin(dist, axis=1)
        searching[wandering] = False


def imitate_brain(brain, true_pose: np.ndarray) -> None:
    """:func:`imitate_globally` on a :class:`~swarmloc.agents.foraging.ForagingBrain` holding the
    whole swarm, given the robots' true poses (the world's ``pose``)."""
    imitate_globally(brain.goal_xy, brain.known, brain.goal_p_m, brain.target, brain.searching,
                     brain.pose, true_pose)
