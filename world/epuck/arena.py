"""The foraging arena: walls, ground colours of the nest and prey areas, and body collisions.

The arena of seed 000 §6.1 (fig. 7, table 2) and seed 001 §4.1 is a walled rectangle with a
white floor and two circular goal areas: the *nest* (central place), painted black, and the
*prey* (resource site), painted grey. The e-puck ground sensors tell them apart by reflectance
(seed 000 §5, §6.1; ``world/epuck/sensors.py`` adds the ±30 % noise).

Physics is kinematic, as is usual for e-puck swarm simulators at 10 Hz: after the world moves the
bodies, :func:`resolve_collisions` pushes overlapping discs apart along their centre line and
clamps every body inside the walls. It is deterministic and scales to thousands of robots: a
compiled kernel on a spatial hash grid (``world/epuck/kernels.py``), with a vectorised KD-tree version
(``np.bincount`` sums the pushes) for crowds, where the order of the sums is the KD-tree's.

Coordinates: metres, walls at ``x = 0``, ``x = width_m``, ``y = 0``, ``y = height_m``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarmloc.world.epuck import kernels

#: Ground reflectance of the three floor colours (dimensionless, white = 1).
GROUND_WHITE = 1.0
GROUND_GREY = 0.5
GROUND_BLACK = 0.1

#: Integer codes of the areas a point can lie in (stored as int8).
AREA_NONE = 0
AREA_NEST = 1
AREA_PREY = 2


def _finite_positive(value: float, name: str) -> None:
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"{name} must be a number, got {value!r}") from None
    if isinstance(value, (bool, str)) or not math.isfinite(number) or number <= 0.0:
        raise ValueError(f"{name} must be a finite number > 0, got {value!r}")


@dataclass(frozen=True)
class Disc:
    """A circular floor area: centre ``(x_m, y_m)`` and radius in metres."""

    centre_m: tuple[float, float]
    radius_m: float

    def __post_init__(self) -> None:
        try:
            x_m, y_m = (float(c) for c in self.centre_m)
        except (TypeError, ValueError):
            raise ValueError(f"centre_m must be a pair of numbers, got {self.centre_m!r}") from None
        if not (math.isfinite(x_m) and math.isfinite(y_m)):
            raise ValueError(f"centre_m must be finite, got {self.centre_m!r}")
        object.__setattr__(self, "centre_m", (x_m, y_m))
        _finite_positive(self.radius_m, "radius_m")


@dataclass(frozen=True)
class Arena:
    """A walled rectangle ``[0, width_m] x [0, height_m]`` with a black nest and a grey prey disc.

    Validation (``ValueError`` naming the field): positive finite sizes, each disc entirely inside
    the walls, and the two discs not overlapping (touching is allowed).
    """

    width_m: float
    height_m: float
    nest: Disc
    prey: Disc
    #: A tiled floor (scaled scenario families): the floor of ``[0, tile_m[0]] x [0, tile_m[1]]``,
    #: with the nest and the prey, repeats every ``tile_m`` over the whole arena; the walls are
    #: only the outer ones. None: one nest and one prey.
    tile_m: tuple[float, float] | None = None

    def __post_init__(self) -> None:
        _finite_positive(self.width_m, "width_m")
        _finite_positive(self.height_m, "height_m")
        for name in ("nest", "prey"):
            disc = getattr(self, name)
            if not isinstance(disc, Disc):
                raise ValueError(f"{name} must be a Disc, got {type(disc).__name__}")  # noqa: TRY004
            (x_m, y_m), r_m = disc.centre_m, disc.radius_m
            if (
                x_m - r_m < 0.0
                or x_m + r_m > self.width_m
                or y_m - r_m < 0.0
                or (y_m + r_m > self.height_m)
            ):
                raise ValueError(
                    f"{name} disc (centre {disc.centre_m}, radius {r_m}) is not inside the "
                    f"{self.width_m} x {self.height_m} m arena"
                )
        gap_m = math.dist(self.nest.centre_m, self.prey.centre_m)
        if gap_m < self.nest.radius_m + self.prey.radius_m:
            raise ValueError(
                f"prey disc overlaps nest disc (centre distance {gap_m} m < sum of radii "
                f"{self.nest.radius_m + self.prey.radius_m} m)"
            )
        tile = ()
        if self.tile_m is not None:
            tile_w, tile_h = (float(v) for v in self.tile_m)
            _finite_positive(tile_w, "tile_m[0]")
            _finite_positive(tile_h, "tile_m[1]")
            for name in ("nest", "prey"):
                (x_m, y_m), r_m = getattr(self, name).centre_m, getattr(self, name).radius_m
                if x_m + r_m > tile_w or y_m + r_m > tile_h:
                    raise ValueError(f"{name} disc is not inside the {tile_w} x {tile_h} m tile")
            tile = (tile_w, tile_h)
        # 8 numbers for a tiled floor: the kernels then find areas in tile coordinates
        discs = np.array([*self.nest.centre_m, self.nest.radius_m, *self.prey.centre_m, self.prey.radius_m, *tile])
        discs.flags.writeable = False
        object.__setattr__(self, "_discs", discs)


def arena_discs(arena: Arena) -> np.ndarray:
    """``(nest x, y, radius, prey x, y, radius)`` in metres, then ``(tile width, height)`` for a
    tiled floor: the arena as the kernels take it."""
    return arena._discs


def _inside(points_m: np.ndarray, disc: Disc) -> np.ndarray:
    dx = points_m[..., 0] - disc.centre_m[0]
    dy = points_m[..., 1] - disc.centre_m[1]
    return dx * dx + dy * dy <= disc.radius_m * disc.radius_m


def area_at(points_m: np.ndarray, arena: Arena) -> np.ndarray:
    """Area code (``AREA_NEST``, ``AREA_PREY`` or ``AREA_NONE``, int8) of points ``(..., 2)``.

    A point on a disc's rim counts as inside it.
    """
    points_m = np.asarray(points_m, dtype=float)
    if arena.tile_m is not None:  # the same reduction to tile coordinates as the kernels'
        tile = np.asarray(arena.tile_m, dtype=float)
        points_m = points_m - tile * np.floor(points_m / tile)
    out = np.full(points_m.shape[:-1], AREA_NONE, dtype=np.int8)
    out[_inside(points_m, arena.prey)] = AREA_PREY
    out[_inside(points_m, arena.nest)] = AREA_NEST
    return out


#: Floor reflectance by area code (AREA_NONE, AREA_NEST, AREA_PREY).
REFLECTANCE_BY_AREA = np.array([GROUND_WHITE, GROUND_BLACK, GROUND_GREY])


def ground_reflectance(points_m: np.ndarray, arena: Arena) -> np.ndarray:
    """True floor reflectance at points ``(..., 2)``: black nest, grey prey, white elsewhere."""
    return REFLECTANCE_BY_AREA[area_at(points_m, arena)]


def resolve_collisions(
    position_m: np.ndarray,
    radius_m: float,
    arena: Arena,
    movable: np.ndarray | None = None,
    iterations: int = 2,
) -> np.ndarray:
    """Separate overlapping bodies and keep them inside the walls; returns a new ``(N, 2)`` array.

    Each iteration: every pair whose centres are closer than ``2 * radius_m`` is pushed apart
    along the centre line by the overlap, split evenly between the two bodies, or all of it to
    the movable one if only one is movable (none if neither is). All pushes of an iteration are
    computed from the same positions and summed (Jacobi style), so a lone overlapping pair ends
    exactly ``2 * radius_m`` apart after one iteration; crowds need more iterations. Then every
    movable body is clamped into ``[radius_m, width_m - radius_m] x [radius_m, height_m -
    radius_m]``. Bodies with ``movable=False`` are never moved, not even by the clamp. Two bodies
    at exactly the same centre are split along the x axis (lower index to -x). Deterministic: no
    randomness.

    When every body is movable (the world's case) a compiled kernel does the work on a cell grid
    (``world/epuck/kernels.py``); it hands over to the vectorised KD-tree version, which defines the
    summation order of the pushes, whenever a body overlaps three or more others at once.
    """
    pos = np.array(position_m, dtype=float, copy=True)
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise ValueError(f"position_m must have shape (N, 2), got {pos.shape}")
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations}")
    if movable is None or bool(np.all(movable)):
        if np.shape(movable) not in ((), (pos.shape[0],)):
            raise ValueError(f"movable must have shape ({pos.shape[0]},), got {np.shape(movable)}")
        fast = pos.copy()
        if kernels.separate_bodies(fast, float(radius_m), arena.width_m, arena.height_m, int(iterations)):
            return fast
    return _resolve_collisions_kdtree(pos, radius_m, arena, movable, iterations)


def _resolve_collisions_kdtree(
    position_m: np.ndarray,
    radius_m: float,
    arena: Arena,
    movable: np.ndarray | None = None,
    iterations: int = 2,
) -> np.ndarray:
    """:func:`resolve_collisions` in numpy: overlapping pairs from a KD-tree, pushes summed with
    ``np.bincount`` in pair order.

    Each iteration: every pair whose centres are closer than ``2 * radius_m`` (found with a
    KD-tree) is pushed apart along the centre line by the overlap, split evenly between the two
    bodies, or all of it to the movable one if only one is movable (none if neither is). All pushes
    of an iteration are computed from the same positions and summed (Jacobi style), so a lone
    overlapping pair ends exactly ``2 * radius_m`` apart after one iteration; crowds need more
    iterations. Then every movable body is clamped into
    ``[radius_m, width_m - radius_m] x [radius_m, height_m - radius_m]``. Bodies with
    ``movable=False`` are never moved, not even by the clamp. Two bodies at exactly the same
    centre are split along the x axis (lower index to -x). Deterministic: no randomness.
    """
    pos = np.array(position_m, dtype=float, copy=True)
    if pos.ndim != 2 or pos.shape[1] != 2:
        raise ValueError(f"position_m must have shape (N, 2), got {pos.shape}")
    n = pos.shape[0]
    if movable is None:
        movable = np.ones(n, dtype=bool)
    else:
        movable = np.asarray(movable, dtype=bool)
        if movable.shape != (n,):
            raise ValueError(f"movable must have shape ({n},), got {movable.shape}")
    if iterations < 0:
        raise ValueError(f"iterations must be >= 0, got {iterations}")
    min_gap_m = 2.0 * radius_m
    lo = np.array([radius_m, radius_m])
    hi = np.array([arena.width_m - radius_m, arena.height_m - radius_m])
    mov_f = movable.astype(float)
    all_movable = bool(movable.all())
    from scipy.spatial import cKDTree  # here: scipy costs every agent process 0.4 s and memory

    for _ in range(iterations):
        if n >= 2:
            tree = cKDTree(pos, balanced_tree=False, compact_nodes=False)
            pairs = tree.query_pairs(min_gap_m, output_type="ndarray")
            if len(pairs):
                i, j = pairs[:, 0], pairs[:, 1]
                delta = pos[j] - pos[i]
                dist_m = np.hypot(delta[:, 0], delta[:, 1])
                keep = dist_m < min_gap_m
                i, j, delta, dist_m = i[keep], j[keep], delta[keep], dist_m[keep]
                if len(i):
                    unit = np.zeros_like(delta)
                    nz = dist_m > 0.0
                    unit[nz] = delta[nz] / dist_m[nz, None]
                    # Coincident centres: split along x, lower index towards -x.
                    unit[~nz] = np.where((i[~nz] < j[~nz])[:, None], [1.0, 0.0], [-1.0, 0.0])
                    overlap_m = min_gap_m - dist_m
                    mi, mj = mov_f[i], mov_f[j]
                    total = mi + mj
                    share_i = np.divide(mi, total, out=np.zeros_like(mi), where=total > 0)
                    share_j = np.divide(mj, total, out=np.zeros_like(mj), where=total > 0)
                    push_i = -(share_i * overlap_m)[:, None] * unit
                    push_j = (share_j * overlap_m)[:, None] * unit
                    idx = np.concatenate([i, j])
                    push = np.concatenate([push_i, push_j])
                    pos[:, 0] += np.bincount(idx, weights=push[:, 0], minlength=n)
                    pos[:, 1] += np.bincount(idx, weights=push[:, 1], minlength=n)
        _clamp(pos, lo, hi, movable, all_movable)
    if iterations == 0:
        _clamp(pos, lo, hi, movable, all_movable)
    return pos


def _clamp(pos, lo, hi, movable, all_movable) -> None:
    if all_movable:
        np.clip(pos, lo, hi, out=pos)
    else:
        pos[movable] = np.clip(pos[movable], lo, hi)
