"""Suite-wide set-up: the e-puck kernels compiled (or found compiled) once, before any test.

Tests import the kernels directly, not through a ``swarmloc`` entry point, so without this they
would load whatever numba has cached, and numba checks an entry against its own source file only:
after a change to a callee in another file (``git pull``, a branch switch) they would run old
machine code. :func:`swarmloc.deploy.warm.ensure_compiled` finds the stamp stale, deletes this
install's entries and compiles, once, under the cache's lock (a few milliseconds when current).
"""

from __future__ import annotations

import pytest
from mrclam_synthetic import synthetic_dataset

from swarmloc.deploy.warm import ensure_compiled


def pytest_sessionstart(session) -> None:
    ensure_compiled(lambda line: print(line, flush=True))


@pytest.fixture(scope="module")
def synthetic():
    """The MRCLAM test modules' small synthetic data set (``mrclam_synthetic``), once per module."""
    return synthetic_dataset()
