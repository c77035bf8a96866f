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
  back twice. Connecting is checked up front: a malformed address, a scheduler that does not
  answer, a refused or bad TLS certificate (:class:`DaskTls`, ``tls://`` addresses), or no worker
  within ``worker_timeout_s`` raises :class:`~swarmloc.config.ConfigError` (exit 2) before the
  results file is touched.

Rows are identical whichever executor computed them except :data:`TIMING_COLUMNS`.
"""

from __future__ import annotations

import multiprocessing
import os
import re
import signal
import ssl
import sys
from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from contextlib import contextmanager
from dataclasses import dataclass
from typing import Any, Protocol

from swarmloc.config import ConfigError

#: Result columns that measure the machine, not the model: they differ from run to run and from
#: executor to executor; every other column of a row is the same whichever executor ran it.
TIMING_COLUMNS = ("wall_s", "cpu_s")
EXECUTORS = ("local", "dask", "inline")
#: How long the client waits for the Dask scheduler to answer before giving up.
DEFAULT_SCHEDULER_TIMEOUT_S = 10.0
#: How long the client waits for a first worker to connect to the scheduler (a batch system may
#: queue the workers' jobs for a while; ``--worker-timeout-s`` sets it).
DEFAULT_WORKER_TIMEOUT_S = 600.0
#: How many times one run of the local pool starts a fresh pool after a worker process died.
MAX_POOL_RESTARTS = 3
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


# -- in this process ---------------------------------------------------------------------------


class InlineExecutor:
    """Every job in the calling process, one after the other: no pool to spawn, so it works from
    a script read on stdin, under a debugger, and in a notebook whose functions a spawned worker
    could not import. ``swarmloc.batch(..., workers=1)`` and ``--executor inline`` use it."""

    name = "inline"
    on_this_host = True

    def workers(self) -> int:
        return 1

    def as_completed(self, fn, jobs):
        from concurrent.futures import Future

        for job in jobs:
            fut: Future = Future()
            try:
                fut.set_result(fn(job))
            except Exception as exc:  # noqa: BLE001 -- handed back as a pool would hand it
                fut.set_exception(exc)
            yield job, fut

    def stop(self) -> None:
        pass

    def close(self) -> None:
        pass


# -- the local pool ---------------------------------------------------------------------------


def _init_worker(parent_pid: int) -> None:
    """Each pool worker, as it starts: Ctrl-C reaches the whole process group, so the parent
    alone handles it and stops the workers; and the worker asks Linux for SIGTERM when the
    parent dies, so that a SIGKILLed ``swarmloc experiment`` leaves no worker behind (issue 47:
    two idle workers of ~190 MB each, and the resource tracker they kept alive, stayed as
    orphans for good). A worker whose parent is already gone exits at once."""
    signal.signal(signal.SIGINT, signal.SIG_IGN)
    from swarmloc.deploy.fork.server import die_with_parent

    if not die_with_parent(signal.SIGTERM, parent_pid=parent_pid):
        os._exit(1)


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
    """``workers`` spawned processes on this host, started with the first jobs and kept for every
    later job (each process imports the engine and loads the kernels once, on its first job).

    A pool given to :func:`~swarmloc.deploy.lab.experiment.run_experiment` as an instance stays
    up after the run (its owner calls :meth:`close`), so successive runs in one Python process
    pay the start-up once; ``swarmloc experiment`` makes its own and closes it.

    A worker process that dies (SIGKILL, out of memory) breaks a ``ProcessPoolExecutor``: every
    job not yet handed back fails with ``BrokenProcessPool``. Those jobs run again on a fresh
    pool, up to :data:`MAX_POOL_RESTARTS` times a run (a job that kills its worker every time
    then fails the run, naming it); each (setting, seed) is still written once, by the engine.
    """

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
        #: Pools started again after a worker died, this run (for the tests and the log).
        self.restarts = 0

    def workers(self) -> int:
        return self._size

    def pids(self) -> list[int]:
        """The process ids of the pool's live workers (none before the first job)."""
        processes = (getattr(self._pool, "_processes", None) or {}) if self._pool else {}
        return sorted(pid for pid, p in processes.items() if p.is_alive())

    def _submit(self, fn, jobs: list) -> set[Future]:
        with one_thread_per_worker():  # processes start at submit: one BLAS thread each
            if self._pool is None:
                self._pool = ProcessPoolExecutor(max_workers=self._max,
                                                 mp_context=multiprocessing.get_context("spawn"),
                                                 initializer=_init_worker, initargs=(os.getpid(),))
            submitted = {self._pool.submit(fn, job): job for job in jobs}
        self._futures.update(submitted)
        return set(submitted)

    def as_completed(self, fn, jobs):
        jobs = list(jobs)
        self._futures = {}
        self.restarts = 0
        if not jobs:
            return
        self._size = min(self._max, len(jobs))
        pending = self._submit(fn, jobs)
        while pending:
            finished, pending = wait(pending, return_when=FIRST_COMPLETED)
            lost = [f for f in finished if not f.cancelled()
                    and isinstance(f.exception(), BrokenProcessPool)]
            for fut in finished:
                if fut not in lost or self.restarts >= MAX_POOL_RESTARTS:
                    yield self._futures[fut], fut
            if lost and self.restarts < MAX_POOL_RESTARTS:
                # A broken pool fails every job still out: those that finished first are
                # handed back, the others run again on a new pool.
                rest, _ = wait(pending)
                for fut in rest:
                    if not fut.cancelled() and isinstance(fut.exception(), BrokenProcessPool):
                        lost.append(fut)
                    else:
                        yield self._futures[fut], fut
                self._pool.shutdown(wait=True, cancel_futures=True)
                self._pool = None
                self.restarts += 1
                again = [self._futures.pop(f) for f in lost]
                print(f"swarmloc: a worker process died; running the {len(again)} unfinished "
                      f"jobs again on a fresh pool ({self.restarts}/{MAX_POOL_RESTARTS})",
                      file=sys.stderr, flush=True)
                pending = self._submit(fn, again)

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


@dataclass(frozen=True)
class DaskTls:
    """The client's side of Dask's mutual TLS (``--tls-ca-file``, ``--tls-cert``, ``--tls-key``,
    the flags ``dask scheduler`` and ``dask worker`` take too): the CA that signed the scheduler's
    and workers' certificates, and this client's certificate and key, signed by the same CA
    (``swarmloc tls make-ca`` / ``issue``; the CA may be the Zenoh router's)."""

    ca_file: str
    cert: str
    key: str

    @classmethod
    def from_flags(cls, ca_file: str | None, cert: str | None, key: str | None) -> DaskTls | None:
        """None if no flag is given; ConfigError if only some are."""
        given = {"--tls-ca-file": ca_file, "--tls-cert": cert, "--tls-key": key}
        if not any(given.values()):
            return None
        missing = [flag for flag, v in given.items() if not v]
        if missing:
            raise ConfigError(f"Dask TLS needs --tls-ca-file, --tls-cert and --tls-key; "
                              f"missing {', '.join(missing)}")
        return cls(str(ca_file), str(cert), str(key))

    def check(self) -> None:
        """ConfigError naming the file and what is wrong (missing, not PEM, expired, not yet
        valid, not signed by the CA, a key that is not the certificate's)."""
        from swarmloc.protocol.tls import check_files

        try:
            check_files(self.ca_file, self.cert, self.key)
        except ValueError as exc:
            raise ConfigError(f"Dask {exc}") from None

    def security(self):
        """``distributed.Security`` requiring encryption, with these files for the client."""
        from distributed.security import Security

        return Security(require_encryption=True, tls_ca_file=self.ca_file,
                        tls_client_cert=self.cert, tls_client_key=self.key)


class DaskExecutor:
    """Jobs on the workers of a running Dask scheduler (``dask scheduler``; workers started with
    ``dask worker ADDRESS --nthreads 1``, one job per worker process at a time)."""

    name = "dask"
    on_this_host = False

    def __init__(self, address: str | None, timeout_s: float = DEFAULT_SCHEDULER_TIMEOUT_S,
                 tls: DaskTls | None = None,
                 worker_timeout_s: float = DEFAULT_WORKER_TIMEOUT_S) -> None:
        self.address = check_scheduler_address(address)
        if self.address.startswith("tls://") and tls is None:
            raise ConfigError(f"--scheduler {self.address}: a tls:// scheduler needs this client's "
                              f"certificate: --tls-ca-file CA.pem --tls-cert NAME.pem --tls-key "
                              f"NAME-key.pem (swarmloc tls issue DIR NAME)")
        if tls is not None and not self.address.startswith("tls://"):
            raise ConfigError(f"--tls-cert is for a tls:// scheduler; --scheduler is "
                              f"{self.address} (did you mean tls://{self.address.split('://', 1)[1]}?)")
        if worker_timeout_s <= 0:
            raise ConfigError(f"--worker-timeout-s: must be > 0, got {worker_timeout_s:g}")
        if tls is not None:
            tls.check()
        try:
            import distributed
            from distributed.comm.core import CommClosedError
        except ImportError:
            raise ConfigError("--executor dask needs Dask distributed on this host and on every "
                              "worker: pip install 'swarmloc[cluster]'") from None
        self._distributed = distributed
        self._client = None
        try:
            self._client = distributed.Client(self.address, timeout=timeout_s, set_as_default=False,
                                              **({"security": tls.security()} if tls else {}))
        except CommClosedError as exc:
            if tls is None:
                raise ConfigError(f"--scheduler {self.address}: the scheduler closed the "
                                  f"connection ({exc}); a TLS scheduler needs tls:// and "
                                  f"--tls-ca-file/--tls-cert/--tls-key") from None
            if isinstance(exc.__cause__, ssl.SSLCertVerificationError):
                # This client's own check of the scheduler's certificate failed.
                raise ConfigError(f"--scheduler {self.address}: the scheduler's TLS certificate "
                                  f"is not signed by --tls-ca-file {tls.ca_file} or has expired "
                                  f"({exc.__cause__})") from None
            # The scheduler ended the handshake (an "unknown ca" alert, or a plain close).
            raise ConfigError(f"--scheduler {self.address}: the scheduler refused this client's "
                              f"certificate {tls.cert} (TLS handshake closed: {exc}); it must be "
                              f"signed by the CA the scheduler trusts (its --tls-ca-file)") from None
        except (OSError, TimeoutError) as exc:
            hint = (" (a TLS scheduler needs tls:// and --tls-ca-file/--tls-cert/--tls-key)"
                    if tls is None else "")
            raise ConfigError(f"--scheduler {self.address}: no Dask scheduler answered within "
                              f"{timeout_s:g} s ({type(exc).__name__}: {exc}); is `dask scheduler` "
                              f"running there and the port open?{hint}") from None
        self._futures: dict[Any, Any] = {}
        try:
            self._wait_for_a_worker(worker_timeout_s)
        except BaseException:
            self.close()
            raise

    def _wait_for_a_worker(self, timeout_s: float) -> None:
        """Return once a worker is connected; say so while waiting; ConfigError after
        ``timeout_s``."""
        if self._client.scheduler_info().get("workers"):
            return
        print(f"swarmloc: no Dask worker is connected to {self.address} yet; waiting up to "
              f"{timeout_s:g} s for one (start `dask worker {self.address} --nthreads 1`)",
              file=sys.stderr, flush=True)
        try:
            self._client.wait_for_workers(1, timeout=timeout_s)
        except TimeoutError:
            raise ConfigError(f"--scheduler {self.address}: no Dask worker connected within "
                              f"{timeout_s:g} s (start `dask worker {self.address} --nthreads 1` "
                              f"on the worker hosts, or wait longer with --worker-timeout-s)") from None

    def workers(self) -> int:
        info = self._client.scheduler_info()
        threads = sum(w.get("nthreads", 1) for w in info.get("workers", {}).values())
        return max(1, threads)

    def as_completed(self, fn, jobs):
        jobs = list(jobs)
        if not jobs:
            return
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
                  scheduler_timeout_s: float = DEFAULT_SCHEDULER_TIMEOUT_S,
                  tls: DaskTls | None = None,
                  worker_timeout_s: float = DEFAULT_WORKER_TIMEOUT_S) -> Executor:
    """The executor called ``name`` (:data:`EXECUTORS`); ConfigError for a bad combination."""
    if name == "inline":
        if scheduler or tls is not None:
            raise ConfigError("--scheduler and --tls-* are for --executor dask")
        return InlineExecutor()
    if name == "local":
        if scheduler:
            raise ConfigError("--scheduler is for --executor dask (the local pool needs none)")
        if tls is not None:
            raise ConfigError("--tls-ca-file/--tls-cert/--tls-key are for --executor dask")
        return LocalPool(workers)
    if name == "dask":
        return DaskExecutor(scheduler, timeout_s=scheduler_timeout_s, tls=tls,
                            worker_timeout_s=worker_timeout_s)
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


__all__ = ["DEFAULT_SCHEDULER_TIMEOUT_S", "DEFAULT_WORKER_TIMEOUT_S", "EXECUTORS", "TIMING_COLUMNS",
           "DaskExecutor", "DaskTls",
           "Executor", "LocalPool", "check_scheduler_address", "make_executor",
           "one_thread_per_worker", "sigterm_as_interrupt"]
