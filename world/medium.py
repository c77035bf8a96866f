"""The e-puck infrared range-and-bearing (RAB) communication medium.

Implements the simulated range-and-bearing board of seed 000 §6.1 (also seed 001 §4.1, which uses
a 25 cm range; pass ``RabMedium(range_m=0.25)`` for that setup):

- a message reaches only robots whose centre is within ``range_m`` (15 cm) of the sender's;
- it is lost with a probability that rises linearly from 1 % at 1 cm (and below) to 50 % at
  ``range_m``: :func:`loss_probability`;
- the receiver's board tags it with the measured range (true distance + U(±2.5 cm), clipped at 0)
  and the bearing of the sender in the receiver's own frame (+ U(±20°), wrapped to [-pi, pi)).

Two limits of the real board are modelled: a payload cap (``max_payload_bytes``: the board
carries about 5 kbit/s, ~62 bytes per 100 ms tick; enforcing it on payloads is the caller's job)
and a decoding cap (``max_received_per_tick``): a receiver keeps only the nearest few messages.

:func:`deliver` works on the whole swarm at once: candidate pairs come from a KD-tree, never from
a loop over robots. Random draws, in this fixed order:

1. ``rng.random(M)``: one loss uniform per candidate (sender, receiver) pair, candidates sorted
   by (receiver, sender); a candidate is lost if its uniform is ``< loss_probability``;
2. ``rng.uniform(-range_noise_m, range_noise_m, K)``: range noise of the K kept messages, sorted
   by (receiver, sender);
3. ``rng.uniform(-bearing_noise_rad, bearing_noise_rad, K)``: bearing noise, same order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from swarmloc.protocol.epuck import wrap_angle


def _is_number(value) -> bool:
    return (
        isinstance(value, (int, float, np.integer, np.floating))
        and not isinstance(value, bool)
        and math.isfinite(value)
    )


def _is_int(value) -> bool:
    return isinstance(value, (int, np.integer)) and not isinstance(value, bool)


@dataclass(frozen=True)
class RabMedium:
    """Parameters of the range-and-bearing medium (seed 000 §6.1).

    Validation (``ValueError`` naming the field): ``range_m > near_m > 0``; noises finite and
    ``>= 0`` (bearing noise at most pi); loss probabilities in [0, 1]; payload and decoding caps
    integers ``>= 1``.
    """

    range_m: float = 0.15
    range_noise_m: float = 0.025
    bearing_noise_rad: float = math.radians(20)
    loss_near: float = 0.01
    near_m: float = 0.01
    loss_far: float = 0.50
    max_payload_bytes: int = 64
    max_received_per_tick: int = 4

    def __post_init__(self) -> None:
        for name in (
            "range_m",
            "range_noise_m",
            "bearing_noise_rad",
            "loss_near",
            "near_m",
            "loss_far",
        ):
            if not _is_number(getattr(self, name)):
                raise ValueError(f"{name} must be a finite number, got {getattr(self, name)!r}")
        if not self.near_m > 0.0:
            raise ValueError(f"near_m must be > 0, got {self.near_m!r}")
        if not self.range_m > self.near_m:
            raise ValueError(f"range_m must be > near_m ({self.near_m}), got {self.range_m!r}")
        if self.range_noise_m < 0.0:
            raise ValueError(f"range_noise_m must be >= 0, got {self.range_noise_m!r}")
        if not 0.0 <= self.bearing_noise_rad <= math.pi:
            raise ValueError(
                f"bearing_noise_rad must be in [0, pi], got {self.bearing_noise_rad!r}"
            )
        for name in ("loss_near", "loss_far"):
            if not 0.0 <= getattr(self, name) <= 1.0:
                raise ValueError(f"{name} must be in [0, 1], got {getattr(self, name)!r}")
        for name in ("max_payload_bytes", "max_received_per_tick"):
            value = getattr(self, name)
            if not _is_int(value) or value < 1:
                raise ValueError(f"{name} must be an integer >= 1, got {value!r}")


def loss_probability(distance_m: np.ndarray, medium: RabMedium) -> np.ndarray:
    """Probability that a message is lost over ``distance_m`` (seed 000 §6.1).

    ``loss_near`` at and below ``near_m``, rising linearly to ``loss_far`` at ``range_m``, and
    ``loss_far`` beyond (where nothing is delivered anyway).
    """
    distance_m = np.asarray(distance_m, dtype=float)
    t = np.clip((distance_m - medium.near_m) / (medium.range_m - medium.near_m), 0.0, 1.0)
    return medium.loss_near + (medium.loss_far - medium.loss_near) * t


@dataclass(frozen=True, eq=False)
class Deliveries:
    """Messages delivered in one tick, sorted by (receiver, sender); all arrays ``(M,)``.

    ``sender`` and ``receiver`` are robot indices (int64); ``range_m`` and ``bearing_rad`` are
    what the receiver's board measures (bearing in the receiver's frame, in [-pi, pi)).
    """

    sender: np.ndarray
    receiver: np.ndarray
    range_m: np.ndarray
    bearing_rad: np.ndarray

    def __len__(self) -> int:
        return int(self.sender.shape[0])


def _empty() -> Deliveries:
    return Deliveries(
        sender=np.empty(0, dtype=np.int64),
        receiver=np.empty(0, dtype=np.int64),
        range_m=np.empty(0),
        bearing_rad=np.empty(0),
    )


def deliver(
    pose: np.ndarray, sending: np.ndarray, medium: RabMedium, rng: np.random.Generator
) -> Deliveries:
    """Who hears whom this tick, and the range and bearing each receiver measures.

    Candidates: every ordered pair (sender ``i`` with ``sending[i]``, receiver ``j != i``) whose
    centres are at most ``medium.range_m`` apart. Each is lost with
    ``loss_probability(true distance)``; then each receiver keeps at most
    ``max_received_per_tick`` survivors, the nearest (ties by sender index). All robots are
    receivers: the caller passes ``sending=False`` for dead robots and drops dead receivers.
    See the module docstring for the fixed order of random draws.
    """
    pose = np.asarray(pose, dtype=float)
    if pose.ndim != 2 or pose.shape[1] != 3:
        raise ValueError(f"pose must have shape (N, 3), got {pose.shape}")
    n = pose.shape[0]
    sending = np.asarray(sending, dtype=bool)
    if sending.shape != (n,):
        raise ValueError(f"sending must have shape ({n},), got {sending.shape}")
    xy = pose[:, :2]

    if n >= 2 and sending.any():
        tree = cKDTree(xy, balanced_tree=False, compact_nodes=False)
        pairs = tree.query_pairs(medium.range_m, output_type="ndarray")
    else:
        pairs = np.empty((0, 2), dtype=np.int64)
    a = pairs[:, 0].astype(np.int64)
    b = pairs[:, 1].astype(np.int64)
    a_sends, b_sends = sending[a], sending[b]
    sender = np.concatenate([a[a_sends], b[b_sends]])
    receiver = np.concatenate([b[a_sends], a[b_sends]])
    order = np.argsort(receiver * n + sender)  # (receiver, sender) order; keys are unique
    sender, receiver = sender[order], receiver[order]
    x_m, y_m = pose[:, 0], pose[:, 1]
    rel = np.column_stack([x_m[sender] - x_m[receiver], y_m[sender] - y_m[receiver]])
    dist_m = np.hypot(rel[:, 0], rel[:, 1])
    inside = dist_m <= medium.range_m  # guard against KD-tree rounding at the boundary
    if not inside.all():
        sender, receiver, rel, dist_m = (
            sender[inside],
            receiver[inside],
            rel[inside],
            dist_m[inside],
        )

    # 1. Loss, one uniform per candidate in (receiver, sender) order.
    survive = rng.random(sender.shape[0]) >= loss_probability(dist_m, medium)
    sender, receiver, rel, dist_m = (
        sender[survive],
        receiver[survive],
        rel[survive],
        dist_m[survive],
    )
    if sender.shape[0] == 0:
        return _empty()  # nothing survived: no noise to draw

    # Decoding cap: a receiver with more survivors than the cap keeps the nearest ones, ties by
    # sender index. Only the (usually few) over-full receivers are ranked.
    cap = medium.max_received_per_tick
    full = np.bincount(receiver, minlength=n) > cap
    crowded = full[receiver]
    if crowded.any():
        rows = np.flatnonzero(crowded)  # still in (receiver, sender) order
        # Stable sort by distance, then stable by receiver: order (receiver, distance, sender).
        by_dist = rows[np.argsort(dist_m[rows], kind="stable")]
        by_near = by_dist[np.argsort(receiver[by_dist], kind="stable")]
        recv_sorted = receiver[by_near]
        starts = np.flatnonzero(np.r_[True, recv_sorted[1:] != recv_sorted[:-1]])
        group_start = np.repeat(starts, np.diff(np.r_[starts, recv_sorted.shape[0]]))
        rank = np.arange(recv_sorted.shape[0]) - group_start
        keep = ~crowded
        keep[by_near[rank < cap]] = True
        sender, receiver, rel, dist_m = sender[keep], receiver[keep], rel[keep], dist_m[keep]

    k = sender.shape[0]
    # 2. Range noise, 3. bearing noise, both in (receiver, sender) order.
    range_noise = rng.uniform(-medium.range_noise_m, medium.range_noise_m, size=k)
    bearing_noise = rng.uniform(-medium.bearing_noise_rad, medium.bearing_noise_rad, size=k)
    range_m = np.maximum(dist_m + range_noise, 0.0)
    bearing_rad = wrap_angle(np.arctan2(rel[:, 1], rel[:, 0]) - pose[receiver, 2] + bearing_noise)
    return Deliveries(
        sender=sender, receiver=receiver, range_m=range_m, bearing_rad=np.asarray(bearing_rad)
    )
