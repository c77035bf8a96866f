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

:func:`deliver` works on the whole swarm at once: candidate pairs come from a spatial hash grid
in a compiled kernel (``world/epuck/kernels.py``), never from a Python loop over robots. Random draws,
in this fixed order:

1. ``rng.random(M)``: one loss uniform per candidate (sender, receiver) pair, candidates sorted
   by (receiver, sender); a candidate is lost if its uniform is ``< loss_probability``;
2. ``rng.uniform(-range_noise_m, range_noise_m, K)``: range noise of the K kept messages, sorted
   by (receiver, sender);
3. ``rng.uniform(-bearing_noise_rad, bearing_noise_rad, K)``: bearing noise, same order.

Draws 2 and 3 are taken as one ``rng.random(2 K)`` call, which yields the very same numbers
(``uniform(lo, hi)`` is ``lo + (hi - lo) * random()`` in numpy); the world takes them together with
its slip draw (``ForagingWorld.step``), still in this order.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from swarmloc.world.epuck import kernels


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
    survivors = crossing(pose, sending, medium, rng)
    k = survivors.sender.shape[0]
    if k == 0:
        return _empty()  # nothing survived: no noise to draw
    # 2. Range noise, 3. bearing noise, both in (receiver, sender) order: one random(2K) call
    # gives the same numbers as uniform(K) twice (world/epuck/kernels.py: uniform).
    rn, bn = medium.range_noise_m, medium.bearing_noise_rad
    range_m, bearing_rad = kernels.rab_measure(
        survivors.dist_m, rng.random(2 * k), -rn, rn - -rn, survivors.bearing_atan(),
        survivors.receiver_theta, -bn, bn - -bn,
    )
    return Deliveries(sender=survivors.sender, receiver=survivors.receiver, range_m=range_m, bearing_rad=bearing_rad)


@dataclass(frozen=True, eq=False)
class Survivors:
    """Messages that crossed (survived loss and the decoding cap), before the boards measure them:
    true distance, sender minus receiver position, and the receiver's heading; ``(K,)`` each."""

    sender: np.ndarray
    receiver: np.ndarray
    dist_m: np.ndarray
    rel_x_m: np.ndarray
    rel_y_m: np.ndarray
    receiver_theta: np.ndarray

    def bearing_atan(self) -> np.ndarray:
        """World-frame direction of each sender seen from its receiver (numpy's arctan2)."""
        return np.arctan2(self.rel_y_m, self.rel_x_m)


def crossing(
    pose: np.ndarray, sending: np.ndarray, medium: RabMedium, rng: np.random.Generator, pairs=None
) -> Survivors:
    """The first half of :func:`deliver`: candidates, loss (draw 1) and the decoding cap. The
    caller draws the measurement noises next (:func:`deliver`, or ``ForagingWorld.step``, which
    draws them together with the odometry slip). ``pairs``: the ``world.epuck.kernels.neighbour_pairs``
    of these very poses within at least ``medium.range_m``, if the caller has them already."""
    pose = np.asarray(pose, dtype=float)
    if pose.ndim != 2 or pose.shape[1] != 3:
        raise ValueError(f"pose must have shape (N, 3), got {pose.shape}")
    n = pose.shape[0]
    sending = np.asarray(sending, dtype=bool)
    if sending.shape != (n,):
        raise ValueError(f"sending must have shape ({n},), got {sending.shape}")

    # Candidates from a cell grid (world/epuck/kernels.py), already in (receiver, sender) order.
    if n >= 2 and sending.any():
        if pairs is None:
            sender, receiver, dist_m, rel_x, rel_y = kernels.rab_candidates(pose, sending, medium.range_m)
        else:
            sender, receiver, dist_m, rel_x, rel_y = kernels.rab_candidates_from_pairs(
                pose, sending, medium.range_m, *pairs
            )
    else:
        sender = receiver = np.empty(0, np.int64)
        dist_m = rel_x = rel_y = np.empty(0)

    # 1. Loss, one uniform per candidate in (receiver, sender) order; then the decoding cap: a
    # receiver with more survivors than the cap keeps the nearest ones, ties by sender index.
    loss_u = rng.random(sender.shape[0])
    return Survivors(*kernels.rab_select(
        sender, receiver, dist_m, rel_x, rel_y, pose[:, 2], loss_u, medium.near_m, medium.range_m,
        medium.loss_near, medium.loss_far, medium.max_received_per_tick,
    ))
