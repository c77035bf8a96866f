"""The laser family's lab: the in-process runner, experiments and report of seeds 002 and 003.

:mod:`~swarmloc.deploy.lab.laser.runner` runs the laser world with one localizer per robot (MR-SSGA,
the simple GA, CFS-GA, AMCL) in one process; :mod:`~swarmloc.deploy.lab.laser.experiment` gives the
experiment engine the laser family's settings, jobs and columns (``swarmloc experiment laser-*``);
:mod:`~swarmloc.deploy.lab.laser.report` writes ``docs/laser/`` (seed 002 table 3, seed 003 figures
1-4) next to the papers' numbers.
"""
