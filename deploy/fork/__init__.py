"""Agents forked from one warm process (``swarmloc agents``): see :mod:`.server`."""
