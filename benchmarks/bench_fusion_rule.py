"""What a user's fusion rule costs (agents/epuck/fusion.py): whole seeded batch replications with
the built-in induced Kalman gain (SSGIKF) and with the same gain written as a user's rule
(``FusionRule``, called by the kernels through its compiled C function's address), side by side in
one process, interleaved so that other load on the machine falls on both. Prints the CPU time
(``time.process_time``) per replication of each, the ratio (target: at most 1.3x) and whether the
two runs are identical (they must be: the rule restates eq. 20-22 with the kernel's expressions).

    python benchmarks/bench_fusion_rule.py [--scenario ES2] [--seeds 1 2 3] [--rounds 3]
"""

from __future__ import annotations

import argparse
import time

import numpy as np


def kalman_gain(p_own, p_other, beta):  # seed 000 eq. 20, as agents/epuck/kernels.py writes it
    total = p_own + p_other
    return p_own / total if total > 0.0 else 0.5


def kalman_confidence(p_own, p_other, g, beta):  # eq. 22
    return (1.0 - g) * p_own


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--scenario", default="ES2")
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3])
    p.add_argument("--rounds", type=int, default=3, help="replications of each seed per gain (best kept)")
    args = p.parse_args(argv)

    from swarmloc.agents.epuck.fusion import FusionRule
    from swarmloc.agents.epuck.fusion import register as register_rule
    from swarmloc.agents.epuck.social_odometry import STRATEGIES, Strategy
    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.scenario import load_scenario

    register_rule(FusionRule("bench-kalman", kalman_gain, kalman_confidence))
    STRATEGIES.register(Strategy("BENCH_SK", communicates=True, double=False, gain="bench-kalman"))

    def replication(strategy: str, seed: int):
        scenario = load_scenario(args.scenario, [f'agent.strategy="{strategy}"', f"world.seed={seed}"])
        t0 = time.process_time()
        result = run_batch(scenario)
        return time.process_time() - t0, result

    replication("SSGIKF", args.seeds[0])  # warm-up: kernels loaded, caches filled
    replication("BENCH_SK", args.seeds[0])
    cpu = {"SSGIKF": [], "BENCH_SK": []}
    same = True
    for seed in args.seeds:
        best = {}
        for _ in range(args.rounds):
            for strategy in cpu:
                t, result = replication(strategy, seed)
                best[strategy] = min(best.get(strategy, (np.inf,))[0], t), result
        for strategy, times in cpu.items():
            times.append(best[strategy][0])
        a, b = best["SSGIKF"][1], best["BENCH_SK"][1]
        same &= a.metrics == b.metrics and np.array_equal(a.final_pose, b.final_pose)
    builtin, custom = float(np.sum(cpu["SSGIKF"])), float(np.sum(cpu["BENCH_SK"]))
    n = len(args.seeds)
    print(f"{args.scenario}, seeds {args.seeds}, best of {args.rounds} per seed, CPU s per replication:")
    print(f"  built-in Kalman gain (SSGIKF)        : {builtin / n:.3f}")
    print(f"  the same gain as a user's FusionRule : {custom / n:.3f}")
    print(f"  ratio (target <= 1.3)                : {custom / builtin:.3f}")
    print(f"  identical runs                       : {same}")
    return 0 if same else 1


if __name__ == "__main__":
    raise SystemExit(main())
