"""Lockstep tick rate of a swarm of real processes over Zenoh (issue: core swarm).

Runs `swarmloc run` (router + world-server + N agent processes) for each swarm size and prints the
ticks per second and the tick time percentiles the world-server measured. With ``--with-floor``
each swarmloc run is paired with a run of the plain-Zenoh floor of the same size
(benchmarks/bench_zenoh_floor.py: a lockstep world and N robots that answer at once, no swarmloc
code), alternating ``--repeat`` times, so that both see the same machine in the same minutes; it
prints each pair and swarmloc's rate as a share of the floor's (``--floor-as-agents``: a floor
whose Zenoh is configured as swarmloc's e-puck agents', bench_zenoh_floor.py --as-agents, instead
of Zenoh's defaults). ``--null-brain`` runs agents that
answer each Sense with a standstill Act (`swarmloc run --null-brains`): what an agent process
costs without its brain. Usage:

    python benchmarks/bench_lockstep.py [--robots 10 50 100] [--duration-s 30] [--realtime]
    python benchmarks/bench_lockstep.py --robots 100 --with-floor --repeat 3
    python benchmarks/bench_lockstep.py --robots 100 --null-brain
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

HERE = Path(__file__).resolve().parent


def swarmloc_run(n: int, scenario: str, duration_s: float, realtime: bool, tmp: str,
                 null_brain: bool = False) -> dict | str:
    """One `swarmloc run`; its transport figures, or the error text if it failed."""
    run = f"bench{n}"
    cmd = [sys.executable, "-m", "swarmloc", "run", scenario, "--robots", str(n),
           "--duration-s", str(duration_s), "--out", tmp, "--run", run, "--quiet"]
    if realtime:
        cmd.append("--realtime")
    if null_brain:
        cmd.append("--null-brains")
    proc = subprocess.run(cmd, capture_output=True, text=True, check=False)
    if proc.returncode != 0:
        return proc.stderr.strip()[-300:]
    return json.loads((Path(tmp) / run / "results.json").read_text())["transport"]


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--robots", type=int, nargs="+", default=[10, 50, 100])
    parser.add_argument("--duration-s", type=float, default=30.0, help="simulated seconds per run")
    parser.add_argument("--scenario", default="ES3")
    parser.add_argument("--realtime", action="store_true")
    parser.add_argument("--with-floor", action="store_true",
                        help="pair each run with a plain-Zenoh floor run of the same size")
    parser.add_argument("--repeat", type=int, default=1, help="runs per size (alternating with the floor)")
    parser.add_argument("--floor-s", type=float, default=15.0, help="wall seconds of each floor run")
    parser.add_argument("--floor-as-agents", action="store_true",
                        help="the floor's Zenoh configured as swarmloc's e-puck agents' (default: Zenoh's)")
    parser.add_argument("--null-brain", action="store_true",
                        help="agents answer with a standstill Act instead of running their brains")
    args = parser.parse_args()
    if args.with_floor and args.realtime:
        parser.error("--with-floor compares lockstep rates; drop --realtime")
    floor_world = None
    if args.with_floor:
        sys.path.insert(0, str(HERE))
        from bench_zenoh_floor import AS_AGENTS, Settings
        from bench_zenoh_floor import world as floor_world

        floor_settings = AS_AGENTS if args.floor_as_agents else Settings()
    mode = ("realtime" if args.realtime else "lockstep") + ("/null" if args.null_brain else "")
    head = f"{'robots':>6} {'mode':>13} {'ticks':>6} {'ticks/s':>8} {'p50 ms':>7} {'p99 ms':>7} {'late':>5} {'overruns':>8}"
    print(head + (f" {'floor ticks/s':>13} {'share':>6}" if args.with_floor else ""))
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.robots:
            shares = []
            for _ in range(args.repeat):
                floor = floor_world(n, args.floor_s, "direct", floor_settings) if floor_world else None
                t = swarmloc_run(n, args.scenario, args.duration_s, args.realtime, tmp, args.null_brain)
                if isinstance(t, str):
                    print(f"{n:>6} failed: {t}")
                    continue
                line = (f"{n:>6} {mode:>13} {t['ticks']:>6} {t['ticks_per_s']:>8} {t['tick_ms_p50']:>7} "
                        f"{t['tick_ms_p99']:>7} {t['late_acts']:>5} {t['overruns']:>8}")
                if floor is not None:
                    shares.append(t["ticks_per_s"] / floor["ticks_per_s"])
                    line += f" {floor['ticks_per_s']:>13.1f} {shares[-1]:>6.0%}"
                print(line, flush=True)
            if len(shares) > 1:
                print(f"{n:>6} median share of the floor over {len(shares)} pairs: {statistics.median(shares):.0%}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
