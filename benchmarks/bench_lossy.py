"""Lockstep over lossy links between network namespaces (issue 6): ticks/s and tick latency.

For each loss rate, runs the same seeded lockstep scenario (ES1's robots in the lab's small arena,
:func:`swarmloc.deploy.lab.netns.lab_scenario`) with the router, the world and every agent in its own
network namespace (:mod:`swarmloc.deploy.lab.netns`), and prints what the world-server measured
(its ``transport`` figures: ticks/s, tick p50/p99, late acts) and whether the metrics equal the
batch engine's (the lossless run). Needs root and nftables. Usage:

    python benchmarks/bench_lossy.py [--loss 0 0.1 0.2 0.3] [--robots 3] [--duration-s 20]
                                     [--protocol tcp|udp] [--untuned]

``tcp`` (default) uses the lab's TCP tuning for lossy links (route rto_min 10 ms + quickack,
thin-stream linear timeouts, 60 s Zenoh lease, 120 s act timeout; see docs/deploy.md);
``--untuned`` runs with the kernel's and Zenoh's defaults (rto_min 200 ms, 10 s lease, 10 s act
timeout). ``udp`` is best effort: the loss is switched on once the run ticks, the act deadline is
50 ms, and "late" counts robot-ticks whose Sense or Act was lost.
"""

from __future__ import annotations

import argparse
import json
import sys
import tempfile
import time
import uuid
from pathlib import Path

from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.lab.netns import (
    NetnsLab,
    lab_hosts,
    lab_scenario,
    remove_stale_labs,
    start_lab_swarm,
    unavailable,
)
from swarmloc.deploy.launch import supervised


def _wait_running(results_file: Path, timeout_s: float = 120.0) -> int:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if results_file.exists():
            recorded = json.loads(results_file.read_text())
            if recorded["reason"] == "running" and recorded["tick"] > 0:
                return recorded["tick"]
        time.sleep(0.05)
    raise RuntimeError("the world never started ticking")


def run_one(lab: NetnsLab, scenario_file: Path, robots: int, loss: float, protocol: str, tuned: bool,
            folder: Path) -> tuple[dict, float]:
    """One run at ``loss``; returns the world's results and the wall seconds of the whole run."""
    out = folder / "out"
    if protocol == "udp":
        world_args, lease_s = ("--act-timeout-s", "0.05", "--checkpoint-s", "0.1"), None
        lab.set_loss(0.0)
    else:
        world_args, lease_s = (("--act-timeout-s", "120"), 60) if tuned else ((), None)
        lab.set_loss(loss)
    t0 = time.perf_counter()
    with supervised() as sup:
        swarm = start_lab_swarm(lab, sup, scenario_file, run="b" + uuid.uuid4().hex[:10], robots=robots,
                                out=out, log_dir=folder, protocol=protocol, lease_s=lease_s,
                                world_args=world_args)
        if protocol == "udp":
            _wait_running(out / "results.json")
            lab.set_loss(loss)
        code = swarm.world.wait(timeout=1800)
    if code != 0:
        raise RuntimeError(f"world exited {code} at loss {loss}; logs in {folder}")
    return json.loads((out / "results.json").read_text()), time.perf_counter() - t0


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--loss", type=float, nargs="+", default=[0.0, 0.1, 0.2, 0.3])
    parser.add_argument("--robots", type=int, default=3)
    parser.add_argument("--duration-s", type=float, default=20.0)
    parser.add_argument("--seed", type=int, default=5)
    parser.add_argument("--protocol", choices=("tcp", "udp"), default="tcp")
    parser.add_argument("--untuned", action="store_true", help="kernel and Zenoh defaults")
    args = parser.parse_args()
    reason = unavailable()
    if reason is not None:
        print(f"bench_lossy: cannot build the lab here: {reason}", file=sys.stderr)
        return 2
    remove_stale_labs()
    tuned = not args.untuned
    scenario = lab_scenario(args.robots, args.duration_s, args.seed)
    expected = json.loads(json.dumps(run_batch(scenario).metrics))
    print(f"{args.robots} robots, {scenario.world.n_ticks} ticks, {args.protocol}"
          f"{' (tuned)' if tuned and args.protocol == 'tcp' else ''}, loss on every host's input")
    print(f"{'loss':>5} {'ticks/s':>8} {'p50 ms':>8} {'p99 ms':>9} {'late':>5} {'dead':>4} "
          f"{'dropped':>8} {'wall s':>7}  metrics")
    with tempfile.TemporaryDirectory() as tmp, \
            NetnsLab(lab_hosts(args.robots), tcp_rto_min_ms=10 if tuned else None,
                     tcp_thin_linear_timeouts=tuned) as lab:
        scenario_file = Path(tmp) / "scenario.json"
        scenario_file.write_text(json.dumps(scenario.to_dict()))
        for k, loss in enumerate(args.loss):
            folder = Path(tmp) / f"run{k}"
            folder.mkdir()
            result, wall_s = run_one(lab, scenario_file, args.robots, loss, args.protocol, tuned, folder)
            counters = lab.drop_counters()
            arrived = sum(a for a, _ in counters.values())
            dropped = sum(d for _, d in counters.values())
            t = result["transport"]
            same = "= lossless" if result["metrics"] == expected else "DIFFERENT"
            print(f"{loss:5.2f} {t['ticks_per_s']:8.2f} {t['tick_ms_p50']:8.2f} {t['tick_ms_p99']:9.1f} "
                  f"{t['late_acts']:5d} {len(result['dead_robots']):4d} "
                  f"{dropped / max(arrived, 1):8.1%} {wall_s:7.1f}  {same}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
