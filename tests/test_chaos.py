"""The chaos benchmark's accounting, short (issue 47): 10 real-time agents for 24 s, deployed
through a router, two SIGKILLed agents (forked again by ``swarmloc agents --respawn``), the router
killed and restarted, the world SIGSTOPped for 2 s; then every (tick, robot) accounted for from
the recording. The full runs (100 and 300 agents, 5 minutes) are ``benchmarks/bench_chaos.py``."""

from __future__ import annotations

import sys
from pathlib import Path

import pytest

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))
from bench_chaos import account, checks, run_chaos


@pytest.mark.integration
def test_every_tick_of_every_robot_is_accounted_for_through_kills_a_router_restart_and_a_pause(tmp_path):
    chaos = run_chaos(10, 24.0, kill_every_s=8.0, pause_s=2.0, seed=3, workdir=tmp_path, join_timeout_s=120)
    assert [what.split()[0] for _, what in chaos.events] == ["SIGKILL", "router", "SIGKILL", "world"]
    assert len(chaos.killed) == 2
    acc = account(chaos)
    failed = [name for name, ok in checks(chaos, acc).items() if not ok]
    assert not failed, (failed, chaos.events, chaos.results.get("transport"))
    # the accounting can tell the three fates apart: each cell is exactly one of them, and the
    # faults left a trace (the router's restart cuts every agent off for a moment)
    assert sum(sum(c) for c in acc.fate.values()) == 10 * 240
    assert sum(c[0] for c in acc.fate.values()) < 10 * 240
    # the pause is one stall, the clock resumed without a catch-up burst (docs/deploy.md)
    assert chaos.results["transport"]["stalls"] >= 1 and chaos.results["transport"]["overruns_after_1s"] <= 3
