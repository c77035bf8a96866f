"""Camera rendering (world/vision/camera.py) and colour-blob detection (agents/vision/detection.py), seed 004 §II.

Synthetic images with known answers: the renderer places objects at known bearings and
distances; the detector must recover them.
"""

from __future__ import annotations

import math

import cv2
import numpy as np
import pytest

from swarmloc.agents.vision.detection import COLOUR_CLASSES, ColourClass, detect_blobs
from swarmloc.world.vision.camera import (
    COLOURS_BGR,
    OBJECT_KINDS,
    CameraParams,
    SceneObject,
    make_object,
    project,
    render,
)

CLEAN = CameraParams(noise_sigma=0.0, gain_min=1.0, gain_max=1.0)
NOISY = CameraParams()  # default noise sigma 6 grey levels, gain 0.7-1.3


def _place(pose, pan_rad, bearing_rad, distance_m):
    """World (x, y) at ``bearing_rad`` (camera frame) and floor range ``distance_m``."""
    yaw_rad = pose[2] + pan_rad + bearing_rad
    return pose[0] + distance_m * math.cos(yaw_rad), pose[1] + distance_m * math.sin(yaw_rad)


def _angle_error_rad(a, b):
    return abs((a - b + math.pi) % (2.0 * math.pi) - math.pi)


def _of(blobs, colour):
    return [b for b in blobs if b.colour == colour]


# ---- the contract between renderer and detector ----


def test_colour_classes_match_rendered_colours_and_sizes():
    hsv_field = cv2.cvtColor(np.uint8([[COLOURS_BGR["field"]]]), cv2.COLOR_BGR2HSV)
    for kind, spec in OBJECT_KINDS.items():
        cls = COLOUR_CLASSES[spec.colour]
        assert cls.size_m == spec.radius_m, kind
        assert cls.size_measure == ("area" if spec.shape == "sphere" else "width"), kind
    for colour, bgr in COLOURS_BGR.items():
        for gain in (NOISY.gain_min, 1.0, NOISY.gain_max):
            pixel = np.clip(np.array(bgr, float) * gain + 0.5, 0, 255).astype(np.uint8)
            hsv = cv2.cvtColor(pixel.reshape(1, 1, 3), cv2.COLOR_BGR2HSV)
            hits = [
                name
                for name, cls in COLOUR_CLASSES.items()
                if cv2.inRange(hsv, cls.hsv_lower, cls.hsv_upper)[0, 0]
            ]
            assert hits == ([] if colour == "field" else [colour]), (colour, gain, hsv)
    assert not any(
        cv2.inRange(hsv_field, c.hsv_lower, c.hsv_upper)[0, 0] for c in COLOUR_CLASSES.values()
    )


# ---- known answers, no noise ----


def test_empty_field_has_no_blobs():
    for seed in range(5):
        image = render((1.0, 2.0, 0.3), 0.0, [], NOISY, np.random.default_rng(seed))
        assert image.shape == (160, 208, 3) and image.dtype == np.uint8
        assert detect_blobs(image, NOISY) == []


@pytest.mark.parametrize(
    "pose, pan_deg, bearing_deg, distance_m",
    [
        ((0.0, 0.0, 0.0), 0.0, 0.0, 1.0),
        ((1.0, -2.0, 0.7), -20.0, 12.0, 1.5),
        ((-3.0, 0.5, -2.5), 45.0, -20.0, 0.6),
        ((0.0, 0.0, math.pi), 0.0, 5.0, 2.5),
    ],
)
def test_one_ball_bearing_and_distance(pose, pan_deg, bearing_deg, distance_m):
    pan_rad, bearing_rad = math.radians(pan_deg), math.radians(bearing_deg)
    ball = make_object("ball", *_place(pose, pan_rad, bearing_rad, distance_m))
    image = render(pose, pan_rad, [ball], CLEAN, np.random.default_rng(0))
    blobs = detect_blobs(image, CLEAN)
    assert [b.colour for b in blobs] == ["pink"]
    (blob,) = blobs
    assert abs(math.degrees(blob.bearing_rad) - bearing_deg) < 1.0
    assert abs(blob.distance_m / distance_m - 1.0) < 0.05
    assert not blob.touches_border


@pytest.mark.parametrize("kind", ["teammate", "rival", "obstacle", "beacon"])
def test_cylinder_kinds_bearing_and_distance(kind):
    pose, bearing_rad, distance_m = (0.5, 0.5, 1.0), math.radians(-8.0), 1.4
    obj = make_object(kind, *_place(pose, 0.0, bearing_rad, distance_m))
    blobs = detect_blobs(render(pose, 0.0, [obj], CLEAN, np.random.default_rng(0)), CLEAN)
    assert [b.colour for b in blobs] == [OBJECT_KINDS[kind].colour]
    assert abs(blobs[0].bearing_rad - bearing_rad) < math.radians(1.0)
    assert abs(blobs[0].distance_m / distance_m - 1.0) < 0.05


def test_two_blobs_of_one_colour():
    pose = (0.0, 0.0, 0.0)
    bearings_rad = [math.radians(15.0), math.radians(-10.0)]
    team = [
        make_object("teammate", *_place(pose, 0.0, bearings_rad[0], 1.2)),
        make_object("teammate", *_place(pose, 0.0, bearings_rad[1], 2.0)),
    ]
    blobs = detect_blobs(render(pose, 0.0, team, CLEAN, np.random.default_rng(0)), CLEAN)
    yellow = _of(blobs, "yellow")
    assert len(blobs) == len(yellow) == 2
    # Largest first: the nearer robot.
    assert abs(yellow[0].bearing_rad - bearings_rad[0]) < math.radians(1.0)
    assert abs(yellow[1].bearing_rad - bearings_rad[1]) < math.radians(1.0)
    assert abs(yellow[0].distance_m - 1.2) < 0.05 * 1.2
    assert abs(yellow[1].distance_m - 2.0) < 0.05 * 2.0


def test_near_robot_fully_hides_ball_behind_it():
    pose = (0.0, 0.0, 0.0)
    scene = [make_object("ball", 2.0, 0.0), make_object("teammate", 0.8, 0.0)]
    for objects in (scene, scene[::-1]):  # drawing order follows depth, not list order
        blobs = detect_blobs(render(pose, 0.0, objects, CLEAN, np.random.default_rng(0)), CLEAN)
        assert [b.colour for b in blobs] == ["yellow"]


def test_partial_occlusion_shrinks_the_ball():
    pose = (0.0, 0.0, 0.0)
    ball = make_object("ball", 1.5, 0.0)
    alone = detect_blobs(render(pose, 0.0, [ball], CLEAN, np.random.default_rng(0)), CLEAN)
    # The robot's right edge (seen from the camera) lies on the ball's centre line.
    robot = make_object("teammate", 0.75, 0.1)
    hidden = detect_blobs(render(pose, 0.0, [ball, robot], CLEAN, np.random.default_rng(0)), CLEAN)
    (ball_alone,) = _of(alone, "pink")
    (ball_hidden,) = _of(hidden, "pink")
    assert len(_of(hidden, "yellow")) == 1
    assert ball_hidden.area_px < 0.8 * ball_alone.area_px
    assert ball_hidden.size_px < ball_alone.size_px
    assert ball_hidden.distance_m > ball_alone.distance_m  # looks farther: a known bias


def test_objects_behind_or_outside_the_view_are_not_drawn():
    pose = (0.0, 0.0, 0.0)
    objects = [
        make_object("ball", -1.0, 0.0),  # behind
        make_object("teammate", 0.5, 2.0),  # 76 deg to the left
        make_object("rival", 1.0, -3.0),  # 72 deg to the right
    ]
    image = render(pose, 0.0, objects, CLEAN, np.random.default_rng(0))
    assert np.all(image == COLOURS_BGR["field"])
    # Panning the head towards the teammate brings it into view.
    image = render(pose, math.radians(76.0), objects, CLEAN, np.random.default_rng(0))
    assert [b.colour for b in detect_blobs(image, CLEAN)] == ["yellow"]


def test_project_matches_the_pinhole_formulas():
    pose, pan_rad = (1.0, 1.0, 0.4), -0.1
    bearing_rad, distance_m = math.radians(10.0), 2.0
    ball = make_object("ball", *_place(pose, pan_rad, bearing_rad, distance_m))
    u_px, v_px, radius_px, depth_m = project(pose, pan_rad, ball, CLEAN)
    assert depth_m == pytest.approx(distance_m * math.cos(bearing_rad))
    assert u_px == pytest.approx(CLEAN.cx_px - 190.0 * math.tan(bearing_rad))
    assert radius_px == pytest.approx(190.0 * 0.04 / depth_m)
    assert v_px == pytest.approx(CLEAN.cy_px + 190.0 * (0.12 - 0.04) / depth_m)


# ---- noise and lighting ----


def test_render_is_deterministic_given_the_generator():
    objects = [make_object("ball", 1.0, 0.1), make_object("rival", 2.0, -0.3)]
    a = render((0.0, 0.0, 0.0), 0.0, objects, NOISY, np.random.default_rng(7))
    b = render((0.0, 0.0, 0.0), 0.0, objects, NOISY, np.random.default_rng(7))
    c = render((0.0, 0.0, 0.0), 0.0, objects, NOISY, np.random.default_rng(8))
    assert np.array_equal(a, b)
    assert not np.array_equal(a, c)


def test_detection_under_noise_and_lighting():
    """200 seeded placements of the ball wholly in view at 0.3-3 m, noise sigma 6, gain 0.7-1.3.

    Stated bounds: detection rate >= 95 %, median bearing error < 0.25 deg, median relative
    distance error < 3 % (observed: 100 %, 0.013 deg and 0.7 %).
    """
    rng = np.random.default_rng(2024)
    bearing_errors_deg, distance_errors, detected, placements = [], [], 0, 0
    while placements < 200:
        pose = (rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-math.pi, math.pi))
        pan_rad = rng.uniform(-1.0, 1.0)
        bearing_rad = rng.uniform(-NOISY.half_fov_rad, NOISY.half_fov_rad)
        distance_m = rng.uniform(0.3, 3.0)
        ball = make_object("ball", *_place(pose, pan_rad, bearing_rad, distance_m))
        u_px, v_px, radius_px, _ = project(pose, pan_rad, ball, NOISY)
        if not (
            u_px - radius_px >= 0
            and u_px + radius_px <= NOISY.width_px - 1
            and v_px + radius_px <= NOISY.height_px - 1
        ):
            continue  # not wholly in view: draw another placement
        placements += 1
        pink = _of(detect_blobs(render(pose, pan_rad, [ball], NOISY, rng), NOISY), "pink")
        if len(pink) == 1:
            detected += 1
            bearing_errors_deg.append(
                math.degrees(_angle_error_rad(pink[0].bearing_rad, bearing_rad))
            )
            distance_errors.append(abs(pink[0].distance_m / distance_m - 1.0))
    assert detected / placements >= 0.95
    assert np.median(bearing_errors_deg) < 0.25
    assert np.median(distance_errors) < 0.03


# ---- bad input ----


@pytest.mark.parametrize(
    "image, match",
    [
        (np.zeros((160, 208), np.uint8), r"shape \(H, W, 3\)"),
        (np.zeros((160, 208, 4), np.uint8), r"shape \(H, W, 3\)"),
        (np.zeros((160, 208, 3), np.float32), "dtype uint8"),
        (np.zeros((120, 160, 3), np.uint8), "160 x 208"),
        ([[0, 0, 0]], "numpy array"),
        (b"\xff\xd8 not decoded", "numpy array"),
    ],
)
def test_bad_image_raises(image, match):
    with pytest.raises(ValueError, match=match):
        detect_blobs(image, CLEAN)


@pytest.mark.parametrize(
    "field, value",
    [
        ("width_px", 0),
        ("height_px", 100.5),
        ("focal_px", -1.0),
        ("camera_height_m", math.nan),
        ("noise_sigma", -1.0),
        ("gain_min", 0.0),
    ],
)
def test_camera_params_validation_names_the_field(field, value):
    with pytest.raises(ValueError, match=field):
        CameraParams(**{field: value})
    with pytest.raises(ValueError, match="gain_max"):
        CameraParams(gain_min=1.2, gain_max=1.1)


def test_scene_object_and_render_validation():
    with pytest.raises(ValueError, match="kind"):
        make_object("goal", 0.0, 0.0)
    with pytest.raises(ValueError, match="colour"):
        SceneObject("ball", "purple", (0.0, 0.0), 0.04, 0.08)
    with pytest.raises(ValueError, match="radius_m"):
        SceneObject("rival", "orange", (0.0, 0.0), 0.0, 0.25)
    with pytest.raises(ValueError, match="centre_m"):
        SceneObject("rival", "orange", (0.0, math.inf), 0.1, 0.25)
    with pytest.raises(ValueError, match="height_m"):
        SceneObject("ball", "pink", (0.0, 0.0), 0.04, 0.2)
    rng = np.random.default_rng(0)
    with pytest.raises(ValueError, match="pan_rad"):
        render((0.0, 0.0, 0.0), 2.0, [], CLEAN, rng)
    with pytest.raises(ValueError, match="camera_pose"):
        render((0.0, 0.0), 0.0, [], CLEAN, rng)
    with pytest.raises(ValueError, match="SceneObject"):
        render((0.0, 0.0, 0.0), 0.0, [("ball", 1.0, 0.0)], CLEAN, rng)
    with pytest.raises(ValueError, match="size_measure"):
        ColourClass((0, 0, 0), (10, 255, 255), 0.1, "perimeter")
