"""Speed and accuracy of the vision pipeline: world/vision/camera.py render + agents/vision/detection.py detect.

Seed 004 §II (size-based distance with f = 190 px). Prints:

1. milliseconds per frame of ``render`` + ``detect_blobs`` (median over 500 frames; a scene with a
   ball, two teammates, two rivals and a beacon; default noise and lighting), on one core.
   Target of issue 5: within 5 ms.
2. detection rate and median bearing and relative distance errors of the ball over distance bins,
   200 seeded placements per bin, the ball wholly in the image, default noise and lighting;
3. the same at 1-2 m with a nearer teammate hiding part of the ball, by visible fraction.

Usage: python benchmarks/bench_vision.py
"""

from __future__ import annotations

import os

# One core: set before numpy and OpenCV start their thread pools.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import math
import time

import cv2
import numpy as np

from swarmloc.agents.vision.detection import detect_blobs
from swarmloc.world.vision.camera import CameraParams, make_object, project, render

N_FRAMES = 500
N_PLACEMENTS = 200
DISTANCE_BINS_M = [(0.3, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 4.0)]
VISIBLE_BINS = [(0.75, 1.0), (0.5, 0.75), (0.25, 0.5), (0.0, 0.25)]


def time_frames(params: CameraParams, rng: np.random.Generator) -> tuple[float, float, float]:
    """Median ms per frame of render, detect, and both, over N_FRAMES frames."""
    pose = (0.0, 0.0, 0.0)
    objects = [
        make_object("ball", 1.5, 0.1),
        make_object("teammate", 2.0, 0.6),
        make_object("teammate", 2.5, -0.5),
        make_object("rival", 1.2, -0.4),
        make_object("rival", 3.0, 0.3),
        make_object("beacon", 3.5, 1.2),
    ]
    assert len(detect_blobs(render(pose, 0.0, objects, params, rng), params)) == 6
    render_s, detect_s = [], []
    for _ in range(N_FRAMES):
        t0 = time.perf_counter()
        image = render(pose, 0.0, objects, params, rng)
        t1 = time.perf_counter()
        detect_blobs(image, params)
        t2 = time.perf_counter()
        render_s.append(t1 - t0)
        detect_s.append(t2 - t1)
    render_ms, detect_ms = np.array(render_s) * 1e3, np.array(detect_s) * 1e3
    return (
        float(np.median(render_ms)),
        float(np.median(detect_ms)),
        float(np.median(render_ms + detect_ms)),
    )


def _random_view(rng: np.random.Generator):
    pose = (rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-math.pi, math.pi))
    return pose, rng.uniform(-1.0, 1.0)


def _place(pose, pan_rad, bearing_rad, distance_m):
    yaw_rad = pose[2] + pan_rad + bearing_rad
    return pose[0] + distance_m * math.cos(yaw_rad), pose[1] + distance_m * math.sin(yaw_rad)


def _wholly_in_view(pose, pan_rad, obj, params: CameraParams) -> bool:
    u_px, v_px, radius_px, _ = project(pose, pan_rad, obj, params)
    return (
        u_px - radius_px >= 0
        and u_px + radius_px <= params.width_px - 1
        and v_px + radius_px <= params.height_px - 1
    )


def _errors(blob, bearing_rad, distance_m):
    bearing_err_deg = abs(math.degrees(blob.bearing_rad - bearing_rad))
    return bearing_err_deg, abs(blob.distance_m / distance_m - 1.0)


def _row(label: str, n: int, found: list[tuple[float, float]]) -> str:
    if not found:
        return f"{label:>12} {n:5d} {0.0:8.1f} {'-':>10} {'-':>10}"
    bearing, distance = np.median(np.array(found), axis=0)
    rate = 100.0 * len(found) / n
    return f"{label:>12} {n:5d} {rate:8.1f} {bearing:10.3f} {100 * distance:10.2f}"


def accuracy_by_distance(params: CameraParams, rng: np.random.Generator) -> list[str]:
    rows = []
    for lo_m, hi_m in DISTANCE_BINS_M:
        found, n = [], 0
        while n < N_PLACEMENTS:
            pose, pan_rad = _random_view(rng)
            bearing_rad = rng.uniform(-params.half_fov_rad, params.half_fov_rad)
            distance_m = rng.uniform(lo_m, hi_m)
            ball = make_object("ball", *_place(pose, pan_rad, bearing_rad, distance_m))
            if not _wholly_in_view(pose, pan_rad, ball, params):
                continue
            n += 1
            blobs = detect_blobs(render(pose, pan_rad, [ball], params, rng), params)
            pink = [b for b in blobs if b.colour == "pink"]
            if len(pink) == 1:
                found.append(_errors(pink[0], bearing_rad, distance_m))
        rows.append(_row(f"{lo_m:.1f}-{hi_m:.1f} m", n, found))
    return rows


def accuracy_by_occlusion(params: CameraParams, rng: np.random.Generator) -> list[str]:
    clean = CameraParams(noise_sigma=0.0, gain_min=1.0, gain_max=1.0)
    counts = {b: 0 for b in VISIBLE_BINS}
    found = {b: [] for b in VISIBLE_BINS}
    while min(counts.values()) < N_PLACEMENTS:
        pose, pan_rad = _random_view(rng)
        bearing_rad = rng.uniform(-0.6 * params.half_fov_rad, 0.6 * params.half_fov_rad)
        distance_m = rng.uniform(1.0, 2.0)
        ball = make_object("ball", *_place(pose, pan_rad, bearing_rad, distance_m))
        if not _wholly_in_view(pose, pan_rad, ball, params):
            continue
        # A teammate halfway, its edge somewhere across the ball's width.
        ball_half_angle_rad = math.atan(0.04 / distance_m)
        robot_half_angle_rad = math.atan(0.10 / (distance_m / 2))
        side = rng.choice([-1.0, 1.0])
        edge_rad = bearing_rad + side * rng.uniform(-1.0, 1.0) * ball_half_angle_rad
        robot_bearing_rad = edge_rad + side * robot_half_angle_rad
        robot = make_object("teammate", *_place(pose, pan_rad, robot_bearing_rad, distance_m / 2))
        seen = np.random.default_rng(0)
        alone = detect_blobs(render(pose, pan_rad, [ball], clean, seen), clean)
        hidden = detect_blobs(render(pose, pan_rad, [ball, robot], clean, seen), clean)
        area_alone = sum(b.area_px for b in alone if b.colour == "pink")
        area_hidden = sum(b.area_px for b in hidden if b.colour == "pink")
        visible = area_hidden / area_alone if area_alone else 0.0
        for lo, hi in VISIBLE_BINS:
            if lo < visible <= hi or (lo == 0.0 and visible == 0.0):
                if counts[(lo, hi)] >= N_PLACEMENTS:
                    break
                counts[(lo, hi)] += 1
                blobs = detect_blobs(render(pose, pan_rad, [ball, robot], params, rng), params)
                pink = [b for b in blobs if b.colour == "pink"]
                if len(pink) == 1:
                    found[(lo, hi)].append(_errors(pink[0], bearing_rad, distance_m))
                break
    return [
        _row(f"{100 * lo:.0f}-{100 * hi:.0f} %", counts[(lo, hi)], found[(lo, hi)])
        for lo, hi in VISIBLE_BINS
    ]


def main() -> int:
    cv2.setNumThreads(1)
    params = CameraParams()
    rng = np.random.default_rng(20240505)
    render_ms, detect_ms, total_ms = time_frames(params, rng)
    print(
        f"camera {params.width_px}x{params.height_px} px, f = {params.focal_px} px, noise sigma "
        f"{params.noise_sigma}, gain {params.gain_min}-{params.gain_max}; one core"
    )
    print(
        f"render {render_ms:.3f} ms + detect {detect_ms:.3f} ms = {total_ms:.3f} ms per frame "
        f"(median of {N_FRAMES}; 6 objects; target 5 ms)"
    )
    header = f"{'':>12} {'n':>5} {'rate %':>8} {'bearing °':>10} {'dist err %':>10}"
    print("\nball detection by distance (median absolute errors of detected balls)")
    print(header.replace(" " * 12, f"{'distance':>12}", 1))
    for row in accuracy_by_distance(params, rng):
        print(row)
    print("\nball at 1-2 m partly hidden by a teammate, by visible fraction of its area")
    print(header.replace(" " * 12, f"{'visible':>12}", 1))
    for row in accuracy_by_occlusion(params, rng):
        print(row)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
