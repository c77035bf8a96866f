"""What one e-puck agent process spends per lockstep tick, warm and with cold caches.

An agent's tick is: decode its Sense, step its brain (a ForagingBrain of one robot), encode its
Act. Timed in a loop the caches stay warm; in a swarm of 100 processes sharing 2 cores they are
not: every other process ran in between. This benchmark records robot 0's Senses from an
in-process ES3 world (100 robots, the same bytes the world-server sends), then replays them into a
fresh agent twice: back to back (warm), and after walking a 64 MB buffer before each tick to evict
the CPU caches (cold). A "null" agent (decode, answer a fixed Act, encode) is the floor the brain
adds to; "wire" is the agent as it runs (Sense bytes to Act bytes in one compiled call,
agents/epuck/agent_tick.py), "brain" the same with the protocol codec around the compiled tick (the
path for Senses the compiled parser leaves to it), "reference" the brain stepped through
ForagingBrain.step. Usage:

    python benchmarks/bench_agent_tick.py [--ticks 600] [--evict-mb 64]
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from swarmloc.agents.epuck.agent import ForagingAgent
from swarmloc.agents.epuck.foraging import ForagingBrain, agent_rng
from swarmloc.deploy.scenario import load_scenario
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.messages import EpuckAct, EpuckSense, decode, encode
from swarmloc.world.service import served_world


def _agent(sc, rid: int, packed: bool = True) -> ForagingAgent:
    return ForagingAgent(ForagingBrain(sc.agent, sc.world.body, [rid], [agent_rng(sc.world.seed, rid)],
                                       sc.world.tick_s), rid, packed=packed)


def record(ticks: int) -> list[bytes]:
    """Robot 0's Sense bytes over ``ticks`` ticks of ES3 with every robot's agent answering."""
    from swarmloc.deploy.scenario import load_any

    loaded = load_any("ES3", {"seed": 1}, [])
    sc = loaded.scenario
    world = served_world(loaded)
    agents = [_agent(sc, i) for i in range(sc.world.robots)]
    errors = ErrorCounter()
    out = []
    for _ in range(ticks):
        acts = []
        for rid, data in world.senses():
            if rid == 0:
                out.append(data)
            acts.append(agents[rid].act(decode(data, EpuckSense), errors))
        world.step(acts)
    return out


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--ticks", type=int, default=600)
    parser.add_argument("--evict-mb", type=int, default=64)
    args = parser.parse_args()
    sc = load_scenario("ES3", ["world.seed=1"])
    senses = record(args.ticks)
    buffer = np.zeros(args.evict_mb * 2**20 // 8)
    null_act = EpuckAct(tick=0, robot_id=0, wheel_speed_steps_s=(0.0, 0.0), payload=None, state=0,
                        pose_estimate=(0.0, 0.0, 0.0))

    def brain_tick(agent, errors, data):
        return encode(agent.act(decode(data, EpuckSense), errors))

    def wire_tick(agent, errors, data):
        act = agent.act_wire(data, errors)
        return act if act is not None else brain_tick(agent, errors, data)

    def null_tick(agent, errors, data):
        decode(data, EpuckSense)
        return encode(null_act)

    def per_tick_us(tick, cold: bool, packed: bool = True) -> float:
        agent, errors = _agent(sc, 0, packed), ErrorCounter()
        total = 0.0
        for data in senses:
            if cold:
                buffer[::8] += 1.0  # one write per 64-byte cache line
            t0 = time.perf_counter()
            tick(agent, errors, data)
            total += time.perf_counter() - t0
        return total / len(senses) * 1e6

    per_tick_us(brain_tick, False)  # load the kernels, fill the caches once
    with_mail = sum(1 for d in senses if decode(d, EpuckSense).received) / len(senses)
    print(f"robot 0 of ES3, {len(senses)} ticks, {with_mail:.0%} of them with received messages")
    print(f"{'agent':>10} {'warm us/tick':>13} {'cold us/tick':>13}")
    for name, tick, packed in (("null", null_tick, True), ("wire", wire_tick, True), ("brain", brain_tick, True),
                               ("reference", brain_tick, False)):
        warm = min(per_tick_us(tick, False, packed) for _ in range(3))
        cold = min(per_tick_us(tick, True, packed) for _ in range(3))
        print(f"{name:>10} {warm:>13.1f} {cold:>13.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
