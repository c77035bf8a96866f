"""Integration: vision robots (seed 004) as agent processes over real Zenoh.

Each agent gets its camera frames from the world-server and shares its detections with its
teammate directly on the team keys; the process run must reproduce the in-process runner for the
same seed. Processes are started as `swarmloc run` starts them, on free ports, stopped by id.
"""

from __future__ import annotations

import json
import uuid

import numpy as np
import pytest

from swarmloc.agents.brains import brain_from_welcome
from swarmloc.deploy.lab.vision.runner import run_vision, world_config
from swarmloc.deploy.launch import supervised
from swarmloc.deploy.run import start_swarm
from swarmloc.deploy.scenario import load_any
from swarmloc.protocol.errors import ErrorCounter
from swarmloc.protocol.messages import VisionSense, Welcome
from swarmloc.world.vision.world import VisionWorld

pytestmark = pytest.mark.integration

COMPARED = ("collisions", "goals", "teammate_err_median_m", "teammate_known_fraction",
            "ball_err_median_m", "blind_relayed_ball_err_median_m", "sim_s")


def _run_processes(tmp_path, scenario) -> dict:
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(scenario.to_dict()))
    out = tmp_path / "out"
    with supervised() as sup:
        swarm = start_swarm(sup, path, run="vis" + uuid.uuid4().hex[:8], robots=scenario.robots,
                            out=out, log_dir=tmp_path, join_timeout_s=60)
        code = swarm.world.wait(timeout=180)
        agent_codes = [a.wait(timeout=30) for a in swarm.agents]
    assert code == 0, (tmp_path / "world.log").read_text()[-2000:]
    assert agent_codes == [0] * scenario.robots
    return json.loads((out / "results.json").read_text())


PRIOR = ['agent.relative_heading="odometry"', "agent.initial_relative_heading_rad=0.0",
         "agent.shared_odometry=true"]


@pytest.mark.parametrize(
    ("name", "sharing", "extra"),
    [("vision-exp3", True, []),  # perception alone, the reproduction
     ("vision-exp1", False, []),
     ("vision-exp1", True, ['world.robot_body="box"']),  # the AIBO-like box body
     ("vision-exp2", True, PRIOR)],  # the additions beyond the paper
)
def test_vision_agents_over_zenoh_reproduce_the_in_process_run(tmp_path, name, sharing, extra):
    seed = 4
    scenario = load_any(name, {"seed": seed}, [f"agent.sharing={json.dumps(sharing)}", *extra])
    result = _run_processes(tmp_path, scenario)
    assert result["reason"] == "completed" and result["rejected"] == {}
    metrics = result["metrics"]
    local, _ = run_vision(scenario.scenario, seed)
    for key in COMPARED:
        assert metrics[key] == local[key], key
    assert metrics["reach_s"] == [local["reach_s_0"], local["reach_s_1"]]
    if name == "vision-exp3":  # the robot that cannot see the ball locates it from its teammate
        assert metrics["collisions"] == 0 and metrics["goals_correct"]
        assert metrics["blind_relayed_ball_err_median_m"] is not None
    elif sharing:
        assert metrics["teammate_known_fraction"] > 0.5
    else:  # experiment 1 without sharing: they collide (seed 004 §IV-A)
        assert metrics["collisions"] > 0


def test_a_frame_that_does_not_decode_is_counted_and_the_previous_command_kept():
    scenario = load_any("vision-exp1", {"seed": 2})
    welcome = Welcome(robot_id=0, run="unit", seed=2, scenario=scenario.to_dict())
    agent = brain_from_welcome(welcome)
    world = VisionWorld(world_config(scenario.scenario, 2)[0])
    errors = ErrorCounter()
    obs = world.observe()[0]
    good = VisionSense(tick=0, robot_id=0, time_s=obs.time_s, image=obs.image,
                       odometry_pose=obs.odometry_pose, head_pan_rad=obs.head_pan_rad)
    first = agent.act(good, errors)
    assert dict(errors.counts) == {}
    assert any(abs(c) > 0 for c in first.command), "the robot starts walking"
    for junk in (b"", b"\xff\xd8 not a jpeg", np.zeros(10, np.uint8).tobytes()):
        bad = VisionSense(tick=1, robot_id=0, time_s=0.1, image=junk,
                          odometry_pose=obs.odometry_pose, head_pan_rad=obs.head_pan_rad)
        act = agent.act(bad, errors)
        assert act.command == first.command
    assert sum(errors.counts.values()) == 3
