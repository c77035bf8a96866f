"""A soak: a real-time swarm held for a long time, and whether anything drifts (issue 47).

``swarmloc run ES3-tiled --robots N --realtime`` runs for ``--minutes``; every ``--window-min``
the benchmark reads the world's checkpointed results (written every 5 s by the world-server:
cumulative ticks, overruns, late Acts, rejected messages, tick percentiles so far) and the
memory of the run's processes (``/proc/PID/smaps_rollup``), and prints one line per window:

- ticks/s over the window, overruns and late Acts in the window, messages rejected so far;
- the world's mean tick time over the window, and its tick p50 / p99 so far (cumulative: the
  world keeps every tick's duration);
- PSS of the world, of the run's router, of all agents together, of the agent server
  (``swarmloc agents``, which forks them), and of the whole tree; the world's RSS (read one
  process per :data:`bench_scale.MEMORY_PACE_S`, so that reading 300 agents does not stall the
  run it measures);
- the run's metrics so far: round trips nest-prey-nest, robots that found both goals.

It ends by comparing the first and the last window (after the first, which includes start-up):
ticks/s and the memory figures, as ratios. No growth beyond noise is the target.

    python benchmarks/bench_soak.py --robots 300 --minutes 60          # the issue's soak
    python benchmarks/bench_soak.py --robots 30 --minutes 3 --window-min 0.5   # a quick look
"""

from __future__ import annotations

import argparse
import json
import signal
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from bench_scale import MEMORY_PACE_S, Run, cmdline, descendants, memory_kib, parents, pieces


def snapshot(run: Run) -> dict:
    results = run.out / run.run / "results.json"
    try:
        t = json.loads(results.read_text())
    except (OSError, ValueError):
        return {}
    parent = parents()
    agents, world = pieces(run.proc.pid, parent)
    tree = [run.proc.pid, *descendants(run.proc.pid, parent)]
    mem = {}
    for pid in tree:
        mem[pid] = memory_kib(pid)
        time.sleep(MEMORY_PACE_S)  # pacing, not a readiness wait
    router = next((p for p in tree if parent.get(p) == run.proc.pid and "router" in cmdline(p)[3:4]), None)
    metrics = t.get("metrics", {})
    pss = {pid: m[0] for pid, m in mem.items() if m}
    servers = {parent[a] for a in agents if parent.get(a) not in (None, run.proc.pid)}
    tr = t.get("transport", {})
    return {"at": time.monotonic(), "wall_s": tr.get("wall_s", 0.0), "ticks": tr.get("ticks", 0), "overruns": tr.get("overruns", 0),
            "late": tr.get("late_acts", 0), "rejected": sum(t.get("rejected", {}).values()),
            "p50": tr.get("tick_ms_p50"), "p99": tr.get("tick_ms_p99"), "tick_ms_sum": tr.get("tick_ms_sum", 0.0),
            "pss_world": pss.get(world, 0) if world else 0,
            "rss_world": (mem.get(world) or (0, 0))[1] if world else 0,
            "pss_agents": sum(pss.get(p, 0) for p in agents), "pss_server": sum(pss.get(p, 0) for p in servers),
            "pss_router": pss.get(router, 0) if router else 0, "pss_tree": sum(pss.values()),
            "round_trips": metrics.get("round_trips_total", 0), "found_both": metrics.get("robots_found_both", 0)}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robots", type=int, default=300)
    p.add_argument("--minutes", type=float, default=60.0)
    p.add_argument("--window-min", type=float, default=5.0)
    p.add_argument("--scenario", default="ES3-tiled")
    args = p.parse_args(argv)
    # SIGTERM (a stopped background soak) unwinds like Ctrl-C, so the swarm is stopped with it:
    # before, the benchmark died and left its 300 agents running.
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))
    with tempfile.TemporaryDirectory() as tmp:
        run = Run(args.robots, tmp, scenario=args.scenario, duration_s=args.minutes * 60.0, realtime=True)
        try:
            return _soak(run, args)
        finally:
            run.stop()


def _soak(run: Run, args) -> int:
    joined = run.watch_joins(timeout_s=600.0)
    if joined is None:
        print(f"the {args.robots} agents did not join: {''.join(run.stderr)[-2000:]}", file=sys.stderr)
        return 1
    print(f"{args.robots} agents joined in {joined:.1f} s; windows of {args.window_min:g} min", flush=True)
    print(f"{'min':>5} {'ticks/s':>8} {'overruns':>8} {'late':>6} {'rejected':>8} {'mean ms':>7} {'p50 ms':>7} {'p99 ms':>7} "
          f"{'world PSS MiB':>13} {'world RSS MiB':>13} {'router PSS MiB':>14} {'agents PSS MiB':>14} {'server PSS MiB':>14} "
          f"{'tree PSS MiB':>12} {'round trips':>11} {'found both':>10}", flush=True)
    windows = []
    previous = {}
    while not previous and run.proc.poll() is None:
        time.sleep(0.5)  # until the world's first checkpoint (every 5 s): polling a file
        previous = snapshot(run)
    start = time.monotonic()
    while run.proc.poll() is None:
        time.sleep(args.window_min * 60.0)  # the window's length: the soak's schedule, not a readiness wait
        if run.proc.poll() is not None:
            break  # the run ended inside this window: its processes are gone, no figures
        now = snapshot(run)
        if not now or not previous:
            previous = now
            continue
        dt = now["wall_s"] - previous["wall_s"]  # between the two checkpoints the figures come from
        w = {"min": (now["at"] - start) / 60.0,
             "ticks_per_s": (now["ticks"] - previous["ticks"]) / dt if dt > 0 else 0.0,
             "overruns": now["overruns"] - previous["overruns"], "late": now["late"] - previous["late"],
             "mean_ms": ((now["tick_ms_sum"] - previous["tick_ms_sum"]) / (now["ticks"] - previous["ticks"])
                         if now["ticks"] > previous["ticks"] else 0.0),
             **{k: now[k] for k in ("rejected", "p50", "p99", "pss_world", "rss_world", "pss_router", "pss_agents",
                                    "pss_server", "pss_tree", "round_trips", "found_both")}}
        windows.append(w)
        print(f"{w['min']:5.1f} {w['ticks_per_s']:8.2f} {w['overruns']:8d} {w['late']:6d} {w['rejected']:8d} {w['mean_ms']:7.1f} "
              f"{w['p50'] or 0:7.1f} {w['p99'] or 0:7.1f} {w['pss_world'] / 1024:13.1f} {w['rss_world'] / 1024:13.1f} "
              f"{w['pss_router'] / 1024:14.1f} {w['pss_agents'] / 1024:14.1f} {w['pss_server'] / 1024:14.1f} "
              f"{w['pss_tree'] / 1024:12.1f} {w['round_trips']:11d} {w['found_both']:10d}", flush=True)
        previous = now
    run.close_watch()
    code = run.proc.wait()
    steady = [w for w in windows[1:] if w["ticks_per_s"] > 0] or windows
    if len(steady) >= 2:
        a, b = steady[0], steady[-1]
        print("last window / first steady window: " + ", ".join(
            f"{k} {b[k] / a[k]:.3f}" for k in ("ticks_per_s", "pss_world", "rss_world", "pss_router", "pss_agents",
                                               "pss_server", "pss_tree")
            if a[k]))
    print(f"swarmloc run exited {code}")
    return 0 if code == 0 else 1


if __name__ == "__main__":
    raise SystemExit(main())
