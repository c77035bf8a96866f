"""``swarmloc status``: the live world and agents of a run, from liveliness.

The pure parts (grouping token keys, the table) are checked on hand-written keys. The command is
checked against a real swarm started with ``start_swarm`` (own router on a free port, unique run
name). Readiness is the command's own: it repeats its liveliness query until it sees what
``--expect-agents`` asks for or its deadline passes, so the test never sleeps; a wrong answer
shows up as a non-zero exit or a wrong table, never as a hang (every wait is bounded).
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import uuid

import pytest

from swarmloc.deploy.launch import supervised
from swarmloc.deploy.observe.status import (
    RunStatus,
    format_table,
    id_ranges,
    satisfied,
    selector,
    summarise,
)
from swarmloc.deploy.run import start_swarm
from swarmloc.deploy.scenario import load_scenario

# -- pure parts --------------------------------------------------------------------------------


def test_summarise_groups_tokens_by_run_and_ignores_foreign_keys():
    keys = [
        "swarmloc/a/alive/world", "swarmloc/a/alive/0", "swarmloc/a/alive/2",
        "swarmloc/b/alive/7",  # agents without a world
        "swarmloc/c/alive/world",
        "other/a/alive/1",  # another root
        "swarmloc/a/alive/01", "swarmloc/a/alive/+3", "swarmloc/a/alive/65536",  # not canonical ids
        "swarmloc/a/alive/x", "swarmloc/a/robot/1/act", "swarmloc/a b/alive/1",  # not tokens
    ]
    runs = summarise(keys)
    assert list(runs) == ["a", "b", "c"]
    assert runs["a"].world and runs["a"].agents == {0, 2}
    assert not runs["b"].world and runs["b"].agents == {7}
    assert runs["c"].world and runs["c"].agents == set()


def test_id_ranges():
    assert id_ranges([]) == "-"
    assert id_ranges([4]) == "4"
    assert id_ranges([8, 0, 1, 2, 5, 7, 2]) == "0-2,5,7-8"
    assert id_ranges(range(100)) == "0-99"


def test_table_has_one_row_per_run():
    table = format_table({"r1": RunStatus("r1", True, {0, 1, 2}), "long-run": RunStatus("long-run", False, {3})})
    lines = table.splitlines()
    assert lines[0].split() == ["run", "world", "agents", "ids"]
    assert lines[1].split() == ["r1", "live", "3", "0-2"]
    assert lines[2].split() == ["long-run", "-", "1", "3"]
    assert "no live" in format_table({})


def test_selector_and_what_is_waited_for():
    assert selector("r1") == "swarmloc/r1/alive/*"
    assert selector(None) == "swarmloc/*/alive/*"
    with pytest.raises(ValueError, match="run name"):
        selector("a/*")
    assert not satisfied({}, None)
    assert not satisfied({"a": RunStatus("a", False, {0})}, None)
    assert satisfied({"a": RunStatus("a", True, {0})}, None)
    assert satisfied({"a": RunStatus("a", True, {0, 1})}, 2)
    assert not satisfied({"a": RunStatus("a", True, {0})}, 2)


# -- the command against a real swarm ----------------------------------------------------------


def _status(*args: str, timeout_s: float = 60.0) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "swarmloc", "status", *args], capture_output=True,
                          text=True, timeout=timeout_s + 30, check=False)


def _row(stdout: str, run: str) -> list[str]:
    rows = [line.split() for line in stdout.splitlines() if line.split()[:1] == [run]]
    assert len(rows) == 1, stdout
    return rows[0]


@pytest.mark.integration
def test_status_lists_the_live_world_and_agents_of_a_real_swarm(tmp_path):
    scenario = load_scenario("ES1", ["world.robots=3", "world.duration_s=6000.0"])
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(scenario.to_dict()))
    run = "st" + uuid.uuid4().hex[:10]
    with supervised() as sup:
        swarm = start_swarm(sup, path, run=run, robots=3, out=tmp_path / "out", log_dir=tmp_path,
                            join_timeout_s=60)
        ep = swarm.router_endpoint
        # Right after the start: the command waits (bounded) until all three agents are live.
        first = _status("-e", ep, "--run", run, "--expect-agents", "3", "--timeout-s", "60")
        assert first.returncode == 0, first.stdout + first.stderr
        assert _row(first.stdout, run) == [run, "live", "3", "0-2"]

        # Every run under swarmloc/*: this router knows only ours.
        every = _status("-e", ep, "--expect-agents", "3", "--timeout-s", "30")
        assert every.returncode == 0, every.stdout + every.stderr
        assert _row(every.stdout, run) == [run, "live", "3", "0-2"]

        # A dead agent's token goes away: the table says so.
        os.kill(swarm.agents[1].pid, signal.SIGKILL)
        swarm.agents[1].wait(timeout=10)
        dead = _status("-e", ep, "--run", run, "--expect-agents", "2", "--timeout-s", "30")
        assert dead.returncode == 0, dead.stdout + dead.stderr
        assert _row(dead.stdout, run) == [run, "live", "2", "0,2"]

        # A run that does not exist: no world, exit 1 once the (short) deadline has passed.
        other = _status("-e", ep, "--run", run + "x", "--timeout-s", "0.5")
        assert other.returncode == 1
        assert "no live" in other.stdout

        # The world gone: its token with it, exit 1 (killed: what is checked here is status,
        # not how fast a world stops, which test_integration checks).
        os.kill(swarm.world.pid, signal.SIGKILL)
        swarm.world.wait(timeout=10)
        gone = _status("-e", ep, "--run", run, "--expect-agents", "0", "--timeout-s", "0.5")
        assert gone.returncode == 1, gone.stdout
        assert run not in gone.stdout or _row(gone.stdout, run)[1] == "-"


def test_status_without_a_router_fails_fast():
    # Port 9 (discard) on loopback: nothing listens there in this sandbox's tests.
    result = _status("-e", "tcp/127.0.0.1:9", "--timeout-s", "0.5", timeout_s=10)
    assert result.returncode == 1
    assert "cannot connect" in result.stderr
