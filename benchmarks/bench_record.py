"""What recording costs the world's tick, and what it weighs: the indexed layout (zstd chunks of
CHUNK_S simulated seconds, issue 44) beside the layout before it (one record per message, no
compression), on the same frames, side by side.

    python benchmarks/bench_record.py                 # 10 and 100 e-pucks, 60 simulated s each

For each swarm size it runs the batch engine once to collect every tick's frame (as
``swarmloc batch --record`` makes them), then times only ``RecordingWriter.frame`` over those
frames for each layout (best of 3), and prints the cost per tick, its ratio to the unchunked
writer and the file size per simulated minute. The issue's target (within 10 % at 100 agents) is
on the tick, so it also times the batch engine's own tick on the same scenario without recording
(world and every brain in one process, the cheapest tick there is: a world-server's tick, which
also encodes Senses and waits for Acts, is longer) and prints the whole tick's ratio, tick plus
chunked writer over tick plus unchunked writer: an upper bound of what chunking adds to a tick.
"""

from __future__ import annotations

import argparse
import tempfile
import time
from pathlib import Path


def frames_of(robots: int, duration_s: float) -> tuple[dict, list[dict]]:
    from swarmloc.deploy.lab.epuck.batch import run_ticks, swarm_brain
    from swarmloc.deploy.observe.frames import BatchForagingSource, brain_goals
    from swarmloc.deploy.scenario import load_scenario
    from swarmloc.world.epuck.foraging import ForagingWorld

    scenario = load_scenario("ES2" if robots > 10 else "ES1", [f"world.robots={robots}", f"world.duration_s={duration_s}"])
    world, brain = ForagingWorld(scenario.world), swarm_brain(scenario)
    source = BatchForagingSource(world, brain)
    frames: list[dict] = []
    pending: list = [None, None]

    def between() -> None:
        frames.append(source.frame(*pending))
        pending[:] = [brain.pose.copy(), tuple(a.copy() for a in brain_goals(brain))]

    run_ticks(world, brain, between)
    return {**source.scene(), "run": "bench", "scenario": scenario.name}, frames


def tick_cost_s(robots: int, duration_s: float) -> float:
    """CPU seconds per tick of the batch engine on :func:`frames_of`'s scenario, no recording
    (best of 3 runs; ``time.process_time``: other load on the machine does not count)."""
    from swarmloc.deploy.lab.epuck.batch import run_ticks, swarm_brain
    from swarmloc.deploy.scenario import load_scenario
    from swarmloc.world.epuck.foraging import ForagingWorld

    scenario = load_scenario("ES2" if robots > 10 else "ES1", [f"world.robots={robots}", f"world.duration_s={duration_s}"])
    best = float("inf")
    for _ in range(3):
        world, brain = ForagingWorld(scenario.world), swarm_brain(scenario)
        t0 = time.process_time()
        run_ticks(world, brain)
        best = min(best, (time.process_time() - t0) / world.tick)
    return best


def time_writer(scene: dict, frames: list[dict], chunked: bool, folder: Path) -> tuple[float, int]:
    from swarmloc.deploy.observe.record import RecordingWriter

    best = float("inf")
    size = 0
    for k in range(3):
        path = folder / f"{'chunked' if chunked else 'flat'}-{k}.mcap"
        writer = RecordingWriter(path, chunked=chunked)
        writer.scene(scene)
        t0 = time.perf_counter()
        for frame in frames:
            writer.frame(frame)
        writer.close()
        best = min(best, time.perf_counter() - t0)
        size = path.stat().st_size
    return best, size


def main() -> int:
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--robots", type=int, nargs="+", default=[10, 100])
    p.add_argument("--duration-s", type=float, default=60.0)
    args = p.parse_args()
    print(f"{'robots':>6} {'layout':>8} {'writer us/tick':>14} {'writer ratio':>12} {'tick us':>8} "
          f"{'tick+writer ratio':>17} {'MB/min':>7}")
    with tempfile.TemporaryDirectory() as tmp:
        for robots in args.robots:
            scene, frames = frames_of(robots, args.duration_s)
            tick_s = tick_cost_s(robots, args.duration_s)
            minutes = args.duration_s / 60.0
            flat_s, flat_size = time_writer(scene, frames, False, Path(tmp))
            for layout, (secs, size) in (("flat", (flat_s, flat_size)),
                                         ("chunked", time_writer(scene, frames, True, Path(tmp)))):
                per_tick, flat_per_tick = secs / len(frames), flat_s / len(frames)
                print(f"{robots:6d} {layout:>8} {1e6 * per_tick:14.1f} {secs / flat_s:12.2f} {1e6 * tick_s:8.0f} "
                      f"{(tick_s + per_tick) / (tick_s + flat_per_tick):17.3f} {size / 1e6 / minutes:7.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
