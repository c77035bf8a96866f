"""E-puck proximity and ground sensors, and how a robot reads its ground sensors.

Seed 000 §6.1: the simulated e-puck carries 8 infrared proximity sensors around its body and 3
ground sensors on the bottom-front of the body; uniformly distributed noise of ±20 % is added to
the infrared readings and ±30 % to the ground readings. Sensor placement (angles, offsets) comes
from ``swarmloc.protocol.epuck``.

- :func:`ir_proximity`: each sensor casts a ray radially outward from its spot on the body
  perimeter; the distance ``d`` to the nearest wall or robot body (ray-circle intersection)
  gives ``clip(1 - d / ir_range_m, 0, 1)`` (1 = touching, 0 = nothing in range), then
  multiplicative noise ``1 + U(-f, f)``, clipped to [0, 1].
- :func:`ground_sensors`: floor reflectance (``world/arena.py``) under each ground sensor, times
  ``1 + U(-f, f)``.
  What a robot concludes from the readings is the agent's business
  (``swarmloc.agents.foraging.classify_ground``).

Random draws (fixed order, so a run is deterministic given ``rng``): :func:`ir_proximity` makes one
``rng.uniform(-f, f, size=(N, 8))`` call; :func:`ground_sensors` one
``rng.uniform(-f, f, size=(N, 3))`` call. Both draw even when the noise fraction is 0.
All functions work on a batch of robots: poses ``(N, 3)`` = (x_m, y_m, theta_rad).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from swarmloc.protocol.epuck import GROUND_SENSOR_OFFSETS_M, IR_SENSOR_ANGLES_RAD
from swarmloc.world.arena import Arena, ground_reflectance


@dataclass(frozen=True)
class SensorParams:
    """Proximity range and uniform noise fractions of seed 000 §6.1."""

    ir_range_m: float = 0.04
    ir_noise_fraction: float = 0.2
    ground_noise_fraction: float = 0.3

    def __post_init__(self) -> None:
        if not (math.isfinite(self.ir_range_m) and self.ir_range_m > 0.0):
            raise ValueError(f"ir_range_m must be finite and > 0, got {self.ir_range_m!r}")
        for name in ("ir_noise_fraction", "ground_noise_fraction"):
            value = getattr(self, name)
            if not (math.isfinite(value) and 0.0 <= value < 1.0):
                raise ValueError(f"{name} must be in [0, 1), got {value!r}")


def _check_pose(pose: np.ndarray) -> np.ndarray:
    pose = np.asarray(pose, dtype=float)
    if pose.ndim != 2 or pose.shape[1] != 3:
        raise ValueError(f"pose must have shape (N, 3), got {pose.shape}")
    return pose


def _kdtree(points_m: np.ndarray) -> cKDTree:
    # Unbalanced, non-compacted trees build about twice as fast and query as fast for the
    # near-uniform robot positions of a swarm.
    return cKDTree(points_m, balanced_tree=False, compact_nodes=False)


def ir_proximity(
    pose: np.ndarray,
    body_radius_m: float,
    arena: Arena,
    params: SensorParams,
    rng: np.random.Generator,
) -> np.ndarray:
    """Noisy readings ``(N, 8)`` in [0, 1] of the 8 IR proximity sensors (seed 000 §6.1).

    Sensor ``s`` sits on the body perimeter at ``IR_SENSOR_ANGLES_RAD[s]`` from the heading and
    looks radially outward. Obstacles: the 4 walls and the other robots (circles of
    ``body_radius_m``; candidates from a KD-tree within ``2 * body_radius_m + ir_range_m``).
    A sensor whose spot lies outside the walls or inside another body reads distance 0.
    Value ``clip(1 - d / ir_range_m, 0, 1) * (1 + U(-f, f))`` clipped to [0, 1], with ``f`` the
    IR noise fraction; one ``(N, 8)`` uniform draw.
    """
    pose = _check_pose(pose)
    n = pose.shape[0]
    n_s = IR_SENSOR_ANGLES_RAD.shape[0]
    r_m = float(body_radius_m)
    range_m = params.ir_range_m
    cos_a = np.cos(IR_SENSOR_ANGLES_RAD)
    sin_a = np.sin(IR_SENSOR_ANGLES_RAD)
    # Distance along each ray to the nearest obstacle; only robots near a wall or a robot are
    # worked on (fewer large temporaries: allocation dominates at N = 10,000).
    dist_m = np.full((n, n_s), np.inf)

    # Walls, for robots whose body is within ir_range_m of one (others cannot see a wall).
    reach_m = r_m + range_m
    x, y = pose[:, 0], pose[:, 1]
    near_wall = np.flatnonzero(
        (x < reach_m)
        | (x > arena.width_m - reach_m)
        | (y < reach_m)
        | (y > arena.height_m - reach_m)
    )
    if near_wall.size:
        th = pose[near_wall, 2:3]
        ux = np.cos(th) * cos_a - np.sin(th) * sin_a  # (W, 8) world ray directions
        uy = np.sin(th) * cos_a + np.cos(th) * sin_a
        ox = pose[near_wall, 0:1] + r_m * ux  # ray origins on the perimeter
        oy = pose[near_wall, 1:2] + r_m * uy
        wall_x = np.where(ux > 0.0, arena.width_m, 0.0)  # the wall each ray heads towards
        wall_y = np.where(uy > 0.0, arena.height_m, 0.0)
        tx = np.divide(wall_x - ox, ux, out=np.full_like(ux, np.inf), where=ux != 0.0)
        ty = np.divide(wall_y - oy, uy, out=np.full_like(uy, np.inf), where=uy != 0.0)
        d_wall = np.minimum(tx, ty)
        outside = (ox < 0.0) | (ox > arena.width_m) | (oy < 0.0) | (oy > arena.height_m)
        d_wall[outside] = 0.0
        dist_m[near_wall] = d_wall

    # Other robots: ordered candidate pairs (observer a, obstacle b), ray-circle intersection.
    # With D = centre_b - centre_a and k = D . u_s, the ray from the perimeter point
    # centre_a + r u_s meets circle b at t = k - r - sqrt(k^2 + r^2 - |D|^2) (if k - r >= 0 and
    # the root is real); |D|^2 <= 2 r k means the spot is inside or on body b (t = 0).
    if n >= 2:
        pairs = _kdtree(pose[:, :2]).query_pairs(2.0 * r_m + range_m, output_type="ndarray")
        if len(pairs):
            a = np.concatenate([pairs[:, 0], pairs[:, 1]])
            b = np.concatenate([pairs[:, 1], pairs[:, 0]])
            dx = pose[b, 0] - pose[a, 0]
            dy = pose[b, 1] - pose[a, 1]
            cos_t, sin_t = np.cos(pose[a, 2]), np.sin(pose[a, 2])
            fwd = dx * cos_t + dy * sin_t  # D in observer a's frame
            left = dy * cos_t - dx * sin_t
            d2 = dx * dx + dy * dy
            k = cos_a[:, None] * fwd + sin_a[:, None] * left  # (8, P)
            disc = k * k + (r_m * r_m - d2)
            t = k - r_m
            hit = (disc >= 0.0) & (t >= 0.0)
            d_pair = np.full(k.shape, np.inf)
            d_pair[hit] = t[hit] - np.sqrt(disc[hit])
            d_pair[d2 - 2.0 * r_m * k <= 0.0] = 0.0  # spot inside or on body b
            idx = a[None, :] * n_s + np.arange(n_s)[:, None]
            np.minimum.at(dist_m.reshape(-1), idx.reshape(-1), d_pair.reshape(-1))

    # Proximity value, then multiplicative noise (one (N, 8) draw), computed in place.
    value = dist_m
    value *= -1.0 / range_m
    value += 1.0
    np.clip(value, 0.0, 1.0, out=value)
    f = params.ir_noise_fraction
    noise = rng.uniform(-f, f, size=(n, n_s))
    noise += 1.0
    value *= noise
    return np.clip(value, 0.0, 1.0, out=value)


def ground_sensors(
    pose: np.ndarray, arena: Arena, params: SensorParams, rng: np.random.Generator
) -> np.ndarray:
    """Noisy readings ``(N, 3)`` of the 3 ground sensors (seed 000 §6.1).

    The sensor points ``GROUND_SENSOR_OFFSETS_M`` (robot frame) are moved to the world frame; the
    reading is the floor reflectance there times ``1 + U(-f, f)``, with ``f`` the ground noise
    fraction (one ``(N, 3)`` uniform draw). Not clipped: white reads in [0.7, 1.3] at f = 0.3.
    """
    pose = _check_pose(pose)
    c = np.cos(pose[:, 2])[:, None]
    s = np.sin(pose[:, 2])[:, None]
    offs = GROUND_SENSOR_OFFSETS_M
    points_m = np.empty((pose.shape[0], offs.shape[0], 2))
    points_m[..., 0] = pose[:, 0:1] + c * offs[None, :, 0] - s * offs[None, :, 1]
    points_m[..., 1] = pose[:, 1:2] + s * offs[None, :, 0] + c * offs[None, :, 1]
    reflectance = ground_reflectance(points_m, arena)
    f = params.ground_noise_fraction
    noise = rng.uniform(-f, f, size=reflectance.shape)
    return reflectance * (1.0 + noise)
