"""Observers of a run: the live browser view, the MCAP recorder and the replayer (issue 17).

Everything here reads what the world already has (its state, the Acts that carry the agents'
estimates) and never slows the lockstep: the world streams frames at a bounded wall-clock rate
(:mod:`.tap`), a recording of a lockstep run is written by the world itself, every tick
(:mod:`.record`), and a browser that lags only drops frames (:mod:`.view`).
:mod:`.status` (``swarmloc status``) lists the live worlds and agents from liveliness.
"""
