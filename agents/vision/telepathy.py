"""The vision robots' shared-detections payload (seed 004 §III, "Telepathy").

Each robot publishes, per frame, its detections with the head angle ("the angle of the neck"),
the time and, only with the addition ``shared_odometry``, its odometry pose; every yellow blob's
bearing (``yb``) travels too, so that a teammate knows where a robot was seen even when its blob
was not whole. :func:`encode_share` packs a :class:`SharedFrame` as msgpack,
:func:`decode_share` rejects impossible values with ``ValueError`` naming the field. Used by
:mod:`swarmloc.agents.vision.brain`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import msgpack

from swarmloc.agents.vision.cooperative import Detection, wrap_rad
from swarmloc.agents.vision.detection import COLOUR_CLASSES
from swarmloc.world.vision.camera import CameraParams

#: Version of the shared-detections payload.
SHARE_VERSION = 1
#: Upper bound on one shared-detections payload and on its number of detections.
MAX_SHARE_BYTES = 8 * 1024
MAX_SHARED_DETECTIONS = 64
MAX_ROBOT_ID = 65535
MAX_DISTANCE_M = 100.0
MAX_ODOMETRY_M = 1.0e6
#: Slack on the field-of-view check of a shared bearing (rounding, blob centroid at the edge).
FOV_TOLERANCE_RAD = 0.02
_SHARE_KEYS = ("v", "id", "t", "pan", "odom", "det")


# -- the shared-detections payload (Telepathy) --------------------------------------------------


@dataclass(frozen=True)
class SharedFrame:
    """One robot's frame as shared with its team: time, head pan, odometry, detections."""

    robot_id: int
    time_s: float
    head_pan_rad: float
    odometry_pose: tuple[float, float, float] | None  # None: odometry not shared (the paper)
    detections: tuple[Detection, ...]
    #: Body bearings of every yellow blob the sender saw, whole or not (optional on the wire).
    yellow_bearings: tuple[float, ...] = ()


def encode_share(frame: SharedFrame) -> bytes:
    """The msgpack payload of ``frame`` (a map ``v, id, t, pan, odom, det``; each detection is
    ``[colour, bearing_rad, size_px, distance_m]``)."""
    payload = msgpack.packb(
        {
            "v": SHARE_VERSION,
            "id": int(frame.robot_id),
            "t": float(frame.time_s),
            "pan": float(frame.head_pan_rad),
            "odom": (
                None if frame.odometry_pose is None else [float(v) for v in frame.odometry_pose]
            ),
            "det": [
                [d.colour, float(d.bearing_rad), float(d.size_px), float(d.distance_m)]
                for d in frame.detections[:MAX_SHARED_DETECTIONS]
            ],
            "yb": [float(b) for b in frame.yellow_bearings[:MAX_SHARED_DETECTIONS]],
        },
        use_bin_type=True,
    )
    if len(payload) > MAX_SHARE_BYTES:  # pragma: no cover - 64 detections fit easily
        raise ValueError(f"payload: {len(payload)} bytes exceeds {MAX_SHARE_BYTES}")
    return payload


def _number(
    name: str, value, lo: float | None = None, hi: float | None = None, positive: bool = False
) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float)):
        raise ValueError(f"{name}: expected a number, got {type(value).__name__}")  # noqa: TRY004
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name}: must be finite, got {number!r}")
    if positive and number <= 0.0:
        raise ValueError(f"{name}: must be > 0, got {number!r}")
    if lo is not None and number < lo:
        raise ValueError(f"{name}: must be >= {lo}, got {number!r}")
    if hi is not None and number > hi:
        raise ValueError(f"{name}: must be <= {hi}, got {number!r}")
    return number


def decode_share(
    payload,
    camera: CameraParams,
    sender_id: int | None = None,
    now_s: float | None = None,
    max_clock_skew_s: float = 0.05,
) -> SharedFrame:
    """Decode and validate a teammate's payload; ``ValueError`` naming the field if it is bad.

    ``sender_id``: who the transport says sent it (the payload must claim the same id);
    ``now_s``: the receiver's time (a frame more than ``max_clock_skew_s`` later is refused).
    """
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise ValueError(f"payload: expected bytes, got {type(payload).__name__}")  # noqa: TRY004
    size = payload.nbytes if isinstance(payload, memoryview) else len(payload)
    if size > MAX_SHARE_BYTES:
        raise ValueError(f"payload: {size} bytes exceeds the limit of {MAX_SHARE_BYTES} bytes")
    try:
        wire = msgpack.unpackb(
            payload,
            raw=False,
            use_list=True,
            strict_map_key=True,
            max_str_len=MAX_SHARE_BYTES,
            max_bin_len=0,
            max_ext_len=0,
            max_array_len=MAX_SHARED_DETECTIONS + 8,
            max_map_len=16,
        )
    except Exception as error:  # noqa: BLE001 -- msgpack raises many types, all mean "invalid"
        raise ValueError(f"payload: not msgpack ({type(error).__name__})") from None
    if not isinstance(wire, dict):
        raise ValueError(f"payload: expected a msgpack map, got {type(wire).__name__}")  # noqa: TRY004
    for key in _SHARE_KEYS:
        if key not in wire:
            raise ValueError(f"{key}: missing field")
    extra = sorted(str(k) for k in wire if k not in (*_SHARE_KEYS, "yb"))
    if extra:
        raise ValueError(f"{extra[0]}: unknown field")
    if wire["v"] != SHARE_VERSION or isinstance(wire["v"], bool):
        raise ValueError(f"v: version {wire['v']!r}, expected {SHARE_VERSION}")
    robot_id = wire["id"]
    if (
        isinstance(robot_id, bool)
        or not isinstance(robot_id, int)
        or not 0 <= robot_id <= MAX_ROBOT_ID
    ):
        raise ValueError(f"id: expected a robot id in 0..{MAX_ROBOT_ID}, got {robot_id!r}")
    if sender_id is not None and robot_id != sender_id:
        raise ValueError(f"id: payload from robot {sender_id} claims to be robot {robot_id}")
    time_s = _number("t", wire["t"], lo=0.0)
    if now_s is not None and time_s > now_s + max_clock_skew_s:
        raise ValueError(f"t: {time_s:.3f} s is in the future (receiver's time {now_s:.3f} s)")
    pan = _number(
        "pan", wire["pan"], lo=-camera.pan_limit_rad - 1e-9, hi=camera.pan_limit_rad + 1e-9
    )
    odom = wire["odom"]
    if odom is None:  # the sender does not share its odometry (seed 004 shares none)
        odometry = None
    else:
        if not isinstance(odom, list) or len(odom) != 3:
            raise ValueError("odom: expected [x_m, y_m, heading_rad] or nil")
        odometry = (
            _number("odom[0]", odom[0], -MAX_ODOMETRY_M, MAX_ODOMETRY_M),
            _number("odom[1]", odom[1], -MAX_ODOMETRY_M, MAX_ODOMETRY_M),
            _number("odom[2]", odom[2], -math.pi, math.pi),
        )
    det = wire["det"]
    if not isinstance(det, list):
        raise ValueError(f"det: expected a list, got {type(det).__name__}")  # noqa: TRY004
    if len(det) > MAX_SHARED_DETECTIONS:
        raise ValueError(f"det: {len(det)} detections, at most {MAX_SHARED_DETECTIONS}")
    half_fov = camera.half_fov_rad + FOV_TOLERANCE_RAD
    max_size_px = float(max(camera.width_px, camera.height_px))
    detections = []
    for i, item in enumerate(det):
        where = f"det[{i}]"
        if not isinstance(item, list) or len(item) != 4:
            raise ValueError(f"{where}: expected [colour, bearing_rad, size_px, distance_m]")
        colour, bearing, size_px, distance = item
        if colour not in COLOUR_CLASSES:
            raise ValueError(f"{where}.colour: unknown colour {colour!r}")
        bearing = _number(f"{where}.bearing_rad", bearing, -math.pi, math.pi)
        if abs(float(wrap_rad(bearing - pan))) > half_fov:
            raise ValueError(
                f"{where}.bearing_rad: {bearing:.3f} rad is outside the camera's field of view "
                f"(head pan {pan:.3f} rad, half field of view {camera.half_fov_rad:.3f} rad)"
            )
        size_px = _number(f"{where}.size_px", size_px, positive=True, hi=max_size_px)
        distance = _number(f"{where}.distance_m", distance, positive=True, hi=MAX_DISTANCE_M)
        detections.append(Detection(robot_id, time_s, colour, bearing, pan, size_px, distance))
    yb = wire.get("yb", [])
    if not isinstance(yb, list) or len(yb) > MAX_SHARED_DETECTIONS:
        raise ValueError(f"yb: expected a list of at most {MAX_SHARED_DETECTIONS} bearings")
    yellow = []
    for i, b in enumerate(yb):
        b = _number(f"yb[{i}]", b, -math.pi, math.pi)
        if abs(float(wrap_rad(b - pan))) > half_fov:
            raise ValueError(f"yb[{i}]: {b:.3f} rad is outside the camera's field of view")
        yellow.append(b)
    return SharedFrame(robot_id, time_s, pan, odometry, tuple(detections), tuple(yellow))
