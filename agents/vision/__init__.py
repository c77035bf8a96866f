"""The vision family's brains: robots that localize from coloured objects their teammates also see.

Seed 004 (explicit coordinated localization using common visual objects):
:mod:`~swarmloc.agents.vision.detection` finds colour blobs and their distance by size,
:mod:`~swarmloc.agents.vision.cooperative` shares events and triangulates a common object
(eq. 1-2), :mod:`~swarmloc.agents.vision.potential_field` navigates (eq. 3-5), and
:mod:`~swarmloc.agents.vision.brain` puts them together; :mod:`~swarmloc.agents.vision.agent` is
the adapter the agent-node shell runs (family ``vision``).
"""
