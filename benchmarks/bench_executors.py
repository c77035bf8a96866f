"""Experiment executors: runs per second and overhead per job, the Dask executor against the local
pool, on this machine with two workers each.

Workloads (e-puck batch jobs, as ``swarmloc experiment`` runs them):

- short: ES1 shortened to 30 simulated seconds (about 20 ms of compute per job), 2 strategies x
  ``--short-replications`` (default 30) = 60 jobs;
- long: ES3 at its full 7200 s (100 robots; about 9 s per job here), 2 strategies x
  ``--long-replications`` (default 2) = 4 jobs.

Each executor runs the same spec into a fresh results file with :func:`run_experiment`:

- local pool, fresh: ``--executor local --workers 2`` (the pool's two spawned processes start
  with the run and import and load the kernels on their first job, as for every ``swarmloc
  experiment`` command);
- local pool, kept: one :class:`LocalPool` of 2 processes warmed by one small run and passed to
  every run (what a Python script running several specs gets), the like of a running cluster;
- dask: a scheduler and two ``dask worker --nthreads 1 --no-nanny`` processes on 127.0.0.1
  (``tests/dask_cluster.py``), started once and warmed by one small run before the timed runs, as
  a lab's cluster would be already up.

Reported per executor and workload: wall seconds of the run, runs (jobs) per second, and the
overhead per job = (wall x workers - sum of the jobs' own ``wall_s``) / jobs: the worker time not
spent inside a job (start-up, scheduling, transfer, the client writing rows). Rows of the two
executors are checked equal (all but the timing columns). Usage::

    python benchmarks/bench_executors.py [--short-replications 30] [--long-replications 2]

(``--long-replications 0`` skips the long workload.)
"""

from __future__ import annotations

import argparse
import csv
import sys
import tempfile
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent.parent / "tests"))

from dask_cluster import LocalDaskCluster

from swarmloc.deploy.lab.executors import TIMING_COLUMNS, LocalPool
from swarmloc.deploy.lab.experiment import load_spec, run_experiment
from swarmloc.deploy.warm import ensure_compiled

SPEC = """\
name = "{name}"
replications = {replications}
seed = 1
[[group]]
name = "g"
scenarios = ["{scenario}"]
{duration}
[group.grid]
"agent.strategy" = ["NC", "SSGIKF"]
"""
WORKERS = 2


def _spec(folder: Path, name: str, scenario: str, replications: int, duration_s: float | None):
    path = folder / f"{name}.toml"
    duration = f"duration_s = {duration_s}" if duration_s is not None else ""
    path.write_text(SPEC.format(name=name, scenario=scenario, replications=replications,
                                duration=duration))
    return load_spec(path)


def _rows(path: Path) -> list[dict]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def _timed(spec, out: Path, **kw) -> dict:
    t0 = time.perf_counter()
    jobs = run_experiment(spec, out, progress=False, **kw)
    wall = time.perf_counter() - t0
    rows = _rows(out)
    assert len(rows) == jobs
    inside = sum(float(r["wall_s"]) for r in rows)
    return {"wall_s": wall, "jobs": jobs, "runs_per_s": jobs / wall,
            "overhead_ms": 1000 * (wall * WORKERS - inside) / jobs, "job_ms": 1000 * inside / jobs,
            "rows": rows}


def _model(rows):
    return sorted(tuple((k, v) for k, v in r.items() if k not in TIMING_COLUMNS) for r in rows)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--short-replications", type=int, default=30)
    parser.add_argument("--long-replications", type=int, default=2)
    args = parser.parse_args(argv)
    ensure_compiled(lambda line: print(line, file=sys.stderr))
    with tempfile.TemporaryDirectory(prefix="bench-executors-") as tmp:
        folder = Path(tmp)
        workloads = {"short (ES1, 30 s)": _spec(folder, "short", "ES1", args.short_replications, 30.0)}
        if args.long_replications > 0:
            workloads["long (ES3, 7200 s)"] = _spec(folder, "long", "ES3", args.long_replications, None)
        warm = _spec(folder, "warm", "ES1", 2, 30.0)
        results = []
        kept = LocalPool(WORKERS)
        try:
            with LocalDaskCluster(workers=WORKERS) as cluster:
                run_experiment(warm, folder / "warm.csv", progress=False, executor="dask",
                               scheduler=cluster.address)
                run_experiment(warm, folder / "warm-local.csv", progress=False, executor=kept)
                for label, spec in workloads.items():
                    fresh = _timed(spec, folder / f"{spec.name}-local.csv", workers=WORKERS)
                    reused = _timed(spec, folder / f"{spec.name}-kept.csv", executor=kept)
                    dask = _timed(spec, folder / f"{spec.name}-dask.csv", executor="dask",
                                  scheduler=cluster.address)
                    for other in (reused, dask):
                        assert _model(fresh["rows"]) == _model(other["rows"]), "rows differ"
                    results += [(label, "local, fresh", fresh), (label, "local, kept", reused),
                                (label, "dask", dask)]
        finally:
            kept.close()
    print(f"{WORKERS} workers each; rows of every executor equal (all but {', '.join(TIMING_COLUMNS)})")
    print(f"{'workload':20s} {'executor':12s} {'jobs':>4s} {'wall s':>7s} {'runs/s':>7s} "
          f"{'job ms':>8s} {'overhead ms/job':>15s}")
    for label, name, r in results:
        print(f"{label:20s} {name:12s} {r['jobs']:4d} {r['wall_s']:7.2f} {r['runs_per_s']:7.2f} "
              f"{r['job_ms']:8.0f} {r['overhead_ms']:15.0f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
