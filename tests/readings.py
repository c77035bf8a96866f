"""The e-puck settings away from today's defaults, as scenario overrides, so that the equality
tests (batch against brains of one, packed tick against ``ForagingBrain.step``, processes against
the batch engine) cover both sides of every issue 18 setting: today's defaults are the readings
of seeds 000 and 001 (``AgentConfig.p_after_fusion``, ``sends``, ``give_up_factor``,
``encounter_memory``, ``OdometryConfig.substeps``); ``READINGS`` is the named variant
``v0-defaults`` (the defaults before issue 18), with a give-up factor kept on (1.5, not 0) so that
the give-up rule also runs away from its default factor."""

from swarmloc.deploy.scenario import VARIANTS

READINGS = tuple(o for o in VARIANTS["v0-defaults"] if not o.startswith("agent.give_up_factor=")) + (
    "agent.give_up_factor=1.5",)

#: Issue 42's communication process on, both ways of combining and both stops: ``COMM`` the mean
#: of five messages with wandering robots waiting, ``COMM_EACH`` every one of three messages
#: fused as it comes with every robot waiting, and nest and prey moved (``goal_fraction``).
COMM = ("agent.encounter_messages=5", 'agent.encounter_stop="wandering"', "agent.encounter_window_s=1.5")
COMM_EACH = ("agent.encounter_messages=3", 'agent.encounter_combine="each"', 'agent.encounter_stop="all"',
             "world.arena.goal_fraction=0.25")
