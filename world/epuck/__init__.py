"""The e-puck family's world: foraging e-pucks in an arena with a nest and a prey area.

Seeds 000 (social odometry: kinematics and odometry error, sensors, the range-and-bearing
medium, experiments ES1-ES3) and 001 (the arenas and noise of the imitation study). The pure
model is :mod:`~swarmloc.world.epuck.foraging` (arena, sensors, medium and metrics beside it, their
inner loops compiled in :mod:`~swarmloc.world.epuck.kernels`); :mod:`~swarmloc.world.epuck.service`
serves it behind the world-server shell (family ``foraging``).
"""
