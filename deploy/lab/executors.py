"""Where an experiment's jobs run: a local pool of spawned processes, or a Dask cluster.

The engine (:func:`swarmloc.deploy.lab.experiment.run_experiment`) plans the jobs, writes the rows
and shows progress; an executor only runs ``fn(job)`` for each job and hands back each finished
one. Both implement the same small contract (:class:`Executor`)::

    with make_executor("local", workers=2) as ex:          # or ("dask", scheduler="tcp://h:8786")
        for job, future in ex.as_completed(run_job, jobs):
            out = future.result()                          # the job's dict, or its exception

- :class:`LocalPool`: ``concurrent.futures.ProcessPoolExecutor`` with the ``spawn`` context
  (a forked child of a process with a Zenoh session hangs), one BLAS thread per worker, workers
  ignoring SIGINT (the parent alone handles Ctrl-C and stops them).
- :class:`DaskExecutor`: ``distributed.Client(address)``, ``client.submit(fn, job, pure=False)``
  and ``distributed.as_completed``. The scheduler reschedules the job of a worker that died on
  another worker; the engine writes each (setting, seed) once even if an executor handed a job
  back twice. Connecting is checked up front: a malformed address or a scheduler that does not
  answer raises :class:`~swarmloc.config.ConfigError` (exit 2) before the results file is touched.

Rows are identical whichever executor computed them except :data:`TIMING_COLUMNS`.
"""

from __future__ import annotations

import multiprocessing
import os
import re
import signal
import sys
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from contextlib import contextmanager
from typing import Any, Protocol

from swarmloc.config import ConfigError

#: Result columns that measure the machine, not the model: they differ from run to run and from
#: executor to executor; every other column of a row is the same whichever executor ran it.
TIMING_COLUMNS = ("wall_s", "cpu_s")
EXECUTORS = ("local", "dask")
#: How long the client waits for the Dask scheduler to answer before giving up.
DEFAULT_SCHEDULER_TIMEOUT_S = 10.0
#: Thread pools of numerical libraries: one thread per worker, the pool is the parallelism.
_THREAD_VARS = ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")
#: Addresses a Dask client connects to: ``tcp://HOST:PORT`` (or tls, ws, wss, ucx).
_SCHEDULER_RE = re.compile(
    r"^(?P<proto>tcp|tls|ws|wss|ucx)://(?P<host>\[[0-9A-Fa-f:.]+\]|[A-Za-z0-9]([A-Za-z0-9.-]*[A-Za-z0-9])?)"
    r":(?P<port>[0-9]{1,5})$")


class Executor(Protocol):
    """What the engine needs from an executor."""

    #: ``"local"`` or ``"dask"``.
    name: str
    #: Whether jobs run on this host (then the engine compiles the kernels once up front).
    on_this_host: bool

    def workers(self) -> int:
        """How many jobs run at once (for the progress line)."""

    def as_completed(self, fn: Callable[[Any], Any], jobs: Iterable[Any]) -> Iterator[tuple[Any, Any]]:
        """Run ``fn(job)`` for every job; yield ``(job, future)`` as each finishes
        (``future.result()`` is its value or raises its exception)."""

    def stop(self) -> None:
        """Interrupted or failed: drop what has not finished, stop what runs if it can."""

    def close(self) -> None:
        """Every job was handed back: release the workers or the connection."""


# -- the local pool ---------------------------------------------------------------------------


def _ignore_sigint() -> None:
    # Ctrl-C reaches the whole process group: the parent alone handles it and stops the workers.
    signal.signal(signal.SIGINT, signal.SIG_IGN)


@contextmanager
def one_thread_per_worker() -> Iterator[None]:
    """Spawned workers inherit the environment when they start: one BLAS thread each."""
    saved = {k: os.environ.get(k) for k in _THREAD_VARS}
    os.environ.update({k: "1" for k in _THREAD_VARS})
    try:
        yield
    finally:
        for k, v in saved.items():
            if v is None:
                os.environ.pop(k, None)
            else:
                os.environ[k] = v


class LocalPool:
    """``workers`` spawned processes on this host (started with the first jobs)."""

    name = "local"
    on_this_host = True

    def __init__(self, workers: int | None = None) -> None:
        workers = (os.cpu_count() or 1) if workers is None else workers
        if workers < 1:
            raise ConfigError(f"workers: must be >= 1, got {workers}")
        self._max = workers
        self._size = workers
        self._pool: ProcessPoolExecutor | None = None
        self._futures: dict[Future, Any] = {}

    def workers(self) -> int:
        return self._size

    def as_completed(self, fn, jobs):
        jobs = list(jobs)
        if not jobs:
            return
        self._size = min(self._max, len(jobs))
        with one_thread_per_worker():
            self._pool = ProcessPoolExecutor(max_workers=self._size,
                                             mp_context=multiprocessing.get_context("spawn"),
                                             initializer=_ignore_sigint)
            self._futures = {self._pool.submit(fn, job): job for job in jobs}
        pending = set(self._futures)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            for fut in finished:
                yield self._futures[fut], fut

    def stop(self) -> None:
        if self._pool is None:
            return
        for f in self._futures:
            f.cancel()
        # The executor has no public way to stop running jobs: terminate the workers it started,
        # by their own handles (they ignore SIGINT), then let it shut down.
        processes = list((getattr(self._pool, "_processes", None) or {}).values())
        self._pool.shutdown(wait=False, cancel_futures=True)
        for p in processes:
            if p.is_alive():
                p.terminate()
        for p in processes:
            p.join(timeout=5)
        self._pool = None

    def close(self) -> None:
        if self._pool is not None:
            self._pool.shutdown(wait=True)
            self._pool = None


# -- Dask -------------------------------------------------------------------------------------


def check_scheduler_address(address: str | None) -> str:
    """``address`` if it is a Dask scheduler address such as ``tcp://10.0.0.5:8786``, else
    ConfigError naming ``--scheduler`` and what is wrong."""
    if not address:
        raise ConfigError("--executor dask needs --scheduler ADDRESS, e.g. tcp://HOST:8786 "
                          "(the address `dask scheduler` prints)")
    m = _SCHEDULER_RE.match(address)
    if m is None:
        hint = ""
        if "://" not in address:
            hint = f" (did you mean tcp://{address}?)" if ":" in address else " (expected tcp://HOST:PORT)"
        raise ConfigError(f"--scheduler {address!r}: not a Dask scheduler address{hint}; "
                          f"expected PROTOCOL://HOST:PORT with PROTOCOL tcp, tls, ws, wss or ucx")
    if not 0 < int(m["port"]) <= 65535:
        raise ConfigError(f"--scheduler {address!r}: port {m['port']} is not in 1..65535")
    return address


class DaskExecutor:
    """Jobs on the workers of a running Dask scheduler (``dask scheduler``; workers started with
    ``dask worker ADDRESS --nthreads 1``, one job per worker process at a time)."""

    name = "dask"
    on_this_host = False

    def __init__(self, address: str | None, timeout_s: float = DEFAULT_SCHEDULER_TIMEOUT_S) -> None:
        self.address = check_scheduler_address(address)
        try:
            import distributed
        except ImportError:
            raise ConfigError("--executor dask needs Dask distributed on this host and on every "
                              "worker: pip install 'swarmloc[cluster]'") from None
        self._distributed = distributed
        try:
            self._client = distributed.Client(self.address, timeout=timeout_s, set_as_default=False)
        except (OSError, TimeoutError) as exc:
            raise ConfigError(f"--scheduler {self.address}: no Dask scheduler answered within "
                              f"{timeout_s:g} s ({type(exc).__name__}: {exc}); is `dask scheduler` "
                              f"running there and the port open?") from None
        self._futures: dict[Any, Any] = {}

    def workers(self) -> int:
        info = self._client.scheduler_info()
        threads = sum(w.get("nthreads", 1) for w in info.get("workers", {}).values())
        return max(1, threads)

    def as_completed(self, fn, jobs):
        jobs = list(jobs)
        if not jobs:
            return
        if not self._client.scheduler_info().get("workers"):
            print(f"swarmloc: no Dask worker is connected to {self.address} yet; the jobs wait "
                  f"for one (start `dask worker {self.address} --nthreads 1`)", file=sys.stderr,
                  flush=True)
        futures = [self._client.submit(fn, job, pure=False) for job in jobs]
        self._futures = dict(zip(futures, jobs))
        for fut in self._distributed.as_completed(futures, loop=self._client.loop):
            yield self._futures[fut], fut

    def stop(self) -> None:
        # Cancelling releases the jobs not started; a job already running on a worker runs to its
        # end there and its result is dropped (a Python thread cannot be stopped from outside).
        try:
            if self._futures:
                self._client.cancel(list(self._futures), force=True)
        finally:
            self.close()

    def close(self) -> None:
        if self._client is not None:
            self._client.close()
            self._client = None


def make_executor(name: str, workers: int | None = None, scheduler: str | None = None,
                  scheduler_timeout_s: float = DEFAULT_SCHEDULER_TIMEOUT_S) -> Executor:
    """The executor called ``name`` (:data:`EXECUTORS`); ConfigError for a bad combination."""
    if name == "local":
        if scheduler:
            raise ConfigError("--scheduler is for --executor dask (the local pool needs none)")
        return LocalPool(workers)
    if name == "dask":
        return DaskExecutor(scheduler, timeout_s=scheduler_timeout_s)
    raise ConfigError(f"--executor: expected one of {', '.join(EXECUTORS)}, got {name!r}")


@contextmanager
def sigterm_as_interrupt() -> Iterator[None]:
    """SIGTERM raises KeyboardInterrupt in the main thread while inside: a batch system's
    ``scancel`` or ``kill`` stops the client the way Ctrl-C does (finished rows kept, workers
    stopped), instead of killing it between two rows."""
    def handler(signum, frame):
        raise KeyboardInterrupt

    try:
        previous = signal.signal(signal.SIGTERM, handler)
    except ValueError:  # not the main thread: leave SIGTERM alone
        yield
        return
    try:
        yield
    finally:
        signal.signal(signal.SIGTERM, previous)


__all__ = ["DEFAULT_SCHEDULER_TIMEOUT_S", "EXECUTORS", "TIMING_COLUMNS", "DaskExecutor",
           "Executor", "LocalPool", "check_scheduler_address", "make_executor",
           "one_thread_per_worker", "sigterm_as_interrupt"]
