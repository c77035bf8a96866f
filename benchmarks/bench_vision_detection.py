"""Detection accuracy and frame cost of the vision robots' whole image path (seed 004 §II-III).

Prints, on one core:

1. CPU milliseconds per frame (``time.process_time``, median over 500 frames; the scene of
   ``bench_vision.py``: a ball, two teammates, two rivals and a beacon): render + detect (the
   issue's budget: 5 ms), and the path an agent's frame takes: render + JPEG encode (world) +
   decode + detect + the agent's detections (``swarmloc.agents.vision.brain``).
   Also the CPU of one ``VisionBrain.step`` (the agent's whole tick) on experiment 1.
2. ``swarmloc.deploy.lab.vision.experiment.detection_accuracy``: detection rate and median bearing and
   distance errors of every object kind over distance, and of the ball and a teammate partly
   hidden by a nearer robot, against the rendered ground truth (markdown; the same table as in
   ``docs/vision/README.md``).

Usage: python benchmarks/bench_vision_detection.py [--n 200] [--frames 500]
"""

from __future__ import annotations

import os

# One core: set before numpy and OpenCV start their thread pools.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("OMP_NUM_THREADS", "1")

import argparse
import time

import cv2
import numpy as np

from swarmloc.agents.vision.brain import (
    VisionAgentConfig,
    VisionBrain,
)
from swarmloc.deploy.lab.vision.experiment import (
    TIMING_SCENE,
    detection_accuracy,
    detection_table,
    frame_costs,
)
from swarmloc.world.vision.world import RobotStart, VisionWorld, VisionWorldConfig


def brain_step_cost(n_ticks: int) -> float:
    """Median CPU ms of one ``VisionBrain.step`` (decode, detect, localize, navigate) with sharing,
    two robots walking to the ball of experiment 1 (payloads exchanged, not timed)."""
    world = VisionWorld(VisionWorldConfig(robots=(RobotStart(0.0, 0.3), RobotStart(0.0, -0.3))))
    brains = [
        VisionBrain(i, [1 - i], VisionAgentConfig(), world.config.camera, np.random.default_rng(i))
        for i in range(2)
    ]
    costs, payloads = [], [None, None]
    for _ in range(n_ticks):
        observations = world.observe()
        commands = []
        for i, (brain, obs) in enumerate(zip(brains, observations)):
            if payloads[1 - i] is not None:
                brain.receive(1 - i, payloads[1 - i])
            t0 = time.process_time()
            commands.append(brain.step(obs))
            costs.append(time.process_time() - t0)
        payloads = [b.share() for b in brains]
        world.step(commands)
    return float(np.median(costs)) * 1e3


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--n", type=int, default=200, help="placements per accuracy bin")
    parser.add_argument("--frames", type=int, default=500, help="frames timed")
    args = parser.parse_args(argv)
    cv2.setNumThreads(1)
    short_ms, full_ms = frame_costs(args.frames)
    print(
        f"render + detect: {short_ms:.3f} ms CPU per frame (median of {args.frames}; "
        f"{len(TIMING_SCENE)} objects; target 5 ms)"
    )
    print(
        f"render + JPEG encode + decode + detect + agent detections: {full_ms:.3f} ms CPU per frame"
    )
    print(
        f"VisionBrain.step (decode, detect, localize, navigate): {brain_step_cost(60):.3f} ms "
        "CPU (median over 2 robots x 60 ticks of experiment 1)"
    )
    print()
    t0 = time.process_time()
    print(detection_table(detection_accuracy(args.n)))
    print(f"\n({time.process_time() - t0:.1f} s CPU for the accuracy tables)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
