"""Issue 18's readings of seeds 000 and 001, every one away from today's default, as scenario
overrides: the settings ``AgentConfig.p_after_fusion``, ``sends``, ``give_up_factor``,
``encounter_memory`` and ``OdometryConfig.substeps`` document them. The equality tests (batch
against brains of one, packed tick against ``ForagingBrain.step``, processes against the batch
engine) run with these too."""

AGENT_READINGS = ('agent.p_after_fusion="distance"', 'agent.sends="last-visited"', "agent.give_up_factor=1.5",
                  "agent.encounter_memory=16")
READINGS = (*AGENT_READINGS, "world.odometry.substeps=10")
