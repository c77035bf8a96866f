"""Test helper: run a ``swarmloc`` command as a process to its end, and never leave it behind."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path


def run_swarmloc(args: list[str], *, cwd: Path, timeout_s: float, env: dict | None = None,
                 python: str = sys.executable) -> subprocess.CompletedProcess:
    """``python -m swarmloc ARGS`` with its output captured; on a timeout, SIGTERM (``swarmloc
    run`` then stops every piece it started), then SIGKILL, and TimeoutExpired is raised."""
    proc = subprocess.Popen([python, "-m", "swarmloc", *args], cwd=cwd, env=env, text=True,
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, stdin=subprocess.DEVNULL,
                            start_new_session=True)
    try:
        stdout, stderr = proc.communicate(timeout=timeout_s)
    except subprocess.TimeoutExpired:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.communicate(timeout=20)
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.wait()
        raise
    return subprocess.CompletedProcess(proc.args, proc.returncode, stdout, stderr)
