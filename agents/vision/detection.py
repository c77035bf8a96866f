"""Colour-blob detection and size-based distance for the vision robots.

Seed 004 §II-III: robots are "subscribed to color detection events, where each color is associated
to a different item" (pink ball, yellow teammate, orange rival or obstacle, beacons), and each robot
"can estimate its distance to that landmark because their sizes are known a priori". With the
pinhole model of the seed (f = 190 px, the f of eq. 1):

- bearing of a blob from the optical axis, positive to the left:
  ``bearing_rad = atan((cx - u_px) / focal_px)``, ``cx = (width_px - 1) / 2``;
- depth along the optical axis from apparent size: ``depth_m = focal_px * size_m / size_px``;
- range on the floor from the camera to the object's axis:
  ``distance_m = depth_m / cos(bearing_rad)`` (equal to ``focal_px * size_m / size_px`` on the
  optical axis; off-axis, the pinhole scale follows depth, not range).

``size_px`` is measured per colour class: for the ball (a sphere, a disc in the image) the radius
of the disc of equal area, ``sqrt(area_px / pi)``, so a partly hidden ball looks smaller and
farther; for upright cylinders (robots, beacons) half the blob's width, which stays right when the
bottom or the top of the body leaves the image. Bearings are in the camera frame: add the head's
pan angle for the body frame.

Pipeline (OpenCV): BGR -> HSV, ``cv2.inRange`` per class, a morphological opening (removes
speckle) and closing (fills holes) with a 3 x 3 cross, ``cv2.connectedComponentsWithStats``,
blobs below ``min_area_px`` rejected. The class table :data:`COLOUR_CLASSES` must agree with the
colours and sizes that ``swarmloc.world.vision.camera`` renders; the tests check that it does.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import cv2
import numpy as np


class PinholeIntrinsics(Protocol):
    """What the detector needs to know of the camera (``world.vision.camera.CameraParams`` has it)."""

    width_px: int
    height_px: int
    focal_px: float


@dataclass(frozen=True)
class ColourClass:
    """HSV range (OpenCV scale: H 0-180, S and V 0-255) and known size of one colour class.

    ``size_measure`` says how the blob's size in pixels is measured: ``"area"`` (radius of the disc
    of equal area, for spheres) or ``"width"`` (half the blob's width, for upright cylinders);
    ``size_m`` is the matching true size (the object's radius).
    """

    hsv_lower: tuple[int, int, int]
    hsv_upper: tuple[int, int, int]
    size_m: float
    size_measure: str

    def __post_init__(self) -> None:
        for name in ("hsv_lower", "hsv_upper"):
            value = getattr(self, name)
            if len(value) != 3 or not all(isinstance(c, int) and 0 <= c <= 255 for c in value):
                raise ValueError(f"{name} must be 3 integers in [0, 255], got {value!r}")
        if not (math.isfinite(self.size_m) and self.size_m > 0.0):
            raise ValueError(f"size_m must be finite and > 0, got {self.size_m!r}")
        if self.size_measure not in ("area", "width"):
            raise ValueError(f"size_measure must be 'area' or 'width', got {self.size_measure!r}")


#: Colour classes of seed 004. Rendered hues under gains 0.7-1.3: pink 150-159, yellow 29-30,
#: orange 12-15, blue 100-103, field 57; the ranges leave margins of 5 or more hue units for pixel
#: noise, and S >= 90, V >= 50 exclude dark and washed-out pixels.
COLOUR_CLASSES: dict[str, ColourClass] = {
    "pink": ColourClass((140, 90, 50), (175, 255, 255), 0.04, "area"),
    "yellow": ColourClass((23, 90, 50), (40, 255, 255), 0.10, "width"),
    "orange": ColourClass((0, 90, 50), (20, 255, 255), 0.10, "width"),
    "blue": ColourClass((90, 90, 50), (125, 255, 255), 0.05, "width"),
}

_KERNEL = cv2.getStructuringElement(cv2.MORPH_CROSS, (3, 3))


@dataclass(frozen=True)
class Blob:
    """One detected blob: its colour class, image geometry, and what they imply.

    ``u_px, v_px``: centroid (pixel-centre coordinates); ``area_px``: pixel count; ``width_px,
    height_px``: bounding box; ``size_px``: apparent radius as measured for the class;
    ``bearing_rad``: from the optical axis, positive to the left; ``depth_m`` along the optical
    axis and ``distance_m`` on the floor, from size; ``touches_border``: the blob reaches the image
    edge, so it may be cut and its size (hence distance) unreliable.
    """

    colour: str
    u_px: float
    v_px: float
    area_px: int
    width_px: int
    height_px: int
    size_px: float
    bearing_rad: float
    depth_m: float
    distance_m: float
    touches_border: bool


def _check_image(image_bgr: np.ndarray, params: PinholeIntrinsics) -> None:
    # Bad input of any kind is one error type (ValueError), as everywhere at the shell boundary.
    if not isinstance(image_bgr, np.ndarray):
        kind = type(image_bgr).__name__
        raise ValueError(f"image_bgr must be a numpy array, got {kind}")  # noqa: TRY004
    if image_bgr.ndim != 3 or image_bgr.shape[2] != 3:
        raise ValueError(f"image_bgr must have shape (H, W, 3), got {image_bgr.shape}")
    if image_bgr.dtype != np.uint8:
        raise ValueError(f"image_bgr must have dtype uint8, got {image_bgr.dtype}")
    expected = (params.height_px, params.width_px)
    if image_bgr.shape[:2] != expected:
        raise ValueError(
            f"image_bgr must be {expected[0]} x {expected[1]} px (H x W) for this camera, "
            f"got {image_bgr.shape[0]} x {image_bgr.shape[1]}"
        )


def detect_blobs(
    image_bgr: np.ndarray,
    params: PinholeIntrinsics,
    classes: dict[str, ColourClass] | None = None,
    min_area_px: int = 6,
) -> list[Blob]:
    """Blobs of every colour class in ``image_bgr``, largest first within each class.

    ``image_bgr`` must be ``(height_px, width_px, 3)`` uint8 for the camera ``params``; anything
    else raises ``ValueError`` naming the problem. ``classes`` defaults to
    :data:`COLOUR_CLASSES`. Components with fewer than ``min_area_px`` pixels are rejected.
    """
    _check_image(image_bgr, params)
    if classes is None:
        classes = COLOUR_CLASSES
    focal_px = float(params.focal_px)
    cx_px = (params.width_px - 1) / 2.0
    w, h = params.width_px, params.height_px
    hsv = cv2.cvtColor(image_bgr, cv2.COLOR_BGR2HSV)
    blobs: list[Blob] = []
    for colour, cls in classes.items():
        mask = cv2.inRange(hsv, cls.hsv_lower, cls.hsv_upper)
        mask = cv2.morphologyEx(mask, cv2.MORPH_OPEN, _KERNEL)
        mask = cv2.morphologyEx(mask, cv2.MORPH_CLOSE, _KERNEL)
        n_labels, _, stats, centroids = cv2.connectedComponentsWithStats(mask, connectivity=8)
        found = []
        for label in range(1, n_labels):  # label 0 is the background
            left, top, width, height, area = (int(s) for s in stats[label])
            if area < min_area_px:
                continue
            u_px, v_px = float(centroids[label, 0]), float(centroids[label, 1])
            if cls.size_measure == "area":
                size_px = math.sqrt(area / math.pi)
            else:
                size_px = width / 2.0
            bearing_rad = math.atan((cx_px - u_px) / focal_px)
            depth_m = focal_px * cls.size_m / size_px
            found.append(
                Blob(
                    colour=colour,
                    u_px=u_px,
                    v_px=v_px,
                    area_px=area,
                    width_px=width,
                    height_px=height,
                    size_px=size_px,
                    bearing_rad=bearing_rad,
                    depth_m=depth_m,
                    distance_m=depth_m / math.cos(bearing_rad),
                    touches_border=(
                        left == 0 or top == 0 or left + width == w or top + height == h
                    ),
                )
            )
        found.sort(key=lambda blob: -blob.area_px)
        blobs.extend(found)
    return blobs
