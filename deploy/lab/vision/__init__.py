"""The vision family's lab: seed 004's experiments 1-3 in one process, repeated, and their report.

:mod:`~swarmloc.deploy.lab.vision.runner` draws a seeded layout and runs the vision world with one
brain per robot (shared detections through an in-process team channel);
:mod:`~swarmloc.deploy.lab.vision.experiment` gives the experiment engine the vision family's
settings, jobs and columns (``swarmloc experiment vision``) and measures the detection accuracy;
:mod:`~swarmloc.deploy.lab.vision.report` is its report template (``docs/vision/``).
"""
