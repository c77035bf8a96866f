"""``swarmloc batch --record FILE.mcap``: the batch engine's run, every tick to a recording.

The frames are those a world-server's tap writes for the same seed (deploy/observe/tap.py): the
frame of tick ``k`` holds the poses after ``k`` steps and the estimates of the brains' step of
tick ``k - 1`` (what the Acts that moved the world carried), so the two recordings compare tick by
tick; their poses are equal bit for bit (tests/test_observe.py).
"""

from __future__ import annotations

from pathlib import Path

from swarmloc.deploy.lab.epuck.batch import BatchResult, run_ticks, swarm_brain
from swarmloc.deploy.observe.frames import BatchForagingSource, brain_goals
from swarmloc.deploy.observe.record import RecordingWriter
from swarmloc.world.epuck.foraging import ForagingWorld


def run_batch_recorded(scenario, path: str | Path) -> BatchResult:
    """:func:`swarmloc.deploy.lab.epuck.batch.run_batch` that also records every tick to ``path``."""
    from swarmloc.agents.epuck.global_imitation import central_rng, imitate_brain

    world = ForagingWorld(scenario.world)
    brain = swarm_brain(scenario)
    central = central_rng(scenario.world.seed) if brain.strategy.central else None
    source = BatchForagingSource(world, brain)
    writer = RecordingWriter(path, metadata={"run": "batch", "scenario": scenario.name})
    writer.scene({**source.scene(), "run": "batch", "scenario": scenario.name})
    pending: list = [None, None]  # the estimates of the brains' last step: the next frame's

    def between() -> None:  # world.tick = k: poses after k steps; the brains just stepped tick k
        if central is not None:
            imitate_brain(brain, world.pose, central, scenario.world.medium)
        writer.frame(source.frame(*pending))
        pending[:] = [brain.pose.copy(), tuple(a.copy() for a in brain_goals(brain))]

    try:
        run_ticks(world, brain, between)
        writer.frame(source.frame(*pending))
    finally:
        writer.close()
    return BatchResult(world.metrics.summary(), world.pose.copy(), brain.pose.copy(), brain.lost_count)
