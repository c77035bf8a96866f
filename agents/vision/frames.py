"""From an encoded camera frame to the detections a vision robot uses (seed 004 §III).

:func:`decode_image` decodes a frame (``ValueError`` naming the problem); after
:func:`~swarmloc.agents.vision.detection.detect_blobs`, :func:`detections_from_blobs` keeps the
blobs whose shape is that of a whole object (their size, hence distance, and centroid, hence
bearing, are right) as body-frame :class:`~swarmloc.agents.vision.cooperative.Detection` records.
Used by :mod:`swarmloc.agents.vision.brain`, which re-exports both.
"""

from __future__ import annotations

import math

import cv2
import numpy as np

from swarmloc.agents.vision.cooperative import Detection, wrap_rad
from swarmloc.agents.vision.detection import COLOUR_CLASSES
from swarmloc.world.vision.camera import OBJECT_KINDS, CameraParams

#: Upper bound on an encoded camera frame.
MAX_IMAGE_BYTES = 2 * 1024 * 1024


# -- image decoding -----------------------------------------------------------------------------


def decode_image(payload, camera: CameraParams) -> np.ndarray:
    """The BGR frame of an encoded (JPEG or PNG) ``payload``; ``ValueError`` naming the problem
    if it is not bytes, is empty or too large, does not decode, or has the wrong size."""
    if not isinstance(payload, (bytes, bytearray, memoryview)):
        raise ValueError(f"image: expected bytes, got {type(payload).__name__}")  # noqa: TRY004
    size = payload.nbytes if isinstance(payload, memoryview) else len(payload)
    if size == 0:
        raise ValueError("image: empty payload")
    if size > MAX_IMAGE_BYTES:
        raise ValueError(f"image: {size} bytes exceeds the limit of {MAX_IMAGE_BYTES} bytes")
    image = cv2.imdecode(np.frombuffer(payload, dtype=np.uint8), cv2.IMREAD_COLOR)
    if image is None:
        raise ValueError(f"image: {size} bytes do not decode as an image (JPEG or PNG expected)")
    if image.shape[:2] != (camera.height_px, camera.width_px):
        raise ValueError(
            f"image: decodes to {image.shape[1]} x {image.shape[0]} px, expected "
            f"{camera.width_px} x {camera.height_px} px (W x H)"
        )
    return image


#: Height over width of each colour's upright cylinder in the image (height_m / (2 radius_m)).
_CYLINDER_ASPECT = {
    "yellow": OBJECT_KINDS["teammate"].height_m / (2.0 * OBJECT_KINDS["teammate"].radius_m),
    "orange": OBJECT_KINDS["obstacle"].height_m / (2.0 * OBJECT_KINDS["obstacle"].radius_m),
    "blue": OBJECT_KINDS["beacon"].height_m / (2.0 * OBJECT_KINDS["beacon"].radius_m),
}


def _shape_agrees(measured_px: float, expected_px: float, tolerance: float) -> bool:
    return abs(measured_px - expected_px) <= max(1.0, tolerance * expected_px)


def detections_from_blobs(
    blobs,
    robot_id: int,
    time_s: float,
    head_pan_rad: float,
    camera: CameraParams,
    shape_tolerance: float = 0.15,
) -> list[Detection]:
    """Body-frame :class:`Detection` records of the usable blobs (module docstring, step 1).

    A blob is used only when its shape is that of a whole object, so that its size (hence its
    distance) and its centroid (hence its bearing) are right:

    - a cylinder (robot, obstacle, beacon) must not touch the left or right image edge, and
      unless it touches the top or bottom edge its height must be ``height_m / (2 radius_m)``
      times its width (within ``shape_tolerance`` or 1 px): a narrower blob is a robot partly
      hidden behind a nearer object, whose width-based distance would be far too long;
    - the ball (the largest pink blob only) must be as wide as high, within the same tolerance;
      cut by the bottom of the image only, it keeps its width as diameter.
    """
    out: list[Detection] = []
    focal_px = camera.focal_px
    last_col, last_row = camera.width_px - 1, camera.height_px - 1
    seen_ball = False
    for blob in blobs:
        half_w = (blob.width_px - 1) / 2.0
        half_h = (blob.height_px - 1) / 2.0
        cut_side = blob.u_px - half_w < 0.5 or blob.u_px + half_w > last_col - 0.5
        cut_top = blob.v_px - half_h < 0.5
        cut_bottom = blob.v_px + half_h > last_row - 0.5
        size_px, distance_m = blob.size_px, blob.distance_m
        if cut_side:
            continue
        if blob.colour == "pink":
            if seen_ball:
                continue
            seen_ball = True
            if cut_top:
                continue
            if cut_bottom:
                if blob.height_px < 0.5 * blob.width_px:
                    continue  # less than half the ball: its width is a chord, not the diameter
                size_px = blob.width_px / 2.0
                depth_m = focal_px * COLOUR_CLASSES["pink"].size_m / size_px
                distance_m = depth_m / math.cos(blob.bearing_rad)
            elif not _shape_agrees(blob.height_px, blob.width_px, shape_tolerance):
                continue
        elif blob.colour in _CYLINDER_ASPECT and not (cut_top or cut_bottom):
            expected_h = _CYLINDER_ASPECT[blob.colour] * blob.width_px
            if not _shape_agrees(blob.height_px, expected_h, shape_tolerance):
                continue
        bearing = float(wrap_rad(head_pan_rad + blob.bearing_rad))
        out.append(
            Detection(robot_id, time_s, blob.colour, bearing, head_pan_rad, size_px, distance_m)
        )
    return out
