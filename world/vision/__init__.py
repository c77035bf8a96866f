"""The vision family's world: legged robots with a camera on a pan head among coloured objects.

Seed 004 (explicit coordinated localization from common visual objects: the field, the ball,
teammates, rivals, obstacle and beacons of experiments 1-3). The pure model is
:mod:`~swarmloc.world.vision.world`, whose frames :mod:`~swarmloc.world.vision.camera` renders;
:mod:`~swarmloc.world.vision.service` serves it behind the world-server shell (family ``vision``).
"""
