"""Test helpers for experiment runs as real processes (``tests/test_dask_executor.py``,
``tests/test_local_pool.py``): a small spec, the rows of a results file, and waiting on the
client's rows (each row is one write call) instead of sleeping."""

from __future__ import annotations

import csv
import subprocess
import textwrap
import time
from pathlib import Path

from swarmloc.deploy.lab.executors import TIMING_COLUMNS
from swarmloc.deploy.lab.experiment import load_spec, plan

#: A smoke spec (``name`` to fill in as well): ES1 at 30 simulated seconds, two strategies,
#: two replications (4 jobs).
SMALL = """\
name = "{name}"
replications = {replications}
seed = 1
[[group]]
name = "g"
scenarios = ["ES1"]
duration_s = {duration}
[group.grid]
"agent.strategy" = ["NC", "SSGIKF"]
"""


def spec_file(tmp_path: Path, replications: int = 2, duration: float = 30.0) -> Path:
    path = tmp_path / f"small-{replications}-{duration:g}.toml"
    path.write_text(textwrap.dedent(SMALL.format(name="small", replications=replications, duration=duration)))
    return path


def read_rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def model_columns(rows: list[dict]) -> list[tuple]:
    """Each row without its timing columns, sorted by (setting, seed)."""
    return sorted(tuple((k, v) for k, v in r.items() if k not in TIMING_COLUMNS) for r in rows)


def keys(rows: list[dict]) -> list[tuple[str, int]]:
    return sorted((r["setting"], int(r["seed"])) for r in rows)


def planned(spec_path: Path) -> list[tuple[str, int]]:
    return sorted((j.setting, j.seed) for j in plan(load_spec(spec_path)))


def wait_for_rows(out: Path, n: int, proc: subprocess.Popen, timeout_s: float = 120.0) -> None:
    """Until the results file holds ``n`` complete rows (header aside) or the client ended."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if out.exists() and out.read_bytes().count(b"\n") >= n + 1:
            return
        if proc.poll() is not None:
            raise AssertionError(f"client ended early ({proc.returncode}): {proc.stderr.read()}")
        time.sleep(0.01)  # polling a file that the client appends to; not a readiness guess
    raise AssertionError(f"fewer than {n} rows after {timeout_s} s")


def stop(proc: subprocess.Popen) -> tuple[str, str]:
    try:
        return proc.communicate(timeout=120)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait(timeout=10)
