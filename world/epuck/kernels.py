"""Compiled (numba) kernels of the e-puck world models: the inner loops of ``world/epuck/sensors.py``,
``world/epuck/medium.py``, ``world/epuck/arena.py``, ``world/epuck/metrics.py`` and the kinematics of
``protocol/epuck.py``, over a batch of robots.

They are not a second implementation: the public model functions (``ir_proximity``,
``ground_sensors``, ``deliver``, ``resolve_collisions``, ``ForagingWorld.step``) call them, so
the world-server and the batch engine run exactly this code. Each kernel evaluates the same
floating-point expressions, in the same order, as the numpy formulation it replaced (seed 000
eq. 3-7 for the kinematics, §6.1 for sensors and medium), so a seeded run is bit-identical to
the numpy one (``benchmarks/fingerprint.py``). Notes on exactness:

- random draws: the world's ``numpy.random.Generator`` is called in the documented order.
  ``ForagingWorld``'s two per-tick kernels (:func:`observe_tick`, :func:`step_tick`) draw from it
  themselves, through the ``next_double`` function of its bit generator
  (:func:`~swarmloc.numerics.generator_address`): the very function ``Generator.random`` calls for each number, so
  the stream is numpy's and the generator's state advances as if numpy had drawn. The public
  model functions draw in numpy and pass the uniforms in;
- ``arctan2`` and ``exp``: numpy evaluates them with its own SIMD routines on this hardware,
  which differ from the C library's in the last bit; :func:`~swarmloc.numerics.np_arctan2` calls those very
  routines (:func:`~swarmloc.numerics.numpy_math` finds them and checks them against numpy once per process), else
  the C library's if it agrees with numpy here, else numpy itself from the kernel. ``sin``,
  ``cos``, ``hypot`` and ``sqrt`` agree bit for bit and are used as they are.

Neighbourhoods come from a spatial hash of square cells (side at least the query radius), built
in O(N); the 3 x 3 cells around a robot hold every candidate (:func:`neighbour_pairs`).
``ForagingWorld`` finds the pairs once per tick, when sensing, and the medium and the collisions
of the same tick reuse them (the collisions only while nobody has moved far enough for a new
contact to come from elsewhere, else they search again): the same pairs as a fresh search.
Collisions where a body touches three or more others go back to the KD-tree version of
``world/epuck/arena.py``, whose summation order defines the result.

Per tick the world makes two kernel calls with preallocated outputs and its constants packed in
one array (:func:`world_params`): numba checks the type of every argument of every call and
boxes every array it returns, which at 100 robots costs as much as the work itself. The two
share buffers: the neighbour pairs and the headings' cosines and sines found by one are reused
by the other while the poses are still those they were found at (compared value by value, so a
caller may change ``pose`` in place in between).

Kernels are compiled on first use and cached on disk (``cache=True``, next to this file): the
first run on a machine compiles for some 10-25 s, later processes load them in about a second.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from swarmloc.numerics import call_next_double, np_arctan2, wrap

_PI = math.pi
_TWO_PI = 2.0 * math.pi


@njit(cache=True)
def fill_random(out, fn_address, state_address):
    """``out[:] = rng.random(out.size)`` (flat ``out``), from the addresses of
    :func:`~swarmloc.numerics.generator_address`."""
    for q in range(out.shape[0]):
        out[q] = call_next_double(fn_address, state_address)


@njit(cache=True, inline="always", error_model="numpy")
def uniform(low, span, u):
    """``U(low, low + span)`` from a uniform ``u`` in [0, 1) of ``Generator.random``: exactly
    ``Generator.uniform(low, high)``, which computes ``low + (high - low) * u``. Pass ``span`` as
    ``high - low`` computed in Python (e.g. ``f - -f``); one ``random(a + b)`` call gives the same
    numbers as ``random(a)`` then ``random(b)``, so draws are merged without changing a run."""
    return low + span * u


@njit(cache=True, inline="always", error_model="numpy")
def _clip(value, lo, hi):
    # numpy's clip: max first, then min, comparisons as in npy_clip (-0.0 clips to lo).
    v = max(lo, value)
    return min(hi, v)


@njit(cache=True, error_model="numpy")
def build_grid(x_m, y_m, cell_m, x0_m, y0_m, width_m, height_m):
    """Spatial hash of points on square cells over ``[x0, x0 + width] x [y0, y0 + height]``
    (points outside go to the border cells): ``(cx, cy, start, items, mask, ncx, ncy,
    item_cell)``. The points of cell ``(gx, gy)`` (``0 <= gx < ncx``, ``0 <= gy < ncy``) are among
    ``items[start[b]:start[b + 1]]`` with ``b = cell_bucket(gx, gy, ncx, mask)``, together with
    those of other cells that share the bucket: check ``item_cell[q] == gy * ncx + gx``, which
    lies next to ``items[q]`` in memory (reading ``cx[items[q]]`` instead cost a cache miss per
    foreign point at 100,000 robots). O(N) however sparse or large the arena: about two buckets
    per point.
    """
    n = x_m.shape[0]
    cell_m = cell_m * (1.0 + 1e-9)  # a pair at exactly the query radius stays in adjacent cells
    ncx = min(max(1, int(width_m / cell_m) + 1), 1 << 24)
    ncy = min(max(1, int(height_m / cell_m) + 1), 1 << 24)
    n_buckets = 16
    while n_buckets < 2 * n:
        n_buckets *= 2
    mask = n_buckets - 1
    cx = np.empty(n, np.int64)
    cy = np.empty(n, np.int64)
    bucket = np.empty(n, np.int64)
    start = np.zeros(n_buckets + 1, np.int64)
    for i in range(n):
        gx = (x_m[i] - x0_m) / cell_m
        gy = (y_m[i] - y0_m) / cell_m
        cx[i] = 0 if not gx > 0.0 else (int(gx) if gx < ncx - 1 else ncx - 1)
        cy[i] = 0 if not gy > 0.0 else (int(gy) if gy < ncy - 1 else ncy - 1)
        b = cell_bucket(cx[i], cy[i], ncx, mask)
        bucket[i] = b
        start[b + 1] += 1
    for b in range(n_buckets):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    items = np.empty(n, np.int64)
    item_cell = np.empty(n, np.int64)
    for i in range(n):
        q = fill[bucket[i]]
        items[q] = i
        item_cell[q] = cy[i] * ncx + cx[i]
        fill[bucket[i]] = q + 1
    return cx, cy, start, items, mask, ncx, ncy, item_cell


@njit(cache=True, inline="always", error_model="numpy")
def cell_bucket(gx, gy, ncx, mask):
    """Bucket of cell ``(gx, gy)`` of a grid ``ncx`` cells wide: its row-major index modulo the
    number of buckets. Not a scrambling hash, on purpose: the cells around a point, and those
    of robots near in memory (a tiled arena places them so), then sit in nearby buckets, which
    at 100,000 robots keeps the lookups in the caches (a hash scattered them over megabytes).
    Which cells share a bucket changes no result: lookups check the cell of every point."""
    return (gy * ncx + gx) & mask


@njit(cache=True, inline="always", error_model="numpy")
def _cell_hash(gx, gy, mask):
    """A scrambling hash of cell ``(gx, gy)`` (cells of an unbounded grid)."""
    return ((gx * 73856093) ^ (gy * 19349663)) & mask


@njit(cache=True, error_model="numpy")
def neighbour_pairs(x_m, y_m, cutoff_m, x0_m, y0_m, width_m, height_m):
    """Unordered pairs ``i < j`` of points at most about ``cutoff_m`` apart (a superset: the
    squared distance is compared with ``cutoff_m**2`` enlarged by 1e-9, so that every pair whose
    ``hypot`` is within ``cutoff_m`` is in): ``(i, j, dx, dy, d2)`` with ``dx = x[j] - x[i]``,
    ``d2 = dx * dx + dy * dy``, in order of ``i``. Callers apply their own exact test, and do
    not depend on the order of the pairs (a minimum, a sort, sums of two). Grid over ``[x0, x0 +
    width] x [y0, y0 + height]`` (:func:`build_grid`)."""
    size = 8 * x_m.shape[0] + 16
    while True:
        pair_ij = np.empty((2, size), np.int64)
        pair_f = np.empty((3, size))
        m = neighbour_pairs_into(x_m, y_m, cutoff_m, x0_m, y0_m, width_m, height_m, pair_ij, pair_f,
                                 np.empty((2, size), np.int64))
        if m >= 0:
            return (pair_ij[0, :m].copy(), pair_ij[1, :m].copy(), pair_f[0, :m].copy(), pair_f[1, :m].copy(),
                    pair_f[2, :m].copy())
        size = -m


@njit(cache=True, error_model="numpy")
def neighbour_pairs_into(x_m, y_m, cutoff_m, x0_m, y0_m, width_m, height_m, pair_ij, pair_f, scratch):
    """:func:`neighbour_pairs` into ``pair_ij`` ``(2, capacity)`` (i, j) and ``pair_f``
    ``(3, capacity)`` (dx, dy, d2), with ``scratch`` ``(2, capacity)``: returns how many, or minus
    that number if more than ``capacity`` (then the outputs are not valid)."""
    n = x_m.shape[0]
    size = pair_ij.shape[1]
    m = 0
    if n >= 2:
        near2 = cutoff_m * cutoff_m * (1.0 + 1e-9)
        cx, cy, start, items, mask, ncx, ncy, item_cell = build_grid(x_m, y_m, cutoff_m, x0_m, y0_m, width_m,
                                                                     height_m)
        for i in range(n):
            # Half the 3 x 3 cells around the point: its own (partners j > i), then (+1, 0),
            # (-1, +1), (0, +1), (+1, +1); the point's other neighbours find it from theirs.
            gxi, gyi = cx[i], cy[i]
            for cell in range(5):
                gx = gxi + (0 if cell == 0 else (1 if cell == 1 else cell - 3))
                gy = gyi + (0 if cell <= 1 else 1)
                if gx >= ncx or gy >= ncy or gx < 0:
                    continue  # no point outside the grid
                key = gy * ncx + gx
                bk = cell_bucket(gx, gy, ncx, mask)
                for q in range(start[bk], start[bk + 1]):
                    if item_cell[q] != key:
                        continue  # another cell sharing the bucket
                    j = items[q]
                    if cell == 0 and j <= i:
                        continue  # each pair once
                    a, b = (i, j) if i < j else (j, i)
                    dx = x_m[b] - x_m[a]
                    dy = y_m[b] - y_m[a]
                    if dx * dx + dy * dy > near2:
                        continue
                    if m < size:
                        scratch[0, m] = a
                        scratch[1, m] = b
                    m += 1
    if m > size:
        return -m
    # In order of i (a counting sort; j as found): the consumers' scattered accesses then run
    # through memory in order, which counts for thousands of robots.
    start_i = np.zeros(n + 1, np.int64)
    for q in range(m):
        start_i[scratch[0, q] + 1] += 1
    for i in range(n):
        start_i[i + 1] += start_i[i]
    for q in range(m):
        a = scratch[0, q]
        c = start_i[a]
        pair_ij[0, c] = a
        pair_ij[1, c] = scratch[1, q]
        start_i[a] = c + 1
    for q in range(m):
        dx = x_m[pair_ij[1, q]] - x_m[pair_ij[0, q]]
        dy = y_m[pair_ij[1, q]] - y_m[pair_ij[0, q]]
        pair_f[0, q] = dx
        pair_f[1, q] = dy
        pair_f[2, q] = dx * dx + dy * dy
    return m


# ------------------------------------------------------------------------------------ sensors


@njit(cache=True, error_model="numpy")
def ir_readings(pose, r_m, range_m, width_m, height_m, cos_a, sin_a, noise_u, noise_lo, noise_span):
    """IR proximity ``(N, S)`` of ``world.epuck.sensors.ir_proximity``: walls, then ordered robot pairs
    within ``2 r + range``; multiplicative noise ``U(-f, f)`` from ``(N, S)`` uniforms in [0, 1)
    (see :func:`uniform`)."""
    cos_h, sin_h = heading_cos_sin(pose)
    pairs = neighbour_pairs(pose[:, 0], pose[:, 1], 2.0 * r_m + range_m, 0.0, 0.0, width_m, height_m)
    out = np.empty((pose.shape[0], cos_a.shape[0]))
    _ir_readings(pose, cos_h, sin_h, r_m, range_m, width_m, height_m, cos_a, sin_a, noise_u, noise_lo, noise_span,
                 pairs[0], pairs[1], pairs[2], pairs[3], pairs[4], pairs[0].shape[0], out)
    return out


@njit(cache=True, error_model="numpy")
def heading_cos_sin(pose):
    n = pose.shape[0]
    cos_h = np.empty(n)
    sin_h = np.empty(n)
    for i in range(n):
        cos_h[i] = math.cos(pose[i, 2])
        sin_h[i] = math.sin(pose[i, 2])
    return cos_h, sin_h


@njit(cache=True, inline="always", error_model="numpy")
def _ray_to_body(dist, a, dx, dy, d2, cos_t, sin_t, r_m, cos_a, sin_a):
    """Ray-circle distances from observer ``a`` (heading cos/sin) to a body at ``D = (dx, dy)``:
    with ``k = D . u_s`` the ray from the perimeter point meets the body at ``t = k - r -
    sqrt(k^2 + r^2 - |D|^2)`` (if ``k - r >= 0`` and the root is real); ``|D|^2 <= 2 r k`` means
    the spot is inside or on the body (``t = 0``). Keeps the minimum in ``dist[a]``."""
    fwd = dx * cos_t + dy * sin_t  # D in observer a's frame
    left = dy * cos_t - dx * sin_t
    rr = r_m * r_m
    two_r = 2.0 * r_m
    for k in range(cos_a.shape[0]):
        kk = cos_a[k] * fwd + sin_a[k] * left
        disc = kk * kk + (rr - d2)
        t = kk - r_m
        d = np.inf
        if disc >= 0.0 and t >= 0.0:
            d = t - math.sqrt(disc)
        if d2 - two_r * kk <= 0.0:
            d = 0.0
        dist[a, k] = min(dist[a, k], d)


@njit(cache=True, error_model="numpy")
def _ir_readings(pose, cos_h, sin_h, r_m, range_m, width_m, height_m, cos_a, sin_a, noise_u, noise_lo, noise_span,
                 pair_i, pair_j, pair_dx, pair_dy, pair_d2, n_pairs, out):
    """:func:`ir_readings` into ``out`` ``(N, S)``, from the first ``n_pairs`` neighbour pairs."""
    n = pose.shape[0]
    n_s = cos_a.shape[0]
    dist = out  # distances first, turned into readings in place at the end
    dist[:] = np.inf
    reach_m = r_m + range_m
    x_hi = width_m - reach_m
    y_hi = height_m - reach_m
    for a in range(n):
        x, y = pose[a, 0], pose[a, 1]
        if not (x < reach_m or x > x_hi or y < reach_m or y > y_hi):
            continue
        c, s = cos_h[a], sin_h[a]
        for k in range(n_s):
            ux = c * cos_a[k] - s * sin_a[k]
            uy = s * cos_a[k] + c * sin_a[k]
            ox = x + r_m * ux
            oy = y + r_m * uy
            wall_x = width_m if ux > 0.0 else 0.0
            wall_y = height_m if uy > 0.0 else 0.0
            tx = (wall_x - ox) / ux if ux != 0.0 else np.inf
            ty = (wall_y - oy) / uy if uy != 0.0 else np.inf
            d = min(tx, ty)
            if ox < 0.0 or ox > width_m or oy < 0.0 or oy > height_m:
                d = 0.0
            dist[a, k] = d
    # Robot pairs, each seen from both ends: D = centre_b - centre_a is (dx, dy) from i and
    # exactly (-dx, -dy) from j, with the same squared length.
    cut2 = (2.0 * r_m + range_m) * (2.0 * r_m + range_m)
    for p in range(n_pairs):
        d2 = pair_d2[p]
        if d2 > cut2:
            continue
        i, j = pair_i[p], pair_j[p]
        _ray_to_body(dist, i, pair_dx[p], pair_dy[p], d2, cos_h[i], sin_h[i], r_m, cos_a, sin_a)
        _ray_to_body(dist, j, -pair_dx[p], -pair_dy[p], d2, cos_h[j], sin_h[j], r_m, cos_a, sin_a)
    scale = -1.0 / range_m
    for a in range(n):
        for k in range(n_s):
            v = _clip(dist[a, k] * scale + 1.0, 0.0, 1.0)
            out[a, k] = _clip(v * (uniform(noise_lo, noise_span, noise_u[a, k]) + 1.0), 0.0, 1.0)


@njit(cache=True, inline="always", error_model="numpy")
def _area_code_in(px, py, discs):
    """:func:`_area_code` of a point in an arena's ``discs`` (``world.epuck.arena.arena_discs``):
    on a tiled floor (8 numbers, the last two the tile's size) in the tile's own coordinates."""
    if discs.shape[0] >= 8:
        px = px - discs[6] * math.floor(px / discs[6])
        py = py - discs[7] * math.floor(py / discs[7])
    return _area_code(px, py, discs[0], discs[1], discs[2], discs[3], discs[4], discs[5])


@njit(cache=True, inline="always", error_model="numpy")
def _area_code(px, py, nest_x, nest_y, nest_r, prey_x, prey_y, prey_r):
    """AREA_NEST (1), AREA_PREY (2) or AREA_NONE (0) of a point, as ``world.epuck.arena.area_at``."""
    dx = px - nest_x
    dy = py - nest_y
    if dx * dx + dy * dy <= nest_r * nest_r:
        return 1
    dx = px - prey_x
    dy = py - prey_y
    if dx * dx + dy * dy <= prey_r * prey_r:
        return 2
    return 0


@njit(cache=True, error_model="numpy")
def ground_readings(pose, offsets, discs, reflectance, noise_u, noise_lo, noise_span):
    """Ground readings ``(N, G)`` of ``world.epuck.sensors.ground_sensors`` (noise from uniforms as in
    :func:`ir_readings`); ``discs`` = (nest x, y, r, prey x, y, r), ``reflectance`` indexed by
    area code."""
    cos_h, sin_h = heading_cos_sin(pose)
    out = np.empty((pose.shape[0], offsets.shape[0]))
    _ground_readings(pose, cos_h, sin_h, offsets, discs, reflectance, noise_u, noise_lo, noise_span, out)
    return out


@njit(cache=True, error_model="numpy")
def _ground_readings(pose, cos_h, sin_h, offsets, discs, reflectance, noise_u, noise_lo, noise_span, out):
    """:func:`ground_readings` into ``out`` ``(N, G)``."""
    n, n_g = pose.shape[0], offsets.shape[0]
    for i in range(n):
        c, s = cos_h[i], sin_h[i]
        for g in range(n_g):
            px = pose[i, 0] + c * offsets[g, 0] - s * offsets[g, 1]
            py = pose[i, 1] + s * offsets[g, 0] + c * offsets[g, 1]
            code = _area_code_in(px, py, discs)
            out[i, g] = reflectance[code] * (1.0 + uniform(noise_lo, noise_span, noise_u[i, g]))


@njit(cache=True, error_model="numpy")
def area_codes(points, discs):
    """``world.epuck.arena.area_at`` for points ``(N, 2)`` (int8 codes)."""
    n = points.shape[0]
    out = np.empty(n, np.int8)
    for i in range(n):
        out[i] = _area_code_in(points[i, 0], points[i, 1], discs)
    return out


# ------------------------------------------------------------------------------------- medium


@njit(cache=True, error_model="numpy")
def rab_candidates(pose, sending, range_m):
    """Every (sender, receiver) pair within ``range_m``, senders sending, sorted by (receiver,
    sender): ``(sender, receiver, dist_m, rel_x_m, rel_y_m)``, ``rel`` = sender - receiver."""
    n = pose.shape[0]
    if n < 2:
        return rab_candidates_from_pairs(pose, sending, range_m, *neighbour_pairs(
            pose[:, 0], pose[:, 1], range_m, 0.0, 0.0, 1.0, 1.0))
    x0, y0 = pose[:, 0].min(), pose[:, 1].min()
    width_m = min(pose[:, 0].max() - x0, 1e4 * range_m)  # robots far out share border cells
    height_m = min(pose[:, 1].max() - y0, 1e4 * range_m)
    pairs = neighbour_pairs(pose[:, 0], pose[:, 1], range_m, x0, y0, width_m, height_m)
    return rab_candidates_from_pairs(pose, sending, range_m, *pairs)


@njit(cache=True, error_model="numpy")
def rab_candidates_from_pairs(pose, sending, range_m, pair_i, pair_j, pair_dx, pair_dy, pair_d2):
    """:func:`rab_candidates` from :func:`neighbour_pairs` (any cutoff of at least ``range_m``):
    each pair within ``hypot <= range_m`` gives a message each way its sender sends."""
    n_pairs, n = pair_i.shape[0], pose.shape[0]
    work_i = np.empty((3, max(2 * n_pairs, 1)), np.int64)
    work_f = np.empty((4, max(2 * n_pairs, 1)))
    m = rab_candidates_into(pose, sending, range_m, pair_i, pair_j, pair_dx, pair_dy, pair_d2, n_pairs,
                            np.empty((2, n + 1), np.int64), work_i, work_f)
    return (work_i[1, :m].copy(), work_i[2, :m].copy(), work_f[1, :m].copy(), work_f[2, :m].copy(),
            work_f[3, :m].copy())


@njit(cache=True, error_model="numpy")
def rab_candidates_into(pose, sending, range_m, pair_i, pair_j, pair_dx, pair_dy, pair_d2, n_pairs, per_robot,
                        work_i, work_f):
    """:func:`rab_candidates_from_pairs` of the first ``n_pairs`` pairs, into work arrays of at
    least ``2 n_pairs`` columns: the candidates' sender and receiver go to ``work_i[1]``,
    ``work_i[2]``, their distance and ``rel`` to ``work_f[1:4]`` (rows 0 are scratch, as is
    ``per_robot`` ``(2, N + 1)``). Returns how many."""
    n = pose.shape[0]
    near2 = range_m * range_m * (1.0 + 1e-9)  # cheap pre-filter; hypot decides
    keep = work_i[0]
    dist_of = work_f[0]
    count = per_robot[0]  # messages per receiver, then run starts
    count[:] = 0
    n_keep = 0
    for p in range(n_pairs):
        if pair_d2[p] > near2:
            continue
        d = math.hypot(pair_dx[p], pair_dy[p])  # = hypot(-dx, -dy): either direction
        if d > range_m:
            continue
        i, j = pair_i[p], pair_j[p]
        if not (sending[i] or sending[j]):
            continue
        keep[n_keep] = p
        dist_of[n_keep] = d
        n_keep += 1
        if sending[i]:
            count[j + 1] += 1
        if sending[j]:
            count[i + 1] += 1
    for r in range(n):
        count[r + 1] += count[r]
    m = count[n]
    sender, receiver = work_i[1], work_i[2]
    dist, rel_x, rel_y = work_f[1], work_f[2], work_f[3]
    fill = per_robot[1]
    fill[:n] = count[:n]
    for q in range(n_keep):
        p = keep[q]
        i, j = pair_i[p], pair_j[p]
        if sending[i]:  # i -> j: rel = x_i - x_j = -(x_j - x_i), exactly
            c = fill[j]
            sender[c], receiver[c], dist[c], rel_x[c], rel_y[c] = i, j, dist_of[q], -pair_dx[p], -pair_dy[p]
            fill[j] += 1
        if sending[j]:  # j -> i
            c = fill[i]
            sender[c], receiver[c], dist[c], rel_x[c], rel_y[c] = j, i, dist_of[q], pair_dx[p], pair_dy[p]
            fill[i] += 1
    # within each receiver, order by sender (insertion sort: a handful each)
    for r in range(n):
        for a in range(count[r] + 1, count[r + 1]):
            b = a
            while b > count[r] and sender[b - 1] > sender[b]:
                sender[b - 1], sender[b] = sender[b], sender[b - 1]
                dist[b - 1], dist[b] = dist[b], dist[b - 1]
                rel_x[b - 1], rel_x[b] = rel_x[b], rel_x[b - 1]
                rel_y[b - 1], rel_y[b] = rel_y[b], rel_y[b - 1]
                b -= 1
    return m


@njit(cache=True, error_model="numpy")
def rab_select(sender, receiver, dist, rel_x, rel_y, theta, loss_u, near_m, range_m, loss_near, loss_far, cap):
    """The candidates that survive loss (``loss_u >= loss probability``) and the decoding cap
    (per receiver the ``cap`` nearest, ties by sender), in candidate order: ``(sender, receiver,
    dist, rel_x, rel_y, receiver_theta)``, ``theta`` being every robot's heading."""
    m = receiver.shape[0]
    keep = np.empty((2, m), np.int64)
    kept = rab_select_into(receiver, dist, loss_u, m, near_m, range_m, loss_near, loss_far, cap, keep)
    index = keep[1, :kept]
    return sender[index], receiver[index], dist[index], rel_x[index], rel_y[index], theta[receiver[index]]


@njit(cache=True, error_model="numpy")
def rab_select_into(receiver, dist, loss_u, m, near_m, range_m, loss_near, loss_far, cap, keep):
    """:func:`rab_select` of the first ``m`` candidates: their indices, in order, to ``keep[1]``
    (``keep[0]`` is scratch); returns how many."""
    survive = keep[0]
    k = 0
    span = range_m - near_m
    gain = loss_far - loss_near
    for q in range(m):
        t = _clip((dist[q] - near_m) / span, 0.0, 1.0)
        if loss_u[q] >= loss_near + gain * t:
            survive[k] = q
            k += 1
    out = keep[1]
    kept = 0
    lo = 0
    while lo < k:
        hi = lo
        while hi < k and receiver[survive[hi]] == receiver[survive[lo]]:
            hi += 1
        if hi - lo <= cap:
            for q in range(lo, hi):
                out[kept] = survive[q]
                kept += 1
        else:
            # rank of each survivor by (distance, position in the run); keep rank < cap
            for q in range(lo, hi):
                dq = dist[survive[q]]
                rank = 0
                for o in range(lo, hi):
                    do = dist[survive[o]]
                    if do < dq or (do == dq and o < q):
                        rank += 1
                if rank < cap:
                    out[kept] = survive[q]
                    kept += 1
        lo = hi
    return kept


@njit(cache=True, error_model="numpy")
def rab_measure(dist, noise_u, range_lo, range_span, bearing_atan, receiver_theta, bearing_lo, bearing_span):
    """Measured range ``max(d + noise, 0)`` and bearing ``wrap(atan2 - theta + noise)``; the
    ``2K`` uniforms are the K range noises, then the K bearing noises (see :func:`uniform`)."""
    k = dist.shape[0]
    range_m = np.empty(k)
    bearing = np.empty(k)
    for q in range(k):
        v = dist[q] + uniform(range_lo, range_span, noise_u[q])
        range_m[q] = max(v, 0.0)  # np.maximum keeps -0.0
        bearing[q] = wrap(bearing_atan[q] - receiver_theta[q] + uniform(bearing_lo, bearing_span, noise_u[k + q]))
    return range_m, bearing


# ---------------------------------------------------------------------------- body and arena


@njit(cache=True, error_model="numpy")
def move_bodies(pose, cmd, alive, vmax, tick_s, metres_per_step, slip_u, slip_lo, slip_span, wheelbase_m, out,
                encoder):
    """Wheel commands to encoder counts ``encoder`` ``(N, 2)`` and true poses ``out`` ``(N, 3)``
    (``ForagingWorld.step``; seed 000 eq. 3-7).

    ``slip_u`` ``(S, N, 2)``: the tick is ``S`` physics sub-steps (``OdometryConfig.substeps``),
    each wheel travelling ``1/S`` of its commanded steps in each, times its own slip factor
    ``U(-slip, slip)`` of that sub-step (see :func:`uniform`), the pose integrated after each
    (eq. 7). The encoders count the commanded steps of the whole tick.
    """
    n = pose.shape[0]
    n_sub = slip_u.shape[0]
    for i in range(n):
        left = _clip(cmd[i, 0], -vmax, vmax) * tick_s if alive[i] else 0.0
        right = _clip(cmd[i, 1], -vmax, vmax) * tick_s if alive[i] else 0.0
        encoder[i, 0] = left
        encoder[i, 1] = right
        x, y, theta = pose[i, 0], pose[i, 1], pose[i, 2]
        sub_left = left / n_sub  # exact for S = 1
        sub_right = right / n_sub
        for s in range(n_sub):
            du_left = sub_left * metres_per_step * (1.0 + uniform(slip_lo, slip_span, slip_u[s, i, 0]))
            du_right = sub_right * metres_per_step * (1.0 + uniform(slip_lo, slip_span, slip_u[s, i, 1]))
            d_theta = (du_right - du_left) / wheelbase_m
            d_rho = (du_right + du_left) / 2.0
            zeta = theta + d_theta / 2.0
            x = x + d_rho * math.cos(zeta)
            y = y + d_rho * math.sin(zeta)
            theta = wrap(theta + d_theta)
        out[i, 0] = x
        out[i, 1] = y
        out[i, 2] = theta


@njit(cache=True, error_model="numpy")
def separate_bodies(pos, radius_m, width_m, height_m, iterations):
    """``world.epuck.arena.resolve_collisions`` with every body movable, in place on ``pos`` (N, 2).

    Returns False, leaving ``pos`` partly updated, if in some iteration a body overlaps three or
    more others: the numpy version sums those pushes in KD-tree order, which this kernel does not
    reproduce; the caller then runs the numpy version (for sums of two, order does not matter).
    """
    none = np.empty(0, np.int64)
    return separate_bodies_near(pos, radius_m, width_m, height_m, iterations, pos, none, none, 0.0)


@njit(cache=True, error_model="numpy")
def separate_bodies_near(pos, radius_m, width_m, height_m, iterations, ref_pos, pair_i, pair_j, pair_cutoff_m):
    """:func:`separate_bodies`, given the :func:`neighbour_pairs` ``(pair_i, pair_j)`` of the
    positions ``ref_pos`` within ``pair_cutoff_m``: while no body has moved farther than
    ``(pair_cutoff_m - 2 radius_m) / 2`` from there, every overlapping pair is among them (triangle
    inequality), so no grid is needed; else the grid is searched as in :func:`separate_bodies`.
    The same pairs are found either way, so the result is the same."""
    n = pos.shape[0]
    min_gap = 2.0 * radius_m
    lo_x, lo_y = radius_m, radius_m
    hi_x, hi_y = width_m - radius_m, height_m - radius_m
    acc = np.zeros((n, 2))
    count = np.zeros(n, np.int64)
    near2 = min_gap * min_gap * (1.0 + 1e-9)  # cheap pre-filter; hypot decides
    for _ in range(iterations):
        any_pair = False
        if n >= 2:
            acc[:] = 0.0
            count[:] = 0
            moved2 = 0.0  # the largest squared move: the test has a 1e-9 margin for its rounding
            if pair_cutoff_m > 0.0:
                for i in range(n):
                    dx = pos[i, 0] - ref_pos[i, 0]
                    dy = pos[i, 1] - ref_pos[i, 1]
                    moved2 = max(moved2, dx * dx + dy * dy)
            if pair_cutoff_m > 0.0 and min_gap + 2.0 * math.sqrt(moved2) + 1e-9 <= pair_cutoff_m:
                for p in range(pair_i.shape[0]):
                    any_pair |= _push_pair(pos, pair_i[p], pair_j[p], min_gap, near2, acc, count)
            else:
                cx, cy, start, items, mask, ncx, ncy, item_cell = build_grid(pos[:, 0], pos[:, 1], min_gap, 0.0,
                                                                             0.0, width_m, height_m)
                for i in range(n):
                    for cell in range(9):  # the 3 x 3 cells around the point
                        gx, gy = cx[i] - 1 + cell % 3, cy[i] - 1 + cell // 3
                        if gx < 0 or gy < 0 or gx >= ncx or gy >= ncy:
                            continue  # no point outside the grid
                        key = gy * ncx + gx
                        bk = cell_bucket(gx, gy, ncx, mask)
                        for q in range(start[bk], start[bk + 1]):
                            j = items[q]
                            if j <= i or item_cell[q] != key:
                                continue  # each pair once; skip other cells sharing the bucket
                            any_pair |= _push_pair(pos, i, j, min_gap, near2, acc, count)
            if any_pair:
                for i in range(n):
                    if count[i] >= 3:
                        return False
                for i in range(n):
                    pos[i, 0] += acc[i, 0]
                    pos[i, 1] += acc[i, 1]
        moved = any_pair
        for i in range(n):
            x = _clip(pos[i, 0], lo_x, hi_x)
            y = _clip(pos[i, 1], lo_y, hi_y)
            if x != pos[i, 0] or y != pos[i, 1]:
                moved = True
            pos[i, 0] = x
            pos[i, 1] = y
        if not moved:
            break  # nothing overlaps and nothing moved: further iterations change nothing
    if iterations == 0:
        for i in range(n):
            pos[i, 0] = _clip(pos[i, 0], lo_x, hi_x)
            pos[i, 1] = _clip(pos[i, 1], lo_y, hi_y)
    return True


@njit(cache=True, inline="always", error_model="numpy")
def _push_pair(pos, i, j, min_gap, near2, acc, count):
    """If bodies ``i < j`` overlap, add their pushes (half the overlap each, along the centre
    line) to ``acc`` and count them; returns whether they overlap."""
    dx = pos[j, 0] - pos[i, 0]
    dy = pos[j, 1] - pos[i, 1]
    if dx * dx + dy * dy > near2:
        return False
    dist = math.hypot(dx, dy)
    if not dist < min_gap:
        return False
    if dist > 0.0:
        ux, uy = dx / dist, dy / dist
    else:
        ux, uy = 1.0, 0.0  # coincident: lower index towards -x
    half = 0.5 * (min_gap - dist)
    acc[i, 0] += -half * ux
    acc[i, 1] += -half * uy
    acc[j, 0] += half * ux
    acc[j, 1] += half * uy
    count[i] += 1
    count[j] += 1
    return True


# ------------------------------------------------------------------------------------ metrics


@njit(cache=True, error_model="numpy")
def sensor_areas(pose, ahead_m, discs):
    """True area code under each robot's middle ground sensor (``ground_sensor_point``)."""
    cos_h, sin_h = heading_cos_sin(pose)
    return _sensor_areas(pose, cos_h, sin_h, ahead_m, discs)


@njit(cache=True, error_model="numpy")
def _sensor_areas(pose, cos_h, sin_h, ahead_m, discs):
    n = pose.shape[0]
    out = np.empty(n, np.int8)
    for i in range(n):
        px = pose[i, 0] + ahead_m * cos_h[i]
        py = pose[i, 1] + ahead_m * sin_h[i]
        out[i] = _area_code_in(px, py, discs)
    return out


@njit(cache=True, error_model="numpy")
def update_round_trips(tick, area, first_visit_tick, round_trips, stage, nest, prey, no_nest, to_prey, to_nest):
    """``ForagingMetrics.update`` bookkeeping of first visits and round trips, in place."""
    for i in range(area.shape[0]):
        a = area[i]
        if a == nest:
            if first_visit_tick[i, 0] < 0:
                first_visit_tick[i, 0] = tick
            if stage[i] == to_nest:
                round_trips[i] += 1
            stage[i] = to_prey
        elif a == prey:
            if first_visit_tick[i, 1] < 0:
                first_visit_tick[i, 1] = tick
            if stage[i] == to_prey:
                stage[i] = to_nest




# ------------------------------------------------------------------ one world tick, two calls

#: Slots of the world's constants in :func:`world_params`.
(P_BODY_RADIUS, P_IR_RANGE, P_WIDTH, P_HEIGHT, P_IR_LO, P_IR_SPAN, P_GROUND_LO, P_GROUND_SPAN, P_PAIR_CUTOFF,
 P_RAB_RANGE, P_RANGE_LO, P_RANGE_SPAN, P_BEARING_LO, P_BEARING_SPAN, P_NEAR, P_LOSS_NEAR, P_LOSS_FAR,
 P_MAX_RECEIVED, P_VMAX, P_TICK, P_METRES_PER_STEP, P_SLIP_LO, P_SLIP_SPAN, P_WHEELBASE, P_ITERATIONS,
 P_AHEAD, P_SUBSTEPS, N_PARAMS) = range(28)
#: Slots of the counters that :func:`observe_tick` and :func:`step_tick` share with their caller.
C_PAIRS, C_CROSSED, C_DELIVERED, C_SEPARATED, C_ON_PATH, N_COUNTS = range(6)


def world_params(*, body_radius_m, ir_range_m, width_m, height_m, ir_noise, ground_noise, pair_cutoff_m,
                 rab_range_m, range_noise_m, bearing_noise_rad, near_m, loss_near, loss_far, max_received,
                 vmax, tick_s, metres_per_step, slip_fraction, wheelbase_m, iterations, ahead_m,
                 substeps=1) -> np.ndarray:
    """The world's constants in one array (slots ``P_*``). Each noise ``f`` becomes the ``low``
    and ``span`` of ``U(-f, f)`` as :func:`uniform` wants them: ``-f`` and ``f - -f``."""
    p = np.zeros(N_PARAMS)
    for slot, value in (
        (P_BODY_RADIUS, body_radius_m), (P_IR_RANGE, ir_range_m), (P_WIDTH, width_m), (P_HEIGHT, height_m),
        (P_IR_LO, -ir_noise), (P_IR_SPAN, ir_noise - -ir_noise),
        (P_GROUND_LO, -ground_noise), (P_GROUND_SPAN, ground_noise - -ground_noise),
        (P_PAIR_CUTOFF, max(pair_cutoff_m, 2.0 * body_radius_m + ir_range_m)),
        (P_RAB_RANGE, rab_range_m), (P_RANGE_LO, -range_noise_m), (P_RANGE_SPAN, range_noise_m - -range_noise_m),
        (P_BEARING_LO, -bearing_noise_rad), (P_BEARING_SPAN, bearing_noise_rad - -bearing_noise_rad),
        (P_NEAR, near_m), (P_LOSS_NEAR, loss_near), (P_LOSS_FAR, loss_far), (P_MAX_RECEIVED, max_received),
        (P_VMAX, vmax), (P_TICK, tick_s), (P_METRES_PER_STEP, metres_per_step),
        (P_SLIP_LO, -slip_fraction), (P_SLIP_SPAN, slip_fraction - -slip_fraction), (P_WHEELBASE, wheelbase_m),
        (P_ITERATIONS, iterations), (P_AHEAD, ahead_m), (P_SUBSTEPS, substeps),
    ):
        p[slot] = float(value)
    return p


@njit(cache=True, error_model="numpy")
def observe_tick(pose, params, cos_a, sin_a, offsets, discs, reflectance, rng_fn, rng_state, ir, ground, pair_ij,
                 pair_f, pair_scratch, snapshot, counts, crossed_ij, crossed_f, alive, d_sender, d_receiver, d_range,
                 d_bearing, trig, trig_pose, noise_u):
    """``ForagingWorld.observe`` in one call: the IR and ground readings of ``world/epuck/sensors.py``
    (:func:`ir_readings`, :func:`ground_readings`) into ``ir`` ``(N, S)`` and ``ground`` ``(N, G)``,
    their noises drawn from the world's generator (``rng_fn``, ``rng_state``: see
    :func:`~swarmloc.numerics.generator_address`) as one ``random(N S + N G)``: the IR noises, then the ground ones.

    The neighbour pairs within ``params[P_PAIR_CUTOFF]`` (at least the IR reach ``2 r + range``)
    go to ``pair_ij`` and ``pair_f`` (:func:`neighbour_pairs_into`, with ``pair_scratch``), their
    number to ``counts[C_PAIRS]``, ``pose`` to ``snapshot``: :func:`step_tick` reuses them while
    the poses are these. If they do not fit, nothing else is done (no draw) and
    ``counts[C_PAIRS]`` is minus the capacity needed: returns -1 then, else the number of
    messages delivered. ``noise_u``: room for the ``N (S + G)`` uniforms.

    The messages that crossed at the last :func:`step_tick` (``counts[C_CROSSED]`` of them in
    ``crossed_ij``, ``crossed_f``) to live receivers go to ``d_sender``, ... in order, their
    number to ``counts[C_DELIVERED]``. ``trig`` ``(2, N)``: the cosines and sines of the headings
    ``trig_pose`` that :func:`step_tick` left, used if the poses are still those.
    """
    n, n_s, n_g = pose.shape[0], cos_a.shape[0], offsets.shape[0]
    r_m, ir_range_m = params[P_BODY_RADIUS], params[P_IR_RANGE]
    width_m, height_m = params[P_WIDTH], params[P_HEIGHT]
    m = neighbour_pairs_into(pose[:, 0], pose[:, 1], params[P_PAIR_CUTOFF], 0.0, 0.0, width_m, height_m, pair_ij,
                             pair_f, pair_scratch)
    counts[C_PAIRS] = m
    if m < 0:
        return -1
    snapshot[:] = pose
    u = noise_u[: n * (n_s + n_g)]
    fill_random(u, rng_fn, rng_state)
    same = trig_pose.shape[0] == n
    if same:
        for i in range(n):
            if trig_pose[i, 0] != pose[i, 0] or trig_pose[i, 1] != pose[i, 1] or trig_pose[i, 2] != pose[i, 2]:
                same = False
                break
    if same:
        cos_h, sin_h = trig[0], trig[1]
    else:
        cos_h, sin_h = heading_cos_sin(pose)
    _ir_readings(pose, cos_h, sin_h, r_m, ir_range_m, width_m, height_m, cos_a, sin_a, u[: n * n_s].reshape((n, n_s)),
                 params[P_IR_LO], params[P_IR_SPAN], pair_ij[0], pair_ij[1], pair_f[0], pair_f[1], pair_f[2], m, ir)
    _ground_readings(pose, cos_h, sin_h, offsets, discs, reflectance, u[n * n_s :].reshape((n, n_g)),
                     params[P_GROUND_LO], params[P_GROUND_SPAN], ground)
    kept = 0
    for q in range(counts[C_CROSSED]):
        receiver = crossed_ij[1, q]
        if not alive[receiver]:
            continue  # a dead robot hears nothing
        d_sender[kept] = crossed_ij[0, q]
        d_receiver[kept] = receiver
        d_range[kept] = crossed_f[0, q]
        d_bearing[kept] = crossed_f[1, q]
        kept += 1
    counts[C_DELIVERED] = kept
    return kept


@njit(cache=True, error_model="numpy")
def step_tick(pose, cmd, alive, sending, on_path, params, discs, rng_fn, rng_state, math_fns, pair_ij, pair_f,
              snapshot, counts, pose_out, encoder_out, crossed_ij, crossed_f, tick, first_visit_tick, round_trips, stage,
              stage_codes, trig, trig_pose, per_robot, work_i, work_f, step_u):
    """``ForagingWorld.step`` in one call, drawing from the world's generator (see
    :func:`observe_tick`) in the order of ``world/epuck/medium.py`` and ``ForagingWorld.step``.

    1. The medium (:func:`rab_candidates_from_pairs` on the pairs of :func:`observe_tick` if
       ``pose`` equals its ``snapshot``, else :func:`rab_candidates`; then a loss uniform per
       candidate and :func:`rab_select`): the messages of live senders that cross, to
       ``crossed_ij`` (sender, receiver) and ``crossed_f`` (the range and bearing the receiver
       measures, as :func:`rab_measure`, with numpy's ``arctan2``: :func:`~swarmloc.numerics.np_arctan2`), their
       number to ``counts[C_CROSSED]``; the uniforms for the K range and K bearing noises and the
       ``(S, N, 2)`` slips of the ``S = params[P_SUBSTEPS]`` sub-steps come as one
       ``random(2 K + 2 S N)``;
    2. :func:`move_bodies` into ``pose_out`` and ``encoder_out``, :func:`separate_bodies_near`;
    3. if that succeeded (``counts[C_SEPARATED]`` = 1), the metrics' bookkeeping of ``tick``
       (:func:`sensor_areas`, :func:`update_round_trips` with ``stage_codes`` = nest, prey, and the
       three stages) and the number of live robots on the path, ``counts[C_ON_PATH]``; the
       headings' cosines and sines go to ``trig`` for the next :func:`observe_tick`, with the
       poses to ``trig_pose``. Else (a crowd) ``pose_out`` is before collisions and the caller
       finishes the tick.

    Scratch (reused from tick to tick: a swarm of thousands would otherwise allocate megabytes
    per tick, which the C library hands back to the system and takes again, page by page):
    ``per_robot`` ``(2, N + 1)``, ``work_i`` ``(5, L)``, ``work_f`` ``(7, L)`` with ``L`` at least
    twice the pair capacity of ``pair_ij``, ``step_u`` room for ``2 K + 2 S N`` uniforms.

    Returns ``counts[C_ON_PATH]``, or -1 for a crowd.
    """
    n = pose.shape[0]
    live_sending = np.empty(n, np.bool_)
    for i in range(n):
        live_sending[i] = sending[i] and alive[i]
    n_pairs = counts[C_PAIRS]
    same = (0 <= n_pairs <= pair_ij.shape[1] and snapshot.shape[0] == n and 2 * n_pairs <= work_i.shape[1]
            and 2 * n_pairs <= work_f.shape[1])
    if same:
        for i in range(n):
            if snapshot[i, 0] != pose[i, 0] or snapshot[i, 1] != pose[i, 1] or snapshot[i, 2] != pose[i, 2]:
                same = False
                break
    if not same:
        n_pairs = 0
    pi = pair_ij[0, :n_pairs]
    pj = pair_ij[1, :n_pairs]
    rab_range_m = params[P_RAB_RANGE]
    if same:  # the pairs' dx, dy, d2 are those of these very poses
        m = rab_candidates_into(pose, live_sending, rab_range_m, pi, pj, pair_f[0], pair_f[1], pair_f[2], n_pairs,
                                per_robot, work_i, work_f)
        sender, receiver, dist, rel_x, rel_y = work_i[1], work_i[2], work_f[1], work_f[2], work_f[3]
    else:
        sender, receiver, dist, rel_x, rel_y = rab_candidates(pose, live_sending, rab_range_m)
        m = sender.shape[0]
    if m <= work_f.shape[1]:
        loss_u, keep = work_f[4, :m], work_i[3:5]
    else:  # a fresh search found more than the pairs' room
        loss_u, keep = np.empty(m), np.empty((2, m), np.int64)
    fill_random(loss_u, rng_fn, rng_state)
    k = rab_select_into(receiver, dist, loss_u, m, params[P_NEAR], rab_range_m, params[P_LOSS_NEAR],
                        params[P_LOSS_FAR], int(params[P_MAX_RECEIVED]), keep)
    # The boards' measurements (rab_measure), straight into crossed_f
    n_sub = int(params[P_SUBSTEPS])
    u = step_u[: 2 * k + 2 * n_sub * n]
    fill_random(u, rng_fn, rng_state)
    rel = work_f[5:7, :k] if k <= work_f.shape[1] else np.empty((2, k))
    for q in range(k):
        c = keep[1, q]
        crossed_ij[0, q] = sender[c]
        crossed_ij[1, q] = receiver[c]
        rel[0, q] = rel_x[c]
        rel[1, q] = rel_y[c]
    bearing_atan = crossed_f[1, :k]
    np_arctan2(rel[1], rel[0], bearing_atan, math_fns)
    range_lo, range_span = params[P_RANGE_LO], params[P_RANGE_SPAN]
    bearing_lo, bearing_span = params[P_BEARING_LO], params[P_BEARING_SPAN]
    for q in range(k):
        v = dist[keep[1, q]] + uniform(range_lo, range_span, u[q])
        crossed_f[0, q] = max(v, 0.0)  # np.maximum keeps -0.0
        theta = pose[crossed_ij[1, q], 2]
        crossed_f[1, q] = wrap(bearing_atan[q] - theta + uniform(bearing_lo, bearing_span, u[k + q]))
    counts[C_CROSSED] = k
    move_bodies(pose, cmd, alive, params[P_VMAX], params[P_TICK], params[P_METRES_PER_STEP],
                u[2 * k :].reshape((n_sub, n, 2)), params[P_SLIP_LO], params[P_SLIP_SPAN], params[P_WHEELBASE], pose_out,
                encoder_out)
    r_m = params[P_BODY_RADIUS]
    pos = pose_out[:, :2].copy()
    ok = separate_bodies_near(pos, r_m, params[P_WIDTH], params[P_HEIGHT], int(params[P_ITERATIONS]), pose, pi, pj,
                              params[P_PAIR_CUTOFF] if same else 0.0)
    counts[C_SEPARATED] = 1 if ok else 0
    if not ok:
        return -1
    pose_out[:, :2] = pos
    for i in range(n):
        trig[0, i] = math.cos(pose_out[i, 2])
        trig[1, i] = math.sin(pose_out[i, 2])
    trig_pose[:] = pose_out
    area = _sensor_areas(pose_out, trig[0], trig[1], params[P_AHEAD], discs)
    update_round_trips(tick, area, first_visit_tick, round_trips, stage, stage_codes[0], stage_codes[1],
                       stage_codes[2], stage_codes[3], stage_codes[4])
    on = 0
    for i in range(n):
        if on_path[i] and alive[i]:
            on += 1
    counts[C_ON_PATH] = on
    return on


# ------------------------------------------------------------------------- initial placement


@njit(cache=True, error_model="numpy")
def place_candidates(pose, placed, cand, min_gap_m):
    """``world.epuck.foraging.initial_poses``' rejection step: candidates ``cand`` ``(M, 2)`` in
    order, each kept (written to ``pose[placed]``) if no body kept so far is nearer than
    ``min_gap_m`` (``hypot(pose - c) >= min_gap_m`` for all, the numpy test exactly), until
    ``pose`` ``(N, >= 2)`` is full; returns the new ``placed``. The bodies kept are found on a
    hash grid of cells ``min_gap_m`` wide, so a swarm of 100,000 is placed in O(N) per batch
    instead of O(N^2)."""
    n, m = pose.shape[0], cand.shape[0]
    if placed >= n or m == 0:
        return placed
    cell_m = min_gap_m * (1.0 + 1e-9)  # a body nearer than the gap is in one of the 3 x 3 cells
    x0, y0 = cand[0, 0], cand[0, 1]
    n_buckets = 16
    while n_buckets < 2 * n:
        n_buckets *= 2
    mask = n_buckets - 1
    head = np.full(n_buckets, -1, np.int64)
    nxt = np.empty(n, np.int64)
    gxs = np.empty(n, np.int64)
    gys = np.empty(n, np.int64)
    for i in range(placed):
        gx = int(math.floor((pose[i, 0] - x0) / cell_m))  # noqa: RUF046 -- numba types it
        gy = int(math.floor((pose[i, 1] - y0) / cell_m))  # noqa: RUF046 -- numba types it
        gxs[i], gys[i] = gx, gy
        b = _cell_hash(gx, gy, mask)
        nxt[i] = head[b]
        head[b] = i
    for q in range(m):
        if placed == n:
            break
        cx, cy = cand[q, 0], cand[q, 1]
        gx = int(math.floor((cx - x0) / cell_m))  # noqa: RUF046 -- numba types it
        gy = int(math.floor((cy - y0) / cell_m))  # noqa: RUF046 -- numba types it
        free = True
        for cell in range(9):
            ox, oy = gx - 1 + cell % 3, gy - 1 + cell // 3
            j = head[_cell_hash(ox, oy, mask)]
            while j >= 0:
                if gxs[j] == ox and gys[j] == oy and not math.hypot(pose[j, 0] - cx, pose[j, 1] - cy) >= min_gap_m:
                    free = False
                    break
                j = nxt[j]
            if not free:
                break
        if free:
            pose[placed, 0] = cx
            pose[placed, 1] = cy
            gxs[placed], gys[placed] = gx, gy
            b = _cell_hash(gx, gy, mask)
            nxt[placed] = head[b]
            head[b] = placed
            placed += 1
    return placed
