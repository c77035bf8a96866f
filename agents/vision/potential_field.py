"""Potential-field navigation and goal assignment of seed 004's vision robots (§III-IV, eq. 3-5).

Seed 004 §III models each robot as a free particle in a potential field (PFA):

- eq. 3: ``U(q) = U_g(q) + sum_o U_o(q)``;
- eq. 4: ``U_g(q) = k1 dist(q, goal)^2``, so ``F_g = -grad U_g = 2 k1 (goal - q)``;
- eq. 5: ``U_o(q) = k2 / dist(q, obstacle)``, so ``F_o = -grad U_o = k2 (q - o) / |q - o|^3``
  (magnitude ``k2 / dist^2``, pointing away from the obstacle).

Teammates at their estimated positions are repulsors too ("agents in the environment are simply
modelled as moving obstacles"), with their own gain and radius.

Goal assignment (§IV, experiments 2 and 3): "The AIBO that is nearest to the orange box have to
catch it, so the other AIBO has to catch the rose ball" (:func:`assign_goals`).

Choices where the paper is ambiguous
------------------------------------
- **Gains and radii.** The paper gives no values for ``k1``, ``k2`` and eq. 5 has no range. Here
  each repulsor acts only inside an influence radius (zero force at and beyond it), with the
  unshifted eq. 5 force inside; all values are parameters of :class:`FieldParams`, the defaults
  are tuned for Aibo-sized robots (about 0.3 m long, 0.3 m/s), not taken from the paper.
- **Force as velocity.** The particle's desired velocity is the force itself (gains in 1/s and
  m^3/s make it m/s), saturated at ``max_speed_mps``; the heading is its direction. A zero force
  (at the goal, or balanced) keeps the current heading: ``heading_rad`` is ``None``.
- **Singularity.** Eq. 5 diverges at the obstacle; distances are clamped below at
  ``min_distance_m``. A repulsor exactly at the robot's position has no direction and is skipped.
- **The goal is not a repulsor**: when a robot's goal is the obstacle (experiment 2), the caller
  must not also list it among the obstacles.
- **Ties** in goal assignment go to the lower robot index, so that robots computing the rule
  independently from the same estimates agree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

BALL = "ball"
OBSTACLE = "obstacle"


@dataclass(frozen=True)
class FieldParams:
    """Gains and radii of eq. 3-5 (see the module docstring for units and defaults)."""

    k1_per_s: float = 0.5  # eq. 4 attraction gain
    k2_obstacle_m3_per_s: float = 0.01  # eq. 5 gain for obstacles
    obstacle_radius_m: float = 0.5  # influence radius of an obstacle
    k2_teammate_m3_per_s: float = 0.02  # eq. 5 gain for teammates
    teammate_radius_m: float = 0.6  # influence radius of a teammate
    max_speed_mps: float = 0.3
    min_distance_m: float = 0.05

    def __post_init__(self) -> None:
        for name, value in vars(self).items():
            if not isinstance(value, (int, float)) or not math.isfinite(value):
                raise ValueError(f"{name} must be a finite number, got {value!r}")
            if value < 0.0:
                raise ValueError(f"{name} must be >= 0, got {value}")
        for name in ("max_speed_mps", "min_distance_m"):
            if getattr(self, name) <= 0.0:
                raise ValueError(f"{name} must be > 0")


@dataclass(frozen=True)
class FieldCommand:
    """Result of :func:`potential_field`: forces and the saturated desired velocity (m/s)."""

    attraction: np.ndarray
    repulsion: np.ndarray
    velocity_mps: np.ndarray
    heading_rad: float | None


def _points(points) -> np.ndarray:
    if points is None:
        return np.zeros((0, 2))
    arr = np.asarray(points, dtype=float).reshape(-1, 2)
    if not np.all(np.isfinite(arr)):
        raise ValueError("positions must be finite")
    return arr


def attraction(position_m, goal_m, k1_per_s: float) -> np.ndarray:
    """``-grad`` of eq. 4: ``2 k1 (goal - q)``. Vectorised over leading axes."""
    return 2.0 * k1_per_s * (np.asarray(goal_m, float) - np.asarray(position_m, float))


def repulsion(
    position_m, repulsors_m, k2_m3_per_s: float, radius_m: float, min_distance_m: float
) -> np.ndarray:
    """Sum of ``-grad`` of eq. 5 over ``(N, 2)`` repulsors: ``k2 (q - o) / |q - o|^3``.

    Only repulsors closer than ``radius_m`` act; the distance is clamped below at
    ``min_distance_m``; a repulsor exactly at ``q`` is skipped (no direction).
    """
    q = np.asarray(position_m, dtype=float)
    offsets = q - _points(repulsors_m)
    dist = np.hypot(offsets[:, 0], offsets[:, 1])
    active = (dist < radius_m) & (dist > 0.0)
    safe = np.where(active, dist, 1.0)
    clamped = np.maximum(safe, min_distance_m)
    forces = k2_m3_per_s * offsets / (safe * clamped**2)[:, None]
    return forces[active].sum(axis=0) if active.any() else np.zeros(2)


def potential(
    position_m, goal_m, obstacles_m=None, teammates_m=None, params: FieldParams = FieldParams()
) -> float:
    """Eq. 3 with eq. 4-5, inside the influence radii (for checks and plots)."""
    q = np.asarray(position_m, dtype=float)
    u = params.k1_per_s * float(np.sum((np.asarray(goal_m, float) - q) ** 2))
    for pts, k2, radius in (
        (obstacles_m, params.k2_obstacle_m3_per_s, params.obstacle_radius_m),
        (teammates_m, params.k2_teammate_m3_per_s, params.teammate_radius_m),
    ):
        dist = np.hypot(*(q - _points(pts)).T)
        inside = dist < radius
        u += float(np.sum(k2 / np.maximum(dist[inside], params.min_distance_m)))
    return u


def potential_field(
    position_m, goal_m, obstacles_m=None, teammates_m=None, params: FieldParams = FieldParams()
) -> FieldCommand:
    """Desired velocity and heading at ``position_m`` (eq. 3-5); all positions in one frame.

    ``goal_m`` may be ``None`` (no goal known yet): only the repulsion acts.
    """
    q = _points(position_m)[0]
    f_goal = np.zeros(2) if goal_m is None else attraction(q, _points(goal_m)[0], params.k1_per_s)
    f_rep = repulsion(
        q, obstacles_m, params.k2_obstacle_m3_per_s, params.obstacle_radius_m, params.min_distance_m
    ) + repulsion(
        q, teammates_m, params.k2_teammate_m3_per_s, params.teammate_radius_m, params.min_distance_m
    )
    force = f_goal + f_rep
    speed = float(np.hypot(*force))
    velocity = force * (params.max_speed_mps / speed) if speed > params.max_speed_mps else force
    heading = math.atan2(force[1], force[0]) if speed > 1e-12 else None
    return FieldCommand(f_goal, f_rep, velocity, heading)


def assign_goals(robot_positions_m, obstacle_m=None, ball_m=None) -> list[str | None]:
    """Goals of seed 004 §IV: the robot nearest the obstacle takes it, the others the ball.

    ``robot_positions_m`` is ``(N, 2)`` in one frame. Without an obstacle every robot takes the
    ball (experiment 1); a goal whose position is unknown (``None``) is ``None``; ties go to the
    lower index.
    """
    robots = _points(robot_positions_m)
    goals: list[str | None] = [BALL if ball_m is not None else None] * len(robots)
    if obstacle_m is not None and len(robots):
        dist = np.hypot(*(robots - _points(obstacle_m)[0]).T)
        goals[int(np.argmin(dist))] = OBSTACLE  # argmin returns the first of equal minima
    return goals
