"""Segment maps for the map-based laser robots, and the geometry queries the world needs on them.

Seed 002 (MR-SSGA) §4 describes the environment "entirely by a list M of pairs of points": wall
segments, against which eq. 4 computes laser ranges (``world/laser/laser.py``). The builders here give the
environments the two laser seeds use:

- ``office``: an office-like floor with rooms of different sizes on both sides of a corridor
  (seed 003 §V: "a typical indoor, office-like environment", fig. 1).
- ``symmetric_rooms``: a highly symmetric multi-room floor, three identical rooms on each side of a
  corridor (seed 002 §6, fig. 8); invariant under a half turn, so no sensor can tell a pose from
  its twin.
- ``aliased_rooms``: the same floor with the north-east room opened into a hall at the corridor's
  east end: five identical rooms (perceptual aliasing, 002 §6) but no rigid symmetry, so the floor
  as a whole is unique (the environment of our table 3, seed 002 §6, fig. 8).
- ``wall_two_landmarks``: one wall and two landmarks (seed 002 §5.1, figs. 3-4).
- ``symmetric``: a fully symmetric environment, invariant under the 8 symmetries of the square
  (seed 002 §5.2, figs. 5-6).
- ``three_rooms_corridor``: three rooms joined by a corridor (seed 003 §V, fig. 2).

The exact drawings are not in the seeds' text; these are reconstructions with the stated features,
sized so that the laser ranges of table 2 of 002 (6 m) and table I of 003 (8 m) matter.

Queries, batched over a leading axis and pure (randomness only through an injected
``numpy.random.Generator``):

- :func:`free_space_sample`: random poses inside the map bounds and at least ``clearance_m`` from
  every wall (random start and goal, kidnapping).
- :func:`line_of_sight`: whether the straight segment between two points crosses no wall.
- :func:`distance_to_walls`: distance from points to the nearest wall segment.

Coordinates: metres; poses are ``(x_m, y_m, theta_rad)``.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable
from dataclasses import dataclass, field

import numpy as np

from swarmloc.config import did_you_mean

#: Segments shorter than this are degenerate and rejected (metres).
MIN_SEGMENT_LENGTH_M = 1e-6


@dataclass(frozen=True, eq=False)
class SegmentMap:
    """A 2-D map made of wall segments.

    ``segments_m`` is an ``(S, 4)`` array of rows ``(x1, y1, x2, y2)`` in metres (stored as a
    read-only float64 copy). ``bounds_m`` is ``(x_min, y_min, x_max, y_max)``: the region in which
    robots live and poses are sampled; by default the bounding box of the segments. Every segment
    must lie inside the bounds.
    """

    name: str
    segments_m: np.ndarray
    bounds_m: tuple[float, float, float, float] | None = field(default=None)

    def __post_init__(self) -> None:
        if not isinstance(self.name, str) or not self.name:
            raise ValueError(f"name must be a non-empty string, got {self.name!r}")
        try:
            segments = np.array(self.segments_m, dtype=np.float64)
        except (TypeError, ValueError):
            raise ValueError("segments_m must be an (S, 4) array of numbers") from None
        if segments.ndim != 2 or segments.shape[1] != 4 or segments.shape[0] < 1:
            raise ValueError(f"segments_m must have shape (S, 4) with S >= 1, got {segments.shape}")
        if not np.all(np.isfinite(segments)):
            raise ValueError("segments_m must be finite")
        lengths = np.hypot(segments[:, 2] - segments[:, 0], segments[:, 3] - segments[:, 1])
        short = np.flatnonzero(lengths < MIN_SEGMENT_LENGTH_M)
        if short.size:
            raise ValueError(f"segments_m has zero-length segments at rows {short.tolist()}")
        segments.flags.writeable = False
        object.__setattr__(self, "segments_m", segments)

        xs, ys = segments[:, [0, 2]], segments[:, [1, 3]]
        extent = (float(xs.min()), float(ys.min()), float(xs.max()), float(ys.max()))
        if self.bounds_m is None:
            bounds = extent
        else:
            try:
                bounds = tuple(float(b) for b in self.bounds_m)
            except (TypeError, ValueError):
                raise ValueError(f"bounds_m must be 4 numbers, got {self.bounds_m!r}") from None
            if len(bounds) != 4 or not all(math.isfinite(b) for b in bounds):
                raise ValueError(f"bounds_m must be 4 finite numbers, got {self.bounds_m!r}")
            tol = 1e-9
            if (
                extent[0] < bounds[0] - tol
                or extent[1] < bounds[1] - tol
                or extent[2] > bounds[2] + tol
                or extent[3] > bounds[3] + tol
            ):
                raise ValueError(f"segments extend {extent} beyond bounds_m {bounds}")
        if not (bounds[2] > bounds[0] and bounds[3] > bounds[1]):
            raise ValueError(f"bounds_m must have positive width and height, got {bounds}")
        object.__setattr__(self, "bounds_m", bounds)

    @property
    def n_segments(self) -> int:
        return int(self.segments_m.shape[0])

    @property
    def width_m(self) -> float:
        return self.bounds_m[2] - self.bounds_m[0]

    @property
    def height_m(self) -> float:
        return self.bounds_m[3] - self.bounds_m[1]

    @property
    def diagonal_m(self) -> float:
        """Length of the bounds' diagonal ("size(Env)" of table I of seed 003)."""
        return math.hypot(self.width_m, self.height_m)


# --------------------------------------------------------------------------------------------
# Geometry queries
# --------------------------------------------------------------------------------------------


def _points(points_m: np.ndarray, name: str) -> np.ndarray:
    points = np.asarray(points_m, dtype=np.float64)
    if points.ndim != 2 or points.shape[1] < 2:
        raise ValueError(f"{name} must have shape (N, 2) (or (N, 3) poses), got {points.shape}")
    return points[:, :2]


def distance_to_walls(world_map: SegmentMap, points_m: np.ndarray) -> np.ndarray:
    """Distance in metres from each of ``points_m`` ``(N, 2)`` to the nearest wall: ``(N,)``."""
    points = _points(points_m, "points_m")
    seg = world_map.segments_m
    a = seg[None, :, 0:2]
    edge = seg[:, 2:4] - seg[:, 0:2]
    rel = points[:, None, :] - a  # (N, S, 2)
    fraction = np.clip(np.sum(rel * edge, axis=-1) / np.sum(edge * edge, axis=-1), 0.0, 1.0)
    closest = rel - fraction[..., None] * edge
    return np.sqrt(np.min(np.sum(closest * closest, axis=-1), axis=1))


def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def line_of_sight(world_map: SegmentMap, a_xy: np.ndarray, b_xy: np.ndarray) -> np.ndarray:
    """Whether the straight segment from ``a_xy[k]`` to ``b_xy[k]`` crosses no wall: ``(N,)`` bool.

    ``a_xy`` and ``b_xy`` are ``(N, 2)`` (or poses ``(N, 3)``; the heading is ignored). Touching a
    wall (an endpoint on a wall, or passing through a wall's end) counts as blocked.
    """
    a = _points(a_xy, "a_xy")
    b = _points(b_xy, "b_xy")
    if a.shape != b.shape:
        raise ValueError(f"a_xy and b_xy must have the same shape, got {a.shape} and {b.shape}")
    seg = world_map.segments_m
    px, py = a[:, 0:1], a[:, 1:2]  # (N, 1)
    rx, ry = b[:, 0:1] - px, b[:, 1:2] - py
    qx, qy = seg[None, :, 0], seg[None, :, 1]  # (1, S)
    sx, sy = seg[None, :, 2] - qx, seg[None, :, 3] - qy
    wx, wy = qx - px, qy - py  # (N, S)
    denom = _cross(rx, ry, sx, sy)
    t_num = _cross(wx, wy, sx, sy)  # position along a->b, times denom
    u_num = _cross(wx, wy, rx, ry)  # position along the wall, times denom
    sign = np.where(denom < 0.0, -1.0, 1.0)
    denom_abs = np.abs(denom)
    t_num, u_num = t_num * sign, u_num * sign
    eps = 1e-12
    proper = (
        (denom_abs > eps)
        & (t_num >= -eps)
        & (t_num <= denom_abs + eps)
        & (u_num >= -eps)
        & (u_num <= denom_abs + eps)
    )
    # Parallel and collinear: blocked when the two segments overlap along their common line.
    collinear = (denom_abs <= eps) & (np.abs(_cross(wx, wy, rx, ry)) <= eps)
    rr = rx * rx + ry * ry
    safe_rr = np.where(rr > 0.0, rr, 1.0)
    t0 = (wx * rx + wy * ry) / safe_rr
    t1 = t0 + (sx * rx + sy * ry) / safe_rr
    overlap = (np.maximum(t0, t1) >= 0.0) & (np.minimum(t0, t1) <= 1.0) & (rr > 0.0)
    blocked = proper | (collinear & overlap)
    return ~np.any(blocked, axis=1)


def free_space_sample(
    world_map: SegmentMap,
    n: int,
    rng: np.random.Generator,
    clearance_m: float = 0.3,
    max_batches: int = 1000,
) -> np.ndarray:
    """``n`` random poses ``(n, 3)`` uniform in the map bounds, at least ``clearance_m`` from walls.

    Positions are drawn uniformly in ``bounds_m`` shrunk by ``clearance_m`` and rejected when closer
    than ``clearance_m`` to any wall; headings are uniform in ``[-pi, pi)``. Solid landmarks of the
    built-in maps are thinner than ``2 * clearance_m`` for the default clearance, so no sample falls
    inside one. Raises ``RuntimeError`` if the free space is too small to fill ``n`` samples.
    """
    if isinstance(n, bool) or not isinstance(n, (int, np.integer)) or n < 0:
        raise ValueError(f"n must be an integer >= 0, got {n!r}")
    clearance_m = float(clearance_m)
    if not math.isfinite(clearance_m) or clearance_m < 0.0:
        raise ValueError(f"clearance_m must be a finite number >= 0, got {clearance_m!r}")
    x_min, y_min, x_max, y_max = world_map.bounds_m
    lo = np.array([x_min + clearance_m, y_min + clearance_m])
    hi = np.array([x_max - clearance_m, y_max - clearance_m])
    if np.any(hi <= lo):
        raise ValueError(
            f"clearance_m {clearance_m} leaves no room inside bounds {world_map.bounds_m}"
        )
    accepted: list[np.ndarray] = []
    count = 0
    batch = max(64, 2 * int(n))
    for _ in range(max_batches):
        if count >= n:
            break
        xy = rng.uniform(lo, hi, size=(batch, 2))
        keep = xy[distance_to_walls(world_map, xy) >= clearance_m]
        accepted.append(keep)
        count += keep.shape[0]
    else:
        if count < n:
            raise RuntimeError(
                f"free space of map {world_map.name!r} too small for {n} samples "
                f"with clearance {clearance_m} m"
            )
    xy = np.concatenate(accepted, axis=0)[:n] if accepted else np.empty((0, 2))
    theta = rng.uniform(-math.pi, math.pi, size=n)
    return np.column_stack([xy, theta])


# --------------------------------------------------------------------------------------------
# Map builders
# --------------------------------------------------------------------------------------------


def _box(x0: float, y0: float, x1: float, y1: float) -> list[tuple[float, float, float, float]]:
    """The 4 sides of an axis-aligned rectangle."""
    return [(x0, y0, x1, y0), (x1, y0, x1, y1), (x1, y1, x0, y1), (x0, y1, x0, y0)]


def _wall(
    x0: float, y0: float, x1: float, y1: float, doors: Iterable[tuple[float, float]] = ()
) -> list[tuple[float, float, float, float]]:
    """An axis-aligned wall from (x0, y0) to (x1, y1) with door gaps ``(centre, width)``.

    Door centres are coordinates along the wall's axis (x for a horizontal wall, y for a vertical).
    """
    horizontal = y0 == y1
    if not horizontal and x0 != x1:
        raise ValueError("_wall only builds axis-aligned walls")
    start, end = (min(x0, x1), max(x0, x1)) if horizontal else (min(y0, y1), max(y0, y1))
    pieces, cursor = [], start
    for centre, width in sorted(doors):
        gap_lo, gap_hi = centre - width / 2.0, centre + width / 2.0
        if gap_lo > cursor:
            pieces.append((cursor, gap_lo))
        cursor = max(cursor, gap_hi)
    if end > cursor:
        pieces.append((cursor, end))
    if horizontal:
        return [(a, y0, b, y0) for a, b in pieces]
    return [(x0, a, x0, b) for a, b in pieces]


def office_map() -> SegmentMap:
    """An office floor, 20 x 12 m: a 2 m corridor at y in [5, 7], rooms of unequal widths on both
    sides (doors of 1 m), a partition, a cabinet and six desks (47 segments); asymmetric, so that
    a laser can localize."""
    segs = _box(0.0, 0.0, 20.0, 12.0)
    # South side rooms: walls at x = 4, 9, 15 (widths 4, 5, 6, 5), doors on the corridor wall.
    segs += _wall(0.0, 5.0, 20.0, 5.0, doors=[(2.0, 1.0), (7.5, 1.0), (11.0, 1.0), (18.5, 1.0)])
    for x in (4.0, 9.0, 15.0):
        segs += _wall(x, 0.0, x, 5.0)
    # North side rooms: walls at x = 6, 13 (widths 6, 7, 7), doors off-centre.
    segs += _wall(0.0, 7.0, 20.0, 7.0, doors=[(4.5, 1.0), (7.0, 1.0), (17.0, 1.0)])
    for x in (6.0, 13.0):
        segs += _wall(x, 7.0, x, 12.0)
    # A partition inside the north-middle room, a cabinet in the south-east room, and desks
    # (solid, 0.5 m deep) in the other rooms, each placed differently.
    segs += _wall(9.5, 9.5, 13.0, 9.5)
    segs += _box(16.5, 1.0, 18.0, 1.5)
    for x0, y0, x1, y1 in (
        (0.5, 0.5, 2.0, 1.0),
        (5.0, 2.0, 5.5, 3.5),
        (10.0, 0.5, 12.0, 1.0),
        (1.0, 10.5, 3.0, 11.0),
        (7.0, 10.5, 8.5, 11.0),
        (18.5, 8.5, 19.0, 10.5),
    ):
        segs += _box(x0, y0, x1, y1)
    return SegmentMap("office", np.array(segs))


def symmetric_rooms_map() -> SegmentMap:
    """Seed 002 fig. 8 / table 3: 18 x 10 m, a 2 m corridor at y in [4, 6] with three identical
    6 x 4 m rooms on each side, each with a 1 m door centred on the corridor wall."""
    segs = _box(0.0, 0.0, 18.0, 10.0)
    doors = [(3.0, 1.0), (9.0, 1.0), (15.0, 1.0)]
    segs += _wall(0.0, 4.0, 18.0, 4.0, doors=doors)
    segs += _wall(0.0, 6.0, 18.0, 6.0, doors=doors)
    for x in (6.0, 12.0):
        segs += _wall(x, 0.0, x, 4.0)
        segs += _wall(x, 6.0, x, 10.0)
    return SegmentMap("symmetric_rooms", np.array(segs))


def aliased_rooms_map() -> SegmentMap:
    """Seed 002 fig. 8 / table 3, globally unique: 18 x 10 m, a 2 m corridor at y in [4, 6]; three
    identical 6 x 4 m rooms on the south side and two on the north side (the same room turned by
    a half turn), each with a 1 m door centred on the corridor wall; where the third north room
    would be, the corridor opens into a 6 x 6 m hall (x in [12, 18], y in [4, 10]). Inside a room
    the five rooms look alike; the hall and the corridor's closed west end do not."""
    segs = _box(0.0, 0.0, 18.0, 10.0)
    segs += _wall(0.0, 4.0, 18.0, 4.0, doors=[(3.0, 1.0), (9.0, 1.0), (15.0, 1.0)])
    segs += _wall(0.0, 6.0, 12.0, 6.0, doors=[(3.0, 1.0), (9.0, 1.0)])
    for x in (6.0, 12.0):
        segs += _wall(x, 0.0, x, 4.0)
        segs += _wall(x, 6.0, x, 10.0)
    return SegmentMap("aliased_rooms", np.array(segs))


def wall_two_landmarks_map() -> SegmentMap:
    """Seed 002 §5.1: one 10 m wall and two square landmarks (0.3 m pillars) in front of it, in
    an open 12 x 8 m area (no enclosure: beams that miss return the maximum range)."""
    segs = [(1.0, 1.0, 11.0, 1.0)]
    segs += _box(3.85, 4.85, 4.15, 5.15)
    segs += _box(7.85, 5.85, 8.15, 6.15)
    return SegmentMap("wall_two_landmarks", np.array(segs), bounds_m=(0.0, 0.0, 12.0, 8.0))


def symmetric_map() -> SegmentMap:
    """Seed 002 §5.2: a fully symmetric 10 x 10 m room: a central 2 x 2 m pillar and a 2 m wall
    from the middle of each side inwards; invariant under the 8 symmetries of the square."""
    segs = _box(0.0, 0.0, 10.0, 10.0)
    segs += _box(4.0, 4.0, 6.0, 6.0)
    segs += [
        (5.0, 0.0, 5.0, 2.0),
        (10.0, 5.0, 8.0, 5.0),
        (5.0, 10.0, 5.0, 8.0),
        (0.0, 5.0, 2.0, 5.0),
    ]
    return SegmentMap("symmetric", np.array(segs))


def three_rooms_corridor_map() -> SegmentMap:
    """Seed 003 fig. 2: three 5 x 5 m rooms (x in [0, 15], y in [3, 8]) joined by a 3 m corridor
    below them (y in [0, 3]); 1.2 m doors at different positions along each room's south wall."""
    segs = _box(0.0, 0.0, 15.0, 8.0)
    segs += _wall(0.0, 3.0, 15.0, 3.0, doors=[(1.5, 1.2), (7.5, 1.2), (13.0, 1.2)])
    segs += _wall(5.0, 3.0, 5.0, 8.0)
    segs += _wall(10.0, 3.0, 10.0, 8.0)
    return SegmentMap("three_rooms_corridor", np.array(segs))


def three_corridors_map() -> SegmentMap:
    """Seed 003 fig. 4 as its text describes it (issue 43): "robots have been purposely placed in
    the middle of three different corridors where laser data are temporarily partially useless".
    24 x 14 m: a west and an east hall, 3 m wide (x in [0, 3] and [21, 24]), joined by three 2 m
    corridors at y in [1, 3], [6, 8] and [11, 13]. The floor is invariant under a half turn
    about its centre but for one bay (3 x 2.5 m, open on its whole width) off the north side of
    the middle corridor at x in [12, 15]: in the middle of a corridor the 8 m laser sees two
    parallel walls and nothing along the axis, and every place but the bay's surroundings has a
    twin. The drawing
    of 003's floor is not in its text: this is our reconstruction of the text."""
    segs = _box(0.0, 0.0, 24.0, 14.0)
    for x in (3.0, 21.0):  # the halls' inner sides, between the corridor mouths
        for y0, y1 in ((0.0, 1.0), (3.0, 6.0), (8.0, 11.0), (13.0, 14.0)):
            segs += _wall(x, y0, x, y1)
    for y in (1.0, 3.0, 6.0, 11.0, 13.0):
        segs += _wall(3.0, y, 21.0, y)
    segs += _wall(3.0, 8.0, 21.0, 8.0, doors=[(13.5, 3.0)])
    segs += [(12.0, 8.0, 12.0, 10.5), (12.0, 10.5, 15.0, 10.5), (15.0, 10.5, 15.0, 8.0)]
    return SegmentMap("three_corridors", np.array(segs))


class MapRegistry:
    """Map builders by name. Registering a name twice is an error; an unknown name suggests the
    closest registered one."""

    def __init__(self) -> None:
        self._builders: dict[str, Callable[[], SegmentMap]] = {}

    def register(self, name: str, builder: Callable[[], SegmentMap]) -> None:
        if name in self._builders:
            raise ValueError(f"map {name!r} is already registered")
        self._builders[name] = builder

    def names(self) -> tuple[str, ...]:
        return tuple(self._builders)

    def build(self, name: str) -> SegmentMap:
        try:
            builder = self._builders[name]
        except KeyError:
            hint = did_you_mean(str(name), self._builders, 0.6)
            raise KeyError(
                f"unknown map {name!r}{hint} (known: {', '.join(self._builders)})"
            ) from None
        return builder()


def default_registry() -> MapRegistry:
    """A registry holding the built-in maps of seeds 002 and 003."""
    registry = MapRegistry()
    registry.register("office", office_map)
    registry.register("symmetric_rooms", symmetric_rooms_map)
    registry.register("aliased_rooms", aliased_rooms_map)
    registry.register("wall_two_landmarks", wall_two_landmarks_map)
    registry.register("symmetric", symmetric_map)
    registry.register("three_rooms_corridor", three_rooms_corridor_map)
    registry.register("three_corridors", three_corridors_map)
    return registry


#: The built-in maps (read-only use; make your own :class:`MapRegistry` to add maps).
MAPS = default_registry()


def build_map(name: str) -> SegmentMap:
    """Build a built-in map by name."""
    return MAPS.build(name)
