"""Timing of the MRCLAM replay (issue 7): a full Dataset 6 (900 s, five robots) in-process.

Prints the process CPU time (``time.process_time``: wall time is noisy on a shared machine) of
loading the data set, and of replaying all of it at the default 0.02 s tick (45,000 ticks) with
each localizer alone and cooperative (the particle filter and CFS-GA also from an unknown start,
issue 19), with the default self-calibrating camera, plus the mean position RMSE so that a
speed-up that breaks the filter shows. Target of the issues: the particle filter with five robots
under 60 s, known and unknown start.
One core: BLAS is limited to one thread before numpy loads.

Usage: python benchmarks/bench_mrclam.py [DATASET_FOLDER] [ALGORITHM ...]
(default ../shared/data/mrclam/MRCLAM_Dataset6 and pf ekf cfsga dr)
"""

from __future__ import annotations

import os

os.environ.setdefault("OMP_NUM_THREADS", "1")
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")
os.environ.setdefault("MKL_NUM_THREADS", "1")

import itertools
import sys
import time
from pathlib import Path

import numpy as np

from swarmloc.deploy.lab.replay.mrclam import GLOBAL_ALGORITHMS, ReplayConfig, run_replay, score
from swarmloc.world.replay.mrclam import load_dataset

DEFAULT = Path(__file__).resolve().parents[1].parent / "shared/data/mrclam/MRCLAM_Dataset6"
TARGET_S = 60.0


def main(argv: list[str]) -> int:
    folder = Path(argv[0]) if argv else DEFAULT
    algorithms = argv[1:] or ["pf", "ekf", "cfsga", "dr"]
    if not (folder / "Barcodes.dat").is_file():
        print(f"no MRCLAM data set at {folder}; give its folder as the first argument")
        return 2
    t0 = time.process_time()
    dataset = load_dataset(folder)
    print(f"load {dataset.name}: {time.process_time() - t0:.2f} s CPU")
    failed = False
    for algorithm in algorithms:
        starts = [("known", {})]
        if algorithm in GLOBAL_ALGORITHMS:  # and from nowhere (the PF with its recovery)
            starts.append(("unknown", {"recovery": True} if algorithm == "pf" else {}))
        for (start, params), cooperative in itertools.product(starts, (False, True)):
            config = ReplayConfig(algorithm=algorithm, cooperative=cooperative, start=start,
                                  params=params)
            result = run_replay(dataset, config)
            rmse = np.mean([s["position_rmse_m"] for s in score(result).values()])
            ticks = len(result.times_s)
            line = (f"{config.label:25s} {len(result.robot_ids)} robots x {ticks} ticks "
                    f"({result.times_s[-1] - result.times_s[0] + config.dt_s:.0f} s): "
                    f"{result.cpu_s:6.1f} s CPU ({result.cpu_s / ticks * 1e3:.2f} ms/tick), "
                    f"mean position RMSE {rmse:.3f} m")
            if algorithm == "pf":
                ok = result.cpu_s < TARGET_S
                failed |= not ok
                line += f"  [target < {TARGET_S:.0f} s: {'met' if ok else 'MISSED'}]"
            print(line, flush=True)
    return 1 if failed else 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1:]))
