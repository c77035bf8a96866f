"""A local Dask cluster of real processes for the tests and the benchmark: one ``dask scheduler``
and N ``dask worker --nthreads 1 --no-nanny`` processes, bound to 127.0.0.1 on ports the OS
chooses, each in its own process group, each stopped by its id.

Readiness is read from the processes' own log lines (the scheduler's ``Scheduler at: ADDRESS``,
a worker's ``Registered to:``), never slept for. ``--no-nanny``: the process we start is the
worker, so SIGKILL to it is a worker lost with its job (a nanny would restart it in place).

``tls_dir``: a folder made by ``swarmloc tls make-ca`` holding ``scheduler.pem`` and
``worker.pem`` (``swarmloc tls issue``): the scheduler listens on ``tls://`` and every process
requires mutual TLS with that CA (Dask's ``--tls-ca-file --tls-cert --tls-key``).
"""

from __future__ import annotations

import os
import queue
import re
import signal
import subprocess
import sys
import tempfile
import threading
import time
from dataclasses import dataclass, field

_SCHEDULER_AT = re.compile(r"Scheduler at:\s+((?:tcp|tls)://127\.0\.0\.1:\d+)")


def _env() -> dict:
    env = dict(os.environ)
    env.update({k: "1" for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS", "MKL_NUM_THREADS")})
    return env


class _Lines:
    """A reader thread for a process's stderr: every line kept, and a queue to wait on."""

    def __init__(self, proc: subprocess.Popen) -> None:
        self.lines: list[str] = []
        self.queue: queue.Queue[str | None] = queue.Queue()
        self._thread = threading.Thread(target=self._read, args=(proc,), daemon=True)
        self._thread.start()

    def _read(self, proc) -> None:
        for line in proc.stderr:
            self.lines.append(line)
            self.queue.put(line)
        self.queue.put(None)

    def wait_for(self, pattern: re.Pattern | str, timeout_s: float) -> re.Match:
        pattern = re.compile(pattern) if isinstance(pattern, str) else pattern
        end = time.monotonic() + timeout_s
        while True:
            left = end - time.monotonic()
            if left <= 0:
                raise TimeoutError(f"no line matching {pattern.pattern!r} within {timeout_s} s:\n"
                                   + "".join(self.lines[-20:]))
            try:
                line = self.queue.get(timeout=left)
            except queue.Empty:
                continue
            if line is None:
                raise RuntimeError("process ended before printing "
                                   f"{pattern.pattern!r}:\n" + "".join(self.lines[-20:]))
            m = pattern.search(line)
            if m:
                return m


@dataclass
class LocalDaskCluster:
    """``with LocalDaskCluster(workers=2) as cluster: cluster.address``."""

    workers: int = 2
    tls_dir: str | None = None
    address: str = ""
    scheduler: subprocess.Popen | None = None
    worker_procs: list[subprocess.Popen] = field(default_factory=list)
    #: Each worker's own address (``Start worker at:``), by process id.
    worker_address: dict[int, str] = field(default_factory=dict)
    _logs: dict[int, _Lines] = field(default_factory=dict)
    #: The workers' scratch space (not the shared /tmp/dask-scratch-space).
    _scratch: tempfile.TemporaryDirectory | None = None

    def _start(self, argv: list[str]) -> subprocess.Popen:
        proc = subprocess.Popen([sys.executable, "-m", *argv], stdin=subprocess.DEVNULL,
                                stdout=subprocess.DEVNULL, stderr=subprocess.PIPE, text=True,
                                env=_env(), start_new_session=True)
        self._logs[proc.pid] = _Lines(proc)
        return proc

    def _tls(self, name: str) -> list[str]:
        if self.tls_dir is None:
            return []
        folder = os.fspath(self.tls_dir)
        return ["--tls-ca-file", os.path.join(folder, "ca.pem"),
                "--tls-cert", os.path.join(folder, f"{name}.pem"),
                "--tls-key", os.path.join(folder, f"{name}-key.pem")]

    def __enter__(self) -> LocalDaskCluster:  # noqa: PYI034 -- a final test helper
        self._scratch = tempfile.TemporaryDirectory(prefix="swarmloc-dask-")
        try:
            self.scheduler = self._start(["distributed.cli.dask_scheduler", "--host", "127.0.0.1",
                                          "--port", "0", "--dashboard-address", "127.0.0.1:0",
                                          *(["--protocol", "tls"] if self.tls_dir else []),
                                          *self._tls("scheduler")])
            self.address = self._logs[self.scheduler.pid].wait_for(_SCHEDULER_AT, 60).group(1)
            for i in range(self.workers):
                self.add_worker(f"w{i}")
        except BaseException:
            self.__exit__(None, None, None)
            raise
        return self

    def add_worker(self, name: str) -> subprocess.Popen:
        proc = self._start(["distributed.cli.dask_worker", self.address, "--nthreads", "1",
                            "--no-nanny", "--host", "127.0.0.1", "--local-directory",
                            self._scratch.name, "--dashboard-address",
                            "127.0.0.1:0", "--name", name, *self._tls("worker")])
        self.worker_procs.append(proc)
        logs = self._logs[proc.pid]
        self.worker_address[proc.pid] = logs.wait_for(r"Start worker at:\s+((?:tcp|tls)://\S+)", 60).group(1)
        logs.wait_for("Registered to:", 60)
        return proc

    def log(self, proc: subprocess.Popen) -> str:
        return "".join(self._logs[proc.pid].lines)

    def kill_worker(self, proc: subprocess.Popen) -> None:
        """SIGKILL, as a lost machine: no goodbye to the scheduler."""
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=10)

    def __exit__(self, *exc) -> None:
        for proc in [*self.worker_procs, self.scheduler]:
            if proc is not None and proc.poll() is None:
                proc.terminate()
        for proc in [*self.worker_procs, self.scheduler]:
            if proc is None:
                continue
            try:
                proc.wait(timeout=15)
            except subprocess.TimeoutExpired:
                proc.kill()
                proc.wait(timeout=5)
            self._logs[proc.pid]._thread.join(timeout=5)
        if self._scratch is not None:
            self._scratch.cleanup()
