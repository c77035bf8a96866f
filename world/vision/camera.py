"""Pinhole camera renderer for the vision robots: coloured objects on a green field.

Seed 004 §II: each legged robot (an AIBO ERS-7 in the seed) sees the field with one camera on a
pan head and recognises items by colour: a pink ball, yellow teammates, orange rivals and the
orange obstacle box of §IV, and beacons. Sizes are known a priori so that distance follows from
apparent size; the seed's focal length is f = 190 px (§II, used in eq. 1), the image here is
208 x 160 px (the ERS-7's low-resolution camera layer).

Camera model (a stand-in, not the ERS-7's optics): the camera sits at the robot's position
``(x_m, y_m)`` at ``camera_height_m`` above the floor; it looks horizontally (no tilt) along the
yaw ``heading_rad + pan_rad``. For an object centre at forward depth ``z`` (along the optical axis)
and lateral offset ``y`` (positive to the left) its bearing is ``atan2(y, z)`` and

- column ``u = cx - f * y / z = cx - f * tan(bearing)``,
- row ``v = cy + f * (camera_height_m - centre height) / z``,
- apparent radius ``f * radius_m / z`` (pinhole scale at the centre's depth),

with the principal point at the image centre in pixel-centre coordinates,
``cx = (width_px - 1) / 2``, ``cy = (height_px - 1) / 2``. A ball is a sphere resting on the
floor, drawn as a filled disc; every other kind is an upright cylinder drawn as a filled
rectangle ``2 * f * radius_m / z`` wide from the floor to ``height_m``. A pixel is painted when its
centre lies inside the shape (exact areas, no anti-aliasing that would mix colours).
Objects are drawn farthest first, so nearer ones occlude farther ones; objects closer than
``near_clip_m`` in depth (or behind the camera) and objects wholly outside the image are not
drawn. The robot's own body is not drawn: callers pass the other objects only.

Sensor effects, drawn from ``rng`` in a fixed order: one ``rng.uniform(gain_min, gain_max)``
brightness gain for the frame (lighting variation), then, if ``noise_sigma > 0``, one
``rng.standard_normal((height_px, width_px, 3), dtype=float32)`` draw of additive Gaussian pixel
noise of ``noise_sigma`` grey levels. Output ``round(clip(gain * image + noise, 0, 255))``.

The object kinds, their colours (:data:`COLOURS_BGR`) and nominal sizes (:data:`OBJECT_KINDS`)
are the physical contract that the detector in ``swarmloc.agents.vision.detection`` relies on; a test checks
that the two agree.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

#: Colours of the field and of each colour class, BGR uint8 (OpenCV's channel order). Hues (OpenCV
#: 0-180 scale): field 57, pink 159, yellow 29, orange 12, blue 103; all strongly saturated, so
#: a brightness gain keeps the hue (clipping at 255 moves pink to 150 and orange to 15 at 1.3).
COLOURS_BGR: dict[str, tuple[int, int, int]] = {
    "field": (40, 150, 50),
    "pink": (200, 80, 255),
    "yellow": (0, 215, 225),
    "orange": (0, 100, 255),
    "blue": (230, 140, 20),
}


@dataclass(frozen=True)
class ObjectKind:
    """Colour, shape and nominal size of one kind of object on the field."""

    colour: str
    shape: str  # "sphere" or "cylinder"
    radius_m: float
    height_m: float


#: Object kinds of seed 004 (§II-IV): one nominal size per colour, so that size-based distance is
#: unambiguous (the orange obstacle box is a stand-in with the size of an orange rival).
OBJECT_KINDS: dict[str, ObjectKind] = {
    "ball": ObjectKind("pink", "sphere", 0.04, 0.08),
    "teammate": ObjectKind("yellow", "cylinder", 0.10, 0.25),
    "rival": ObjectKind("orange", "cylinder", 0.10, 0.25),
    "obstacle": ObjectKind("orange", "cylinder", 0.10, 0.25),
    "beacon": ObjectKind("blue", "cylinder", 0.05, 0.40),
}


def _finite_positive(name: str, value: float) -> None:
    if not (isinstance(value, int | float) and math.isfinite(value) and value > 0.0):
        raise ValueError(f"{name} must be finite and > 0, got {value!r}")


@dataclass(frozen=True)
class CameraParams:
    """Intrinsics, mounting and sensor effects of a vision robot's camera (seed 004 §II)."""

    width_px: int = 208
    height_px: int = 160
    focal_px: float = 190.0
    camera_height_m: float = 0.12
    pan_limit_rad: float = math.radians(90.0)
    near_clip_m: float = 0.05
    noise_sigma: float = 6.0
    gain_min: float = 0.7
    gain_max: float = 1.3

    def __post_init__(self) -> None:
        for name in ("width_px", "height_px"):
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, int) or not 8 <= value <= 4096:
                raise ValueError(f"{name} must be an integer in [8, 4096], got {value!r}")
        for name in ("focal_px", "camera_height_m", "pan_limit_rad", "near_clip_m"):
            _finite_positive(name, getattr(self, name))
        if not (math.isfinite(self.noise_sigma) and 0.0 <= self.noise_sigma <= 128.0):
            raise ValueError(f"noise_sigma must be in [0, 128], got {self.noise_sigma!r}")
        _finite_positive("gain_min", self.gain_min)
        _finite_positive("gain_max", self.gain_max)
        if self.gain_max < self.gain_min:
            raise ValueError(
                f"gain_max must be >= gain_min, got gain_min={self.gain_min!r}, "
                f"gain_max={self.gain_max!r}"
            )

    @property
    def cx_px(self) -> float:
        """Principal point column (image centre, pixel-centre coordinates)."""
        return (self.width_px - 1) / 2.0

    @property
    def cy_px(self) -> float:
        """Principal point row (image centre, pixel-centre coordinates)."""
        return (self.height_px - 1) / 2.0

    @property
    def half_fov_rad(self) -> float:
        """Half the horizontal field of view, to the outer edge of the border pixels."""
        return math.atan((self.width_px / 2.0) / self.focal_px)


@dataclass(frozen=True)
class SceneObject:
    """One object on the field: ``kind`` in :data:`OBJECT_KINDS`, drawn in ``colour``.

    ``centre_m`` is the (x, y) of its vertical axis on the floor. A ``"ball"`` is a sphere of
    ``radius_m`` resting on the floor (``height_m`` must be ``2 * radius_m``); the other kinds are
    upright cylinders. Use :func:`make_object` for the nominal colour and size of a kind.
    """

    kind: str
    colour: str
    centre_m: tuple[float, float]
    radius_m: float
    height_m: float
    #: A box instead of a cylinder (an AIBO-like robot body, ``VisionWorldConfig.robot_body``):
    #: ``length_m`` along ``heading_rad``, width ``2 radius_m``. ``None``: a cylinder.
    length_m: float | None = None
    heading_rad: float = 0.0

    def __post_init__(self) -> None:
        if self.kind not in OBJECT_KINDS:
            raise ValueError(f"kind must be one of {sorted(OBJECT_KINDS)}, got {self.kind!r}")
        if self.colour not in COLOURS_BGR or self.colour == "field":
            colours = sorted(c for c in COLOURS_BGR if c != "field")
            raise ValueError(f"colour must be one of {colours}, got {self.colour!r}")
        centre = tuple(self.centre_m)
        if len(centre) != 2 or not all(
            isinstance(c, int | float) and math.isfinite(c) for c in centre
        ):
            raise ValueError(f"centre_m must be two finite numbers, got {self.centre_m!r}")
        object.__setattr__(self, "centre_m", (float(centre[0]), float(centre[1])))
        _finite_positive("radius_m", self.radius_m)
        _finite_positive("height_m", self.height_m)
        if self.length_m is not None:
            _finite_positive("length_m", self.length_m)
            if self.is_sphere:
                raise ValueError("length_m: a ball is not a box")
        if not math.isfinite(self.heading_rad):
            raise ValueError(f"heading_rad must be finite, got {self.heading_rad!r}")
        if self.is_sphere and not math.isclose(self.height_m, 2.0 * self.radius_m):
            raise ValueError(
                f"height_m of a ball must be 2 * radius_m = {2.0 * self.radius_m!r}, "
                f"got {self.height_m!r}"
            )

    @property
    def is_sphere(self) -> bool:
        return OBJECT_KINDS[self.kind].shape == "sphere"

    def half_width_m(self, sight_yaw_rad: float) -> float:
        """Half the width the object shows across a line of sight of yaw ``sight_yaw_rad``
        (world frame): its radius for a ball or a cylinder; for a box of length ``L`` and width
        ``W`` at relative angle ``a`` to the sight line, ``(L |sin a| + W |cos a|) / 2`` (its
        silhouette drawn at the depth of its centre)."""
        if self.length_m is None:
            return self.radius_m
        a = self.heading_rad - sight_yaw_rad
        return 0.5 * (self.length_m * abs(math.sin(a)) + 2.0 * self.radius_m * abs(math.cos(a)))


def make_object(kind: str, x_m: float, y_m: float) -> SceneObject:
    """A :class:`SceneObject` of ``kind`` at ``(x_m, y_m)`` with its nominal colour and size."""
    if kind not in OBJECT_KINDS:
        raise ValueError(f"kind must be one of {sorted(OBJECT_KINDS)}, got {kind!r}")
    spec = OBJECT_KINDS[kind]
    return SceneObject(kind, spec.colour, (x_m, y_m), spec.radius_m, spec.height_m)


def project(
    camera_pose: tuple[float, float, float], pan_rad: float, obj: SceneObject, params: CameraParams
) -> tuple[float, float, float, float]:
    """``(u_px, v_px, radius_px, depth_m)`` of ``obj``'s centre; depth <= 0 means behind.

    ``u_px, v_px`` are the image of the object's centre (the sphere's centre, or the cylinder's
    axis at half its height); ``radius_px = focal_px * half width / depth_m`` (the half width
    is ``radius_m`` except for a box, :meth:`SceneObject.half_width_m`).
    """
    x_m, y_m, heading_rad = camera_pose
    yaw_rad = heading_rad + pan_rad
    dx_m = obj.centre_m[0] - x_m
    dy_m = obj.centre_m[1] - y_m
    depth_m = dx_m * math.cos(yaw_rad) + dy_m * math.sin(yaw_rad)
    left_m = -dx_m * math.sin(yaw_rad) + dy_m * math.cos(yaw_rad)
    if depth_m <= 0.0:
        return math.nan, math.nan, math.nan, depth_m
    scale = params.focal_px / depth_m
    centre_height_m = obj.radius_m if obj.is_sphere else obj.height_m / 2.0
    u_px = params.cx_px - scale * left_m
    v_px = params.cy_px + scale * (params.camera_height_m - centre_height_m)
    half_width_m = obj.half_width_m(math.atan2(dy_m, dx_m))
    return u_px, v_px, scale * half_width_m, depth_m


def _pixel_span(lo: float, hi: float, size: int) -> tuple[int, int]:
    """Indices ``[i0, i1)`` of the pixels whose centres lie in ``[lo, hi]``, clipped to the image."""
    i0 = max(math.ceil(lo), 0)
    i1 = min(math.floor(hi) + 1, size)
    return i0, max(i1, i0)


def _check_pose(camera_pose) -> tuple[float, float, float]:
    try:
        pose = tuple(float(c) for c in camera_pose)
    except (TypeError, ValueError):
        raise ValueError(f"camera_pose must be (x_m, y_m, heading_rad), got {camera_pose!r}")
    if len(pose) != 3 or not all(math.isfinite(c) for c in pose):
        raise ValueError(f"camera_pose must be 3 finite numbers, got {camera_pose!r}")
    return pose


def render(
    camera_pose: tuple[float, float, float],
    pan_rad: float,
    objects: list[SceneObject],
    params: CameraParams,
    rng: np.random.Generator,
) -> np.ndarray:
    """The camera image ``(height_px, width_px, 3)`` uint8 BGR seen from ``camera_pose``.

    ``camera_pose`` = (x_m, y_m, heading_rad) of the robot; ``pan_rad`` the head's pan relative
    to the heading, within ``±pan_limit_rad``. See the module docstring for the projection, the
    drawing order and the random draws.
    """
    pose = _check_pose(camera_pose)
    if not (math.isfinite(pan_rad) and abs(pan_rad) <= params.pan_limit_rad):
        raise ValueError(
            f"pan_rad must be finite and within ±{params.pan_limit_rad:.4f}, got {pan_rad!r}"
        )
    w, h = params.width_px, params.height_px
    image = np.empty((h, w, 3), dtype=np.uint8)
    image[:] = COLOURS_BGR["field"]

    visible = []
    for obj in objects:
        if not isinstance(obj, SceneObject):
            kind = type(obj).__name__
            raise ValueError(f"objects must be SceneObject instances, got {kind}")  # noqa: TRY004
        u_px, v_px, radius_px, depth_m = project(pose, pan_rad, obj, params)
        if depth_m >= params.near_clip_m:
            visible.append((depth_m, u_px, v_px, radius_px, obj))
    visible.sort(key=lambda item: -item[0])  # farthest first: nearer objects paint over them

    for depth_m, u_px, v_px, radius_px, obj in visible:
        c0, c1 = _pixel_span(u_px - radius_px, u_px + radius_px, w)
        if obj.is_sphere:
            r0, r1 = _pixel_span(v_px - radius_px, v_px + radius_px, h)
        else:
            scale = params.focal_px / depth_m
            top_px = params.cy_px + scale * (params.camera_height_m - obj.height_m)
            bottom_px = params.cy_px + scale * params.camera_height_m
            r0, r1 = _pixel_span(top_px, bottom_px, h)
        if c0 >= c1 or r0 >= r1:
            continue  # wholly outside the image
        colour = COLOURS_BGR[obj.colour]
        if obj.is_sphere:
            rows = np.arange(r0, r1, dtype=np.float64)[:, None] - v_px
            cols = np.arange(c0, c1, dtype=np.float64)[None, :] - u_px
            inside = rows * rows + cols * cols <= radius_px * radius_px
            image[r0:r1, c0:c1][inside] = colour
        else:
            image[r0:r1, c0:c1] = colour

    gain = rng.uniform(params.gain_min, params.gain_max)
    frame = image.astype(np.float32)
    frame *= np.float32(gain)
    if params.noise_sigma > 0.0:
        noise = rng.standard_normal((h, w, 3), dtype=np.float32)
        noise *= np.float32(params.noise_sigma)
        frame += noise
    frame += np.float32(0.5)  # round to nearest on the truncating cast below
    np.clip(frame, 0.0, 255.0, out=frame)
    return frame.astype(np.uint8)
