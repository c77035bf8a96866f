"""How long a killed e-puck agent's robot stands still: restarted as ``swarmloc agent`` (a fresh
interpreter: imports, kernels loaded from the cache, a Zenoh session, the join) against forked
again by the warm agent server (``swarmloc agents --respawn``), side by side, each in its own
real-time run of ES1 with ``--robots`` robots. The figure is the world's own: the time between
the agent's liveliness token going and coming back (``transport.rejoin_away_s_max`` of the
results), over ``--kills`` kills a run (one every 3 s, a different robot each time).

    python benchmarks/bench_rejoin.py [--robots 10] [--kills 3]
"""

from __future__ import annotations

import argparse
import json
import os
import signal
import sys
import tempfile
import time
import uuid
from pathlib import Path


def _run(mode: str, robots: int, kills: int) -> dict:
    from swarmloc.deploy.launch import supervised
    from swarmloc.deploy.run import start_swarm
    from swarmloc.deploy.scenario import load_scenario

    with tempfile.TemporaryDirectory() as tmp:
        tmp_path = Path(tmp)
        scenario = load_scenario("ES1", [f"world.robots={robots}", f"world.duration_s={10 + 3 * kills}"])
        path = tmp_path / "scenario.json"
        path.write_text(json.dumps(scenario.to_dict()))
        run = "rj" + uuid.uuid4().hex[:8]
        with supervised() as sup:
            swarm = start_swarm(sup, path, run=run, robots=robots, out=tmp_path / "out", log_dir=tmp_path,
                                realtime=True, join_timeout_s=120,
                                agent_args=("--respawn",) if mode == "respawn" else ())
            time.sleep(3.0)  # the run ticks (a real-time run: wall time is the schedule)
            for k in range(kills):
                robot = 1 + k % (robots - 1)
                agent = swarm.agents[robot]
                os.kill(agent.pid, signal.SIGKILL)
                agent.wait(timeout=10)
                if mode == "restart":  # as an operator, or systemd's Restart=, would
                    swarm.agents[robot] = sup.start(
                        ["agent", "--robot", str(robot), "-m", "client", "-e", swarm.world_endpoint, "--run", run],
                        log_path=tmp_path / f"agent-{robot}-again-{k}.log")
                time.sleep(3.0)
            code = swarm.world.wait(timeout=300)
        result = json.loads((tmp_path / "out" / "results.json").read_text())
    t = result["transport"]
    return {"code": code, "rejoins": t["rejoins"], "away_max_s": t["rejoin_away_s_max"],
            "dead": result["dead_robots"]}


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--robots", type=int, default=10)
    p.add_argument("--kills", type=int, default=3)
    args = p.parse_args(argv)
    print(f"ES1, {args.robots} robots, real time, {args.kills} agents killed (SIGKILL) a run")
    print(f"{'how the agent comes back':32s} {'rejoins':>8s} {'longest away (s)':>17s} {'dead at end':>12s}")
    for mode, label in (("restart", "swarmloc agent, started again"), ("respawn", "swarmloc agents --respawn")):
        r = _run(mode, args.robots, args.kills)
        print(f"{label:32s} {r['rejoins']:>8d} {r['away_max_s']!s:>17s} {r['dead']!s:>12s}", flush=True)
        if r["code"] != 0:
            print(f"  the world exited {r['code']}", file=sys.stderr)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
