"""The particle-set arithmetic of the AMCL-style filter (:mod:`swarmloc.agents.laser.amcl`).

- :func:`kld_sample_count`, :func:`kld_sample_size`: how many particles KLD-sampling (Fox 2003)
  draws for the number of histogram bins they occupy, clamped to the filter's bounds;
- :func:`low_variance_resample`: low-variance (systematic) resampling of a weighted set;
- :func:`histogram_bin_keys`, :func:`cluster_labels`, :func:`best_cluster_estimate`: the
  ``bin_size_m`` x ``bin_size_m`` x ``bin_size_rad`` histogram (the heading axis wraps around),
  clusters of adjacent occupied bins as ``amcl`` clusters, and the weighted mean of the heaviest;
- :func:`recovery_probability`: Augmented_MCL's injection probability ``max(0, 1 - w_fast /
  w_slow)`` (Probabilistic Robotics, ch. 8), from the logs of the two averages.

Seeds 002 and 003 compare their GAs with this filter; neither describes it further.
"""


from __future__ import annotations

import itertools
import math
from typing import TYPE_CHECKING

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

from swarmloc.world.laser.laser import wrap_angle

if TYPE_CHECKING:
    from swarmloc.agents.laser.amcl import AMCLParams


TWO_PI = 2.0 * math.pi


def _integer(value, name: str) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
        raise TypeError(f"{name} must be an integer, got {value!r}")
    return int(value)


# --------------------------------------------------------------------------------------------
# Resampling: KLD sample size and low-variance resampling
# --------------------------------------------------------------------------------------------


def kld_sample_count(k_bins, epsilon: float, z: float) -> np.ndarray:
    """Fox 2003 (KLD-sampling): particles needed when ``k_bins`` histogram bins are
    occupied, ``ceil((k-1)/(2 eps) * (1 - 2/(9(k-1)) + sqrt(2/(9(k-1))) z)^3)``, the Wilson-Hilferty
    approximation of ``chi2_{k-1, 1-delta} / (2 eps)``; 0 for ``k <= 1``. ``z`` is the upper
    ``1 - delta`` quantile of the standard normal. Not clamped (see :func:`kld_sample_size`)."""
    k = np.asarray(k_bins, dtype=np.float64)
    dof = np.maximum(k - 1.0, 1.0)
    a = 2.0 / (9.0 * dof)
    cube = (1.0 - a + np.sqrt(a) * z) ** 3
    count = np.ceil(dof / (2.0 * epsilon) * cube)
    return np.where(k > 1.0, count, 0.0).astype(np.int64)


def kld_sample_size(k_bins, params: AMCLParams) -> np.ndarray:
    """:func:`kld_sample_count` clamped to ``[min_particles, max_particles]``."""
    count = kld_sample_count(k_bins, params.kld_epsilon, params.kld_z)
    return np.clip(count, params.min_particles, params.max_particles)


def low_variance_resample(weights: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """Low-variance (systematic) resampling, Probabilistic Robotics table 4.4: ``n`` indices
    into ``weights`` drawn with one random offset ``r ~ U[0, 1/n)`` and pointers ``r + m/n``.
    Index ``i`` is drawn ``floor(n w_i)`` or ``ceil(n w_i)`` times (``w`` normalised)."""
    w = np.asarray(weights, dtype=np.float64)
    if w.ndim != 1 or w.size == 0:
        raise ValueError(f"weights must be a non-empty 1-D array, got shape {w.shape}")
    if not np.all(np.isfinite(w)) or np.any(w < 0.0) or not w.sum() > 0.0:
        raise ValueError("weights must be finite, >= 0, with a positive sum")
    n = _integer(n, "n")
    if n < 0:
        raise ValueError(f"n must be >= 0, got {n}")
    cumulative = np.cumsum(w)
    cumulative /= cumulative[-1]
    pointers = (rng.random() + np.arange(n)) / n
    index = np.searchsorted(cumulative, pointers, side="right")
    return np.minimum(index, w.size - 1)


# --------------------------------------------------------------------------------------------
# Histogram bins and clusters
# --------------------------------------------------------------------------------------------

_BIN_BITS = 20
_BIN_OFFSET = 1 << (_BIN_BITS - 1)
_BIN_MASK = (1 << _BIN_BITS) - 1


#: Half of the 26 neighbour offsets of a bin (those lexicographically after (0, 0, 0)): enough,
#: since adjacency is symmetric.
_HALF_NEIGHBOURS = tuple(o for o in itertools.product((-1, 0, 1), repeat=3) if o > (0, 0, 0))


def _n_theta_bins(bin_size_rad: float) -> int:
    return max(1, math.ceil(TWO_PI / bin_size_rad - 1e-9))


def _bin_indices(particles: np.ndarray, bin_size_m: float, bin_size_rad: float):
    n_theta = _n_theta_bins(bin_size_rad)
    ix = np.floor(particles[:, 0] / bin_size_m)
    iy = np.floor(particles[:, 1] / bin_size_m)
    ix = np.clip(ix, -_BIN_OFFSET, _BIN_OFFSET - 2).astype(np.int64) + _BIN_OFFSET
    iy = np.clip(iy, -_BIN_OFFSET, _BIN_OFFSET - 2).astype(np.int64) + _BIN_OFFSET
    it = np.floor((wrap_angle(particles[:, 2]) + math.pi) / bin_size_rad).astype(np.int64)
    it = np.clip(it, 0, n_theta - 1)
    return ix, iy, it, n_theta


def _bin_key(ix, iy, it):
    return (ix << (2 * _BIN_BITS)) | (iy << _BIN_BITS) | it


def histogram_bin_keys(particles: np.ndarray, bin_size_m: float, bin_size_rad: float) -> np.ndarray:
    """One int64 key per particle naming its ``bin_size_m`` x ``bin_size_m`` x ``bin_size_rad``
    histogram bin (equal keys: same bin)."""
    ix, iy, it, _ = _bin_indices(particles, bin_size_m, bin_size_rad)
    return _bin_key(ix, iy, it)


def cluster_labels(particles: np.ndarray, bin_size_m: float, bin_size_rad: float) -> np.ndarray:
    """Cluster label per particle ``(P,)``: connected components of the occupied histogram bins,
    bins being adjacent when they differ by at most one in each of x, y and heading (heading
    wraps around). Labels are ``0 .. n_clusters - 1``."""
    ix, iy, it, n_theta = _bin_indices(particles, bin_size_m, bin_size_rad)
    keys = _bin_key(ix, iy, it)
    unique_keys, inverse = np.unique(keys, return_inverse=True)
    n_bins = unique_keys.size
    if n_bins == 0:
        return np.zeros(0, dtype=np.int64)
    ux = (unique_keys >> (2 * _BIN_BITS)) & _BIN_MASK
    uy = (unique_keys >> _BIN_BITS) & _BIN_MASK
    ut = unique_keys & _BIN_MASK
    rows, cols = [], []
    for dx, dy, dt in _HALF_NEIGHBOURS:
        neighbour = _bin_key(ux + dx, uy + dy, (ut + dt) % n_theta)
        pos = np.minimum(np.searchsorted(unique_keys, neighbour), n_bins - 1)
        hit = unique_keys[pos] == neighbour
        rows.append(np.flatnonzero(hit))
        cols.append(pos[hit])
    rows_all, cols_all = np.concatenate(rows), np.concatenate(cols)
    graph = coo_matrix((np.ones(rows_all.size), (rows_all, cols_all)), shape=(n_bins, n_bins))
    _, bin_label = connected_components(graph, directed=False)
    return bin_label[inverse].astype(np.int64)


def best_cluster_estimate(
    particles: np.ndarray, weights: np.ndarray, labels: np.ndarray
) -> tuple[np.ndarray, float]:
    """Weighted mean pose of the heaviest cluster (circular mean of the headings) and that
    cluster's share of the total weight."""
    w = np.asarray(weights, dtype=np.float64)
    cluster_weight = np.bincount(labels, weights=w)
    best = int(np.argmax(cluster_weight))
    member = labels == best
    wm, pm = w[member], particles[member]
    total = wm.sum()
    if not total > 0.0:  # a cluster of zero weight: plain mean
        wm, total = np.ones(pm.shape[0]), float(pm.shape[0])
    mean = np.empty(3)
    mean[0] = np.dot(wm, pm[:, 0]) / total
    mean[1] = np.dot(wm, pm[:, 1]) / total
    mean[2] = math.atan2(np.dot(wm, np.sin(pm[:, 2])), np.dot(wm, np.cos(pm[:, 2])))
    share = float(cluster_weight[best] / cluster_weight.sum()) if cluster_weight.sum() > 0 else 1.0
    return mean, share


# --------------------------------------------------------------------------------------------
# Recovery: the injection probability of Augmented_MCL
# --------------------------------------------------------------------------------------------


def recovery_probability(log_w_slow: float | None, log_w_fast: float | None) -> float:
    """Augmented_MCL's injection probability ``max(0, 1 - w_fast / w_slow)`` from the logs of the
    two averages (0 before the first measurement)."""
    if log_w_slow is None or log_w_fast is None or log_w_slow == -math.inf:
        return 0.0
    return max(0.0, 1.0 - math.exp(min(0.0, log_w_fast - log_w_slow)))
