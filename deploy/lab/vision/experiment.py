"""Seed 004's experiments, repeated: runs over seeds and sharing modes, their table, and the
detection accuracy; the ``swarmloc vision-experiment`` command.

:func:`run_experiments` repeats :func:`~swarmloc.deploy.lab.vision.runner.run_vision` over seeds
and both sharing modes in a pool of spawned processes; :func:`write_csv` / :func:`read_csv` keep
the rows and :func:`summarize` gives one row per scenario and mode. :func:`detection_accuracy`
measures the agent's colour-blob detection against the renderer's ground truth (also printed by
``benchmarks/bench_vision_detection.py``), :func:`frame_costs` what a frame costs. :func:`main`
runs the command and, with ``--report``, writes the page of
:mod:`swarmloc.deploy.lab.vision.report`.
"""

from __future__ import annotations

import csv
import dataclasses
import math
import multiprocessing
import os
import time
from concurrent.futures import ProcessPoolExecutor
from pathlib import Path

import numpy as np

from swarmloc.agents.vision.brain import decode_image, detections_from_blobs
from swarmloc.agents.vision.detection import detect_blobs
from swarmloc.config import ConfigError
from swarmloc.deploy.lab.vision.runner import EXPERIMENTS, load_vision_scenario, run_vision
from swarmloc.world.vision.camera import OBJECT_KINDS, CameraParams, make_object, project, render
from swarmloc.world.vision.world import (
    VisionWorldConfig,
    encode_image,
)

# -- experiments --------------------------------------------------------------------------------

COLUMNS = [
    "experiment",
    "scenario",
    "sharing",
    "seed",
    "variant",
    "collisions",
    "contact_s",
    "obstacle_collisions",
    "goals_correct",
    "goals",
    "true_goals",
    "reach_s_0",
    "reach_s_1",
    "all_reached",
    "all_reached_s",
    "teammate_err_median_m",
    "teammate_err_p90_m",
    "teammate_known_fraction",
    "ball_err_median_m",
    "ball_known_fraction",
    "blind_ball_first_s",
    "blind_relayed_ball_err_median_m",
    "bad_images",
    "bad_payloads",
    "payloads",
    "sim_s",
    "cpu_s",
]


def _job(args: tuple[str, int, bool, tuple[str, ...]]) -> dict:
    import cv2

    cv2.setNumThreads(1)
    name, seed, sharing, overrides = args
    metrics, _ = run_vision(load_vision_scenario(name, list(overrides)), seed, sharing)
    return metrics


def run_experiments(
    names: list[str],
    runs: int,
    seed: int = 1,
    sharing_modes=(True, False),
    workers: int = 2,
    overrides: tuple[str, ...] = (),
    progress=None,
) -> list[dict]:
    """Every (scenario, sharing mode, seed ``seed .. seed + runs - 1``) run; rows in job order."""
    for name in names:
        load_vision_scenario(name, list(overrides))  # refuse a bad name or override up front
    jobs = [
        (name, seed + r, sharing, tuple(overrides))
        for name in names
        for sharing in sharing_modes
        for r in range(runs)
    ]
    if workers <= 1:
        rows = []
        for job in jobs:
            rows.append(_job(job))
            if progress:
                progress(len(rows), len(jobs))
        return rows
    saved = {k: os.environ.get(k) for k in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS")}
    os.environ.update({k: "1" for k in saved})
    try:
        with ProcessPoolExecutor(
            max_workers=workers, mp_context=multiprocessing.get_context("spawn")
        ) as pool:
            rows = []
            for row in pool.map(_job, jobs, chunksize=1):
                rows.append(row)
                if progress:
                    progress(len(rows), len(jobs))
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v
    return rows


_TEXT_COLUMNS = ("scenario", "variant", "goals", "true_goals")


def write_csv(rows: list[dict], path: str | Path) -> None:
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=COLUMNS, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in COLUMNS})


def read_csv(path: str | Path) -> list[dict]:
    """Rows of :func:`write_csv`, with numbers and booleans parsed back."""
    rows = []
    with Path(path).open(newline="") as handle:
        for raw in csv.DictReader(handle):
            row: dict = {}
            for k, v in raw.items():
                if k in _TEXT_COLUMNS:
                    row[k] = v
                elif v == "":
                    row[k] = None
                elif v in ("True", "False"):
                    row[k] = v == "True"
                else:
                    try:
                        row[k] = int(v)
                    except ValueError:
                        try:
                            row[k] = float(v)
                        except ValueError:
                            row[k] = v
            rows.append(row)
    return rows


def summarize(rows: list[dict]) -> list[dict]:
    """One line per (scenario, sharing): rates, medians and interquartile ranges."""
    out = []
    keys = sorted({(r["scenario"], r["sharing"]) for r in rows}, key=lambda k: (k[0], not k[1]))
    for scenario, sharing in keys:
        group = [r for r in rows if r["scenario"] == scenario and r["sharing"] == sharing]
        n = len(group)

        def values(key, group=group):
            return [r[key] for r in group if r[key] is not None]

        def median(key, values=values):
            v = values(key)
            return float(np.median(v)) if v else None

        out.append(
            {
                "scenario": scenario,
                "sharing": sharing,
                "runs": n,
                "runs_with_collision": sum(r["collisions"] > 0 for r in group),
                "collisions_mean": float(np.mean([r["collisions"] for r in group])),
                "contact_s_median": median("contact_s"),
                "obstacle_collision_runs": sum(r["obstacle_collisions"] > 0 for r in group),
                "goals_correct": sum(bool(r["goals_correct"]) for r in group),
                "all_reached": sum(bool(r["all_reached"]) for r in group),
                "all_reached_s_median": median("all_reached_s"),
                "reach_s_median": (
                    float(np.median(values("reach_s_0") + values("reach_s_1")))
                    if values("reach_s_0") + values("reach_s_1")
                    else None
                ),
                "teammate_err_median_m": median("teammate_err_median_m"),
                "teammate_err_p90_m": median("teammate_err_p90_m"),
                "teammate_known_fraction": median("teammate_known_fraction"),
                "ball_err_median_m": median("ball_err_median_m"),
                "blind_ball_runs": sum(r["blind_ball_first_s"] is not None for r in group),
                "blind_ball_first_s": median("blind_ball_first_s"),
                "blind_relayed_ball_err_median_m": median("blind_relayed_ball_err_median_m"),
                "bad_images": sum(r["bad_images"] for r in group),
                "bad_payloads": sum(r["bad_payloads"] for r in group),
                "cpu_s_mean": float(np.mean([r["cpu_s"] for r in group])),
                "variants": "/".join(
                    f"{v}:{sum(r['variant'] == v for r in group)}"
                    for v in sorted({r["variant"] for r in group})
                    if v
                ),
            }
        )
    return out


# -- detection accuracy -------------------------------------------------------------------------

DETECTION_DISTANCE_BINS_M = ((0.3, 1.0), (1.0, 2.0), (2.0, 3.0), (3.0, 4.0))
DETECTION_VISIBLE_BINS = ((0.75, 1.0), (0.5, 0.75), (0.25, 0.5), (0.0, 0.25))
_KIND_COLOUR = {"ball": "pink", "teammate": "yellow", "obstacle": "orange", "beacon": "blue"}


def _view(rng):
    return (rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-math.pi, math.pi)), rng.uniform(
        -1, 1
    )


def _place(pose, pan, bearing, distance):
    yaw = pose[2] + pan + bearing
    return pose[0] + distance * math.cos(yaw), pose[1] + distance * math.sin(yaw)


def _wholly_in_view(pose, pan, obj, camera: CameraParams) -> bool:
    u, v, r, _ = project(pose, pan, obj, camera)
    if obj.is_sphere:
        return (
            u - r >= 0
            and u + r <= camera.width_px - 1
            and v - r >= 0
            and v + r <= camera.height_px - 1
        )
    depth = camera.focal_px * obj.radius_m / r
    scale = camera.focal_px / depth
    top = camera.cy_px + scale * (camera.camera_height_m - obj.height_m)
    bottom = camera.cy_px + scale * camera.camera_height_m
    return (
        u - r >= 0 and u + r <= camera.width_px - 1 and top >= 0 and bottom <= camera.height_px - 1
    )


def _agent_sees(image, pose_pan, camera, world_cfg):
    """Blobs and usable detections of a frame as the agent gets it (encoded, decoded)."""
    payload = encode_image(image, world_cfg.image_format, world_cfg.jpeg_quality)
    decoded = decode_image(payload, camera)
    blobs = detect_blobs(decoded, camera)
    return blobs, detections_from_blobs(blobs, 0, 0.0, pose_pan, camera)


class _Tally:
    """Counts and errors of one detection bin."""

    def __init__(self) -> None:
        self.n = self.blob_hits = 0
        self.used: list[tuple[float, float]] = []  # (bearing error deg, relative distance error)
        self.raw: list[float] = []  # relative distance error of the largest blob, used or not

    def add(self, blobs, used, colour: str, bearing: float, distance: float) -> None:
        self.n += 1
        raw = [b for b in blobs if b.colour == colour]
        if raw:
            self.blob_hits += 1
            self.raw.append(abs(raw[0].distance_m / distance - 1.0))
        mine = [d for d in used if d.colour == colour]
        if len(mine) == 1:
            d = mine[0]
            self.used.append(
                (
                    abs(math.degrees(float(d.bearing_rad) - bearing)),
                    abs(d.distance_m / distance - 1),
                )
            )

    def row(self, kind: str, label: str) -> tuple:
        n = max(self.n, 1)
        bearing = dist = None
        if self.used:
            bearing, dist = (float(v) for v in np.median(np.array(self.used), axis=0))
            dist *= 100.0
        raw = 100.0 * float(np.median(self.raw)) if self.raw else None
        return (
            kind,
            label,
            self.n,
            100.0 * self.blob_hits / n,
            100.0 * len(self.used) / n,
            bearing,
            dist,
            raw,
        )


def detection_accuracy(
    n_per_bin: int = 200, seed: int = 20240505, world: VisionWorldConfig | None = None
) -> dict:
    """Detection rate and errors over distance (every kind) and over partial occlusion (ball and
    teammate behind a nearer robot), on rendered frames through the agent's whole pipeline
    (JPEG encode, decode, blobs, usable detections), default noise and lighting.

    Returns ``{"distance": rows, "occlusion": rows}``; a row is ``(kind, bin label, n, blob
    rate %, used rate %, median bearing error deg, median distance error %, median distance
    error % of the raw blob)``: the errors are those of the *used* detections (``None`` if none);
    the blob rate and the raw error count the largest blob of the colour, used or not. Bearing
    is in the camera frame.
    """
    world = world or VisionWorldConfig()
    camera = world.camera
    rng = np.random.default_rng(seed)
    distance_rows = []
    for kind in ("ball", "teammate", "obstacle", "beacon"):
        colour = _KIND_COLOUR[kind]
        for lo, hi in DETECTION_DISTANCE_BINS_M:
            tally = _Tally()
            while tally.n < n_per_bin:
                pose, pan = _view(rng)
                bearing = rng.uniform(-camera.half_fov_rad, camera.half_fov_rad)
                distance = rng.uniform(lo, hi)
                obj = make_object(kind, *_place(pose, pan, bearing, distance))
                if not _wholly_in_view(pose, pan, obj, camera):
                    continue
                blobs, used = _agent_sees(render(pose, pan, [obj], camera, rng), 0.0, camera, world)
                tally.add(blobs, used, colour, bearing, distance)
            distance_rows.append(tally.row(kind, f"{lo:.1f}-{hi:.1f} m"))
    occlusion_rows = []
    clean = dataclasses.replace(camera, noise_sigma=0.0, gain_min=1.0, gain_max=1.0)
    for kind in ("ball", "teammate"):
        colour = _KIND_COLOUR[kind]
        tallies = {b: _Tally() for b in DETECTION_VISIBLE_BINS}
        radius = OBJECT_KINDS[kind].radius_m
        while min(t.n for t in tallies.values()) < n_per_bin:
            pose, pan = _view(rng)
            bearing = rng.uniform(-0.5 * camera.half_fov_rad, 0.5 * camera.half_fov_rad)
            distance = rng.uniform(1.0, 2.0)
            target = make_object(kind, *_place(pose, pan, bearing, distance))
            if not _wholly_in_view(pose, pan, target, camera):
                continue
            # An orange robot halfway, its edge somewhere across the target's width.
            half = math.atan(radius / distance)
            blocker_half = math.atan(0.10 / (distance / 2))
            side = rng.choice([-1.0, 1.0])
            edge = bearing + side * rng.uniform(-1.0, 1.0) * half
            blocker = make_object(
                "rival", *_place(pose, pan, edge + side * blocker_half, distance / 2)
            )
            # Visible fraction: the target's pixels with and without the blocker (no noise).
            u_px, v_px, _, _ = project(pose, pan, target, clean)
            alone = render(pose, pan, [target], clean, np.random.default_rng(0))
            hidden = render(pose, pan, [target, blocker], clean, np.random.default_rng(0))
            colour_bgr = alone[round(v_px), round(u_px)]
            area_alone = int(np.all(alone == colour_bgr, axis=2).sum())
            area_hidden = int(np.all(hidden == colour_bgr, axis=2).sum())
            visible = area_hidden / area_alone if area_alone else 0.0
            for b in DETECTION_VISIBLE_BINS:
                if b[0] < visible <= b[1] or (b[0] == 0.0 and visible == 0.0):
                    if tallies[b].n < n_per_bin:
                        image = render(pose, pan, [target, blocker], camera, rng)
                        blobs, used = _agent_sees(image, 0.0, camera, world)
                        tallies[b].add(blobs, used, colour, bearing, distance)
                    break
        for b in DETECTION_VISIBLE_BINS:
            occlusion_rows.append(tallies[b].row(kind, f"{100 * b[0]:.0f}-{100 * b[1]:.0f} %"))
    return {"distance": distance_rows, "occlusion": occlusion_rows}


def detection_table(result: dict) -> str:
    """Markdown tables of :func:`detection_accuracy`."""

    def fmt(v, spec):
        return "-" if v is None else format(v, spec)

    columns = (
        "| n | blob found % | used % | bearing error ° | distance error % | "
        "distance error % of the raw blob |"
    )
    lines = ["| object | distance " + columns, "|---" * 8 + "|"]
    for kind, label, n, blob, used, bearing, dist, raw in result["distance"]:
        lines.append(
            f"| {kind} | {label} | {n} | {blob:.1f} | {used:.1f} | {fmt(bearing, '.3f')} | "
            f"{fmt(dist, '.2f')} | {fmt(raw, '.2f')} |"
        )
    lines += ["", "| object | visible at 1-2 m " + columns, "|---" * 8 + "|"]
    for kind, label, n, blob, used, bearing, dist, raw in result["occlusion"]:
        lines.append(
            f"| {kind} | {label} | {n} | {blob:.1f} | {used:.1f} | {fmt(bearing, '.3f')} | "
            f"{fmt(dist, '.2f')} | {fmt(raw, '.2f')} |"
        )
    return "\n".join(lines)


#: Scene timed by :func:`frame_costs` (the scene of ``benchmarks/bench_vision.py``).
TIMING_SCENE = (
    ("ball", 1.5, 0.1),
    ("teammate", 2.0, 0.6),
    ("teammate", 2.5, -0.5),
    ("rival", 1.2, -0.4),
    ("rival", 3.0, 0.3),
    ("beacon", 3.5, 1.2),
)


def frame_costs(n_frames: int = 500, seed: int = 20240505) -> tuple[float, float]:
    """Median CPU ms (``time.process_time``) per frame of render + detect, and of the path a
    frame takes to the agent: render + JPEG encode + decode + detect + the agent's detections;
    :data:`TIMING_SCENE`, default noise and lighting, this process's threads."""
    world = VisionWorldConfig()
    camera = world.camera
    rng = np.random.default_rng(seed)
    objects = [make_object(kind, x, y) for kind, x, y in TIMING_SCENE]
    pose = (0.0, 0.0, 0.0)
    short, full = [], []
    for _ in range(n_frames):
        t0 = time.process_time()
        detect_blobs(render(pose, 0.0, objects, camera, rng), camera)
        t1 = time.process_time()
        image = render(pose, 0.0, objects, camera, rng)
        payload = encode_image(image, world.image_format, world.jpeg_quality)
        blobs = detect_blobs(decode_image(payload, camera), camera)
        detections_from_blobs(blobs, 0, 0.0, 0.0, camera)
        t2 = time.process_time()
        short.append(t1 - t0)
        full.append(t2 - t1)
    return float(np.median(short)) * 1e3, float(np.median(full)) * 1e3


#: Sensitivity runs of the report (sharing on): what breaks the parallel-start assumption.
SENSITIVITY = (
    (
        (
            "start headings drawn within ±0.15 rad instead of ±0.03 rad: the brains' assumption of "
            "parallel bodies at the start is off by up to 0.3 rad"
        ),
        EXPERIMENTS,
        ("setup.heading_jitter_rad=0.15",),
    ),
    (
        (
            "the same, with the relative heading from the two objects both robots see (Fig. 2, "
            '`agent.relative_heading = "objects"`; experiment 2, where both see ball and obstacle)'
        ),
        ("vision-exp2",),
        ("setup.heading_jitter_rad=0.15", 'agent.relative_heading="objects"'),
    ),
)


# -- command line -------------------------------------------------------------------------------


def main(args) -> int:
    """``swarmloc vision-experiment``: run, print the summary, optionally write CSV and report."""
    import json
    import sys

    from swarmloc.deploy.lab.vision.report import summary_table, write_report

    if args.runs < 1:
        raise ConfigError(f"--runs: must be >= 1, got {args.runs}")
    names = list(EXPERIMENTS) if args.name == "all" else [args.name]
    modes = (True, False) if args.both else ((False,) if args.no_sharing else (True,))
    t0 = time.perf_counter()

    def progress(done, total):
        if done == total or done % max(1, total // 10) == 0:
            print(
                f"  {done}/{total} runs ({time.perf_counter() - t0:.0f} s)",
                file=sys.stderr,
                flush=True,
            )

    rows = run_experiments(
        names, args.runs, args.seed, modes, args.workers, tuple(args.set), progress=progress
    )
    summary = summarize(rows)
    if args.json:
        print(json.dumps(summary, indent=1))
    else:
        print(summary_table(summary))
    if args.csv:
        write_csv(rows, args.csv)
        print(f"rows: {args.csv}", file=sys.stderr)
    if args.report:
        import cv2

        cv2.setNumThreads(1)  # the frame timing below is per core
        sensitivity = []
        if args.name == "all":
            n_sens = min(args.runs, 10)
            for what, names_sens, overrides in SENSITIVITY:
                sens_rows = run_experiments(
                    list(names_sens),
                    n_sens,
                    args.seed,
                    (True,),
                    args.workers,
                    tuple(args.set) + overrides,
                )
                sets = " ".join(f"--set '{o}'" for o in (*args.set, *overrides))
                command = (
                    f"swarmloc vision-experiment {names_sens[0] if len(names_sens) == 1 else 'all'}"
                    f" --runs {n_sens} --seed {args.seed} {sets}"
                )
                sensitivity.append((what, command, sens_rows))
        detection = detection_accuracy(args.detection_n)
        render_ms, path_ms = frame_costs()
        timing = (
            f"Cost per frame (median CPU of 500 frames, 6 objects, this machine): render + detect "
            f"{render_ms:.2f} ms (target 5 ms); render + JPEG encode + decode + detect + the "
            f"agent's detections {path_ms:.2f} ms."
        )
        cli = f"swarmloc vision-experiment {args.name} --runs {args.runs} --seed {args.seed}"
        cli += " --both" if args.both else (" --no-sharing" if args.no_sharing else "")
        cli += "".join(f" --set {s}" for s in args.set)
        cli += f" --report {args.report}"
        readme = write_report(
            args.report,
            rows,
            detection,
            [cli, "python benchmarks/bench_vision_detection.py   # detection table and timing"],
            timing=timing,
            sensitivity=sensitivity,
        )
        print(f"report: {readme}", file=sys.stderr)
    return 0
