"""The laser family's brains: map-based localizers for robots with a laser and a radio.

Seeds 002 (MR-SSGA, :mod:`~swarmloc.agents.laser.ssga`, and the simple GA it is compared with,
:mod:`~swarmloc.agents.laser.simple_ga`) and 003 (CFS-GA, :mod:`~swarmloc.agents.laser.cfsga`,
and two AMCLs: Player's ``amcl`` driver as 003 ran it, :mod:`~swarmloc.agents.laser.amcl_player`,
and the modern, ROS-amcl-like particle filter, :mod:`~swarmloc.agents.laser.amcl`, with its
particle-set arithmetic in :mod:`~swarmloc.agents.laser.amcl_sampling` and its teammates' beliefs
in :mod:`~swarmloc.agents.laser.amcl_belief`; the genetic localizers' optional local refinement is
:mod:`~swarmloc.agents.laser.refine`), all behind the localizer contract of
:mod:`~swarmloc.agents.laser.localizer`; :mod:`~swarmloc.agents.laser.agent` is the adapter the
agent-node shell runs (family ``laser``).
"""
