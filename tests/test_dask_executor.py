"""``swarmloc experiment --executor dask`` on a local Dask cluster of real processes (a scheduler
and two workers started by the test, 127.0.0.1, ports chosen by the OS, ``tests/dask_cluster.py``):
its rows equal the local pool's (every column but :data:`TIMING_COLUMNS`), a worker killed with
SIGKILL mid-run leaves every row present exactly once, an interrupted client resumes, and a bad
or unreachable scheduler stops the command (exit 2, the problem named) with no row lost.

Mid-run moments are observed, not slept for: the test waits for the client's first row in the
results file (each row is one write call) before it kills or interrupts.
"""

from __future__ import annotations

import os
import signal
import socket
import subprocess
import sys
import time
from pathlib import Path

import pytest
from dask_cluster import LocalDaskCluster
from grid_helpers import keys, model_columns, planned, read_rows, spec_file, stop, wait_for_rows

from swarmloc.deploy.cli import main as swarmloc_main
from swarmloc.deploy.lab.executors import check_scheduler_address
from swarmloc.deploy.lab.experiment import load_spec, run_experiment

pytestmark = pytest.mark.integration

pytest.importorskip("distributed")

def _client(spec: Path, out: Path, address: str) -> subprocess.Popen:
    """``swarmloc experiment`` on the cluster, as its own process (progress lines on stderr)."""
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    # A test run started in the background of a non-interactive shell has SIGINT ignored, which a
    # child inherits and Python then keeps: the interrupt tests' Ctrl-C was lost. A handler of
    # ours is reset to the default at exec, so the child gets the default and KeyboardInterrupt.
    if signal.getsignal(signal.SIGINT) == signal.SIG_IGN:
        signal.signal(signal.SIGINT, signal.default_int_handler)
    return subprocess.Popen([sys.executable, "-m", "swarmloc.deploy.cli", "experiment", str(spec),
                             "--out", str(out), "--executor", "dask", "--scheduler", address],
                            stdin=subprocess.DEVNULL, stdout=subprocess.PIPE,
                            stderr=subprocess.PIPE, text=True, env=env, start_new_session=True)



@pytest.fixture(scope="module")
def cluster():
    with LocalDaskCluster(workers=2) as running:
        yield running


def test_dask_rows_equal_local_rows(tmp_path, cluster):
    spec_path = spec_file(tmp_path)
    spec = load_spec(spec_path)
    local, dask = tmp_path / "local.csv", tmp_path / "dask.csv"
    assert run_experiment(spec, local, workers=2, progress=False) == 4
    assert run_experiment(spec, dask, progress=False, executor="dask",
                          scheduler=cluster.address) == 4
    assert local.read_text().splitlines()[0] == dask.read_text().splitlines()[0]
    assert keys(read_rows(dask)) == planned(spec_path)
    assert model_columns(read_rows(dask)) == model_columns(read_rows(local))
    # Resume is the same too: nothing left to run.
    assert run_experiment(spec, dask, progress=False, executor="dask",
                          scheduler=cluster.address) == 0


def test_cli_shows_progress_and_time_left(tmp_path, cluster):
    spec_path, out = spec_file(tmp_path), tmp_path / "out.csv"
    proc = _client(spec_path, out, cluster.address)
    stdout, stderr = stop(proc)
    assert proc.returncode == 0, stderr
    assert "4 jobs to run on 2 workers" in stderr
    assert "4/4 jobs (100 %)" in stderr and "left" in stderr
    assert "4 new rows" in stdout
    assert keys(read_rows(out)) == planned(spec_path)


def test_worker_killed_mid_run_leaves_every_row_exactly_once(tmp_path):
    """Its own cluster (the killed worker is gone for good): 12 jobs of ~1 s; once the first row
    is in and the scheduler says the victim is processing a job, it is killed with SIGKILL; the
    scheduler runs its job again on the other, and the file ends with every (setting, seed)
    once, equal to a local run."""
    import distributed

    spec_path, out = spec_file(tmp_path, replications=6, duration=1800.0), tmp_path / "out.csv"
    with LocalDaskCluster(workers=2) as own:
        proc = _client(spec_path, out, own.address)
        try:
            wait_for_rows(out, 1, proc)
            victim = own.worker_procs[0]
            victim_address = own.worker_address[victim.pid]
            with distributed.Client(own.address, timeout=10, set_as_default=False) as watcher:
                end = time.monotonic() + 60
                while not watcher.processing(workers=[victim_address]).get(victim_address):
                    assert time.monotonic() < end, "the victim never held a job"
                    time.sleep(0.01)  # polling the scheduler's own view
                own.kill_worker(victim)
            assert victim.returncode == -signal.SIGKILL
        finally:
            _stdout, stderr = stop(proc)
        assert f"Remove worker addr: {victim_address}" in own.log(own.scheduler)
        assert proc.returncode == 0, stderr
        rows = read_rows(out)
        assert keys(rows) == planned(spec_path)  # every row, none twice
        assert own.worker_procs[1].poll() is None
    local = tmp_path / "local.csv"
    run_experiment(load_spec(spec_path), local, workers=2, progress=False)
    assert model_columns(rows) == model_columns(read_rows(local))


@pytest.mark.parametrize("sig", [signal.SIGINT, signal.SIGTERM], ids=["SIGINT", "SIGTERM"])
def test_interrupted_client_resumes_with_every_row_once(tmp_path, cluster, sig):
    spec_path, out = spec_file(tmp_path, replications=6, duration=1800.0), tmp_path / "out.csv"
    proc = _client(spec_path, out, cluster.address)
    try:
        wait_for_rows(out, 1, proc)
        proc.send_signal(sig)
    finally:
        _, stderr = stop(proc)
    assert proc.returncode == 130, stderr
    assert "run the same command again to resume" in stderr
    before = out.read_bytes()
    first = read_rows(out)
    assert 1 <= len(first) < 12 and len(set(keys(first))) == len(first)

    again = _client(spec_path, out, cluster.address)
    stdout, stderr = stop(again)
    assert again.returncode == 0, stderr
    assert f"{12 - len(first)} new rows" in stdout
    assert out.read_bytes().startswith(before)  # nothing written before is lost or changed
    assert keys(read_rows(out)) == planned(spec_path)


# -- bad input --------------------------------------------------------------------------------


@pytest.mark.parametrize(("address", "message"), [
    ("127.0.0.1:8786", r"not a Dask scheduler address \(did you mean tcp://127\.0\.0\.1:8786\?\)"),
    ("tcp://127.0.0.1", "not a Dask scheduler address"),
    ("tcp://127.0.0.1:99999", "port 99999 is not in 1..65535"),
    ("http://host:8786", "not a Dask scheduler address"),
    ("tcp://bad host:8786", "not a Dask scheduler address"),
])
def test_malformed_scheduler_address_is_refused(address, message):
    from swarmloc.config import ConfigError

    with pytest.raises(ConfigError, match=message):
        check_scheduler_address(address)


def _results_with_rows(tmp_path: Path, spec_path: Path) -> Path:
    out = tmp_path / "out.csv"
    run_experiment(load_spec(spec_path), out, workers=1, progress=False, limit=2)
    assert len(read_rows(out)) == 2
    return out


@pytest.mark.parametrize("case", ["malformed", "unreachable", "no-scheduler", "scheduler-for-local"])
def test_bad_scheduler_stops_the_command_and_loses_no_row(tmp_path, capsys, case):
    spec_path = spec_file(tmp_path)
    out = _results_with_rows(tmp_path, spec_path)
    before = out.read_bytes()
    holder = None
    if case == "malformed":
        flags, message = ["--executor", "dask", "--scheduler", "tcp:/127.0.0.1:8786"], \
            "--scheduler 'tcp:/127.0.0.1:8786': not a Dask scheduler address"
    elif case == "unreachable":
        # A port that is bound (so nobody else takes it) but never listens: connections refused.
        holder = socket.socket()
        holder.bind(("127.0.0.1", 0))
        address = f"tcp://127.0.0.1:{holder.getsockname()[1]}"
        flags = ["--executor", "dask", "--scheduler", address, "--scheduler-timeout-s", "2"]
        message = f"--scheduler {address}: no Dask scheduler answered within 2 s"
    elif case == "no-scheduler":
        flags, message = ["--executor", "dask"], "--executor dask needs --scheduler ADDRESS"
    else:
        flags, message = ["--scheduler", "tcp://127.0.0.1:8786"], "--scheduler is for --executor dask"
    try:
        assert swarmloc_main(["experiment", str(spec_path), "--out", str(out), *flags]) == 2
    finally:
        if holder is not None:
            holder.close()
    assert message in capsys.readouterr().err
    assert out.read_bytes() == before  # not one byte written or lost
    # And a fresh file is not even created.
    fresh = tmp_path / "fresh.csv"
    if case != "scheduler-for-local":
        assert swarmloc_main(["experiment", str(spec_path), "--out", str(fresh), *flags]) == 2
        assert not fresh.exists()


# -- no worker yet ----------------------------------------------------------------------------


def test_no_worker_yet_waits_with_a_message_then_runs_every_job(tmp_path):
    """A scheduler with no worker: the client says so and waits; once a worker registers, every
    job runs and every row is written once."""
    spec_path, out = spec_file(tmp_path), tmp_path / "out.csv"
    with LocalDaskCluster(workers=0) as empty:
        proc = _client(spec_path, out, empty.address)
        try:
            waiting = ""
            for line in proc.stderr:  # the client's own line, not a sleep
                if "no Dask worker is connected" in line:
                    waiting = line
                    break
            assert empty.address in waiting and "waiting up to 600 s" in waiting
            assert not out.exists()  # nothing opened while no worker can run a job
            empty.add_worker("late")
        finally:
            stdout, stderr = stop(proc)
        assert proc.returncode == 0, stderr
        assert "4 new rows" in stdout
        assert keys(read_rows(out)) == planned(spec_path)


def test_no_worker_within_the_timeout_stops_the_command_and_loses_no_row(tmp_path, capsys):
    spec_path = spec_file(tmp_path)
    out = _results_with_rows(tmp_path, spec_path)
    before = out.read_bytes()
    with LocalDaskCluster(workers=0) as empty:
        flags = ["--executor", "dask", "--scheduler", empty.address, "--worker-timeout-s", "1"]
        assert swarmloc_main(["experiment", str(spec_path), "--out", str(out), *flags]) == 2
        err = capsys.readouterr().err
        assert f"--scheduler {empty.address}: no Dask worker connected within 1 s" in err
        assert out.read_bytes() == before
        fresh = tmp_path / "fresh.csv"
        assert swarmloc_main(["experiment", str(spec_path), "--out", str(fresh), *flags]) == 2
        assert not fresh.exists()
        # The scheduler saw the client go: no client is left connected to it.
        assert "Close client connection" in empty.log(empty.scheduler)


# -- Dask's own mutual TLS --------------------------------------------------------------------


@pytest.fixture(scope="module")
def pki(tmp_path_factory):
    """The lab's CA (``swarmloc tls make-ca``) with certificates for the scheduler, the workers and
    the client, and a second CA with a client certificate of its own."""
    from swarmloc.protocol.tls import issue, make_ca

    lab, other = tmp_path_factory.mktemp("pki"), tmp_path_factory.mktemp("other-pki")
    make_ca(lab)
    for name in ("scheduler", "worker", "client"):
        issue(lab, name)
    make_ca(other, common_name="another lab's CA")
    issue(other, "client")
    return lab, other


@pytest.fixture(scope="module")
def tls_cluster(pki):
    with LocalDaskCluster(workers=2, tls_dir=str(pki[0])) as running:
        assert running.address.startswith("tls://")
        yield running


def _tls_flags(folder: Path, name: str = "client", ca: Path | None = None) -> list[str]:
    return ["--tls-ca-file", str(ca or folder / "ca.pem"), "--tls-cert", str(folder / f"{name}.pem"),
            "--tls-key", str(folder / f"{name}-key.pem")]


def test_tls_cluster_rows_equal_local_rows(tmp_path, pki, tls_cluster):
    """A client with the lab's certificate runs the spec on the TLS cluster (its own process, as
    a user would); the rows equal the local pool's."""
    spec_path, out = spec_file(tmp_path), tmp_path / "tls.csv"
    env = dict(os.environ, PYTHONUNBUFFERED="1")
    done = subprocess.run([sys.executable, "-m", "swarmloc.deploy.cli", "experiment",
                           str(spec_path), "--out", str(out), "--executor", "dask",
                           "--scheduler", tls_cluster.address, *_tls_flags(pki[0])],
                          check=False, stdin=subprocess.DEVNULL, capture_output=True, text=True,
                          env=env,
                          timeout=300)
    assert done.returncode == 0, done.stderr
    assert "4 new rows" in done.stdout
    local = tmp_path / "local.csv"
    run_experiment(load_spec(spec_path), local, workers=2, progress=False)
    assert keys(read_rows(out)) == planned(spec_path)
    assert model_columns(read_rows(out)) == model_columns(read_rows(local))
    # Every connection the scheduler accepted was TLS, and the workers registered over it.
    assert all(a.startswith("tls://") for a in tls_cluster.worker_address.values())


@pytest.mark.parametrize("case", ["no-certificate", "plain-tcp", "other-ca", "foreign-cert",
                                  "refused-by-scheduler", "expired", "missing-key", "tls-for-tcp"])
def test_bad_tls_stops_the_command_and_loses_no_row(tmp_path, capsys, pki, tls_cluster, case):
    """Each refusal exits 2 with a message naming the problem, before any row is written; the
    results file keeps every byte."""
    import datetime as dt

    from swarmloc.protocol.tls import issue

    lab, other = pki
    spec_path = spec_file(tmp_path)
    out = _results_with_rows(tmp_path, spec_path)
    before = out.read_bytes()
    address = tls_cluster.address
    flags = ["--executor", "dask", "--scheduler", address, "--scheduler-timeout-s", "3"]
    if case == "no-certificate":
        message = f"--scheduler {address}: a tls:// scheduler needs this client's certificate"
    elif case == "plain-tcp":
        # A client that does not speak TLS at all: the scheduler hangs up on it.
        flags[3] = address.replace("tls://", "tcp://")
        message = f"--scheduler {flags[3]}: the scheduler closed the connection"
    elif case == "other-ca":
        # Another lab's CA and certificate: this client cannot trust the scheduler's certificate.
        flags += _tls_flags(other)
        message = f"--scheduler {address}: the scheduler's TLS certificate is not signed by " \
                  f"--tls-ca-file {other / 'ca.pem'}"
    elif case == "foreign-cert":
        flags += _tls_flags(other, ca=lab / "ca.pem")
        message = f"Dask TLS certificate {other / 'client.pem'}: not signed by the CA {lab / 'ca.pem'}"
    elif case == "refused-by-scheduler":
        # The client trusts both CAs (a bundle) and shows the other lab's certificate: the
        # scheduler, which trusts only the lab's CA, ends the handshake.
        bundle = tmp_path / "bundle.pem"
        bundle.write_bytes((other / "ca.pem").read_bytes() + (lab / "ca.pem").read_bytes())
        flags += _tls_flags(other, ca=bundle)
        message = f"--scheduler {address}: the scheduler refused this client's certificate " \
                  f"{other / 'client.pem'}"
    elif case == "expired":
        folder = tmp_path / "pki"
        folder.mkdir()
        for name in ("ca.pem", "ca-key.pem"):
            (folder / name).write_bytes((lab / name).read_bytes())
        issue(folder, "old", days=1, valid_from=dt.datetime(2024, 1, 1, tzinfo=dt.UTC))
        flags += _tls_flags(folder, "old")
        message = f"Dask TLS certificate {folder / 'old.pem'}: expired on 2024-01-02 00:00 UTC"
    elif case == "missing-key":
        flags += ["--tls-ca-file", str(lab / "ca.pem"), "--tls-cert", str(lab / "client.pem")]
        message = "Dask TLS needs --tls-ca-file, --tls-cert and --tls-key; missing --tls-key"
    else:
        flags[3] = "tcp://127.0.0.1:8786"
        flags += _tls_flags(lab)
        message = "--tls-cert is for a tls:// scheduler; --scheduler is tcp://127.0.0.1:8786 " \
                  "(did you mean tls://127.0.0.1:8786?)"
    assert swarmloc_main(["experiment", str(spec_path), "--out", str(out), *flags]) == 2
    assert message in capsys.readouterr().err
    assert out.read_bytes() == before
    fresh = tmp_path / "fresh.csv"
    assert swarmloc_main(["experiment", str(spec_path), "--out", str(fresh), *flags]) == 2
    assert not fresh.exists()
