"""The local pool (``deploy/lab/executors.py: LocalPool``) with real spawned processes: its worker
processes serve every job of a run and, when the caller owns the pool, successive runs; a worker
killed with SIGKILL mid-run leaves every row present exactly once (the jobs the broken pool lost
run again on a fresh one).

Mid-run moments are observed, not slept for: the test waits for the client's first row in the
results file (each row is one write call) before it kills.
"""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
from grid_helpers import keys, model_columns, planned, read_rows, spec_file, stop, wait_for_rows

from swarmloc.deploy.lab.executors import LocalPool
from swarmloc.deploy.lab.experiment import load_spec, run_experiment

pytestmark = pytest.mark.integration


def _children(pid: int) -> list[int]:
    """The pool's worker processes among ``pid``'s children (``multiprocessing.spawn``; not its
    resource tracker)."""
    found = []
    for entry in Path("/proc").iterdir():
        if not entry.name.isdigit():
            continue
        try:
            ppid = int((entry / "stat").read_text().rsplit(")", 1)[1].split()[1])
            cmdline = (entry / "cmdline").read_bytes()
        except (OSError, IndexError, ValueError):
            continue
        if ppid == pid and b"spawn_main" in cmdline:
            found.append(int(entry.name))
    return sorted(found)


def test_a_pool_serves_every_job_and_successive_runs_with_the_same_processes(tmp_path):
    spec = load_spec(spec_file(tmp_path))
    pool = LocalPool(2)
    try:
        assert run_experiment(spec, tmp_path / "a.csv", progress=False, executor=pool) == 4
        first = pool.pids()
        assert len(first) == 2
        assert run_experiment(spec, tmp_path / "b.csv", progress=False, executor=pool) == 4
        assert pool.pids() == first  # the same two processes ran the second run's jobs
    finally:
        pool.close()
    assert pool.pids() == []
    for pid in first:  # the processes ended with close()
        assert not Path(f"/proc/{pid}").exists() or "Z" in Path(f"/proc/{pid}/stat").read_text().split()[2]
    assert model_columns(read_rows(tmp_path / "a.csv")) == model_columns(read_rows(tmp_path / "b.csv"))


def test_worker_killed_mid_run_leaves_every_row_exactly_once(tmp_path):
    spec_path, out = spec_file(tmp_path, replications=6, duration=1800.0), tmp_path / "out.csv"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    proc = subprocess.Popen([sys.executable, "-m", "swarmloc.deploy.cli", "experiment",
                             str(spec_path), "--out", str(out), "--workers", "2"],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)
    try:
        wait_for_rows(out, 1, proc)
        workers = _children(proc.pid)
        assert len(workers) == 2, workers
        os.kill(workers[0], signal.SIGKILL)
    finally:
        stdout, stderr = stop(proc)
    assert proc.returncode == 0, stderr
    assert "a worker process died; running the" in stderr
    assert "12 new rows" in stdout
    assert keys(read_rows(out)) == planned(spec_path)  # every row, none twice
    local = tmp_path / "again.csv"
    run_experiment(load_spec(spec_path), local, workers=2, progress=False)
    assert model_columns(read_rows(out)) == model_columns(read_rows(local))


def _alive(pid: int) -> bool:
    try:
        state = (Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return False
    return state != "Z"


def test_a_sigkilled_experiment_leaves_no_worker_behind(tmp_path):
    # Issue 47: every SIGKILL of `swarmloc experiment` left its pool workers (and the resource
    # tracker they kept alive) running as orphans. The workers now ask for SIGTERM when their
    # parent dies (executors._init_worker).
    import time

    out = tmp_path / "rows.csv"
    proc = subprocess.Popen([sys.executable, "-m", "swarmloc", "experiment", str(spec_file(tmp_path, 4, 300.0)),
                             "--workers", "2", "--out", str(out)], stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, start_new_session=True)
    seen: list[int] = []
    try:
        wait_for_rows(out, 1, proc)  # the pool is up and working
        seen = _children(proc.pid)
        helpers = [int(e.name) for e in Path("/proc").iterdir()
                   if e.name.isdigit() and _parent(int(e.name)) == proc.pid]  # workers, resource tracker
        assert len(seen) == 2, seen
        proc.kill()
        proc.wait(timeout=10)
        end = time.monotonic() + 30
        while time.monotonic() < end and any(_alive(p) for p in helpers):
            time.sleep(0.05)  # polling for the kernel's signal to land; not a readiness guess
        assert not [p for p in helpers if _alive(p)], "children of the killed experiment still run"
    finally:
        for pid in seen:
            if _alive(pid):
                os.kill(pid, signal.SIGKILL)
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=10)


def _parent(pid: int) -> int:
    try:
        return int((Path("/proc") / str(pid) / "stat").read_text().rsplit(")", 1)[1].split()[1])
    except (OSError, IndexError, ValueError):
        return -1


def test_an_experiment_killed_at_random_moments_resumes_to_an_uninterrupted_runs_rows(tmp_path):
    # Issue 47: SIGKILL `swarmloc experiment` at seeded random moments (after 1-3 new rows, or
    # while the pool is still starting), once leaving half a row as a kill inside a write would,
    # then resume each time with the same command. The final file holds every planned row once,
    # equal to an uninterrupted run's (timing columns aside), and no process of a killed run lives.
    import random
    import time

    spec = spec_file(tmp_path, 5, 120.0)  # 10 jobs
    reference = tmp_path / "reference.csv"
    run_experiment(load_spec(spec), reference, executor="inline", progress=False)
    out = tmp_path / "rows.csv"
    rng = random.Random(47)
    command = [sys.executable, "-m", "swarmloc", "experiment", str(spec), "--workers", "2", "--out", str(out)]
    killed_helpers: list[int] = []
    stderr: list[str] = []
    for attempt in range(3):
        proc = subprocess.Popen(command, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                                start_new_session=True)
        try:
            before = out.read_bytes().count(b"\n") - 1 if out.exists() else 0
            if attempt > 0:  # the first kill lands while the pool starts: no row yet
                wait_for_rows(out, before + rng.randint(1, 2), proc)
            else:
                deadline = time.monotonic() + 60  # until the pool's workers exist, then at once
                while not _children(proc.pid) and time.monotonic() < deadline:
                    time.sleep(0.01)  # polling /proc for the workers; not a readiness guess
            killed_helpers += [int(e.name) for e in Path("/proc").iterdir()
                               if e.name.isdigit() and _parent(int(e.name)) == proc.pid]
            proc.kill()
            stderr.append(proc.communicate(timeout=30)[1])
        finally:
            if proc.poll() is None:
                os.killpg(proc.pid, signal.SIGKILL)
                proc.communicate(timeout=10)
        if attempt == 1 and out.exists():  # what a kill inside the one write of a row leaves
            rows = out.read_bytes().split(b"\n")
            with open(out, "ab") as handle:
                handle.write(rows[1][: len(rows[1]) // 2])
    done = subprocess.run(command, capture_output=True, text=True, timeout=600, check=False)
    assert done.returncode == 0, done.stderr[-2000:]
    # the half row was cut off by the next start (the third attempt), not read as a row
    assert "cutting off an unfinished last row" in stderr[2], stderr[2][-2000:]
    rows = read_rows(out)
    assert keys(rows) == planned(spec), "every planned row once, none twice, none torn"
    assert model_columns(rows) == model_columns(read_rows(reference))
    end = time.monotonic() + 30
    while time.monotonic() < end and any(_alive(p) for p in killed_helpers):
        time.sleep(0.05)  # the kernel's parent-death signal landing; not a readiness guess
    assert not [p for p in killed_helpers if _alive(p)], "a process of a killed run still lives"
