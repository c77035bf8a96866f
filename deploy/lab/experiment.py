"""``swarmloc experiment SPEC``: seeded replications of a grid of settings, in parallel, resumable.

An experiment spec (TOML, shipped ones in ``deploy/experiments/``) names one or more groups; each
group is a full grid: its scenarios times the cartesian product of its ``grid`` values, with
``set`` overrides fixed for the group. One *setting* is (group, scenario, one combination of the
grid), named by a stable id ``group/scenario/key=value/...`` (e.g.
``no-fermi/ES1/agent.strategy=NC``); each setting runs ``replications`` times, replication ``r``
with seed ``seed + r``::

    name = "so-000"
    replications = 30
    seed = 1
    [[group]]
    name = "no-fermi"
    scenarios = ["ES1", "ES2", "ES3"]
    duration_s = 1800.0                     # optional: overrides each scenario's duration
    [group.grid]
    "agent.strategy" = ["NC", "SSGIKF", "DSGIKF"]
    [group.set]
    "world.robots" = 10

Every setting's scenario is built and validated before anything runs (:func:`plan`), so an unknown
key, an unknown strategy or an impossible value stops the command with a message naming the group
and setting. Jobs (one replication of one setting) run with the batch engine in a pool of spawned
processes (never fork: a forked child of a Zenoh process hangs), or on the workers of a Dask
cluster (``--executor dask --scheduler tcp://HOST:8786``, ``deploy/lab/executors.py``). Each finished job appends one row
to a CSV file with one write call, so an interrupt loses nothing finished and leaves no partial
row; running the same command again skips the (setting, seed) pairs already in the file.
Columns (:meth:`ExperimentSpec.columns`): the setting (experiment, group, setting, scenario,
strategy, beta, robots, duration_s, seed, replication, one column per grid key), the metrics of
seed 000 §6 (recruitment_time_s, empty if not reached; robots_found_both; round_trips_total;
on_path_fraction_mean; lost_total), wall_s, and config_hash (the scenario without its seed): a
file whose rows were made with another configuration is refused rather than mixed.

A spec with ``family = "laser"`` runs the laser robots (seeds 002-003) instead: its scenarios are
laser scenarios, and ``deploy/lab/laser/experiment.py`` builds its settings, runs its jobs and gives
its columns (:data:`FAMILIES`); the spec format, plan, pool, resume and progress are these.
"""

from __future__ import annotations

import csv
import dataclasses
import difflib
import hashlib
import importlib
import io
import itertools
import json
import os
import re
import sys
import time
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Any

from swarmloc.config import ConfigError, from_dict, load_toml
from swarmloc.deploy.lab.executors import (
    DEFAULT_SCHEDULER_TIMEOUT_S,
    EXECUTORS,
    Executor,
    make_executor,
    sigterm_as_interrupt,
)
from swarmloc.deploy.scenario import Scenario, load_scenario

_NAME = re.compile(r"^[A-Za-z0-9_-]+$")
_DOTTED_KEY = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)+$")
#: Keys a group may not set: the seed comes from the spec's ``seed`` and the replication.
_RESERVED_KEYS = ("world.seed",)

#: Columns of the results file before the grid keys and after them.
LEAD_COLUMNS = ("experiment", "group", "setting", "scenario", "strategy", "beta", "robots",
                "duration_s", "seed", "replication")
METRIC_COLUMNS = ("recruitment_time_s", "robots_found_both", "round_trips_total",
                  "on_path_fraction_mean", "lost_total", "wall_s", "config_hash")
#: Robot families an experiment can run: None for the e-puck family of this module, else the
#: module (imported when needed) whose ``settings(spec)``, ``run_job(job)``, ``columns(spec)``
#: and ``row(spec, job, out)`` replace this module's.
FAMILIES = {"epuck": None, "laser": "swarmloc.deploy.lab.laser.experiment"}


def _family(name: str):
    target = FAMILIES[name]
    return None if target is None else importlib.import_module(target)


# -- the spec ---------------------------------------------------------------------------------


def _flatten(table: dict, prefix: str = "") -> dict:
    """``{"agent": {"beta": x}}`` -> ``{"agent.beta": x}`` (TOML reads an unquoted dotted key as
    nested tables; both spellings mean the same)."""
    out = {}
    for key, value in table.items():
        dotted = f"{prefix}.{key}" if prefix else str(key)
        if isinstance(value, dict):
            out.update(_flatten(value, dotted))
        else:
            out[dotted] = value
    return out


def _value_text(value) -> str:
    """A grid or set value as it appears in setting ids and result columns (strings bare)."""
    return value if isinstance(value, str) else json.dumps(value)


def _override_text(value) -> str:
    """A value as a TOML literal for :func:`swarmloc.config.apply_overrides`."""
    return json.dumps(value)


def _check_value(value, where: str) -> None:
    if isinstance(value, list):
        for item in value:
            _check_value(item, where)
    elif isinstance(value, dict) or not isinstance(value, (str, int, float, bool)):
        raise TypeError(f"{where}: unsupported value {value!r} (use numbers, strings, booleans or lists)")


def _check_key(key: str, where: str) -> None:
    if not _DOTTED_KEY.match(key):
        raise ValueError(f"{where} key '{key}': expected a dotted scenario key such as 'agent.strategy'")
    if key in _RESERVED_KEYS:
        raise ValueError(f"{where} key '{key}': seeds come from the spec's 'seed' plus the replication")


@dataclass(frozen=True)
class GroupSpec:
    """One group of settings: ``scenarios`` x the cartesian product of ``grid``.

    ``grid`` and ``set`` are read as tables of dotted scenario keys; after loading they are stored
    as tuples of pairs: ``grid`` as ``((key, (value, ...)), ...)``, ``set`` as ``((key, value), ...)``.
    """

    name: str = ""
    scenarios: tuple[str, ...] = ()
    #: Simulated seconds of every run of the group (default: each scenario's own duration).
    duration_s: float | None = None
    grid: Any = None
    set: Any = None

    def __post_init__(self):
        if not _NAME.match(self.name):
            raise ValueError(f"name: expected letters, digits, '_' or '-', got {self.name!r}")
        if not self.scenarios:
            raise ValueError("scenarios: list at least one scenario")
        if len(set(self.scenarios)) != len(self.scenarios):
            raise ValueError(f"scenarios: listed twice in {list(self.scenarios)}")
        if self.duration_s is not None and not self.duration_s > 0:
            raise ValueError(f"duration_s: must be > 0, got {self.duration_s}")
        object.__setattr__(self, "grid", self._normal_grid(self.grid))
        object.__setattr__(self, "set", self._normal_set(self.set))
        both = {k for k, _ in self.grid} & {k for k, _ in self.set}
        if both:
            raise ValueError(f"'{min(both)}' is both in grid and in set")
        if self.duration_s is not None and "world.duration_s" in {k for k, _ in self.grid + self.set}:
            raise ValueError("world.duration_s: give the duration either as duration_s or in grid/set")

    @staticmethod
    def _normal_grid(grid) -> tuple:
        if grid is None:
            return ()
        items = grid if isinstance(grid, tuple) else None
        if items is None:
            if not isinstance(grid, dict):
                raise ValueError(f"grid: expected a table of 'key' = [values], got {grid!r}")
            items = tuple(_flatten(grid).items())
        out = []
        for key, values in items:
            _check_key(key, "grid")
            if not isinstance(values, (list, tuple)):
                raise TypeError(f"grid '{key}': expected a list of values, got {values!r}")
            if not values:
                raise ValueError(f"grid '{key}': empty list (give at least one value)")
            _check_value(list(values), f"grid '{key}'")
            texts = [_value_text(v) for v in values]
            if len(set(texts)) != len(texts):
                raise ValueError(f"grid '{key}': a value is listed twice in {texts}")
            out.append((key, tuple(values)))
        return tuple(out)

    @staticmethod
    def _normal_set(fixed) -> tuple:
        if fixed is None:
            return ()
        items = fixed if isinstance(fixed, tuple) else None
        if items is None:
            if not isinstance(fixed, dict):
                raise ValueError(f"set: expected a table of 'key' = value, got {fixed!r}")
            items = tuple(_flatten(fixed).items())
        for key, value in items:
            _check_key(key, "set")
            _check_value(value, f"set '{key}'")
        return tuple(items)

    def combinations(self) -> list[tuple[tuple[str, Any], ...]]:
        """Every combination of the grid, as ``((key, value), ...)`` in grid order."""
        keys = [k for k, _ in self.grid]
        return [tuple(zip(keys, values)) for values in itertools.product(*(v for _, v in self.grid))]


@dataclass(frozen=True)
class ExperimentSpec:
    """A whole experiment: groups of settings, each run ``replications`` times (seeds
    ``seed .. seed + replications - 1``)."""

    name: str = ""
    description: str = ""
    replications: int = 30
    seed: int = 1
    group: tuple[GroupSpec, ...] = ()
    #: Which robots the scenarios are (a key of :data:`FAMILIES`).
    family: str = "epuck"

    def __post_init__(self):
        if not _NAME.match(self.name):
            raise ValueError(f"name: expected letters, digits, '_' or '-', got {self.name!r}")
        if self.family not in FAMILIES:
            raise ValueError(f"family: expected one of {', '.join(FAMILIES)}, got {self.family!r}")
        if self.replications < 1:
            raise ValueError(f"replications: must be >= 1, got {self.replications}")
        if not (0 <= self.seed and self.seed + self.replications - 1 < 2**63):
            raise ValueError(f"seed: seeds must stay in 0..2**63-1, got {self.seed}")
        if not self.group:
            raise ValueError("group: give at least one [[group]]")
        names = [g.name for g in self.group]
        for name in names:
            if names.count(name) > 1:
                raise ValueError(f"group: two groups are named '{name}'")

    @property
    def groups(self) -> tuple[GroupSpec, ...]:
        return self.group

    def grid_keys(self) -> list[str]:
        """Every grid key of every group, in order of first appearance: one column each."""
        keys: list[str] = []
        for g in self.group:
            keys += [k for k, _ in g.grid if k not in keys]
        return keys

    def columns(self) -> list[str]:
        """The header of the results file."""
        module = _family(self.family)
        if module is not None:
            return module.columns(self)
        return [*LEAD_COLUMNS, *self.grid_keys(), *METRIC_COLUMNS]


def with_overrides(spec: ExperimentSpec, *, replications: int | None = None,
                   duration_s: float | None = None) -> ExperimentSpec:
    """The spec with the number of replications and/or every group's duration replaced."""
    try:
        if duration_s is not None:
            groups = tuple(dataclasses.replace(g, duration_s=float(duration_s)) for g in spec.group)
            spec = dataclasses.replace(spec, group=groups)
        if replications is not None:
            spec = dataclasses.replace(spec, replications=replications)
    except ValueError as exc:
        raise ConfigError(f"experiment '{spec.name}': {exc}") from None
    return spec


def _experiments_folder():
    return resources.files("swarmloc.deploy") / "experiments"


def shipped_specs() -> list[str]:
    """Names of the specs shipped in ``deploy/experiments/``."""
    return sorted(p.name[:-5] for p in _experiments_folder().iterdir() if p.name.endswith(".toml"))


def load_spec(name_or_path: str | Path) -> ExperimentSpec:
    """Load and check an experiment spec: a path to a ``.toml`` file or a shipped spec's name."""
    path = Path(name_or_path)
    if path.suffix != ".toml" and not path.exists():
        names = shipped_specs()
        if str(name_or_path) not in names:
            close = difflib.get_close_matches(str(name_or_path), names, n=1, cutoff=0.4)
            hint = f"; did you mean '{close[0]}'?" if close else ""
            raise ConfigError(f"experiment '{name_or_path}': no such file or shipped spec{hint} "
                              f"(shipped: {', '.join(names)})")
        path = Path(str(_experiments_folder() / f"{name_or_path}.toml"))
    data = load_toml(path)
    try:
        return from_dict(ExperimentSpec, data)
    except ConfigError as exc:
        raise ConfigError(f"{path}: {exc}") from None


# -- the plan ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Setting:
    """One (group, scenario, grid combination), validated."""

    id: str
    group: str
    scenario: str
    #: Overrides applied to the scenario, without the seed.
    overrides: tuple[str, ...]
    #: The grid combination as ``((key, text), ...)``: the grid columns of the results.
    grid: tuple[tuple[str, str], ...]
    #: Hash of the scenario built for this setting (seed left out): a results row made with
    #: another configuration is not taken for this setting's.
    config_hash: str
    robots: int
    duration_s: float
    strategy: str
    #: Relative cost of one replication (0: robots x ticks of 0.1 s).
    cost: int = 0


@dataclass(frozen=True)
class Job:
    """One replication of one setting: ``run_batch(load_scenario(scenario, overrides))``."""

    setting: str
    group: str
    scenario: str
    overrides: tuple[str, ...]
    seed: int
    replication: int
    grid: tuple[tuple[str, str], ...] = ()
    config_hash: str = ""
    #: Robot-ticks: the relative cost used to weigh progress.
    cost: int = 1
    family: str = "epuck"


def _config_hash(scenario: Scenario) -> str:
    data = scenario.to_dict()
    data["world"].pop("seed", None)
    blob = json.dumps(data, sort_keys=True, separators=(",", ":")).encode()
    return hashlib.sha256(blob).hexdigest()[:12]


def settings(spec: ExperimentSpec) -> list[Setting]:
    """Every setting of the spec, each scenario built once: any error names group and setting."""
    module = _family(spec.family)
    if module is not None:
        return module.settings(spec)
    out = []
    for g in spec.group:
        fixed = [f"{k}={_override_text(v)}" for k, v in g.set]
        for scenario_name in g.scenarios:
            for combo in g.combinations():
                grid = tuple((k, _value_text(v)) for k, v in combo)
                sid = "/".join([g.name, scenario_name, *(f"{k}={t}" for k, t in grid)])
                overrides = fixed + [f"{k}={_override_text(v)}" for k, v in combo]
                if g.duration_s is not None:
                    overrides.append(f"world.duration_s={_override_text(float(g.duration_s))}")
                try:
                    scenario = load_scenario(scenario_name, overrides)
                except ConfigError as exc:
                    raise ConfigError(f"experiment '{spec.name}', group '{g.name}', "
                                      f"setting '{sid}': {exc}") from None
                out.append(Setting(sid, g.name, scenario_name, tuple(overrides), grid,
                                   _config_hash(scenario), scenario.world.robots,
                                   scenario.world.duration_s, scenario.agent.strategy))
    return out


def plan(spec: ExperimentSpec) -> list[Job]:
    """Every job of the experiment (setting-major, then replication), after validating every
    setting. Seeds ``spec.seed + r`` for replication ``r``."""
    jobs = []
    for s in settings(spec):
        ticks = max(1, round(s.duration_s * 10))
        for r in range(spec.replications):
            seed = spec.seed + r
            jobs.append(Job(s.id, s.group, s.scenario, (*s.overrides, f"world.seed={seed}"), seed, r,
                            s.grid, s.config_hash, s.cost or s.robots * ticks, spec.family))
    return jobs


# -- one job, in a worker process -------------------------------------------------------------


def run_job(job: Job) -> dict:
    """Run one replication with the batch engine; a flat dict of what the row needs."""
    from swarmloc.registry import load_plugins

    load_plugins()  # a worker process (local pool or Dask) imports the spec's plugins too
    module = _family(job.family)
    if module is not None:
        return module.run_job(job)
    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.warm import ensure_compiled

    # On a cluster worker's host nobody compiled yet: one process compiles, the others of the
    # host wait on its lock (a stamp check of a few ms once warm).
    ensure_compiled()
    t0 = time.perf_counter()
    scenario = load_scenario(job.scenario, list(job.overrides))
    result = run_batch(scenario)
    m = result.metrics
    return {
        "strategy": scenario.agent.strategy,
        "beta": scenario.agent.beta,
        "robots": scenario.world.robots,
        "duration_s": scenario.world.duration_s,
        "recruitment_time_s": m["recruitment_time_s"],
        "robots_found_both": m["robots_found_both"],
        "round_trips_total": m["round_trips_total"],
        "on_path_fraction_mean": m["on_path_fraction_mean"],
        "lost_total": int(result.lost_count.sum()),
        "wall_s": round(time.perf_counter() - t0, 3),
    }


# -- the results file -------------------------------------------------------------------------


def _csv_line(values: list) -> bytes:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(["" if v is None else v for v in values])
    return buf.getvalue().encode("utf-8")


def _row(spec: ExperimentSpec, job: Job, out: dict) -> list:
    module = _family(spec.family)
    if module is not None:
        return module.row(spec, job, out)
    grid = dict(job.grid)
    return [spec.name, job.group, job.setting, job.scenario, out["strategy"], out["beta"],
            out["robots"], out["duration_s"], job.seed, job.replication,
            *(grid.get(k) for k in spec.grid_keys()),
            out["recruitment_time_s"], out["robots_found_both"], out["round_trips_total"],
            out["on_path_fraction_mean"], out["lost_total"], out["wall_s"], job.config_hash]


def read_done(spec: ExperimentSpec, jobs: list[Job], path: str | Path) -> set[tuple[str, int]]:
    """The (setting, seed) pairs of ``jobs`` already in the results file.

    Refuses (ConfigError) a file with other columns, rows of another experiment, or a row of a
    planned (setting, seed) made with another configuration. A trailing fragment without a
    newline (a write cut short) is cut off the file.
    """
    path = Path(path)
    if not path.exists() or path.stat().st_size == 0:
        return set()
    header = spec.columns()
    raw = path.read_bytes()
    text = raw.decode("utf-8", errors="replace")
    first = next(csv.reader(io.StringIO(text.split("\n", 1)[0])), [])
    if first != header:
        raise ConfigError(
            f"{path}: this file's columns are not those of experiment '{spec.name}' "
            f"(found {','.join(first)[:120]!r}); write to another file (--out) or remove it")
    if not raw.endswith(b"\n"):
        keep = raw.rfind(b"\n") + 1
        print(f"{path}: cutting off an unfinished last row ({len(raw) - keep} bytes)", file=sys.stderr)
        os.truncate(path, keep)
        text = raw[:keep].decode("utf-8", errors="replace")
    planned = {(j.setting, j.seed): j.config_hash for j in jobs}
    col = {name: i for i, name in enumerate(header)}
    done = set()
    reader = csv.reader(io.StringIO(text))
    next(reader)
    for line_no, row in enumerate(reader, start=2):
        if len(row) != len(header):
            raise ConfigError(f"{path}:{line_no}: expected {len(header)} fields, found {len(row)}")
        if row[col["experiment"]] != spec.name:
            raise ConfigError(f"{path}:{line_no}: a row of experiment '{row[col['experiment']]}', "
                              f"not '{spec.name}'; write to another file (--out)")
        try:
            key = (row[col["setting"]], int(row[col["seed"]]))
        except ValueError:
            raise ConfigError(f"{path}:{line_no}: seed {row[col['seed']]!r} is not an integer") from None
        want = planned.get(key)
        if want is not None and row[col["config_hash"]] != want:
            raise ConfigError(
                f"{path}:{line_no}: setting '{key[0]}' seed {key[1]} was run with another "
                f"configuration (another --duration-s, an edited spec or scenario); "
                f"write to another file (--out) or remove it")
        if want is not None:
            done.add(key)
    return done


# -- progress ---------------------------------------------------------------------------------


def _fmt_s(seconds: float) -> str:
    seconds = round(seconds)
    return f"{seconds // 3600}:{seconds // 60 % 60:02d}:{seconds % 60:02d}"


class _Progress:
    """Progress weighted by job cost (robot-ticks), so the time left is sound when jobs differ
    by orders of magnitude (ES1 vs ES3). ``mode``: "bar" (rich), "lines" (a line every ~10 %)
    or None."""

    def __init__(self, mode: str | None, name: str, jobs: int, cost: int, workers: int, done_before: int):
        self.mode, self.name, self.jobs, self.cost = mode, name, jobs, max(1, cost)
        self.done_jobs = self.done_cost = 0
        self.t0 = time.monotonic()
        self.last_decile = 0
        self._bar = None
        if mode == "lines":
            print(f"experiment {name}: {jobs} jobs to run on {workers} workers "
                  f"({done_before} done before)", file=sys.stderr, flush=True)
        elif mode == "bar":
            from rich.console import Console
            from rich.progress import BarColumn, Progress, TextColumn, TimeElapsedColumn

            self._bar = Progress(
                TextColumn("[bold]{task.description}"), BarColumn(),
                TextColumn("{task.fields[done]}/{task.fields[jobs]} jobs"),
                TimeElapsedColumn(), TextColumn("{task.fields[left]}"),
                console=Console(stderr=True, force_terminal=True), refresh_per_second=2)
            self._bar.start()
            self._task = self._bar.add_task(name, total=self.cost, done=0, jobs=jobs, left="")

    def left_s(self) -> float | None:
        if not self.done_cost:
            return None
        elapsed = time.monotonic() - self.t0
        return elapsed * (self.cost - self.done_cost) / self.done_cost

    def advance(self, cost: int) -> None:
        self.done_jobs += 1
        self.done_cost += cost
        left = self.left_s()
        left_text = f"{_fmt_s(left)} left" if left is not None else "-:--:-- left"
        if self._bar is not None:
            self._bar.update(self._task, completed=self.done_cost, done=self.done_jobs, left=left_text)
        elif self.mode == "lines":
            decile = int(10 * self.done_cost / self.cost)
            if decile > self.last_decile or self.done_jobs == self.jobs:
                self.last_decile = decile
                print(f"experiment {self.name}: {self.done_jobs}/{self.jobs} jobs "
                      f"({100 * self.done_cost / self.cost:.0f} %), "
                      f"{_fmt_s(time.monotonic() - self.t0)} elapsed, {left_text}",
                      file=sys.stderr, flush=True)

    def close(self) -> None:
        if self._bar is not None:
            self._bar.stop()
            self._bar = None


def _progress_mode(progress: bool | str) -> str | None:
    if progress in ("bar", "lines"):
        return progress
    if progress is True:
        return "bar" if sys.stderr.isatty() else "lines"
    if progress in (False, None):
        return None
    raise ValueError(f"progress: expected True, False, 'bar' or 'lines', got {progress!r}")


# -- running ----------------------------------------------------------------------------------


def execution_order(jobs: list[Job]) -> list[Job]:
    """Replication-major (an interrupted experiment has every setting's first replications), the
    costliest jobs first within a replication (short jobs fill the pool at the end)."""
    return sorted(jobs, key=lambda j: (j.replication, -j.cost, j.setting))


def run_experiment(
    spec: ExperimentSpec,
    results_path: str | Path,
    workers: int | None = None,
    progress: bool | str = True,
    limit: int | None = None,
    executor: str | Executor = "local",
    scheduler: str | None = None,
    scheduler_timeout_s: float = DEFAULT_SCHEDULER_TIMEOUT_S,
) -> int:
    """Run every job of ``spec`` not yet in ``results_path`` and append one row per job; return
    the number of rows written.

    ``executor``: ``"local"`` runs ``workers`` spawned processes (default: ``os.cpu_count()``);
    ``"dask"`` runs the jobs on the workers of the Dask scheduler at ``scheduler``
    (``tcp://HOST:8786``); an :class:`~swarmloc.deploy.lab.executors.Executor` instance is used
    as it is. Whichever runs them, this process writes the rows as the jobs come back (one write
    call per row, each (setting, seed) once). ``progress``: True shows a rich bar when stderr is
    a terminal and otherwise a line every ~10 %; "bar" or "lines" force one; False shows nothing.
    ``limit``: run at most that many new jobs. A bad scheduler address or a scheduler that does
    not answer raises ConfigError before the results file is touched. On KeyboardInterrupt the
    jobs are stopped, finished rows stay in the file, and the exception propagates.
    """
    jobs = plan(spec)
    path = Path(results_path)
    done = read_done(spec, jobs, path)
    todo = execution_order([j for j in jobs if (j.setting, j.seed) not in done])
    if limit is not None:
        todo = todo[: max(0, limit)]
    if isinstance(executor, str):
        if executor == "local" and workers is not None and workers < 1:
            raise ConfigError(f"workers: must be >= 1, got {workers}")
        executor = make_executor(executor, workers=workers, scheduler=scheduler,
                                 scheduler_timeout_s=scheduler_timeout_s) if todo else None
    mode = _progress_mode(progress)
    path.parent.mkdir(parents=True, exist_ok=True)
    new_file = not path.exists() or path.stat().st_size == 0
    written = 0
    seen: set[tuple[str, int]] = set()
    try:
        with open(path, "ab", buffering=0) as handle:
            if new_file:
                handle.write(_csv_line(spec.columns()))
            if not todo:
                return 0
            if spec.family == "epuck" and executor.on_this_host:
                # Compile once here, not in every worker at once (deploy/warm.py).
                from swarmloc.deploy.warm import ensure_compiled

                ensure_compiled(lambda line: print(f"swarmloc: {line}", file=sys.stderr, flush=True)
                                if mode else None)
            bar = _Progress(mode, spec.name, len(todo), sum(j.cost for j in todo),
                            min(executor.workers(), len(todo)), len(done))
            try:
                for job, fut in executor.as_completed(run_job, todo):
                    key = (job.setting, job.seed)
                    if key in seen:  # an executor handed the same job back twice: one row only
                        continue
                    try:
                        out = fut.result()
                    except Exception as exc:
                        raise RuntimeError(f"job {job.setting} seed {job.seed} failed: "
                                           f"{type(exc).__name__}: {exc}") from exc
                    # One write call per row on an unbuffered append-mode file.
                    handle.write(_csv_line(_row(spec, job, out)))
                    seen.add(key)
                    written += 1
                    bar.advance(job.cost)
            except BaseException:
                executor.stop()
                raise
            finally:
                bar.close()
            executor.close()
    finally:
        if executor is not None:
            executor.close()
    return written


# -- command line -----------------------------------------------------------------------------


def default_results_path(spec: ExperimentSpec, duration_s: float | None = None) -> Path:
    """``results/<name>.csv``; a run shortened with ``--duration-s X`` goes to
    ``results/<name>-<X>s.csv`` so it never mixes with the full one."""
    suffix = f"-{duration_s:g}s" if duration_s is not None else ""
    return Path("results") / f"{spec.name}{suffix}.csv"


def describe(spec: ExperimentSpec, results_path: str | Path) -> str:
    """The plan in words: size, settings, what the results file already holds."""
    all_settings = settings(spec)
    jobs = plan(spec)
    done = read_done(spec, jobs, results_path)
    lines = [
        (f"experiment {spec.name}: {len(all_settings)} settings x {spec.replications} "
         f"replications = {len(jobs)} jobs (seeds {spec.seed}..{spec.seed + spec.replications - 1})"),
        f"results: {results_path} ({len(done)} done, {len(jobs) - len(done)} to run)",
        "settings:",
    ]
    width = max(len(s.id) for s in all_settings)
    for s in all_settings:
        lines.append(f"  {s.id:{width}s}  {s.strategy:7s} {s.robots:4d} robots {s.duration_s:7g} s")
    return "\n".join(lines)


def main_experiment(args) -> int:
    """``swarmloc experiment SPEC``: a ConfigError (bad spec, foreign results file) propagates to
    the CLI, which prints it and exits with 2."""
    spec = with_overrides(load_spec(args.spec), replications=args.replications,
                          duration_s=args.duration_s)
    out = Path(args.out) if args.out else default_results_path(spec, args.duration_s)
    if args.dry_run:
        print(describe(spec, out))
        return 0
    t0 = time.perf_counter()
    try:
        with sigterm_as_interrupt():
            written = run_experiment(spec, out, workers=args.workers, progress=not args.quiet,
                                     executor=args.executor, scheduler=args.scheduler,
                                     scheduler_timeout_s=args.scheduler_timeout_s)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished replications are in {out}; "
              f"run the same command again to resume", file=sys.stderr)
        return 130
    print(f"experiment {spec.name}: {written} new rows in {out} ({time.perf_counter() - t0:.1f} s)")
    return 0


def add_parser(subparsers) -> None:
    """Register ``swarmloc experiment`` on the CLI's subparsers."""
    p = subparsers.add_parser(
        "experiment", help="run an experiment spec: settings x seeded replications, in parallel",
        description="Run every setting of an experiment spec x its replications with the batch "
                    "engine, in parallel; resumable (finished rows are kept and skipped).")
    p.add_argument("spec", help=f"shipped spec ({', '.join(shipped_specs())}) or a .toml file")
    p.add_argument("--out", default=None,
                   help="results CSV (default results/<name>.csv; results/<name>-<X>s.csv "
                        "with --duration-s X)")
    p.add_argument("--workers", type=int, default=os.cpu_count() or 1,
                   help="worker processes (default: the number of cores)")
    p.add_argument("--duration-s", type=float, default=None,
                   help="simulated seconds of every run, all groups (for quick looks)")
    p.add_argument("--replications", type=int, default=None, help="replications per setting")
    p.add_argument("--dry-run", action="store_true", help="print the plan; run nothing")
    p.add_argument("--quiet", action="store_true", help="no progress output")
    p.add_argument("--executor", choices=EXECUTORS, default="local",
                   help="where jobs run: local (a pool of --workers processes, the default) or "
                        "dask (the workers of --scheduler; pip install 'swarmloc[cluster]')")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler address for --executor dask, e.g. tcp://HOST:8786")
    p.add_argument("--scheduler-timeout-s", type=float, default=DEFAULT_SCHEDULER_TIMEOUT_S,
                   help="give up if the scheduler does not answer within this (default 10 s)")
    p.set_defaults(func=main_experiment)


__all__ = [
    "ExperimentSpec", "GroupSpec", "Job", "Setting", "add_parser", "default_results_path",
    "describe", "execution_order", "load_spec", "main_experiment", "plan", "read_done",
    "run_experiment", "run_job", "settings", "shipped_specs", "with_overrides",
]
