"""The e-puck family's brains: foraging e-pucks that share odometry (social odometry).

Seeds 000 (the subsumption controller of §5, dead reckoning eq. 1-7, the SGIKF and SGIFF filters
of table 1, the range-and-bearing frame transform eq. 27) and 001 (the Fermi rule eq. 8-9, global
imitation). :mod:`~swarmloc.agents.epuck.foraging` is the pure brain over a batch of robots, its
inner loops compiled in :mod:`~swarmloc.agents.epuck.kernels` and one robot's whole tick in
:mod:`~swarmloc.agents.epuck.agent_tick` (Sense bytes to Act bytes with
:mod:`~swarmloc.agents.epuck.wire` and :mod:`~swarmloc.agents.epuck.social_codec`);
:mod:`~swarmloc.agents.epuck.agent` is the adapter the agent-node shell runs (family ``foraging``).
"""
