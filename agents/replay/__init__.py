"""The replay family's brains: localizers run on a recorded MRCLAM data set (landmarks, teammates).

No seed paper of its own: the localizers of seeds 000-003 adapted to MRCLAM's landmark and
teammate measurements. :mod:`~swarmloc.agents.replay.localizers` holds their contract, models,
teammate reports, dead reckoning with social odometry (seed 000) and the registry;
:mod:`~swarmloc.agents.replay.populations` the particle filter and CFS-GA (seeds 002/003's
baselines and 003's algorithm), :mod:`~swarmloc.agents.replay.ekf` an EKF;
:mod:`~swarmloc.agents.replay.agent` is the adapter the agent-node shell runs (family ``replay``).
"""
