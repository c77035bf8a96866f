"""Launch and supervise a local swarm: a Zenoh router, the world-server and N agent processes.

Every piece is its own OS process, started with ``subprocess`` (never fork: a forked child that
opens a Zenoh session hangs, see ZENOH.md) in its own process group, so that everything started
is stopped by id at the end, even on an error or Ctrl-C.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
from contextlib import contextmanager
from dataclasses import dataclass, field
from pathlib import Path

PYTHON = [sys.executable, "-m", "swarmloc"]

#: Environment of every piece: one BLAS thread. numpy's OpenBLAS otherwise keeps worker threads
#: that spin after each small matrix product; a hundred agent processes on two cores each
#: spinning cost 25 % of the tick rate at 10 robots (163 -> 219 ticks/s measured).
CHILD_ENV = {"PYTHONUNBUFFERED": "1", "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1",
             "MKL_NUM_THREADS": "1"}
#: Zenoh's async pools (rx, tx, net, acc) handed over to one worker thread of its app pool, as
#: the ``ZENOH_RUNTIME`` variable that Zenoh reads when a process opens its first session. Local
#: e-puck agents run on it (deploy/run.py: start_swarm): an agent sends and receives two small
#: messages a tick, and with a hundred of them on two cores the hand-overs between Zenoh's default
#: pools cost more than they save (100 agents of ES3: 37.1 -> 39.4 ticks/s, three pairs of
#: 600-tick runs). Other pieces keep the defaults: on one thread a single 300 KB message (a vision
#: image) stalled that thread past the link lease, and the world lost every agent's liveliness;
#: the world-server itself gains nothing measurable from it. A ZENOH_RUNTIME set by the user wins.
ONE_THREAD_ZENOH_RUNTIME = (
    "(rx: (handover: app), net: (handover: app), acc: (handover: app), tx: (handover: app), "
    "app: (worker_threads: 1))"
)
#: The world-server's ``ZENOH_RUNTIME`` (deploy/cli.py: main_world sets it before its session
#: opens; a ZENOH_RUNTIME set by the user wins): the acceptor's pool handed over to the two
#: receiving workers. With Zenoh's defaults the agents' links were read by three threads (rx-0,
#: rx-1 and acc-0), each woken about 2,800 times a second at 400 real-time agents; handed over,
#: two threads woke 1,500-1,700 times each. Measured at 400 agents (issue 47, `/proc` per
#: thread, 8 s mid-run): the world 412-504 ms of CPU a second (three runs) -> 362-391 (two).
#: One receiving worker saved no more, and lost up to half of tests/test_fuzz.py's 60,000 bad
#: Acts in one run of three: a flood that fills the Act queue stops the only thread that reads
#: the links. The plain-Zenoh floor's world gains nothing from either (19.9 -> 19.7 ms a tick).
WORLD_ZENOH_RUNTIME = "(acc: (handover: rx))"


@dataclass
class Supervisor:
    """Owns child processes; :meth:`stop_all` ends every one of them, by process group."""

    procs: list[subprocess.Popen] = field(default_factory=list)

    def start(self, args: list[str], *, log_path: Path | None = None, stdout=None,
              env: dict[str, str] | None = None) -> subprocess.Popen:
        """Start ``swarmloc ARGS`` in its own process group. Its stderr (and its stdout unless
        ``stdout`` is given, e.g. ``subprocess.PIPE``) goes to ``log_path``, else nowhere.
        ``env``: defaults for the child's environment, under ours (ours wins)."""
        # The child inherits the descriptor; ours is closed right after the start.
        log = open(log_path, "ab") if log_path else None  # noqa: SIM115
        sink = log if log is not None else subprocess.DEVNULL
        try:
            proc = subprocess.Popen(
                PYTHON + args,
                stdout=stdout if stdout is not None else sink,
                stderr=sink,
                stdin=subprocess.DEVNULL,
                start_new_session=True,
                env={**(env or {}), **os.environ, **CHILD_ENV},
            )
        finally:
            if log is not None:
                log.close()
        self.procs.append(proc)
        return proc

    def stop_all(self, grace_s: float = 5.0) -> None:
        for proc in self.procs:
            if proc.poll() is None:
                _signal_group(proc, signal.SIGTERM)
        deadline = time.monotonic() + grace_s
        for proc in self.procs:
            left = max(0.0, deadline - time.monotonic())
            try:
                proc.wait(timeout=left)
            except subprocess.TimeoutExpired:
                _signal_group(proc, signal.SIGKILL)
                proc.wait()


def _signal_group(proc: subprocess.Popen, sig: int) -> None:
    try:
        os.killpg(proc.pid, sig)
    except ProcessLookupError:
        pass


@contextmanager
def supervised():
    sup = Supervisor()
    try:
        yield sup
    finally:
        sup.stop_all()


def start_router(sup: Supervisor, listen: str = "tcp/127.0.0.1:0", timeout_s: float = 30.0) -> tuple[subprocess.Popen, str]:
    """Start ``swarmloc router``; return it and the endpoint it really listens on."""
    return start_announcing(sup, ["router", "-l", listen, "--announce"], timeout_s=timeout_s)


def start_announcing(
    sup: Supervisor, args: list[str], *, log_path: Path | None = None, timeout_s: float = 60.0
) -> tuple[subprocess.Popen, str | None]:
    """Start a piece that prints one JSON line with its bound endpoints once it listens (the
    readiness signal); return the process and its TCP endpoint (None for a client, which
    listens on none). Its log goes to ``log_path``."""
    proc = sup.start(args, stdout=subprocess.PIPE, log_path=log_path)
    box: dict = {}

    def read():
        line = proc.stdout.readline()
        box["line"] = line

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    reader.join(timeout_s)
    line = box.get("line", b"")
    if not line:
        raise RuntimeError(f"`swarmloc {args[0]}` did not announce its endpoint within {timeout_s:.0f} s")
    endpoints = json.loads(line)["endpoints"]
    tcp = [e for e in endpoints if e.startswith("tcp/")]
    return proc, (tcp or endpoints or [None])[0]
