"""The e-puck family's lab: the batch engine and the report of seeds 000 and 001.

:mod:`~swarmloc.deploy.lab.epuck.batch` steps the same foraging world and brains as the processes
do, the whole swarm in one process (``swarmloc batch``, and every job of ``swarmloc experiment``);
:mod:`~swarmloc.deploy.lab.epuck.report` writes ``swarmloc report``'s page and figures in the
style of seed 000 figures 13-16 and seed 001 figures 6-8, comparing with the papers through
:mod:`~swarmloc.deploy.lab.epuck.claims`.
"""
