"""Global imitation (seed 001 §5): every robot averages the whole group's estimates, every tick.

Seed 001 compares social odometry (local imitation: pairwise, 15 cm, weighted by confidence)
with *global imitation*: "robots learn from all robots present in the arena. Each robot updates
its estimate by averaging the knowledge of the whole group" -- the good estimates and those of
robots already lost alike, which is why the paper finds it worse than the best local imitation.
It "would additionally require either more expensive devices or a central system" (§6).

swarmloc models both means the paper names. Every tick each robot turns each teammate's goal
estimate into its own frame with eq. 27 of seed 000, exactly as social odometry does for one
neighbour, over the true range and bearings between them, and sets its estimate to the plain mean
of those and its own -- the good estimates and the lost robots' alike. Strategy ``GLOBAL`` is the
central system: the transfer is exact. ``GLOBAL_RB`` is range-and-bearing boards of unlimited
range (the "more expensive devices"): the ranges and bearings carry the 15 cm medium's noise
(range +-2.5 cm, each bearing +-20 deg, uniform; no loss), so a teammate metres away arrives
metres off. Its confidence ``p`` becomes the knowers' mean ``p``. Every robot then knows every goal any robot knows; as in the receive layer of
social odometry (seed 000 §6.1.1), a wandering robot that has thereby learnt a goal heads for the
nearer one. With the noise set to zero the transfer is exact: each estimate is carried into the
arena frame by its robot's true and believed poses and back (:func:`to_arena_frame`,
:func:`to_robot_frames`), the test that pins eq. 27 here.

The central system needs the true poses, which only the world has: it runs in the batch engine
(:mod:`swarmloc.deploy.lab.epuck.batch`), between the brains' step and the world's. The world-server and the
agent processes refuse the strategy (``Strategy.central``) rather than run something else.
"""

from __future__ import annotations

import numpy as np

from swarmloc.agents.epuck.social_odometry import transform_received


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


def transfer(
    goal_xy: np.ndarray,
    believed_pose: np.ndarray,
    true_pose: np.ndarray,
    rng: np.random.Generator | None = None,
    range_noise_m: float = 0.0,
    bearing_noise_rad: float = 0.0,
) -> np.ndarray:
    """Every robot's goal estimates as every other robot receives them: ``out[i, j, g]`` is robot
    ``j``'s estimate of goal ``g`` in robot ``i``'s odometric frame (N, N, G, 2), carried over
    the true range and both true bearings between them plus uniform noise (seed 000 eq. 27);
    ``out[i, i]`` is robot ``i``'s own estimate, untouched. Noise needs ``rng``."""
    n = goal_xy.shape[0]
    # each sender's goals in its body frame: distance and angle (what a message carries)
    rel = _rotate(goal_xy - believed_pose[:, None, :2], -believed_pose[:, 2:3])
    goal_distance_m = np.hypot(rel[..., 0], rel[..., 1])  # (N, G)
    goal_angle_rad = np.arctan2(rel[..., 1], rel[..., 0])
    # the true geometry of each pair (receiver i, sender j), then the boards' noise
    v = true_pose[None, :, :2] - true_pose[:, None, :2]  # i -> j, (N, N, 2)
    range_m = np.hypot(v[..., 0], v[..., 1])
    direction = np.arctan2(v[..., 1], v[..., 0])
    bearing_receiver_rad = direction - true_pose[:, None, 2]  # j as seen by i
    bearing_sender_rad = (direction + np.pi) - true_pose[None, :, 2]  # i as seen by j
    if range_noise_m or bearing_noise_rad:
        range_m = range_m + rng.uniform(-range_noise_m, range_noise_m, (n, n))
        bearing_receiver_rad = bearing_receiver_rad + rng.uniform(-bearing_noise_rad, bearing_noise_rad, (n, n))
        bearing_sender_rad = bearing_sender_rad + rng.uniform(-bearing_noise_rad, bearing_noise_rad, (n, n))
    # eq. 27, the very function social odometry uses for one neighbour, for every pair and goal
    n_goals = goal_xy.shape[1]
    pair = np.broadcast_to
    local = transform_received(
        pair(range_m[..., None], (n, n, n_goals)).ravel(),
        pair(bearing_receiver_rad[..., None], (n, n, n_goals)).ravel(),
        pair(bearing_sender_rad[..., None], (n, n, n_goals)).ravel(),
        pair(goal_distance_m[None], (n, n, n_goals)).ravel(),
        pair(goal_angle_rad[None], (n, n, n_goals)).ravel(),
    ).reshape(n, n, n_goals, 2)
    out = believed_pose[:, None, None, :2] + _rotate(local, believed_pose[:, None, None, 2])
    idx = np.arange(n)
    out[idx, idx] = goal_xy
    return out


def imitate_globally(
    goal_xy: np.ndarray,
    known: np.ndarray,
    goal_p_m: np.ndarray,
    target: np.ndarray,
    searching: np.ndarray,
    believed_pose: np.ndarray,
    true_pose: np.ndarray,
    rng: np.random.Generator | None = None,
    range_noise_m: float = 0.0,
    bearing_noise_rad: float = 0.0,
) -> None:
    """One tick of global imitation, in place on the brains' state.

    ``goal_xy`` (N, 2, 2) estimates in each robot's odometric frame, ``known`` (N, 2),
    ``goal_p_m`` (N, 2) the inverse confidences, ``target`` (N,) the goal each robot heads to
    (-1: none), ``searching`` (N,), ``believed_pose``/``true_pose`` (N, 3); the boards' noise
    (uniform half-widths) drawn from ``rng``, none by default.
    """
    n_goals = known.shape[1]
    if not known.any():
        return
    exact = not (range_noise_m or bearing_noise_rad)
    if exact:  # the central system: the mean in the arena frame, handed back to each robot
        arena = to_arena_frame(goal_xy, believed_pose, true_pose)
    else:  # the boards: each robot averages what it received, its own estimate included
        heard = transfer(goal_xy, believed_pose, true_pose, rng, range_noise_m, bearing_noise_rad)
    learnt = np.zeros_like(known)
    for goal in range(n_goals):
        who = known[:, goal]
        if not who.any():
            continue
        if exact:
            mean_xy = arena[who, goal].mean(axis=0)
            goal_xy[:, goal] = to_robot_frames(mean_xy[None, :], believed_pose, true_pose)[:, 0]
        else:
            goal_xy[:, goal] = heard[:, who, goal].mean(axis=1)
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


#: The central system's own random stream (the world's is 0, the agents' 1).
CENTRAL_STREAM = 2


def central_rng(seed: int) -> np.random.Generator:
    """The generator of the boards' noise in global imitation, derived from the run seed."""
    return np.random.default_rng([seed, CENTRAL_STREAM])


def imitate_brain(brain, true_pose: np.ndarray, rng: np.random.Generator, medium) -> None:
    """:func:`imitate_globally` on a :class:`~swarmloc.agents.epuck.foraging.ForagingBrain` holding the
    whole swarm, given the robots' true poses (the world's ``pose``); with its strategy's
    ``central == "boards"``, the transfer has the noise of the range-and-bearing ``medium``
    (``world.epuck.medium.RabMedium``)."""
    if brain.strategy.central == "boards":
        noise = (medium.range_noise_m, medium.bearing_noise_rad)
    else:
        noise = (0.0, 0.0)
    imitate_globally(brain.goal_xy, brain.known, brain.goal_p_m, brain.target, brain.searching,
                     brain.pose, true_pose, rng, *noise)
