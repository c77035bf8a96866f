"""The replay family's world: a recorded MRCLAM data set fed to the robots tick by tick.

No seed paper simulates it: it replays the UTIAS MRCLAM data sets (five robots, 15 landmarks,
Vicon ground truth) so that the localizers of seeds 000-003 (social odometry, particle filter,
CFS-GA) and an EKF run on real data. :mod:`~swarmloc.world.replay.mrclam` loads (and writes)
the data sets, :mod:`~swarmloc.world.replay.replay` is the lockstep world, and
:mod:`~swarmloc.world.replay.service` serves it behind the world-server shell (family ``replay``).
"""
