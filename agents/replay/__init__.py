"""The replay family's brains: localizers run on a recorded MRCLAM data set (landmarks, teammates).

No seed paper of its own: the localizers of seeds 000-003 adapted to MRCLAM's landmark and
teammate measurements (dead reckoning with social odometry, the particle filter, CFS-GA) and an
EKF (:mod:`~swarmloc.agents.replay.ekf`), behind the contract and registry of
:mod:`~swarmloc.agents.replay.localizers`; :mod:`~swarmloc.agents.replay.agent` is the adapter the
agent-node shell runs (family ``replay``).
"""
