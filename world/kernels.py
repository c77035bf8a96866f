"""Compiled (numba) kernels of the e-puck world models: the inner loops of ``world/sensors.py``,
``world/medium.py``, ``world/arena.py``, ``world/metrics.py`` and the kinematics of
``protocol/epuck.py``, over a batch of robots.

They are not a second implementation: the public model functions (``ir_proximity``,
``ground_sensors``, ``deliver``, ``resolve_collisions``, ``ForagingWorld.step``) call them, so
the world-server and the batch engine run exactly this code. Each kernel evaluates the same
floating-point expressions, in the same order, as the numpy formulation it replaced (seed 000
eq. 3-7 for the kinematics, §6.1 for sensors and medium), so a seeded run is bit-identical to
the numpy one (``benchmarks/fingerprint.py``). Two things stay outside, in numpy, on purpose:

- every random draw: the world's generator is called by the model function, in the documented
  order, and the uniforms are passed in (same seed, same numbers);
- ``arctan2`` and ``exp``: numpy evaluates them with its own SIMD routines on this hardware,
  which differ from the C library's in the last bit; ``sin``, ``cos``, ``hypot`` and ``sqrt``
  agree bit for bit and are used here.

Neighbourhoods come from a spatial hash of square cells (side at least the query radius), built
in O(N); the 3 x 3 cells around a robot hold every candidate (:func:`neighbour_pairs`).
``ForagingWorld`` finds the pairs once per tick, when sensing, and the medium and the collisions
of the same tick reuse them (the collisions only while nobody has moved far enough for a new
contact to come from elsewhere, else they search again): the same pairs as a fresh search.
Collisions where a body touches three or more others go back to the KD-tree version of
``world/arena.py``, whose summation order defines the result.

Kernels are compiled on first use and cached on disk (``cache=True``, next to this file): the
first run on a machine compiles for some 10-25 s, later processes load them in about a second.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

_PI = math.pi
_TWO_PI = 2.0 * math.pi


@njit(cache=True, inline="always", error_model="numpy")
def wrap(angle_rad):
    """``(a + pi) % (2 pi) - pi``: Python/numpy float modulo semantics, as ``wrap_angle``."""
    return (angle_rad + _PI) % _TWO_PI - _PI


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
    (points outside go to the border cells): ``(cx, cy, start, items, mask)``. The points of
    cell ``(gx, gy)`` are among ``items[start[b]:start[b + 1]]`` with ``b = cell_bucket(gx, gy,
    mask)``, together with those of other cells that share the bucket (check ``cx``, ``cy``).
    O(N) however sparse or large the arena: about two buckets per point.
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
        b = cell_bucket(cx[i], cy[i], mask)
        bucket[i] = b
        start[b + 1] += 1
    for b in range(n_buckets):
        start[b + 1] += start[b]
    fill = start[:-1].copy()
    items = np.empty(n, np.int64)
    for i in range(n):
        items[fill[bucket[i]]] = i
        fill[bucket[i]] += 1
    return cx, cy, start, items, mask


@njit(cache=True, inline="always", error_model="numpy")
def cell_bucket(gx, gy, mask):
    """Hash bucket of cell ``(gx, gy)``: the 9 cells around a point are looked up by hash."""
    return ((gx * 73856093) ^ (gy * 19349663)) & mask


@njit(cache=True, error_model="numpy")
def neighbour_pairs(x_m, y_m, cutoff_m, x0_m, y0_m, width_m, height_m):
    """Unordered pairs ``i < j`` of points at most about ``cutoff_m`` apart (a superset: the
    squared distance is compared with ``cutoff_m**2`` enlarged by 1e-9, so that every pair whose
    ``hypot`` is within ``cutoff_m`` is in): ``(i, j, dx, dy, d2)`` with ``dx = x[j] - x[i]``,
    ``d2 = dx * dx + dy * dy``. Callers apply their own exact test. Grid over
    ``[x0, x0 + width] x [y0, y0 + height]`` (:func:`build_grid`)."""
    n = x_m.shape[0]
    size = 8 * n + 16
    pi = np.empty(size, np.int64)
    pj = np.empty(size, np.int64)
    m = 0
    if n >= 2:
        near2 = cutoff_m * cutoff_m * (1.0 + 1e-9)
        cx, cy, start, items, mask = build_grid(x_m, y_m, cutoff_m, x0_m, y0_m, width_m, height_m)
        for i in range(n):
            for cell in range(9):  # the 3 x 3 cells around the point
                gx, gy = cx[i] - 1 + cell % 3, cy[i] - 1 + cell // 3
                bk = cell_bucket(gx, gy, mask)
                for q in range(start[bk], start[bk + 1]):
                    j = items[q]
                    if j <= i or cx[j] != gx or cy[j] != gy:
                        continue  # each pair once; skip other cells sharing the bucket
                    dx = x_m[j] - x_m[i]
                    dy = y_m[j] - y_m[i]
                    if dx * dx + dy * dy > near2:
                        continue
                    if m == size:
                        size *= 2
                        grown = np.empty(size, np.int64)
                        grown[:m] = pi[:m]
                        pi = grown
                        grown = np.empty(size, np.int64)
                        grown[:m] = pj[:m]
                        pj = grown
                    pi[m] = i
                    pj[m] = j
                    m += 1
    pi = pi[:m].copy()
    pj = pj[:m].copy()
    pdx = np.empty(m)
    pdy = np.empty(m)
    pd2 = np.empty(m)
    for q in range(m):
        pdx[q] = x_m[pj[q]] - x_m[pi[q]]
        pdy[q] = y_m[pj[q]] - y_m[pi[q]]
        pd2[q] = pdx[q] * pdx[q] + pdy[q] * pdy[q]
    return pi, pj, pdx, pdy, pd2


# ------------------------------------------------------------------------------------ sensors


@njit(cache=True, error_model="numpy")
def ir_readings(pose, r_m, range_m, width_m, height_m, cos_a, sin_a, noise_u, noise_lo, noise_span):
    """IR proximity ``(N, S)`` of ``world.sensors.ir_proximity``: walls, then ordered robot pairs
    within ``2 r + range``; multiplicative noise ``U(-f, f)`` from ``(N, S)`` uniforms in [0, 1)
    (see :func:`uniform`)."""
    cos_h, sin_h = heading_cos_sin(pose)
    pairs = neighbour_pairs(pose[:, 0], pose[:, 1], 2.0 * r_m + range_m, 0.0, 0.0, width_m, height_m)
    return _ir_readings(pose, cos_h, sin_h, r_m, range_m, width_m, height_m, cos_a, sin_a, noise_u,
                        noise_lo, noise_span, *pairs)


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
                 pair_i, pair_j, pair_dx, pair_dy, pair_d2):
    n = pose.shape[0]
    n_s = cos_a.shape[0]
    dist = np.full((n, n_s), np.inf)
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
    for p in range(pair_i.shape[0]):
        d2 = pair_d2[p]
        if d2 > cut2:
            continue
        i, j = pair_i[p], pair_j[p]
        _ray_to_body(dist, i, pair_dx[p], pair_dy[p], d2, cos_h[i], sin_h[i], r_m, cos_a, sin_a)
        _ray_to_body(dist, j, -pair_dx[p], -pair_dy[p], d2, cos_h[j], sin_h[j], r_m, cos_a, sin_a)
    scale = -1.0 / range_m
    out = np.empty((n, n_s))
    for a in range(n):
        for k in range(n_s):
            v = _clip(dist[a, k] * scale + 1.0, 0.0, 1.0)
            out[a, k] = _clip(v * (uniform(noise_lo, noise_span, noise_u[a, k]) + 1.0), 0.0, 1.0)
    return out


@njit(cache=True, inline="always", error_model="numpy")
def _area_code(px, py, nest_x, nest_y, nest_r, prey_x, prey_y, prey_r):
    """AREA_NEST (1), AREA_PREY (2) or AREA_NONE (0) of a point, as ``world.arena.area_at``."""
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
    """Ground readings ``(N, G)`` of ``world.sensors.ground_sensors`` (noise from uniforms as in
    :func:`ir_readings`); ``discs`` = (nest x, y, r, prey x, y, r), ``reflectance`` indexed by
    area code."""
    cos_h, sin_h = heading_cos_sin(pose)
    return _ground_readings(pose, cos_h, sin_h, offsets, discs, reflectance, noise_u, noise_lo, noise_span)


@njit(cache=True, error_model="numpy")
def _ground_readings(pose, cos_h, sin_h, offsets, discs, reflectance, noise_u, noise_lo, noise_span):
    n, n_g = pose.shape[0], offsets.shape[0]
    out = np.empty((n, n_g))
    for i in range(n):
        c, s = cos_h[i], sin_h[i]
        for g in range(n_g):
            px = pose[i, 0] + c * offsets[g, 0] - s * offsets[g, 1]
            py = pose[i, 1] + s * offsets[g, 0] + c * offsets[g, 1]
            code = _area_code(px, py, discs[0], discs[1], discs[2], discs[3], discs[4], discs[5])
            out[i, g] = reflectance[code] * (1.0 + uniform(noise_lo, noise_span, noise_u[i, g]))
    return out


@njit(cache=True, error_model="numpy")
def area_codes(points, discs):
    """``world.arena.area_at`` for points ``(N, 2)`` (int8 codes)."""
    n = points.shape[0]
    out = np.empty(n, np.int8)
    for i in range(n):
        out[i] = _area_code(points[i, 0], points[i, 1], discs[0], discs[1], discs[2], discs[3], discs[4], discs[5])
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
    n = pose.shape[0]
    n_pairs = pair_i.shape[0]
    near2 = range_m * range_m * (1.0 + 1e-9)  # cheap pre-filter; hypot decides
    keep = np.empty(n_pairs, np.int64)
    dist_of = np.empty(n_pairs)
    count = np.zeros(n + 1, np.int64)  # messages per receiver, then run starts
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
    sender = np.empty(m, np.int64)
    receiver = np.empty(m, np.int64)
    dist = np.empty(m)
    rel_x = np.empty(m)
    rel_y = np.empty(m)
    fill = count[:n].copy()
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
    return sender, receiver, dist, rel_x, rel_y


@njit(cache=True, error_model="numpy")
def rab_select(sender, receiver, dist, rel_x, rel_y, theta, loss_u, near_m, range_m, loss_near, loss_far, cap):
    """The candidates that survive loss (``loss_u >= loss probability``) and the decoding cap
    (per receiver the ``cap`` nearest, ties by sender), in candidate order: ``(sender, receiver,
    dist, rel_x, rel_y, receiver_theta)``, ``theta`` being every robot's heading."""
    m = receiver.shape[0]
    survive = np.empty(m, np.int64)
    k = 0
    span = range_m - near_m
    gain = loss_far - loss_near
    for q in range(m):
        t = _clip((dist[q] - near_m) / span, 0.0, 1.0)
        if loss_u[q] >= loss_near + gain * t:
            survive[k] = q
            k += 1
    keep = np.empty(k, np.int64)
    kept = 0
    lo = 0
    while lo < k:
        hi = lo
        while hi < k and receiver[survive[hi]] == receiver[survive[lo]]:
            hi += 1
        if hi - lo <= cap:
            for q in range(lo, hi):
                keep[kept] = survive[q]
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
                    keep[kept] = survive[q]
                    kept += 1
        lo = hi
    out_s = np.empty(kept, np.int64)
    out_r = np.empty(kept, np.int64)
    out_d = np.empty(kept)
    out_x = np.empty(kept)
    out_y = np.empty(kept)
    out_t = np.empty(kept)
    for q in range(kept):
        c = keep[q]
        out_s[q] = sender[c]
        out_r[q] = receiver[c]
        out_d[q] = dist[c]
        out_x[q] = rel_x[c]
        out_y[q] = rel_y[c]
        out_t[q] = theta[receiver[c]]
    return out_s, out_r, out_d, out_x, out_y, out_t


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
def move_bodies(pose, cmd, alive, vmax, tick_s, metres_per_step, slip_u, slip_lo, slip_span, wheelbase_m):
    """Wheel commands to encoder counts and true poses (``ForagingWorld.step``; seed 000 eq. 3-7).

    The slip factor of each wheel is ``U(-slip, slip)`` from the ``(N, 2)`` uniforms ``slip_u``
    (see :func:`uniform`). Returns ``(pose, encoder)``.
    """
    n = pose.shape[0]
    out = np.empty_like(pose)
    encoder = np.empty((n, 2))
    for i in range(n):
        left = _clip(cmd[i, 0], -vmax, vmax) * tick_s if alive[i] else 0.0
        right = _clip(cmd[i, 1], -vmax, vmax) * tick_s if alive[i] else 0.0
        encoder[i, 0] = left
        encoder[i, 1] = right
        du_left = left * metres_per_step * (1.0 + uniform(slip_lo, slip_span, slip_u[i, 0]))
        du_right = right * metres_per_step * (1.0 + uniform(slip_lo, slip_span, slip_u[i, 1]))
        d_theta = (du_right - du_left) / wheelbase_m
        d_rho = (du_right + du_left) / 2.0
        zeta = pose[i, 2] + d_theta / 2.0
        out[i, 0] = pose[i, 0] + d_rho * math.cos(zeta)
        out[i, 1] = pose[i, 1] + d_rho * math.sin(zeta)
        out[i, 2] = wrap(pose[i, 2] + d_theta)
    return out, encoder


@njit(cache=True, error_model="numpy")
def separate_bodies(pos, radius_m, width_m, height_m, iterations):
    """``world.arena.resolve_collisions`` with every body movable, in place on ``pos`` (N, 2).

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
            moved_m = 0.0
            if pair_cutoff_m > 0.0:
                for i in range(n):
                    moved_m = max(moved_m, math.hypot(pos[i, 0] - ref_pos[i, 0], pos[i, 1] - ref_pos[i, 1]))
            if pair_cutoff_m > 0.0 and min_gap + 2.0 * moved_m + 1e-9 <= pair_cutoff_m:
                for p in range(pair_i.shape[0]):
                    any_pair |= _push_pair(pos, pair_i[p], pair_j[p], min_gap, near2, acc, count)
            else:
                cx, cy, start, items, mask = build_grid(pos[:, 0], pos[:, 1], min_gap, 0.0, 0.0, width_m, height_m)
                for i in range(n):
                    for cell in range(9):  # the 3 x 3 cells around the point
                        gx, gy = cx[i] - 1 + cell % 3, cy[i] - 1 + cell // 3
                        bk = cell_bucket(gx, gy, mask)
                        for q in range(start[bk], start[bk + 1]):
                            j = items[q]
                            if j <= i or cx[j] != gx or cy[j] != gy:
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
    n = pose.shape[0]
    out = np.empty(n, np.int8)
    for i in range(n):
        px = pose[i, 0] + ahead_m * math.cos(pose[i, 2])
        py = pose[i, 1] + ahead_m * math.sin(pose[i, 2])
        out[i] = _area_code(px, py, discs[0], discs[1], discs[2], discs[3], discs[4], discs[5])
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


# ----------------------------------------------------------------------- one world tick, fused


@njit(cache=True, error_model="numpy")
def sense(pose, r_m, ir_range_m, width_m, height_m, cos_a, sin_a, ir_lo, ir_span, offsets, discs, reflectance,
          ground_lo, ground_span, u, pair_cutoff_m):
    """:func:`ir_readings` and :func:`ground_readings` in one call (``ForagingWorld.observe``);
    ``u``: the IR noise uniforms ``(N, S)`` then the ground noise uniforms ``(N, G)``, flat.

    Returns ``(ir, ground, pairs)``: :func:`neighbour_pairs` within ``pair_cutoff_m`` (at least
    the IR reach ``2 r + range``), which the medium reuses at the same poses."""
    n, n_s, n_g = pose.shape[0], cos_a.shape[0], offsets.shape[0]
    ir_u = u[: n * n_s].reshape((n, n_s))
    ground_u = u[n * n_s : n * (n_s + n_g)].reshape((n, n_g))
    cos_h, sin_h = heading_cos_sin(pose)
    pairs = neighbour_pairs(pose[:, 0], pose[:, 1], max(pair_cutoff_m, 2.0 * r_m + ir_range_m), 0.0, 0.0,
                            width_m, height_m)
    ir = _ir_readings(pose, cos_h, sin_h, r_m, ir_range_m, width_m, height_m, cos_a, sin_a, ir_u, ir_lo, ir_span,
                      *pairs)
    ground = _ground_readings(pose, cos_h, sin_h, offsets, discs, reflectance, ground_u, ground_lo, ground_span)
    return ir, ground, pairs


@njit(cache=True, error_model="numpy")
def advance(pose, cmd, alive, vmax, tick_s, metres_per_step, slip_lo, slip_span, wheelbase_m, r_m, width_m,
            height_m, iterations, ahead_m, discs, dist, bearing_atan, receiver_theta, range_lo, range_span,
            bearing_lo, bearing_span, u, pair_i, pair_j, pair_cutoff_m):
    """The rest of ``ForagingWorld.step`` in one call: :func:`rab_measure` of this tick's K
    deliveries, :func:`move_bodies`, :func:`separate_bodies` and :func:`sensor_areas`. ``u``: the
    K range and K bearing noise uniforms, then the ``(N, 2)`` slip uniforms, flat. ``pair_i``,
    ``pair_j``: :func:`neighbour_pairs` of ``pose`` within ``pair_cutoff_m`` (0: none), for the
    collisions (:func:`separate_bodies_near`).

    Returns ``(pose, encoder, area, ok, range_m, bearing_rad)``. If not ``ok`` (see
    :func:`separate_bodies`) ``pose`` is before collisions and ``area`` is not computed.
    """
    k, n = dist.shape[0], pose.shape[0]
    range_m, bearing = rab_measure(dist, u[: 2 * k], range_lo, range_span, bearing_atan, receiver_theta,
                                   bearing_lo, bearing_span)
    slip_u = u[2 * k : 2 * k + 2 * n].reshape((n, 2))
    moved, encoder = move_bodies(pose, cmd, alive, vmax, tick_s, metres_per_step, slip_u, slip_lo, slip_span, wheelbase_m)
    pos = moved[:, :2].copy()
    if not separate_bodies_near(pos, r_m, width_m, height_m, iterations, pose, pair_i, pair_j, pair_cutoff_m):
        return moved, encoder, np.zeros(0, np.int8), False, range_m, bearing
    moved[:, :2] = pos
    return moved, encoder, sensor_areas(moved, ahead_m, discs), True, range_m, bearing
