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

#: The Python API (swarmloc/api.py), imported on first use so that ``import swarmloc`` stays
#: light: ``swarmloc.batch(...)``, ``swarmloc.experiment(...)`` and so on.
_API = ("batch", "experiment", "read_recording", "read_results", "replay", "report", "run")
__all__ = ["__version__", "batch", "experiment", "read_recording", "read_results", "replay", "report", "run"]


def __getattr__(name: str):
    if name in _API:
        from swarmloc import api

        return getattr(api, name)
    raise AttributeError(f"module 'swarmloc' has no attribute {name!r}")
