"""Observers: pieces that watch a run over Zenoh without taking part in it.

:mod:`~swarmloc.deploy.observe.status` (``swarmloc status``) follows a run's world state, robot
liveliness and error reports for any robot family (seeds 000-004 alike); a browser view and an
MCAP recorder are meant to land here beside it.
"""
