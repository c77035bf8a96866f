"""The vision family's lab: seed 004's experiments 1-3 in one process, repeated, and their report.

:mod:`~swarmloc.deploy.lab.vision.runner` draws a seeded layout and runs the vision world with one
brain per robot (shared detections through an in-process team channel);
:mod:`~swarmloc.deploy.lab.vision.experiment` repeats runs over seeds and sharing modes, measures
the detection accuracy and is the ``swarmloc vision-experiment`` command;
:mod:`~swarmloc.deploy.lab.vision.report` writes ``docs/vision/``.
"""
