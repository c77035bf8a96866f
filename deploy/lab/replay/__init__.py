"""The replay family's lab: the localizers run on a recorded MRCLAM data set, and their report.

:mod:`~swarmloc.deploy.lab.replay.mrclam` replays a data set in one process for each localizer
(dead reckoning with social odometry as in seed 000, the particle filter and CFS-GA of seed 003,
an EKF), scores the estimates against the Vicon ground truth and writes ``docs/mrclam/``
(``swarmloc mrclam``).
"""
