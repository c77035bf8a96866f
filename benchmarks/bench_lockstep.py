"""Lockstep tick rate of a swarm of real processes over Zenoh (issue: core swarm).

Runs `swarmloc run` (router + world-server + N agent processes) for each swarm size and prints the
ticks per second and the tick time percentiles the world-server measured. Usage:

    python benchmarks/bench_lockstep.py [--robots 10 50 100] [--duration-s 30] [--realtime]
"""

from __future__ import annotations

import argparse
import json
import subprocess
import sys
import tempfile
from pathlib import Path


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 50, 100])
    parser.add_argument("--duration-s", type=float, default=30.0)
    parser.add_argument("--scenario", default="ES3")
    parser.add_argument("--realtime", action="store_true")
    args = parser.parse_args()
    print(f"{'robots':>6} {'mode':>9} {'ticks':>6} {'ticks/s':>8} {'p50 ms':>7} {'p99 ms':>7} {'late':>5} {'overruns':>8}")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.robots:
            run = f"bench{n}"
            cmd = [sys.executable, "-m", "swarmloc", "run", args.scenario, "--robots", str(n),
                   "--duration-s", str(args.duration_s), "--out", tmp, "--run", run, "--quiet"]
            if args.realtime:
                cmd.append("--realtime")
            proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
            if proc.returncode != 0:
                print(f"{n:>6} failed: {proc.stderr.strip()[-300:]}")
                continue
            t = json.loads((Path(tmp) / run / "results.json").read_text())["transport"]
            mode = "realtime" if args.realtime else "lockstep"
            print(f"{n:>6} {mode:>9} {t['ticks']:>6} {t['ticks_per_s']:>8} {t['tick_ms_p50']:>7} "
                  f"{t['tick_ms_p99']:>7} {t['late_acts']:>5} {t['overruns']:>8}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
