"""Lockstep tick rate with and without observers (issue 17): a view attached, a recording.

For each swarm size, runs ``swarmloc run`` (lockstep) three ways: ``plain``; ``view``
(``--view`` with a client on the page's WebSocket reading every frame it is sent: a browser
without the drawing); ``record`` (``--record`` to an MCAP file). The modes are interleaved,
``--repeat`` rounds, each round in a rotated order, so that every mode sees the same machine in
the same minutes. Prints, per mode, the median and the spread (min-max) of

- the world-server's lockstep ticks/s (wall clock: what a user sees, noisy on a shared machine);
- the world-server's CPU time per tick, every thread of the world process while it ticked
  (``results.json: transport.cpu_ms_per_tick``): what the observer costs the world itself, less
  sensitive to what else the machine runs (but a crowded machine still inflates it: caches);
- the world thread's CPU time per tick inside the observer tap's calls
  (``transport.tap_cpu_ms_per_tick``: building frames, writing the file, offering frames to the
  view), the work an observer adds to the lockstep's serial path, measured directly,

and each observer's median as a share of the plain run's (issue 17's targets: the view within
5 %, the recording within 10 %). The machine's load average is printed beside the figures.
Usage (simulated seconds per run, one per swarm size; 0.1 s ticks)::

    python benchmarks/bench_observers.py [--robots 10 100] [--duration-s 300 100] [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import os
import statistics
import subprocess
import sys
import tempfile
import threading
from pathlib import Path

MODES = ("plain", "view", "record")


def _watch(url: str, seen: dict) -> None:
    """A browser stand-in: read every frame the page's socket sends until it closes."""
    import aiohttp

    async def go():
        async with aiohttp.ClientSession() as http, http.ws_connect(url.replace("http", "ws") + "ws") as ws:
            async for msg in ws:
                if msg.type == aiohttp.WSMsgType.TEXT and '"type":"frame"' in msg.data[:40]:
                    seen["frames"] = seen.get("frames", 0) + 1

    try:
        asyncio.run(go())
    except Exception as exc:  # noqa: BLE001 -- the run ended and the page went away
        seen["end"] = type(exc).__name__


def run_once(n: int, mode: str, scenario: str, duration_s: float, tmp: str, timeout_s: float) -> dict:
    run = f"obs{n}{mode}{os.getpid()}"
    cmd = [sys.executable, "-m", "swarmloc", "run", scenario, "--robots", str(n),
           "--duration-s", str(duration_s), "--out", tmp, "--run", run, "--quiet"]
    if mode == "view":
        cmd += ["--view", "--view-http", "127.0.0.1:0"]
    mcap = Path(tmp) / f"{run}.mcap"
    if mode == "record":
        cmd += ["--record", str(mcap)]
    proc = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True)
    seen: dict = {}
    watcher = None
    try:
        if mode == "view":
            for line in proc.stderr:  # `swarmloc run --view` prints the page's URL when it is up
                if line.startswith("view: "):
                    watcher = threading.Thread(target=_watch, args=(line.split()[1], seen), daemon=True)
                    watcher.start()
                    break
        _, err = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.terminate()  # swarmloc run stops its pieces on SIGTERM
        proc.wait(60)
        raise RuntimeError(f"{' '.join(cmd)}: no end within {timeout_s:.0f} s") from None
    if proc.returncode != 0:
        raise RuntimeError(f"{' '.join(cmd)}: exit {proc.returncode}: {err[-1000:]}")
    if watcher:
        watcher.join(10)
    t = json.loads((Path(tmp) / run / "results.json").read_text())["transport"]
    out = {"ticks_per_s": t["ticks_per_s"], "cpu_ms_per_tick": t["cpu_ms_per_tick"],
           "tap_ms_per_tick": t["tap_cpu_ms_per_tick"], "wall_s": t["wall_s"]}
    if mode == "view":
        out["frames_read"] = seen.get("frames", 0)
    if mode == "record":
        out["mcap_mb"] = round(mcap.stat().st_size / 1e6, 1)
        mcap.unlink()
    return out


def _load() -> str:
    return " ".join(Path("/proc/loadavg").read_text().split()[:3])


def _spread(values: list[float]) -> str:
    d = 3 if max(values) < 1 else 2
    return f"{statistics.median(values):8.{d}f} [{min(values):.{d}f}-{max(values):.{d}f}]"


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, nargs="+", default=[10, 100])
    p.add_argument("--duration-s", type=float, nargs="+", default=[300.0, 100.0],
                   help="simulated seconds per run, one per --robots value (or one for all)")
    p.add_argument("--scenario", default="ES3")
    p.add_argument("--repeat", type=int, default=3)
    p.add_argument("--timeout-s", type=float, default=600.0, help="per run")
    args = p.parse_args()
    durations = args.duration_s * len(args.robots) if len(args.duration_s) == 1 else args.duration_s
    if len(durations) != len(args.robots):
        p.error("--duration-s: give one value, or one per --robots value")
    print(f"scenario {args.scenario}, lockstep, {args.repeat} interleaved rounds; "
          f"load average at start {_load()}", flush=True)
    with tempfile.TemporaryDirectory() as tmp:
        for n, duration_s in zip(args.robots, durations):
            runs: dict[str, list[dict]] = {m: [] for m in MODES}
            for r in range(args.repeat):
                order = MODES[r % len(MODES):] + MODES[:r % len(MODES)]
                for m in order:
                    runs[m].append(run_once(n, m, args.scenario, duration_s, tmp, args.timeout_s))
                    print(f"  n={n} round {r + 1} {m:6s} {json.dumps(runs[m][-1])}  load {_load()}",
                          flush=True)
            rate = {m: [x["ticks_per_s"] for x in v] for m, v in runs.items()}
            cpu = {m: [x["cpu_ms_per_tick"] for x in v] for m, v in runs.items()}
            tap = {m: [x["tap_ms_per_tick"] for x in v] for m, v in runs.items()}
            base_rate, base_cpu = statistics.median(rate["plain"]), statistics.median(cpu["plain"])
            base_tap = statistics.median(tap["plain"])
            print(f"\n{n} robots, {round(duration_s / 0.1)} ticks per run (load average now {_load()}):")
            print(f"  {'mode':6s} {'ticks/s median [min-max]':>30s} {'vs plain':>9s}   "
                  f"{'world CPU ms/tick median [min-max]':>36s} {'vs plain':>9s}   "
                  f"{'tap ms/tick median [min-max]':>30s} {'added/plain CPU':>15s}")
            for m in MODES:
                added = (statistics.median(tap[m]) - base_tap) / base_cpu
                print(f"  {m:6s} {_spread(rate[m]):>30s} {statistics.median(rate[m]) / base_rate - 1:>+9.1%}   "
                      f"{_spread(cpu[m]):>36s} {statistics.median(cpu[m]) / base_cpu - 1:>+9.1%}   "
                      f"{_spread(tap[m]):>30s} {added:>+15.1%}", flush=True)
            print()
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
