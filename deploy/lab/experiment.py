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
and setting. Jobs (one replication of one setting, the family's ``run_job``) run in a pool of spawned
processes (never fork: a forked child of a Zenoh process hangs), or on the workers of a Dask
cluster (``--executor dask --scheduler tcp://HOST:8786``, ``deploy/lab/executors.py``). Each finished job appends one row
to a CSV file with one write call, so an interrupt loses nothing finished and leaves no partial
row; running the same command again skips the (setting, seed) pairs already in the file.
Columns (:meth:`ExperimentSpec.columns`, the family's): always experiment, group, setting,
scenario, seed, replication, one column per grid key, the family's measures, wall_s and
config_hash (the scenario without its seed): a file whose rows were made with another
configuration is refused rather than mixed.

Every robot family runs through this engine: a spec's ``family`` (default ``"foraging"``, also
called ``"epuck"``) names an entry of :data:`FAMILIES` (``swarmloc.families``, the one registry
of families), whose ``experiment`` is the module that builds its settings, runs one job and gives
its columns and rows (:class:`Family`); the spec format, checks, plan, executors, resume, progress
and the results file are these, whatever the family. A group may give its own ``replications``
(at most the spec's ``--replications`` when that is given) and a ``description``;
``swarmloc experiment SPEC --set KEY=VALUE`` fixes a scenario key in every group (e.g. where
a data set lives); ``swarmloc experiment --list`` lists the shipped specs of every family.
"""

from __future__ import annotations

import csv
import dataclasses
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
from typing import Any, Protocol

from swarmloc.config import ConfigError, did_you_mean, from_dict, load_toml
from swarmloc.deploy.lab.executors import (
    DEFAULT_SCHEDULER_TIMEOUT_S,
    DEFAULT_WORKER_TIMEOUT_S,
    EXECUTORS,
    DaskTls,
    Executor,
    make_executor,
    sigterm_as_interrupt,
)
from swarmloc.families import FAMILIES as _FAMILIES
from swarmloc.registry import load_plugins, resolve

_NAME = re.compile(r"^[A-Za-z0-9_-]+$")
#: A scenario key: dotted (``agent.strategy``) or, for families whose scenarios are flat tables
#: (replay), a bare name (``algorithm``); the family's scenario loader refuses unknown keys.
_SCENARIO_KEY = re.compile(r"^[A-Za-z_]\w*(\.[A-Za-z_]\w*)*$")


class Family(Protocol):
    """What a robot family contributes to the engine (a module registered in :data:`FAMILIES`).

    ``settings(spec)`` builds and validates every setting of the spec (an error names group and
    setting); ``run_job(job)`` runs one replication in a worker process and returns a flat dict;
    ``columns(spec)`` is the header of the results file and ``row(spec, job, out)`` one row in
    that order (or ``rows(spec, job, out)``: several rows of one job, written in one call).
    ``SEED_KEY``: the scenario key the replication's seed is set through (None: ``run_job`` reads
    ``job.seed``); groups may not set it. Optional ``prepare(log)``: called once in this process
    before jobs run on this host (e-puck compiles its kernels).
    """

    SEED_KEY: str | None

    def settings(self, spec: ExperimentSpec) -> list[Setting]: ...

    def run_job(self, job: Job) -> dict: ...

    def columns(self, spec: ExperimentSpec) -> list[str]: ...

    def row(self, spec: ExperimentSpec, job: Job, out: dict) -> list: ...


#: The robot families (one registry, ``swarmloc.families``): a family runs in experiments when its
#: ``Family.experiment`` names the module of its hooks. Plugins register more.
FAMILIES = _FAMILIES


def experiment_families() -> list[str]:
    """The families whose entries have experiment hooks (plugins loaded)."""
    load_plugins()
    return [name for name, entry in FAMILIES.items() if entry.experiment is not None]


def family(name: str) -> Family:
    """The hooks module of family ``name`` (plugins loaded first if it is not registered);
    ValueError if it has none."""
    if name not in FAMILIES:
        load_plugins()
    entry = FAMILIES.get(name)
    if entry.experiment is None:
        raise ValueError(f"family {name!r} has no experiment hooks (its Family.experiment is None); "
                         f"families with them: {', '.join(experiment_families())}")
    return resolve(entry.experiment)


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
    if not _SCENARIO_KEY.match(key):
        raise ValueError(f"{where} key '{key}': expected a scenario key such as 'agent.strategy'")


@dataclass(frozen=True)
class GroupSpec:
    """One group of settings: ``scenarios`` x the cartesian product of ``grid``.

    ``grid`` and ``set`` are read as tables of dotted scenario keys; after loading they are stored
    as tuples of pairs: ``grid`` as ``((key, (value, ...)), ...)``, ``set`` as ``((key, value), ...)``.
    """

    name: str = ""
    scenarios: tuple[str, ...] = ()
    #: What the group measures (reports show it).
    description: str = ""
    #: Simulated seconds of every run of the group (default: each scenario's own duration).
    duration_s: float | None = None
    #: Replications of each setting of this group (default: the spec's).
    replications: int | None = None
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
        if self.replications is not None and not (
                isinstance(self.replications, int) and self.replications >= 1):
            raise ValueError(f"replications: must be >= 1, got {self.replications}")
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
    #: Which robots the scenarios are (a family of :data:`FAMILIES`, with experiment hooks;
    #: "epuck" names the foraging e-pucks too).
    family: str = "foraging"

    def __post_init__(self):
        if not _NAME.match(self.name):
            raise ValueError(f"name: expected letters, digits, '_' or '-', got {self.name!r}")
        if self.family not in FAMILIES:
            load_plugins()
        if self.family not in FAMILIES or FAMILIES.get(self.family).experiment is None:
            raise ValueError(f"family: expected one of {', '.join(experiment_families())}, got {self.family!r}")
        object.__setattr__(self, "family", FAMILIES.canonical(self.family))
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
        seed_key = getattr(family(self.family), "SEED_KEY", None) or "world.seed"
        for g in self.group:
            if seed_key in {k for k, _ in g.grid + g.set}:
                raise ValueError(f"group '{g.name}' key '{seed_key}': seeds come from the "
                                 f"spec's 'seed' plus the replication")

    def replications_of(self, group: GroupSpec) -> int:
        """Replications of each setting of ``group``."""
        return group.replications or self.replications

    def job_count(self) -> int:
        """How many jobs the spec plans (without building any scenario)."""
        total = 0
        for g in self.group:
            combos = 1
            for _, values in g.grid:
                combos *= len(values)
            total += len(g.scenarios) * combos * self.replications_of(g)
        return total

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
        return family(self.family).columns(self)


def with_overrides(spec: ExperimentSpec, *, replications: int | None = None,
                   duration_s: float | None = None, fixed: list[str] = ()) -> ExperimentSpec:
    """The spec with the number of replications (a group's own is capped to it), every group's
    duration, and/or ``fixed`` (``KEY=VALUE`` strings, values as TOML) added to every group's
    ``set`` table replaced."""
    try:
        if duration_s is not None:
            groups = tuple(dataclasses.replace(g, duration_s=float(duration_s)) for g in spec.group)
            spec = dataclasses.replace(spec, group=groups)
        if fixed:
            extra = _parse_sets(fixed)
            groups = []
            for g in spec.group:
                grid_keys = {k for k, _ in g.grid}
                clash = sorted(grid_keys & set(extra))
                if clash:
                    raise ValueError(f"--set {clash[0]}: group '{g.name}' varies it in its grid")
                kept = tuple((k, v) for k, v in g.set if k not in extra)
                groups.append(dataclasses.replace(g, set=kept + tuple(extra.items())))
            spec = dataclasses.replace(spec, group=tuple(groups))
        if replications is not None:
            groups = tuple(dataclasses.replace(g, replications=min(g.replications, replications))
                           if g.replications is not None else g for g in spec.group)
            spec = dataclasses.replace(spec, replications=replications, group=groups)
    except (ValueError, TypeError) as exc:
        raise ConfigError(f"experiment '{spec.name}': {exc}") from None
    return spec


def _parse_sets(items: list[str]) -> dict[str, Any]:
    """``["a.b=1", 'c="x"']`` -> ``{"a.b": 1, "c": "x"}`` (values as TOML literals, or bare
    text when they are not one)."""
    from swarmloc.config import parse_assignment

    out: dict[str, Any] = {}
    for item in items:
        key, value = parse_assignment(item, "--set")
        _check_key(key, "--set")
        _check_value(value, f"--set '{key}'")
        out[key] = value
    return out


def _experiments_folder():
    return resources.files("swarmloc.deploy") / "experiments"


def shipped_specs() -> list[str]:
    """Names of the specs shipped in ``deploy/experiments/``."""
    return sorted(p.name[:-5] for p in _experiments_folder().iterdir() if p.name.endswith(".toml"))


def list_specs() -> list[tuple[str, str, int, str]]:
    """(name, family, jobs, description) of every shipped spec, by name."""
    out = []
    for name in shipped_specs():
        spec = load_spec(name)
        out.append((spec.name, spec.family, spec.job_count(), spec.description))
    return out


def load_spec(name_or_path: str | Path) -> ExperimentSpec:
    """Load and check an experiment spec: a path to a ``.toml`` file or a shipped spec's name."""
    path = Path(name_or_path)
    if path.suffix != ".toml" and not path.exists():
        names = shipped_specs()
        if str(name_or_path) not in names:
            hint = did_you_mean(str(name_or_path), names, 0.4)
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
    """One replication of one setting: the family's ``run_job`` builds the scenario from
    ``scenario`` and ``overrides`` (the seed included when the family has a ``SEED_KEY``)."""

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
    family: str = "foraging"


def value_text(value) -> str:
    """A grid or set value as it appears in setting ids and result columns (strings bare)."""
    return _value_text(value)


def override_text(value) -> str:
    """A value as a TOML literal for :func:`swarmloc.config.apply_overrides`."""
    return _override_text(value)


def setting_grid(g: GroupSpec) -> list[tuple[str, tuple, list[str]]]:
    """Per scenario and grid combination of ``g``: (setting id, the grid as ``((key, text),
    ...)``, the overrides: the group's ``set`` then the combination)."""
    fixed = [f"{k}={_override_text(v)}" for k, v in g.set]
    out = []
    for scenario_name in g.scenarios:
        for combo in g.combinations():
            grid = tuple((k, _value_text(v)) for k, v in combo)
            sid = "/".join([g.name, scenario_name, *(f"{k}={t}" for k, t in grid)])
            out.append((scenario_name, sid, grid,
                        fixed + [f"{k}={_override_text(v)}" for k, v in combo]))
    return out


def settings(spec: ExperimentSpec) -> list[Setting]:
    """Every setting of the spec, each scenario built once: any error names group and setting."""
    return family(spec.family).settings(spec)


def plan(spec: ExperimentSpec) -> list[Job]:
    """Every job of the experiment (setting-major, then replication), after validating every
    setting. Seeds ``spec.seed + r`` for replication ``r``; the family's ``SEED_KEY`` (if any)
    is set to it in the job's overrides."""
    seed_key = getattr(family(spec.family), "SEED_KEY", None)
    groups = {g.name: g for g in spec.group}
    jobs = []
    for s in settings(spec):
        ticks = max(1, round(s.duration_s * 10))
        for r in range(spec.replications_of(groups[s.group])):
            seed = spec.seed + r
            seeded = (f"{seed_key}={seed}",) if seed_key else ()
            jobs.append(Job(s.id, s.group, s.scenario, (*s.overrides, *seeded), seed, r,
                            s.grid, s.config_hash, s.cost or s.robots * ticks, spec.family))
    return jobs


# -- one job, in a worker process -------------------------------------------------------------


def run_job(job: Job) -> dict:
    """Run one replication with its family's ``run_job``; a flat dict of what the row needs."""
    from swarmloc.registry import load_plugins

    load_plugins()  # a worker process (local pool or Dask) imports the spec's plugins too
    return family(job.family).run_job(job)


# -- the results file -------------------------------------------------------------------------


def _csv_line(values: list) -> bytes:
    buf = io.StringIO()
    csv.writer(buf, lineterminator="\n").writerow(["" if v is None else v for v in values])
    return buf.getvalue().encode("utf-8")


def _rows(spec: ExperimentSpec, job: Job, out: dict) -> list[list]:
    module = family(spec.family)
    if hasattr(module, "rows"):
        return module.rows(spec, job, out)
    return [module.row(spec, job, out)]


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


#: Ticks of each run of the determinism pre-check (three runs a setting).
PRECHECK_TICKS = 10


def precheck(todo: list[Job], ticks: int = PRECHECK_TICKS) -> int:
    """Hold the first job of every setting in ``todo`` to the contract checker's determinism
    check (``swarmloc.checker.check_determinism``: two runs of its seed give the same bytes, for
    ``ticks`` ticks), if any registry holds code from outside swarmloc (a plugin, a notebook);
    swarmloc's own entries are checked by its test suite. Returns how many settings were checked.
    ConfigError naming the setting and the cause if one is not deterministic: a grid of such
    runs would give rows that no seed reproduces (issue 48: the same seed gave 0.072 and 0.239 m).
    A scenario this host cannot load (a data set only the cluster's workers have) is skipped."""
    from swarmloc.checker import CheckError, check_determinism
    from swarmloc.deploy.scenario import load_any
    from swarmloc.registry import foreign_entries

    if not foreign_entries():
        return 0
    checked = 0
    first: dict[str, Job] = {}
    for job in todo:
        first.setdefault(job.setting, job)
    for setting, job in first.items():
        try:
            scenario = load_any(job.scenario, overrides=list(job.overrides))
        except (ConfigError, OSError):
            continue  # not loadable here; the workers load it
        try:
            check_determinism(scenario, ticks)
        except CheckError as exc:
            raise ConfigError(f"setting {setting}: not reproducible, so no grid was started "
                              f"(seed {job.seed}, {ticks} ticks): {exc}; run `swarmloc check` on it, "
                              f"or --no-check to run anyway") from None
        checked += 1
    return checked


def run_experiment(
    spec: ExperimentSpec,
    results_path: str | Path,
    workers: int | None = None,
    progress: bool | str = True,
    limit: int | None = None,
    executor: str | Executor = "local",
    scheduler: str | None = None,
    scheduler_timeout_s: float = DEFAULT_SCHEDULER_TIMEOUT_S,
    tls: DaskTls | None = None,
    worker_timeout_s: float = DEFAULT_WORKER_TIMEOUT_S,
    check: bool = True,
) -> int:
    """Run every job of ``spec`` not yet in ``results_path`` and append one row per job; return
    the number of rows written.

    ``check``: when code registered outside swarmloc is loaded (a plugin's localizer, strategy,
    fusion rule or family), first hold one job of each setting to :func:`precheck`'s
    determinism check, and refuse the grid (ConfigError, nothing written) if one fails.

    ``executor``: ``"local"`` runs ``workers`` spawned processes (default: ``os.cpu_count()``);
    ``"dask"`` runs the jobs on the workers of the Dask scheduler at ``scheduler``
    (``tcp://HOST:8786``, or ``tls://HOST:8786`` with ``tls`` the client's certificate files),
    waiting up to ``worker_timeout_s`` for a first worker; an
    :class:`~swarmloc.deploy.lab.executors.Executor` instance is used as it is and left open
    (its owner closes it: a ``LocalPool`` then keeps its processes for the next run). Whichever
    runs them, this process writes the rows as the jobs come back (one write call per row, each
    (setting, seed) once). ``progress``: True shows a rich bar when stderr is
    a terminal and otherwise a line every ~10 %; "bar" or "lines" force one; False shows nothing.
    ``limit``: run at most that many new jobs. A bad scheduler address or a scheduler that does
    not answer, a bad or refused TLS certificate, or no worker in time raises ConfigError before
    the results file is touched. On KeyboardInterrupt the jobs are stopped, finished rows stay in
    the file, and the exception propagates.
    """
    jobs = plan(spec)
    path = Path(results_path)
    done = read_done(spec, jobs, path)
    todo = execution_order([j for j in jobs if (j.setting, j.seed) not in done])
    if limit is not None:
        todo = todo[: max(0, limit)]
    if check and todo:
        precheck(todo)
    owned = isinstance(executor, str)
    if owned:
        if executor == "local" and workers is not None and workers < 1:
            raise ConfigError(f"workers: must be >= 1, got {workers}")
        executor = make_executor(executor, workers=workers, scheduler=scheduler,
                                 scheduler_timeout_s=scheduler_timeout_s, tls=tls,
                                 worker_timeout_s=worker_timeout_s) if todo else None
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
            prepare = getattr(family(spec.family), "prepare", None)
            if prepare is not None and executor.on_this_host:
                prepare(lambda line: print(f"swarmloc: {line}", file=sys.stderr, flush=True)
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
                    # One write call per job on an unbuffered append-mode file.
                    handle.write(b"".join(_csv_line(r) for r in _rows(spec, job, out)))
                    seen.add(key)
                    written += 1
                    bar.advance(job.cost)
            except BaseException:
                executor.stop()
                raise
            finally:
                bar.close()
    finally:
        if owned and executor is not None:
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
    reps = sorted({spec.replications_of(g) for g in spec.group})
    reps_text = (f"{reps[0]} replications" if len(reps) == 1
                 else f"{reps[0]}-{reps[-1]} replications (per group)")
    lines = [
        (f"experiment {spec.name}: {len(all_settings)} settings x {reps_text} = {len(jobs)} jobs "
         f"(seeds from {spec.seed})"),
        f"results: {results_path} ({len(done)} done, {len(jobs) - len(done)} to run)",
        "settings:",
    ]
    width = max(len(s.id) for s in all_settings)
    for s in all_settings:
        lines.append(f"  {s.id:{width}s}  {s.strategy:7s} {s.robots:4d} robots {s.duration_s:7g} s")
    return "\n".join(lines)


def main_experiment(args) -> int:
    """``swarmloc experiment SPEC``: a ConfigError (bad spec, foreign results file) propagates to
    the CLI, which prints it and exits with 2. ``--list``: the shipped specs."""
    if args.list:
        print(format_spec_list(list_specs()))
        return 0
    if not args.spec:
        raise ConfigError("experiment: name a spec (shipped or a .toml file), or --list")
    spec = with_overrides(load_spec(args.spec), replications=args.replications,
                          duration_s=args.duration_s, fixed=args.set)
    out = Path(args.out) if args.out else default_results_path(spec, args.duration_s)
    if args.dry_run:
        print(describe(spec, out))
        return 0
    tls = DaskTls.from_flags(args.tls_ca_file, args.tls_cert, args.tls_key)
    t0 = time.perf_counter()
    try:
        with sigterm_as_interrupt():
            written = run_experiment(spec, out, workers=args.workers, progress=not args.quiet,
                                     executor=args.executor, scheduler=args.scheduler,
                                     scheduler_timeout_s=args.scheduler_timeout_s, tls=tls,
                                     worker_timeout_s=args.worker_timeout_s, check=not args.no_check)
    except KeyboardInterrupt:
        print(f"\ninterrupted: finished replications are in {out}; "
              f"run the same command again to resume", file=sys.stderr)
        return 130
    print(f"experiment {spec.name}: {written} new rows in {out} ({time.perf_counter() - t0:.1f} s)")
    return 0


def format_spec_list(specs: list[tuple[str, str, int, str]]) -> str:
    """The table of ``swarmloc experiment --list``."""
    head = ("spec", "family", "jobs", "description")
    widths = [max(len(str(r[i])) for r in [head, *specs]) for i in range(3)]
    lines = [f"{head[0]:{widths[0]}}  {head[1]:{widths[1]}}  {head[2]:>{widths[2]}}  {head[3]}"]
    for name, fam, jobs, description in specs:
        lines.append(f"{name:{widths[0]}}  {fam:{widths[1]}}  {jobs:>{widths[2]}}  "
                     f"{' '.join(description.split())}")
    return "\n".join(lines)


def add_parser(subparsers) -> None:
    """Register ``swarmloc experiment`` on the CLI's subparsers."""
    p = subparsers.add_parser(
        "experiment", help="run an experiment spec: settings x seeded replications, in parallel",
        description="Run every setting of an experiment spec x its replications, for any robot "
                    "family, in parallel; resumable (finished rows are kept and skipped).")
    p.add_argument("spec", nargs="?", default=None,
                   help="a shipped spec (see --list) or a .toml file")
    p.add_argument("--list", action="store_true",
                   help="list the shipped specs of every family (name, family, jobs, description)")
    p.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="fix a scenario key in every group, value as TOML (repeatable), e.g. "
                        "--set dataset=/data/mrclam/MRCLAM_Dataset6")
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
    p.add_argument("--no-check", action="store_true",
                   help="skip the determinism pre-check of code registered by plugins (one job of each "
                        "setting run twice for a few ticks before the grid)")
    p.add_argument("--executor", choices=EXECUTORS, default="local",
                   help="where jobs run: local (a pool of --workers processes, the default) or "
                        "dask (the workers of --scheduler; pip install 'swarmloc[cluster]')")
    p.add_argument("--scheduler", default=None, metavar="ADDRESS",
                   help="Dask scheduler address for --executor dask, e.g. tcp://HOST:8786")
    p.add_argument("--scheduler-timeout-s", type=float, default=DEFAULT_SCHEDULER_TIMEOUT_S,
                   help="give up if the scheduler does not answer within this (default 10 s)")
    p.add_argument("--worker-timeout-s", type=float, default=DEFAULT_WORKER_TIMEOUT_S,
                   help="give up if no Dask worker has connected to the scheduler within this "
                        f"(default {DEFAULT_WORKER_TIMEOUT_S:g} s)")
    tls = p.add_argument_group("Dask TLS (a tls:// scheduler; the flags `dask scheduler` and "
                               "`dask worker` take, files from `swarmloc tls issue`)")
    tls.add_argument("--tls-ca-file", default=None, metavar="CA.pem",
                     help="the CA that signed the scheduler's, the workers' and this certificate")
    tls.add_argument("--tls-cert", default=None, metavar="NAME.pem", help="this client's certificate")
    tls.add_argument("--tls-key", default=None, metavar="NAME-key.pem",
                     help="this client's private key")
    p.set_defaults(func=main_experiment)


__all__ = [
    "FAMILIES", "ExperimentSpec", "Family", "GroupSpec", "Job", "Setting", "add_parser",
    "default_results_path", "describe", "execution_order", "family", "format_spec_list",
    "list_specs", "load_spec", "main_experiment", "override_text", "plan", "read_done",
    "run_experiment", "run_job", "setting_grid", "settings", "shipped_specs", "value_text",
    "with_overrides",
]
