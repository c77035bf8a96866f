"""The vision robots' world: legged robots with a camera on a pan head, and coloured objects.

Seed 004 (``seeds/004_e71d8ee95e0baa56.txt``) §II-IV: Aibo ERS-7 robots (a body with one camera on a pan head) walk on a flat field
with objects of known size and colour, a pink ball, yellow teammates, orange rivals and the orange
obstacle box of experiments 2 and 3, and blue beacons. This module is the pure world model that
the batch runner (``swarmloc.deploy.lab.vision.runner``) steps, and that a world-server shell can step
over Zenoh: ``observe()`` gives each robot its camera frame and its odometry, ``step(commands)``
moves the robots by their velocity and head commands.

Per tick ``k`` (lockstep, ``tick_s`` apart):

1. :meth:`VisionWorld.observe` renders every robot's camera image from its *true* pose and head
   pan with ``swarmloc.world.vision.camera.render`` (pinhole, f = 190 px, 208 x 160 px, occlusion, a
   per-frame brightness gain for lighting variation and Gaussian pixel noise), and encodes it as
   JPEG (default, quality 90, 4:4:4 chroma so that small colour blobs keep their size) or PNG with
   ``cv2.imencode``. Other robots are drawn as ``"teammate"`` (yellow) cylinders if they are on the
   observer's team and as ``"rival"`` (orange) cylinders otherwise; the observer's own body is not
   drawn. The robot also gets its odometry pose and its head's pan angle (joint encoder, exact).
2. The agents answer with a :class:`VisionCommand` each: a body-frame walking velocity (legged
   robots walk in any direction), a turn rate, and a target head pan.
3. :meth:`VisionWorld.step` clips the commands to the robot's limits, turns the head towards its
   target at the pan rate limit, and moves the body. **Odometry** is the commanded motion
   integrated (a legged robot's walk engine knows what it asked for, not what the feet did); the
   **true motion** is the commanded one with multiplicative Gaussian errors per tick,
   ``d_true = d_cmd (1 + e)``, ``e ~ N(0, linear_std)`` for each body-frame translation component
   and ``N(0, angular_std)`` for the rotation, plus, while the robot walks or turns, an additive
   heading drift ``N(0, heading_drift_std_rad_per_sqrt_s^2 * tick_s)`` (a robot standing still
   stays put). Poses integrate with the mid-point
   heading. Then bodies that overlap are pushed apart (robots from robots, evenly; robots out of
   static obstacles, rivals and beacons) and **collisions** are counted: a collision event is a
   pair that comes into contact (centres closer than the sum of radii + 1 mm) after not being in
   contact at the previous tick; contact ticks are counted too. The ball is not a physical body
   (robots "catch" it by reaching it).

Randomness: one generator, ``default_rng([seed, 0])``, drawn in a fixed order: per observe, for
each robot in index order, the camera's gain and noise (see ``world/vision/camera.py``); per step, one
``normal(size=(N, 4))`` (three translation/rotation factors and the drift). Same seed, same run.

Coordinates: metres, radians, counter-clockwise; a robot's body frame has x forward, y left.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field

import cv2
import numpy as np

from swarmloc.world.vision.camera import (
    OBJECT_KINDS,
    CameraParams,
    SceneObject,
    make_object,
    render,
)

#: Stream id of the world's generator (``[seed, stream]``).
WORLD_STREAM = 0
#: Object kinds a scenario may place on the field (robots are robots, not objects).
FIELD_KINDS = ("ball", "obstacle", "rival", "beacon")
#: Pairs closer than the sum of their radii plus this are in contact.
CONTACT_MARGIN_M = 1e-3
#: Physical bodies (robots collide with them); the ball is not one.
_SOLID_KINDS = ("obstacle", "rival", "beacon")
_IMAGE_FORMATS = {"jpeg": ".jpg", "png": ".png"}
#: Robot bodies (``VisionWorldConfig.robot_body``) and the box's length: an AIBO ERS-7 is about
#: 0.28 m long; its width here is the cylinder's diameter, 0.2 m.
ROBOT_BODIES = ("cylinder", "box")
BOX_LENGTH_M = 0.28


def _finite(
    name: str, value, lo: float | None = None, hi: float | None = None, positive: bool = False
) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError(f"{name} must be a number, got {value!r}")  # noqa: TRY004
    number = float(value)
    if not math.isfinite(number):
        raise ValueError(f"{name} must be finite, got {value!r}")
    if positive and number <= 0.0:
        raise ValueError(f"{name} must be > 0, got {value!r}")
    if lo is not None and number < lo:
        raise ValueError(f"{name} must be >= {lo}, got {value!r}")
    if hi is not None and number > hi:
        raise ValueError(f"{name} must be <= {hi}, got {value!r}")
    return number


@dataclass(frozen=True)
class RobotStart:
    """A robot's start: true pose, team, and head pan (radians, body frame)."""

    x_m: float
    y_m: float
    heading_rad: float = 0.0
    team: str = "A"
    head_pan_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("x_m", "y_m", "heading_rad", "head_pan_rad"):
            _finite(name, getattr(self, name))
        if not isinstance(self.team, str) or not self.team:
            raise ValueError(f"team must be a non-empty string, got {self.team!r}")


@dataclass(frozen=True)
class FieldObject:
    """An object of ``kind`` (one of :data:`FIELD_KINDS`) at ``(x_m, y_m)``, nominal size."""

    kind: str
    x_m: float
    y_m: float

    def __post_init__(self) -> None:
        if self.kind not in FIELD_KINDS:
            raise ValueError(f"kind must be one of {list(FIELD_KINDS)}, got {self.kind!r}")
        _finite("x_m", self.x_m)
        _finite("y_m", self.y_m)

    @property
    def radius_m(self) -> float:
        return OBJECT_KINDS[self.kind].radius_m

    def scene_object(self) -> SceneObject:
        return make_object(self.kind, self.x_m, self.y_m)


@dataclass(frozen=True)
class OdometryNoise:
    """True motion = commanded motion with these errors (see the module docstring)."""

    linear_std: float = 0.05  # relative, per body-frame translation component and tick
    angular_std: float = 0.05  # relative, per tick
    heading_drift_std_rad_per_sqrt_s: float = 0.01

    def __post_init__(self) -> None:
        _finite("linear_std", self.linear_std, 0.0, 0.5)
        _finite("angular_std", self.angular_std, 0.0, 0.5)
        _finite("heading_drift_std_rad_per_sqrt_s", self.heading_drift_std_rad_per_sqrt_s, 0.0, 1.0)


@dataclass(frozen=True)
class VisionWorldConfig:
    """Everything the vision world needs for one run (placements are explicit)."""

    robots: tuple[RobotStart, ...] = (RobotStart(0.0, 0.25), RobotStart(0.0, -0.25))
    objects: tuple[FieldObject, ...] = (FieldObject("ball", 1.5, 0.0),)
    seed: int = 1
    tick_s: float = 0.1
    #: Body radius of a robot; robots are drawn as ``"teammate"``/``"rival"`` cylinders, whose
    #: nominal radius (``world.camera.OBJECT_KINDS``) this must equal so that size-based
    #: distance to a robot is right.
    body_radius_m: float = 0.10
    max_speed_mps: float = 0.3
    max_turn_rate_rad_s: float = 1.5
    max_pan_rate_rad_s: float = 4.0
    odometry: OdometryNoise = field(default_factory=OdometryNoise)
    camera: CameraParams = field(default_factory=CameraParams)
    image_format: str = "jpeg"
    jpeg_quality: int = 90
    #: How robots look to each other: ``"cylinder"`` (the same width from every side) or
    #: ``"box"``, an AIBO-like body ``BOX_LENGTH_M`` long and ``2 body_radius_m`` wide, whose
    #: apparent width (hence size-based distance) depends on which way it faces. Bodies collide
    #: as discs of ``body_radius_m`` in both cases.
    robot_body: str = "cylinder"

    def __post_init__(self) -> None:
        robots = tuple(self.robots)
        objects = tuple(self.objects)
        object.__setattr__(self, "robots", robots)
        object.__setattr__(self, "objects", objects)
        if not 1 <= len(robots) <= 64:
            raise ValueError(f"robots: between 1 and 64 robots, got {len(robots)}")
        for i, r in enumerate(robots):
            if not isinstance(r, RobotStart):
                raise ValueError(f"robots[{i}]: expected a RobotStart, got {type(r).__name__}")  # noqa: TRY004
        for i, o in enumerate(objects):
            if not isinstance(o, FieldObject):
                raise ValueError(f"objects[{i}]: expected a FieldObject, got {type(o).__name__}")  # noqa: TRY004
        if (
            isinstance(self.seed, bool)
            or not isinstance(self.seed, int)
            or not 0 <= self.seed < 2**63
        ):
            raise ValueError(f"seed: must be an integer in 0..2**63-1, got {self.seed!r}")
        _finite("tick_s", self.tick_s, positive=True, hi=10.0)
        radius = _finite("body_radius_m", self.body_radius_m, positive=True)
        if not math.isclose(radius, OBJECT_KINDS["teammate"].radius_m):
            raise ValueError(
                f"body_radius_m: must equal the rendered robot radius "
                f"{OBJECT_KINDS['teammate'].radius_m} m, got {radius}"
            )
        _finite("max_speed_mps", self.max_speed_mps, positive=True, hi=10.0)
        _finite("max_turn_rate_rad_s", self.max_turn_rate_rad_s, positive=True, hi=100.0)
        _finite("max_pan_rate_rad_s", self.max_pan_rate_rad_s, positive=True, hi=100.0)
        for i, r in enumerate(robots):
            if abs(r.head_pan_rad) > self.camera.pan_limit_rad:
                raise ValueError(
                    f"robots[{i}].head_pan_rad: outside ±{self.camera.pan_limit_rad:.4f}"
                )
        if self.image_format not in _IMAGE_FORMATS:
            raise ValueError(
                f"image_format: must be one of {sorted(_IMAGE_FORMATS)}, got {self.image_format!r}"
            )
        if (
            isinstance(self.jpeg_quality, bool)
            or not isinstance(self.jpeg_quality, int)
            or not (10 <= self.jpeg_quality <= 100)
        ):
            raise ValueError(
                f"jpeg_quality: must be an integer in 10..100, got {self.jpeg_quality!r}"
            )
        if self.robot_body not in ROBOT_BODIES:
            raise ValueError(
                f"robot_body: must be one of {list(ROBOT_BODIES)}, got {self.robot_body!r}"
            )
        # No two bodies may start overlapping.
        centres, radii, names = [], [], []
        for i, r in enumerate(robots):
            centres.append((r.x_m, r.y_m))
            radii.append(radius)
            names.append(f"robots[{i}]")
        for i, o in enumerate(objects):
            if o.kind in _SOLID_KINDS:
                centres.append((o.x_m, o.y_m))
                radii.append(o.radius_m)
                names.append(f"objects[{i}]")
        c = np.asarray(centres, float).reshape(-1, 2)
        gap = np.hypot(*(c[:, None, :] - c[None, :, :]).transpose(2, 0, 1))
        rr = np.asarray(radii)[:, None] + np.asarray(radii)[None, :]
        overlap = np.argwhere(np.triu(gap < rr, k=1))
        if len(overlap):
            i, j = overlap[0]
            raise ValueError(f"{names[i]} and {names[j]} overlap at the start")

    @property
    def n_robots(self) -> int:
        return len(self.robots)


@dataclass(frozen=True)
class VisionObservation:
    """What one robot gets at one tick.

    ``image``: the encoded camera frame (JPEG or PNG bytes); ``odometry_pose``: the robot's
    dead-reckoned pose ``(x_m, y_m, heading_rad)`` in its own odometry frame (the start pose is
    ``(0, 0, 0)``), cumulative so that a lost frame loses nothing; ``head_pan_rad``: the pan the
    image was taken at, body frame.
    """

    robot_id: int
    tick: int
    time_s: float
    image: bytes
    odometry_pose: tuple[float, float, float]
    head_pan_rad: float


@dataclass(frozen=True)
class VisionCommand:
    """One robot's command: body-frame walking velocity, turn rate, target head pan.

    Values beyond the robot's limits are clipped by the world; non-finite values are refused.
    """

    forward_mps: float = 0.0
    left_mps: float = 0.0
    turn_rad_s: float = 0.0
    head_pan_rad: float = 0.0

    def __post_init__(self) -> None:
        for name in ("forward_mps", "left_mps", "turn_rad_s", "head_pan_rad"):
            _finite(name, getattr(self, name))


STOP = VisionCommand()


def encode_image(
    image_bgr: np.ndarray, image_format: str = "jpeg", jpeg_quality: int = 90
) -> bytes:
    """``cv2.imencode`` of a BGR frame as JPEG (4:4:4 chroma) or PNG bytes."""
    if image_format not in _IMAGE_FORMATS:
        raise ValueError(
            f"image_format: must be one of {sorted(_IMAGE_FORMATS)}, got {image_format!r}"
        )
    if image_format == "jpeg":
        params = [
            cv2.IMWRITE_JPEG_QUALITY,
            int(jpeg_quality),
            cv2.IMWRITE_JPEG_SAMPLING_FACTOR,
            cv2.IMWRITE_JPEG_SAMPLING_FACTOR_444,
        ]
    else:
        params = [cv2.IMWRITE_PNG_COMPRESSION, 1]
    ok, buf = cv2.imencode(_IMAGE_FORMATS[image_format], image_bgr, params)
    if not ok:  # pragma: no cover - OpenCV only fails on impossible arrays
        raise ValueError("image: cv2.imencode failed")
    return buf.tobytes()


def wrap_rad(angle_rad):
    """Angles wrapped to ``[-pi, pi)``."""
    return (np.asarray(angle_rad, dtype=float) + math.pi) % (2.0 * math.pi) - math.pi


def integrate_body_motion(
    pose: np.ndarray, forward_m: np.ndarray, left_m: np.ndarray, turn_rad: np.ndarray
) -> np.ndarray:
    """Poses ``(N, 3)`` after a body-frame displacement, with the mid-point heading."""
    mid = pose[:, 2] + 0.5 * turn_rad
    c, s = np.cos(mid), np.sin(mid)
    out = pose.copy()
    out[:, 0] += c * forward_m - s * left_m
    out[:, 1] += s * forward_m + c * left_m
    out[:, 2] = wrap_rad(pose[:, 2] + turn_rad)
    return out


class VisionWorld:
    """The vision world over a batch of robots (see the module docstring)."""

    def __init__(self, config: VisionWorldConfig, rng: np.random.Generator | None = None):
        self.config = config
        self.rng = rng if rng is not None else np.random.default_rng([config.seed, WORLD_STREAM])
        n = config.n_robots
        self.pose = np.array([[r.x_m, r.y_m, r.heading_rad] for r in config.robots], dtype=float)
        self.pan_rad = np.array([r.head_pan_rad for r in config.robots], dtype=float)
        self.odometry = np.zeros((n, 3))
        self.teams = [r.team for r in config.robots]
        self.tick = 0
        self.objects = list(config.objects)
        self._scene = [o.scene_object() for o in self.objects]
        solid = [o for o in self.objects if o.kind in _SOLID_KINDS]
        self._solid_xy = np.array([[o.x_m, o.y_m] for o in solid], dtype=float).reshape(-1, 2)
        self._solid_r = np.array([o.radius_m for o in solid], dtype=float)
        #: Collision events (pairs coming into contact) and contact ticks.
        self.robot_collisions = 0
        self.obstacle_collisions = 0
        self.robot_contact_ticks = 0
        self.obstacle_contact_ticks = 0
        #: Per-robot count of robot-robot collision events it took part in.
        self.collisions_per_robot = np.zeros(n, dtype=int)
        self._rr_contact = np.zeros((n, n), dtype=bool)
        self._ro_contact = np.zeros((n, len(solid)), dtype=bool)

    @property
    def n_robots(self) -> int:
        return self.config.n_robots

    @property
    def time_s(self) -> float:
        return self.tick * self.config.tick_s

    def scene_for(self, index: int) -> list[SceneObject]:
        """The objects robot ``index`` can see: every object, and the other robots."""
        team = self.teams[index]
        others = [
            make_object("teammate" if self.teams[j] == team else "rival", *self.pose[j, :2])
            for j in range(self.n_robots)
            if j != index
        ]
        if self.config.robot_body == "box":
            others = [
                dataclasses.replace(o, length_m=BOX_LENGTH_M, heading_rad=float(self.pose[j, 2]))
                for o, j in zip(others, [j for j in range(self.n_robots) if j != index])
            ]
        return self._scene + others

    def render(self, index: int) -> np.ndarray:
        """Robot ``index``'s camera image (BGR uint8), drawing from the world's generator."""
        cfg = self.config
        return render(
            tuple(self.pose[index]),
            float(self.pan_rad[index]),
            self.scene_for(index),
            cfg.camera,
            self.rng,
        )

    def observe(self) -> list[VisionObservation]:
        """Every robot's observation at the current tick (renders and encodes one frame each)."""
        cfg = self.config
        out = []
        for i in range(self.n_robots):
            image = encode_image(self.render(i), cfg.image_format, cfg.jpeg_quality)
            out.append(
                VisionObservation(
                    robot_id=i,
                    tick=self.tick,
                    time_s=self.time_s,
                    image=image,
                    odometry_pose=tuple(float(v) for v in self.odometry[i]),
                    head_pan_rad=float(self.pan_rad[i]),
                )
            )
        return out

    def step(self, commands) -> None:
        """Apply one tick of commands, one :class:`VisionCommand` per robot, in index order."""
        cfg = self.config
        n = self.n_robots
        commands = list(commands)
        if len(commands) != n:
            raise ValueError(f"commands: expected {n} VisionCommand, got {len(commands)}")
        for i, c in enumerate(commands):
            if not isinstance(c, VisionCommand):
                raise ValueError(f"commands[{i}]: expected a VisionCommand, got {type(c).__name__}")  # noqa: TRY004
        dt = cfg.tick_s
        cmd = np.array(
            [[c.forward_mps, c.left_mps, c.turn_rad_s, c.head_pan_rad] for c in commands]
        )
        # Limits: walking speed (norm of the body-frame velocity), turn rate, pan and pan rate.
        speed = np.hypot(cmd[:, 0], cmd[:, 1])
        scale = np.where(
            speed > cfg.max_speed_mps, cfg.max_speed_mps / np.maximum(speed, 1e-300), 1.0
        )
        forward_m = cmd[:, 0] * scale * dt
        left_m = cmd[:, 1] * scale * dt
        turn_rad = np.clip(cmd[:, 2], -cfg.max_turn_rate_rad_s, cfg.max_turn_rate_rad_s) * dt
        limit = cfg.camera.pan_limit_rad
        target = np.clip(cmd[:, 3], -limit, limit)
        max_pan_step = cfg.max_pan_rate_rad_s * dt
        self.pan_rad = np.clip(
            self.pan_rad + np.clip(target - self.pan_rad, -max_pan_step, max_pan_step),
            -limit,
            limit,
        )

        noise = self.rng.normal(size=(n, 4))
        odo = cfg.odometry
        true_forward = forward_m * (1.0 + odo.linear_std * noise[:, 0])
        true_left = left_m * (1.0 + odo.linear_std * noise[:, 1])
        walking = (forward_m != 0.0) | (left_m != 0.0) | (turn_rad != 0.0)
        true_turn = turn_rad * (1.0 + odo.angular_std * noise[:, 2]) + np.where(
            walking, odo.heading_drift_std_rad_per_sqrt_s * math.sqrt(dt) * noise[:, 3], 0.0
        )
        self.odometry = integrate_body_motion(self.odometry, forward_m, left_m, turn_rad)
        pose = integrate_body_motion(self.pose, true_forward, true_left, true_turn)
        pose[:, :2] = self._resolve(pose[:, :2])
        self.pose = pose
        self._count_contacts()
        self.tick += 1

    # -- physics --------------------------------------------------------------------------------

    def _resolve(self, xy: np.ndarray, iterations: int = 3) -> np.ndarray:
        """Push overlapping robots apart (evenly) and out of static bodies (Jacobi iterations)."""
        r = self.config.body_radius_m
        n = xy.shape[0]
        xy = xy.copy()
        for _ in range(iterations):
            push = np.zeros_like(xy)
            if n >= 2:
                d = xy[:, None, :] - xy[None, :, :]  # (N, N, 2), from j to i
                dist = np.hypot(d[..., 0], d[..., 1])
                overlap = (2.0 * r - dist) * (~np.eye(n, dtype=bool))
                overlap = np.maximum(overlap, 0.0)
                # Coincident centres: split along x, lower index to -x.
                safe = np.where(dist > 0.0, dist, 1.0)
                unit = d / safe[..., None]
                same = (dist == 0.0) & ~np.eye(n, dtype=bool)
                if same.any():
                    idx = np.arange(n)
                    unit[same] = 0.0
                    unit[..., 0] = np.where(
                        same, np.sign(idx[:, None] - idx[None, :]), unit[..., 0]
                    )
                push += 0.5 * (overlap[..., None] * unit).sum(axis=1)
            if len(self._solid_r):
                d = xy[:, None, :] - self._solid_xy[None, :, :]
                dist = np.hypot(d[..., 0], d[..., 1])
                overlap = np.maximum(r + self._solid_r[None, :] - dist, 0.0)
                safe = np.where(dist > 0.0, dist, 1.0)
                unit = np.where((dist > 0.0)[..., None], d / safe[..., None], np.array([-1.0, 0.0]))
                push += (overlap[..., None] * unit).sum(axis=1)
            if not np.any(push):
                break
            xy += push
        return xy

    def _count_contacts(self) -> None:
        r = self.config.body_radius_m
        xy = self.pose[:, :2]
        dist = np.hypot(*(xy[:, None, :] - xy[None, :, :]).transpose(2, 0, 1))
        rr = np.triu(dist < 2.0 * r + CONTACT_MARGIN_M, k=1)
        new = rr & ~self._rr_contact
        self.robot_collisions += int(new.sum())
        self.robot_contact_ticks += int(rr.sum())
        self.collisions_per_robot += new.sum(axis=0) + new.sum(axis=1)
        self._rr_contact = rr
        if len(self._solid_r):
            dist = np.hypot(*(xy[:, None, :] - self._solid_xy[None, :, :]).transpose(2, 0, 1))
            ro = dist < r + self._solid_r[None, :] + CONTACT_MARGIN_M
            self.obstacle_collisions += int((ro & ~self._ro_contact).sum())
            self.obstacle_contact_ticks += int(ro.sum())
            self._ro_contact = ro

    # -- ground truth helpers -------------------------------------------------------------------

    def relative_position(self, observer: int, point_xy) -> np.ndarray:
        """``point_xy`` (world) in robot ``observer``'s true body frame, ``(2,)``."""
        x, y, th = self.pose[observer]
        dx, dy = np.asarray(point_xy, float) - (x, y)
        c, s = math.cos(th), math.sin(th)
        return np.array([c * dx + s * dy, -s * dx + c * dy])
