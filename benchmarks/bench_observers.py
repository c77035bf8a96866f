"""Lockstep tick rate with and without observers (issue 17): a view attached, a recording.

For each swarm size, runs `swarmloc run` three ways, interleaved ``--repeat`` times so that all
see the same machine in the same minutes: plain; ``--view`` with a client on the page's
WebSocket reading every frame it is sent (a browser without the drawing); ``--record`` to an MCAP
file. Prints the world-server's ticks/s side by side and each observer's rate as a share of the
plain run's (targets: view within 5 %, recording within 10 %). Usage:

    python benchmarks/bench_observers.py [--robots 10 100] [--duration-s 100] [--repeat 3]
"""

from __future__ import annotations

import argparse
import asyncio
import json
import statistics
import subprocess
import sys
import tempfile
import threading
from pathlib import Path


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


def run_once(n: int, mode: str, scenario: str, duration_s: float, tmp: str) -> tuple[float, dict]:
    run = f"obs{n}{mode}"
    cmd = [sys.executable, "-m", "swarmloc", "run", scenario, "--robots", str(n),
           "--duration-s", str(duration_s), "--out", tmp, "--run", run, "--quiet"]
    if mode == "view":
        cmd += ["--view", "--view-http", "127.0.0.1:0"]
    if mode == "record":
        cmd += ["--record", str(Path(tmp) / f"{run}.mcap")]
    proc = subprocess.Popen(cmd, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    seen: dict = {}
    watcher = None
    for line in proc.stderr:
        if line.startswith("view: "):
            watcher = threading.Thread(target=_watch, args=(line.split()[1], seen), daemon=True)
            watcher.start()
            break
        if mode != "view":
            break
    proc.communicate()
    if proc.returncode != 0:
        raise RuntimeError(f"{cmd}: exit {proc.returncode}")
    if watcher:
        watcher.join(10)
    extra = dict(seen)
    if mode == "record":
        extra["mcap_mb"] = round((Path(tmp) / f"{run}.mcap").stat().st_size / 1e6, 1)
    return json.loads((Path(tmp) / run / "results.json").read_text())["transport"]["ticks_per_s"], extra


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, nargs="+", default=[10, 100])
    p.add_argument("--duration-s", type=float, default=100.0, help="simulated seconds per run")
    p.add_argument("--scenario", default="ES3")
    p.add_argument("--repeat", type=int, default=3)
    args = p.parse_args()
    modes = ("plain", "view", "record")
    print(f"{'robots':>6} {'plain':>9} {'view':>9} {'record':>9}   view/plain record/plain  notes")
    with tempfile.TemporaryDirectory() as tmp:
        for n in args.robots:
            rates: dict[str, list[float]] = {m: [] for m in modes}
            notes = {}
            for _ in range(args.repeat):
                for m in modes:
                    rate, extra = run_once(n, m, args.scenario, args.duration_s, tmp)
                    rates[m].append(rate)
                    notes.update({f"{m}.{k}": v for k, v in extra.items()})
            med = {m: statistics.median(v) for m, v in rates.items()}
            print(f"{n:>6} {med['plain']:>9.1f} {med['view']:>9.1f} {med['record']:>9.1f}   "
                  f"{med['view'] / med['plain']:>9.1%} {med['record'] / med['plain']:>11.1%}  "
                  f"{json.dumps(notes)}", flush=True)
            for m in modes:
                print(f"       {m:>6} runs: {', '.join(f'{r:.1f}' for r in rates[m])}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
