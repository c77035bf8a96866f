"""The world-server's side of the e-puck wire per tick (issue 47): every live robot's Sense
encoded through the protocol codec (the reference: an EpuckSense per robot, then ``encode``)
against the compiled encoder (``agents/epuck/wire.py: encode_senses``), on the same observation,
interleaved, and the Acts decoded through the codec, at the swarm sizes of the real-time
benchmark. One process, no Zenoh: the CPU the world spends on the wire, not the transport.

Every robot sends a 32-byte payload each tick (as the SGIKF agents do near teammates), so the
medium's deliveries are there to encode; ES3's density (ES3-tiled).

    python benchmarks/bench_world_wire.py [--robots 100 300 600 800] [--ticks 50]
"""

from __future__ import annotations

import argparse
import gc
import time

import numpy as np

from swarmloc.deploy.scenario import load_any
from swarmloc.protocol.messages import EpuckAct, decode, encode
from swarmloc.world.service import served_world


def measure(robots: int, ticks: int) -> dict:
    world = served_world(load_any("ES3-tiled", {"seed": 1, "robots": robots}))
    rng = np.random.default_rng(1)
    gc.collect()
    gc.freeze()  # as the world-server does for its run (world/server.py: WorldServer.run)
    fast_s, ref_s, act_s, received = [], [], [], 0
    for tick in range(ticks + 5):
        obs = world.world.observe()
        t0 = time.perf_counter()
        fast = world.encode_senses(obs)
        t1 = time.perf_counter()
        ref = world.encode_senses_reference(obs)
        t2 = time.perf_counter()
        assert fast == ref
        acts = [encode(EpuckAct(tick, r, tuple(rng.uniform(-300, 300, 2).tolist()),
                                rng.integers(0, 256, 32, dtype=np.uint8).tobytes(), 1, (0.0, 0.0, 0.0)))
                for r in range(robots)]
        t3 = time.perf_counter()
        decoded = [decode(a, EpuckAct) for a in acts]
        t4 = time.perf_counter()
        world.step(decoded)
        if tick >= 5:  # the first ticks load the kernels
            fast_s.append(t1 - t0)
            ref_s.append(t2 - t1)
            act_s.append(t4 - t3)
            received += len(obs.deliveries)
    med = lambda xs: 1e3 * float(np.median(xs))
    return {"robots": robots, "fast_ms": med(fast_s), "ref_ms": med(ref_s), "acts_ms": med(act_s),
            "deliveries": received / ticks}


def _unfreeze(result: dict) -> dict:
    gc.unfreeze()
    return result


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robots", type=int, nargs="+", default=[100, 300, 600, 800])
    p.add_argument("--ticks", type=int, default=50)
    args = p.parse_args(argv)
    print(f"{'robots':>6} {'deliveries':>10} {'Senses, codec ms':>16} {'Senses, compiled ms':>19} "
          f"{'speed-up':>8} {'Acts decoded ms':>15}   (median per tick)")
    for n in args.robots:
        m = _unfreeze(measure(n, args.ticks))
        print(f"{n:6d} {m['deliveries']:10.0f} {m['ref_ms']:16.2f} {m['fast_ms']:19.2f} "
              f"{m['ref_ms'] / m['fast_ms']:7.1f}x {m['acts_ms']:15.2f}", flush=True)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
