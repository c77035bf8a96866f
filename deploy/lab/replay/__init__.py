"""The replay family's lab: the localizers run on a recorded MRCLAM data set, and their report.

:mod:`~swarmloc.deploy.lab.replay.mrclam` replays a data set in one process for each localizer
(dead reckoning with social odometry as in seed 000, the particle filter and CFS-GA of seed 003,
an EKF) and scores the estimates against the Vicon ground truth (``swarmloc mrclam``);
:mod:`~swarmloc.deploy.lab.replay.experiment` gives the experiment engine the replay family's
settings, jobs and rows (``swarmloc experiment mrclam6``) and
:mod:`~swarmloc.deploy.lab.replay.report` is its report template (``docs/mrclam/``).
"""
