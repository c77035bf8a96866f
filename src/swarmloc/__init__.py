"""swarmloc: cooperative localization in robot swarms over Eclipse Zenoh.

Subpackages: :mod:`swarmloc.protocol` (the wire contract), :mod:`swarmloc.world` (pure world
models and the world-server), :mod:`swarmloc.agents` (pure robot brains and the agent node),
:mod:`swarmloc.deploy` (launching, supervision, the ``swarmloc`` command).
"""

__version__ = "0.1.0"
