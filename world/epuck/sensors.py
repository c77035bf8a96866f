"""E-puck proximity and ground sensors, and how a robot reads its ground sensors.

Seed 000 §6.1: the simulated e-puck carries 8 infrared proximity sensors around its body and 3
ground sensors on the bottom-front of the body; uniformly distributed noise of ±20 % is added to
the infrared readings and ±30 % to the ground readings. Sensor placement (angles, offsets) comes
from ``swarmloc.protocol.epuck``.

- :func:`ir_proximity`: each sensor casts a ray radially outward from its spot on the body
  perimeter; the distance ``d`` to the nearest wall or robot body (ray-circle intersection)
  gives ``clip(1 - d / ir_range_m, 0, 1)`` (1 = touching, 0 = nothing in range), then
  multiplicative noise ``1 + U(-f, f)``, clipped to [0, 1].
- :func:`ground_sensors`: floor reflectance (``world/epuck/arena.py``) under each ground sensor, times
  ``1 + U(-f, f)``.
  What a robot concludes from the readings is the agent's business
  (``swarmloc.agents.epuck.foraging.classify_ground``).

Random draws (fixed order, so a run is deterministic given ``rng``): :func:`ir_proximity` makes one
``rng.uniform(-f, f, size=(N, 8))`` call; :func:`ground_sensors` one
``rng.uniform(-f, f, size=(N, 3))`` call. Both draw even when the noise fraction is 0.
All functions work on a batch of robots: poses ``(N, 3)`` = (x_m, y_m, theta_rad). The loops
are compiled kernels (``world/epuck/kernels.py``); the noises are drawn here as ``rng.random``, which
gives exactly the numbers of ``rng.uniform(-f, f)`` (the kernel computes ``-f + 2 f u``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarmloc.protocol.epuck import GROUND_SENSOR_OFFSETS_M, IR_SENSOR_ANGLES_RAD
from swarmloc.world.epuck import kernels
from swarmloc.world.epuck.arena import (
    REFLECTANCE_BY_AREA,
    Arena,
    arena_discs,
)

_COS_IR = np.cos(IR_SENSOR_ANGLES_RAD)
_SIN_IR = np.sin(IR_SENSOR_ANGLES_RAD)


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
    ``body_radius_m``; candidates from a spatial hash grid within ``2 * body_radius_m +
    ir_range_m``, in the compiled kernel of ``world/epuck/kernels.py``).
    A sensor whose spot lies outside the walls or inside another body reads distance 0.
    Value ``clip(1 - d / ir_range_m, 0, 1) * (1 + U(-f, f))`` clipped to [0, 1], with ``f`` the
    IR noise fraction; one ``(N, 8)`` uniform draw.
    """
    pose = _check_pose(pose)
    f = params.ir_noise_fraction
    u = rng.random((pose.shape[0], IR_SENSOR_ANGLES_RAD.shape[0]))  # = rng.uniform(-f, f, ...)
    return kernels.ir_readings(
        pose, float(body_radius_m), params.ir_range_m, arena.width_m, arena.height_m,
        _COS_IR, _SIN_IR, u, -f, f - -f,
    )


def ground_sensors(
    pose: np.ndarray, arena: Arena, params: SensorParams, rng: np.random.Generator
) -> np.ndarray:
    """Noisy readings ``(N, 3)`` of the 3 ground sensors (seed 000 §6.1).

    The sensor points ``GROUND_SENSOR_OFFSETS_M`` (robot frame) are moved to the world frame; the
    reading is the floor reflectance there times ``1 + U(-f, f)``, with ``f`` the ground noise
    fraction (one ``(N, 3)`` uniform draw). Not clipped: white reads in [0.7, 1.3] at f = 0.3.
    """
    pose = _check_pose(pose)
    f = params.ground_noise_fraction
    u = rng.random((pose.shape[0], GROUND_SENSOR_OFFSETS_M.shape[0]))  # = rng.uniform(-f, f, ...)
    return kernels.ground_readings(pose, GROUND_SENSOR_OFFSETS_M, arena_discs(arena), REFLECTANCE_BY_AREA, u, -f, f - -f)
