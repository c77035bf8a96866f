"""The laser family's world: unicycle robots with laser rangefinders and a radio on a floor map.

Seeds 002 (MR-SSGA: unicycle and laser models eq. 3-4, relative observations, table 2) and 003
(CFS-GA: table I, the kidnapped robot and robustness runs). The pure model is
:mod:`~swarmloc.world.laser.world`, built on :mod:`~swarmloc.world.laser.laser` (rays, motion,
relative observations) and the segment maps of :mod:`~swarmloc.world.laser.maps`;
:mod:`~swarmloc.world.laser.service` serves it behind the world-server shell (family ``laser``).
"""
