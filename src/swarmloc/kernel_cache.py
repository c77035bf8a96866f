"""Where swarmloc's compiled (numba) kernels are cached.

The e-puck world, brain and batch engine run in numba kernels compiled with ``cache=True``
(``world/epuck/kernels.py``, ``agents/epuck/kernels.py``, ...). numba fixes where a function's cache lives when
the function is decorated, that is when its module is imported, so the place is chosen here, by
``swarmloc/__init__.py``, before any kernel module is imported:

- ``NUMBA_CACHE_DIR`` if the user set it (numba's own variable: it wins, always);
- else ``$XDG_CACHE_HOME/swarmloc/numba`` (``~/.cache/swarmloc/numba``): per user, so that a
  second user of the machine never needs write access to the first one's files, and outside the
  installed package, so that ``pip install .`` into a read-only site-packages works (numba's own
  default writes ``__pycache__`` beside the sources, and falls back to ``~/.cache/numba`` only
  where it cannot);
- else, when no home folder is writable (a service user), a per-user folder under the system's
  temporary directory.

The choice is exported through the environment, so that every piece ``swarmloc run`` starts
shares it. numba keys each entry by the source file (path, modification time, size), the
function's signature and the CPU, so several installs and checkouts can share one folder. Compiling
once per machine, under a lock, is :mod:`swarmloc.deploy.warm`'s job.
"""

from __future__ import annotations

import os
import sys
import tempfile
from pathlib import Path

#: numba's variable for the cache folder.
ENV_VAR = "NUMBA_CACHE_DIR"


def _writable(folder: Path) -> bool:
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError:
        return False
    return os.access(folder, os.W_OK | os.X_OK)


def default_dir() -> Path:
    """The cache folder swarmloc uses when ``NUMBA_CACHE_DIR`` is not set."""
    xdg = os.environ.get("XDG_CACHE_HOME")
    base = Path(xdg) if xdg else Path.home() / ".cache"
    folder = base / "swarmloc" / "numba"
    if _writable(folder):
        return folder
    return Path(tempfile.gettempdir()) / f"swarmloc-{os.getuid()}" / "numba"


def cache_dir() -> Path:
    """The folder numba caches swarmloc's kernels in, for this process."""
    return Path(os.environ.get(ENV_VAR) or default_dir())


def configure() -> Path:
    """Point numba's cache at :func:`cache_dir` (unless the user already did) for this process
    and the processes it starts; returns the folder."""
    folder = cache_dir()
    os.environ.setdefault(ENV_VAR, str(folder))
    config = sys.modules.get("numba.core.config")
    if config is not None and not getattr(config, "CACHE_DIR", ""):
        # numba was imported before swarmloc: its configuration is read, but kernels not yet
        # decorated still take the folder from it.
        config.CACHE_DIR = str(folder)
    return folder
