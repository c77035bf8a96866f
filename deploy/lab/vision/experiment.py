"""Seed 004's experiments through the experiment engine: the vision family's hooks, the table
of runs, and the detection accuracy.

A spec with ``family = "vision"`` (shipped: ``deploy/experiments/vision.toml``) runs vision
scenarios (``deploy/scenarios/vision/``) with :func:`~swarmloc.deploy.lab.vision.runner.run_vision`,
replication ``r`` with seed ``seed + r`` (the run's seed draws its layout, world and brains; it is
no scenario key). This module is the family's entry in
:data:`swarmloc.families.FAMILIES` (its entry's ``experiment``): :func:`settings`, :func:`run_job`,
:func:`columns` and :func:`row`. Columns: the setting (experiment, group, setting, scenario,
sharing, seed, replication, one column per grid key), the run's measures
(:data:`METRIC_COLUMNS`, as :func:`~swarmloc.deploy.lab.vision.runner.run_vision` returns them),
wall_s and config_hash.

:func:`summarize` gives one row per scenario and sharing mode; :func:`write_csv` /
:func:`read_csv` keep the report's ``results.csv`` (:data:`COLUMNS`, one row per run).
:func:`detection_accuracy` measures the agent's colour-blob detection against the renderer's
ground truth (also printed by ``benchmarks/bench_vision_detection.py``), :func:`frame_costs` what
a frame costs. The report template is :mod:`swarmloc.deploy.lab.vision.report`.
"""

from __future__ import annotations

import csv
import dataclasses
import hashlib
import json
import math
import time
from pathlib import Path

import numpy as np

from swarmloc.agents.vision.brain import decode_image, detections_from_blobs
from swarmloc.agents.vision.detection import detect_blobs
from swarmloc.config import ConfigError
from swarmloc.deploy.lab.experiment import ExperimentSpec, Job, Setting, setting_grid
from swarmloc.deploy.lab.vision.runner import load_vision_scenario, run_vision
from swarmloc.world.vision.camera import OBJECT_KINDS, CameraParams, make_object, project, render
from swarmloc.world.vision.world import (
    VisionWorldConfig,
    encode_image,
)

# -- the report's rows --------------------------------------------------------------------------

#: The columns of one run in the report's ``results.csv`` (``experiment``: 1, 2 or 3 of §IV).
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
    "pair01_err_median_m",
    "teammate_known_fraction",
    "ball_err_median_m",
    "ball_known_fraction",
    "blind_ball_first_s",
    "blind_relayed_ball_err_median_m",
    "ball_angle_end_deg",
    "heading_resolved_fraction",
    "robots",
    "bad_images",
    "bad_payloads",
    "payloads",
    "sim_s",
    "cpu_s",
]

# -- the engine's hooks -------------------------------------------------------------------------

#: No scenario key carries the seed: :func:`run_job` passes ``job.seed`` to ``run_vision``.
SEED_KEY = None
#: The setting's description, before the grid keys.
LEAD_COLUMNS = ("experiment", "group", "setting", "scenario", "sharing", "seed", "replication")
#: The run's measures, after the grid keys.
METRIC_COLUMNS = (*(c for c in COLUMNS if c not in ("experiment", "scenario", "sharing", "seed")),
                  "wall_s", "config_hash")


def columns(spec: ExperimentSpec) -> list[str]:
    """The header of a vision results file."""
    return [*LEAD_COLUMNS, *spec.grid_keys(), *METRIC_COLUMNS]


def _config_hash(scenario) -> str:
    blob = json.dumps(scenario.to_dict(), sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(blob.encode()).hexdigest()[:12]


def settings(spec: ExperimentSpec) -> list[Setting]:
    """Every setting of a vision spec, each scenario loaded and validated once (a group's
    ``duration_s`` becomes ``setup.duration_s``); an error names the group and the setting."""
    out = []
    for g in spec.group:
        for scenario_name, sid, grid, overrides in setting_grid(g):
            if g.duration_s is not None:
                overrides.append(f"setup.duration_s={json.dumps(float(g.duration_s))}")
            try:
                scenario = load_vision_scenario(scenario_name, overrides)
            except (ConfigError, ValueError, TypeError) as exc:
                raise ConfigError(f"experiment '{spec.name}', group '{g.name}', "
                                  f"setting '{sid}': {exc}") from None
            ticks = max(1, round(scenario.setup.duration_s / scenario.world.tick_s))
            n = scenario.setup.robots
            out.append(Setting(
                sid, g.name, scenario_name, tuple(overrides), grid, _config_hash(scenario), n,
                scenario.setup.duration_s, "sharing" if scenario.agent.sharing else "no-sharing",
                cost=n * n * ticks))
    return out


def run_job(job: Job) -> dict:
    """One seeded run of a vision setting; the measures of ``run_vision`` and wall_s."""
    import cv2

    cv2.setNumThreads(1)
    t0 = time.perf_counter()
    metrics, _ = run_vision(load_vision_scenario(job.scenario, list(job.overrides)), job.seed)
    return {**metrics, "wall_s": round(time.perf_counter() - t0, 3)}


def row(spec: ExperimentSpec, job: Job, out: dict) -> list:
    """One results row, in :func:`columns` order (None written as an empty cell)."""
    grid = dict(job.grid)
    lead = {"experiment": spec.name, "group": job.group, "setting": job.setting,
            "scenario": job.scenario, "sharing": out["sharing"], "seed": job.seed,
            "replication": job.replication}
    values = {**out, "config_hash": job.config_hash}
    return [*(lead[c] for c in LEAD_COLUMNS), *(grid.get(k) for k in spec.grid_keys()),
            *(values.get(c) for c in METRIC_COLUMNS)]


_TEXT_COLUMNS = ("scenario", "variant", "goals", "true_goals", "group", "setting")


def write_csv(rows: list[dict], path: str | Path, extra_columns=()) -> None:
    """The report's ``results.csv``: :data:`COLUMNS` (then ``extra_columns``) of each row."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    columns = [*COLUMNS, *extra_columns]
    with path.open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=columns, lineterminator="\n")
        writer.writeheader()
        for row in rows:
            writer.writerow({k: ("" if row.get(k) is None else row.get(k)) for k in columns})


def read_csv(path: str | Path, text_columns=_TEXT_COLUMNS) -> list[dict]:
    """Rows of :func:`write_csv` or of a vision results file of the engine, with numbers and
    booleans parsed back (``text_columns`` stay text)."""
    rows = []
    with Path(path).open(newline="") as handle:
        for raw in csv.DictReader(handle):
            row: dict = {}
            for k, v in raw.items():
                if k in text_columns:
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
                "ball_angle_end_deg": median("ball_angle_end_deg"),
                "heading_resolved_fraction": median("heading_resolved_fraction"),
                "pair01_err_median_m": median("pair01_err_median_m"),
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
