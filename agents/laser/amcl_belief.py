"""The AMCL-style filter's cooperation: belief summaries on the radio and the teammate factor.

The collaborative variant of :mod:`swarmloc.agents.laser.amcl` (Fox, Burgard, Kruppa, Thrun
2000; ref. [5] of seed 002 and [6] of seed 003): each robot broadcasts a small set of weighted
pose samples with a kernel (:class:`BeliefSummary`, :func:`encode_belief`, :func:`decode_belief`:
the payload format is in :mod:`~swarmloc.agents.laser.amcl`'s docstring), and a robot that sees a
teammate weighs its particles by the density of the teammate's belief at the pose each particle
predicts for it (:func:`teammate_log_density`, :func:`teammate_log_factor`), mixed with a uniform
density (:func:`mix_with_uniform`); :func:`poses_from_teammate` draws poses from a teammate's
belief through the inverse sighting.
"""


from __future__ import annotations

import math
from dataclasses import dataclass

import msgpack
import numpy as np
from scipy.special import i0e

from swarmloc.agents.laser.amcl_sampling import TWO_PI
from swarmloc.agents.laser.localizer import (
    MAX_RADIO_PAYLOAD_BYTES,
    Sighting,
)
from swarmloc.world.laser.laser import unicycle_model, wrap_angle

#: Upper bound on the samples of one shared belief (16 bytes each: 16 KiB, within
#: ``MAX_RADIO_PAYLOAD_BYTES``).
MAX_SHARED_SAMPLES = 1024


# --------------------------------------------------------------------------------------------
# Belief summaries on the radio, and the teammate factor
# --------------------------------------------------------------------------------------------

_PAYLOAD_KIND = "swarmloc.amcl.belief"
_PAYLOAD_VERSION = 1
_PAYLOAD_KEYS = {"kind", "v", "id", "step", "poses", "weights", "kernel", "odom"}


@dataclass(frozen=True, eq=False)
class BeliefSummary:
    """A compact belief a robot broadcasts: ``K`` weighted pose samples ``(K, 3)`` with a kernel
    (isotropic Gaussian of std ``kernel_std_m`` on position, von Mises of ``1 / kappa =
    kernel_std_rad^2`` on heading), i.e. a mixture density; and the odometry of the step it was
    taken after, so that a receiver one step later can move the samples forward (the radio
    delivers at the next step)."""

    robot_id: int
    step: int
    poses_m: np.ndarray
    weights: np.ndarray
    kernel_std_m: float
    kernel_std_rad: float
    odometry_delta_s_m: float = 0.0
    odometry_delta_phi_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("robot_id", "step"):
            if isinstance(getattr(self, name), bool) or not isinstance(
                getattr(self, name), (int, np.integer)
            ):
                raise ValueError(  # noqa: TRY004 -- a payload field: decoding fails with ValueError
                    f"{name} must be an integer, got {getattr(self, name)!r}"
                )
        if not -(2**63) <= self.robot_id < 2**63 or not -(2**63) <= self.step < 2**63:
            raise ValueError("robot_id and step must fit in 64 bits")
        poses = np.array(self.poses_m, dtype=np.float64)
        weights = np.array(self.weights, dtype=np.float64)
        if poses.ndim != 2 or poses.shape[1] != 3 or not 1 <= poses.shape[0] <= MAX_SHARED_SAMPLES:
            raise ValueError(
                f"poses must have shape (K, 3) with 1 <= K <= {MAX_SHARED_SAMPLES}, got {poses.shape}"
            )
        if weights.shape != (poses.shape[0],):
            raise ValueError(f"weights must have shape ({poses.shape[0]},), got {weights.shape}")
        if not np.all(np.isfinite(poses)):
            raise ValueError("poses must be finite")
        if not np.all(np.isfinite(weights)) or np.any(weights < 0.0) or not weights.sum() > 0.0:
            raise ValueError("weights must be finite, >= 0, with a positive sum")
        for name in ("kernel_std_m", "kernel_std_rad"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
                raise ValueError(f"{name} must be a number, got {value!r}")  # noqa: TRY004
            if not math.isfinite(value) or value <= 0.0:
                raise ValueError(f"{name} must be finite and > 0, got {value!r}")
        for name in ("odometry_delta_s_m", "odometry_delta_phi_rad"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float, np.floating)):
                raise ValueError(f"{name} must be a number, got {value!r}")  # noqa: TRY004
            if not math.isfinite(value):
                raise ValueError(f"{name} must be finite, got {value!r}")
        poses.flags.writeable = False
        weights.flags.writeable = False
        object.__setattr__(self, "poses_m", poses)
        object.__setattr__(self, "weights", weights)


def encode_belief(summary: BeliefSummary) -> bytes:
    """The msgpack payload of a :class:`BeliefSummary` (samples as little-endian float32)."""
    if not isinstance(summary, BeliefSummary):
        raise TypeError(f"expected a BeliefSummary, got {type(summary).__name__}")
    wire = {
        "kind": _PAYLOAD_KIND,
        "v": _PAYLOAD_VERSION,
        "id": int(summary.robot_id),
        "step": int(summary.step),
        "poses": summary.poses_m.astype("<f4").tobytes(),
        "weights": summary.weights.astype("<f4").tobytes(),
        "kernel": [float(summary.kernel_std_m), float(summary.kernel_std_rad)],
        "odom": [float(summary.odometry_delta_s_m), float(summary.odometry_delta_phi_rad)],
    }
    data = msgpack.packb(wire, use_bin_type=True)
    if len(data) > MAX_RADIO_PAYLOAD_BYTES:
        raise ValueError(f"belief payload of {len(data)} bytes exceeds {MAX_RADIO_PAYLOAD_BYTES}")
    return data


def decode_belief(payload: bytes | bytearray | memoryview) -> BeliefSummary:
    """Decode and validate a belief payload; ``ValueError`` naming the field if it is invalid."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise TypeError(f"payload must be bytes, got {type(payload).__name__}")
    size = payload.nbytes if isinstance(payload, memoryview) else len(payload)
    if size > MAX_RADIO_PAYLOAD_BYTES:
        raise ValueError(f"payload: {size} bytes exceeds {MAX_RADIO_PAYLOAD_BYTES}")
    try:
        wire = msgpack.unpackb(
            payload,
            raw=False,
            use_list=True,
            strict_map_key=True,
            max_str_len=64,
            max_bin_len=MAX_RADIO_PAYLOAD_BYTES,
            max_array_len=8,
            max_map_len=16,
            max_ext_len=0,
        )
    except Exception as error:  # noqa: BLE001 -- msgpack raises many types, all mean "invalid"
        raise ValueError(f"payload: not msgpack ({type(error).__name__})") from None
    if not isinstance(wire, dict):
        raise ValueError(f"payload: expected a msgpack map, got {type(wire).__name__}")  # noqa: TRY004
    missing = _PAYLOAD_KEYS - wire.keys()
    if missing:
        raise ValueError(f"payload: missing field(s) {sorted(missing)}")
    extra = wire.keys() - _PAYLOAD_KEYS
    if extra:
        raise ValueError(f"payload: unknown field(s) {sorted(map(str, extra))}")
    if wire["kind"] != _PAYLOAD_KIND:
        raise ValueError(f"kind: expected {_PAYLOAD_KIND!r}, got {wire['kind']!r}")
    if type(wire["v"]) is not int or wire["v"] != _PAYLOAD_VERSION:
        raise ValueError(f"v: expected version {_PAYLOAD_VERSION}, got {wire['v']!r}")
    for name in ("id", "step"):
        if type(wire[name]) is not int:
            raise ValueError(f"{name}: expected an integer, got {type(wire[name]).__name__}")
    for name in ("poses", "weights"):
        if not isinstance(wire[name], bytes):
            raise ValueError(f"{name}: expected bytes, got {type(wire[name]).__name__}")  # noqa: TRY004
    if len(wire["poses"]) % 12 != 0:
        raise ValueError(f"poses: {len(wire['poses'])} bytes is not a whole number of samples")
    if len(wire["weights"]) % 4 != 0:
        raise ValueError(f"weights: {len(wire['weights'])} bytes is not a whole number of floats")
    for name in ("kernel", "odom"):
        value = wire[name]
        if (
            not isinstance(value, list)
            or len(value) != 2
            or not all(type(v) in (int, float) for v in value)
        ):
            raise ValueError(f"{name}: expected two numbers, got {value!r}")
    poses = np.frombuffer(wire["poses"], dtype="<f4").reshape(-1, 3)
    weights = np.frombuffer(wire["weights"], dtype="<f4")
    try:
        return BeliefSummary(
            robot_id=wire["id"],
            step=wire["step"],
            poses_m=poses,
            weights=weights,
            kernel_std_m=float(wire["kernel"][0]),
            kernel_std_rad=float(wire["kernel"][1]),
            odometry_delta_s_m=float(wire["odom"][0]),
            odometry_delta_phi_rad=float(wire["odom"][1]),
        )
    except ValueError as error:
        raise ValueError(f"payload: {error}") from None


def teammate_log_density(
    particles: np.ndarray,
    sighting: Sighting,
    summary: BeliefSummary,
    distance_std_m: float,
    orientation_std_rad: float,
) -> np.ndarray:
    """Log density of a seen teammate's belief at the pose each particle predicts for it ``(P,)``.

    Particle ``(x, y, theta)`` and the sighting ``(d, b, h)`` predict the teammate at
    ``(x + d cos(theta + b), y + d sin(theta + b), theta + h)``. The density is the mixture of the
    summary's samples (moved forward by the summary's odometry), each a Gaussian in position whose
    variance is the kernel's plus the sighting's noise (along the line of sight
    ``distance_std^2``, across it ``(d orientation_std)^2``) times a von Mises density in heading
    with ``1 / kappa = kernel_std_rad^2 + orientation_std^2`` (the wrapped Gaussian's usual
    stand-in, and its cosine splits into outer products: no trigonometry over particle x sample
    pairs). Fox et al. 2000 §3, the detection model: robot ``j``'s belief propagated through the
    measured relative pose. ``-inf`` where the density underflows (far from every sample).
    """
    samples = unicycle_model(
        summary.poses_m, summary.odometry_delta_s_m, summary.odometry_delta_phi_rad
    )
    weights = summary.weights / summary.weights.sum()
    d = float(sighting.distance_m)
    line = particles[:, 2] + float(sighting.bearing_rad)
    ux, uy = np.cos(line)[:, None], np.sin(line)[:, None]
    pred_x = particles[:, 0:1] + d * ux
    pred_y = particles[:, 1:2] + d * uy
    pred_heading = particles[:, 2:3] + float(sighting.relative_heading_rad)
    var_along = summary.kernel_std_m**2 + distance_std_m**2
    var_across = summary.kernel_std_m**2 + (d * orientation_std_rad) ** 2
    kappa = 1.0 / (summary.kernel_std_rad**2 + orientation_std_rad**2)
    sx, sy = samples[None, :, 0], samples[None, :, 1]  # (1, K)
    # Offsets of the samples from the prediction, along and across the line of sight: (P, K).
    along = sx * ux + sy * uy - (pred_x * ux + pred_y * uy)
    across = sy * ux - sx * uy - (pred_y * ux - pred_x * uy)
    # cos(theta_s - theta_pred) by the difference formula.
    cos_dh = np.cos(samples[None, :, 2]) * np.cos(pred_heading)
    cos_dh += np.sin(samples[None, :, 2]) * np.sin(pred_heading)
    exponent = along * along
    exponent *= -0.5 / var_along
    across *= across
    across *= -0.5 / var_across
    exponent += across
    cos_dh -= 1.0
    cos_dh *= kappa
    exponent += cos_dh  # <= 0 everywhere: exp cannot overflow
    density = np.exp(exponent, out=exponent) @ weights
    log_norm = (
        -math.log(TWO_PI)
        - 0.5 * math.log(var_along * var_across)
        - math.log(TWO_PI * float(i0e(kappa)))
    )
    with np.errstate(divide="ignore"):
        return np.log(density) + log_norm


def teammate_log_factor(
    particles: np.ndarray,
    sighting: Sighting,
    summary: BeliefSummary,
    distance_std_m: float,
    orientation_std_rad: float,
    outlier_probability: float,
    log_uniform_density: float,
) -> np.ndarray:
    """Log of the evidence a seen teammate's belief gives each particle ``(P,)``: the
    :func:`teammate_log_density` mixed with a uniform density ``exp(log_uniform_density)`` with
    weight ``outlier_probability``, so that a wrong teammate cannot erase the true hypothesis."""
    log_density = teammate_log_density(
        particles, sighting, summary, distance_std_m, orientation_std_rad
    )
    return mix_with_uniform(log_density, outlier_probability, log_uniform_density)


def mix_with_uniform(
    log_density: np.ndarray, outlier_probability: float, log_uniform_density: float
) -> np.ndarray:
    """``log((1 - eps) exp(log_density) + eps exp(log_uniform_density))``, ``eps`` the
    outlier probability (``eps = 1``: the uniform density alone)."""
    if outlier_probability >= 1.0:
        return np.full(np.shape(log_density), float(log_uniform_density))
    return np.logaddexp(
        math.log1p(-outlier_probability) + log_density,
        math.log(outlier_probability) + log_uniform_density,
    )


def poses_from_teammate(
    summary: BeliefSummary,
    sighting: Sighting,
    n: int,
    rng: np.random.Generator,
    distance_std_m: float,
    orientation_std_rad: float,
) -> np.ndarray:
    """``n`` poses ``(n, 3)`` of the *observing* robot drawn from a seen teammate's belief through
    the inverse of the sighting: teammate pose ``s`` (a summary sample moved by its odometry, plus
    kernel noise) and a noisy sighting ``(d, b, h)`` put the observer at heading
    ``theta = theta_s - h`` and position ``s_xy - d (cos(theta + b), sin(theta + b))``.
    Draws: one ``rng.choice`` of sample indices, one ``rng.normal`` of shape ``(n, 6)``."""
    samples = unicycle_model(
        summary.poses_m, summary.odometry_delta_s_m, summary.odometry_delta_phi_rad
    )
    weights = summary.weights / summary.weights.sum()
    index = rng.choice(samples.shape[0], size=n, p=weights)
    noise = rng.normal(0.0, 1.0, size=(n, 6))
    teammate = samples[index]
    teammate[:, :2] += noise[:, :2] * summary.kernel_std_m
    teammate[:, 2] += noise[:, 2] * summary.kernel_std_rad
    d = np.abs(float(sighting.distance_m) + noise[:, 3] * distance_std_m)
    b = float(sighting.bearing_rad) + noise[:, 4] * orientation_std_rad
    h = float(sighting.relative_heading_rad) + noise[:, 5] * orientation_std_rad
    heading = wrap_angle(teammate[:, 2] - h)
    return np.column_stack(
        [
            teammate[:, 0] - d * np.cos(heading + b),
            teammate[:, 1] - d * np.sin(heading + b),
            heading,
        ]
    )
