"""swarmloc: cooperative localization in robot swarms over Eclipse Zenoh.

Subpackages: :mod:`swarmloc.protocol` (the wire contract), :mod:`swarmloc.world` (pure world
models and the world-server), :mod:`swarmloc.agents` (pure robot brains and the agent node),
:mod:`swarmloc.deploy` (launching, supervision, the ``swarmloc`` command).

Importing swarmloc sets one default, on purpose: where numba caches swarmloc's compiled kernels
(:mod:`swarmloc.kernel_cache`), which numba fixes when a kernel module is imported.
"""

from swarmloc import kernel_cache as _kernel_cache

__version__ = "0.1.0"

_kernel_cache.configure()
