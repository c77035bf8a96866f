"""The batch engine: the world and every robot's brain stepped in one process, no Zenoh.

It runs the very same models as the world-server and the agent nodes: :class:`ForagingWorld` for
the world and one :class:`ForagingBrain` holding the whole swarm as a batch. Messages that the
medium delivers are routed as arrays instead of bytes (their floats are already rounded to the
float32 they cross the wire with), so a seeded run gives the same trajectories and metrics here
and over processes.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from swarmloc.agents.foraging import BrainOutput, ForagingBrain, Inbox, agent_rng, on_path
from swarmloc.agents.global_imitation import central_rng, imitate_brain
from swarmloc.deploy.scenario import Scenario
from swarmloc.world.foraging import ForagingWorld, Observation


def inbox_from(observation: Observation, sent: BrainOutput | None, robot_ids: np.ndarray) -> Inbox:
    """Route the medium's deliveries to the receivers' inbox, with the senders' content."""
    d = observation.deliveries
    capacity = sent.messages.heard_ids.shape[1] if sent is not None else 0
    if sent is None or d.receiver.shape[0] == 0:
        return Inbox.empty(capacity)
    return Inbox(
        receiver=d.receiver,
        sender_id=robot_ids[d.sender],
        range_m=d.range_m,
        bearing_rad=d.bearing_rad,
        content=sent.messages,  # every robot's message; each delivery reads its sender's row
        content_row=d.sender,
    )


def swarm_brain(scenario: Scenario, robot_ids=None) -> ForagingBrain:
    """One brain holding the robots ``robot_ids`` (default: all) of a scenario, each with its own
    generator, exactly as each agent process builds its batch of one."""
    w = scenario.world
    ids = np.arange(w.robots) if robot_ids is None else np.asarray(robot_ids)
    return ForagingBrain(scenario.agent, w.body, ids, [agent_rng(w.seed, int(i)) for i in ids], w.tick_s)


@dataclass
class BatchResult:
    metrics: dict
    final_pose: np.ndarray
    pose_estimate: np.ndarray
    lost_count: np.ndarray


def run_batch(scenario: Scenario) -> BatchResult:
    """Run one seeded replication to the end."""
    world = ForagingWorld(scenario.world)
    brain = swarm_brain(scenario)
    ids = brain.robot_ids
    sent: BrainOutput | None = None
    # seed 001's global imitation: a central system that knows the true poses, with its own noise
    central = central_rng(scenario.world.seed) if brain.strategy.central else None
    while not world.done:
        obs = world.observe()
        out = brain.step(obs.encoder_steps, obs.ir, obs.ground, inbox_from(obs, sent, ids))
        if central is not None:
            imitate_brain(brain, world.pose, central, scenario.world.medium)
        world.step(out.wheel_speed_steps_s, out.sending, on_path(out.state))
        sent = out
    return BatchResult(world.metrics.summary(), world.pose.copy(), brain.pose.copy(), brain.lost_count)
