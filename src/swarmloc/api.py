"""swarmloc from Python: the functions a notebook calls, each returning a pandas data frame.

Every function is a thin layer over the machinery the ``swarmloc`` command uses, not a second
path: ``batch`` and ``experiment`` plan and run their jobs with the experiment engine
(``swarmloc.deploy.lab.experiment``: the same rows, resume and executors as ``swarmloc
experiment``), ``run`` starts the same processes as ``swarmloc run``, ``replay`` is
``swarmloc mrclam``'s replay, ``read_recording`` reads what ``--record`` wrote, and
``report`` is ``swarmloc report``.

Settings are keyword arguments, checked as the command line checks ``--set``: a family's flags
by their short names (``strategy``, ``robots``, ``beta``, ``seed``, ``duration_s``,
``algorithm``: as ``--strategy`` and so on), any other scenario key dotted through ``**{...}``
or with ``__`` for the dots (``agent__beta=0.01`` is ``agent.beta=0.01``). An unknown key is a
``swarmloc.config.ConfigError`` naming it, with a suggestion.

Results are tidy: one row per run (``batch``, ``experiment``, ``run``), per robot
and tick (``read_recording``, ``replay``), with the columns of the CSV rows the
experiment engine writes (documented per family in ``deploy/lab/<family>/experiment.py``).

Nothing heavy is imported until a function is called: ``import swarmloc`` stays fast (no numba,
Zenoh, OpenCV or pandas).
"""

from __future__ import annotations

import json
import tempfile
from collections.abc import Iterable, Mapping
from pathlib import Path
from typing import TYPE_CHECKING, Any

if TYPE_CHECKING:  # pragma: no cover
    import pandas as pd

__all__ = ["batch", "experiment", "read_recording", "read_results", "replay", "report", "run"]

def _overrides(family: str, settings: Mapping[str, Any]) -> list[str]:
    """``KEY=VALUE`` overrides (values as JSON, which TOML reads alike) from keyword settings:
    a family flag by its short name, any other key dotted or with ``__`` for the dots."""
    from swarmloc.config import ConfigError, did_you_mean
    from swarmloc.families import FAMILIES

    flags = FAMILIES.get(family).flags
    out = []
    for key, value in settings.items():
        if key in flags:
            dotted = flags[key]
        elif "." in key or "__" in key:
            dotted = key.replace("__", ".")
        else:
            raise ConfigError(f"{key}: not a setting of a {family} scenario{did_you_mean(key, flags)}; its short names are "
                              f"{', '.join(sorted(flags))}, any other key is dotted "
                              f"(e.g. agent__beta=0.01 or **{{'agent.beta': 0.01}})")
        out.append(f"{dotted}={json.dumps(value)}")
    return out


def _seeds(seeds: int | Iterable[int]) -> tuple[int, int]:
    """``(first seed, replications)``: ``n`` means seeds 1..n; otherwise consecutive seeds."""
    if isinstance(seeds, bool):
        raise TypeError(f"seeds: expected a count or consecutive seeds, got {seeds!r}")
    if isinstance(seeds, int):
        if seeds < 1:
            raise ValueError(f"seeds: need at least one run, got {seeds}")
        return 1, seeds
    values = [int(s) for s in seeds]
    if not values or values != list(range(values[0], values[0] + len(values))):
        raise ValueError(f"seeds: give a count or consecutive seeds (e.g. range(5, 15)), got {values}")
    return values[0], len(values)


def read_results(path: str | Path) -> pd.DataFrame:
    """A results file of ``swarmloc experiment`` (any family) as a data frame, one row per run;
    empty cells (a recruitment time not reached, a metric the run had none of) are NaN."""
    import pandas as pd

    return pd.read_csv(path)


def batch(scenario: str = "ES1", *, seeds: int | Iterable[int] = 1, grid: Mapping[str, list] | None = None,
          workers: int = 1, results: str | Path | None = None, progress: bool = False,
          **settings: Any) -> pd.DataFrame:
    """Run ``scenario`` in one process per job (no Zenoh), once per seed and per combination of
    ``grid``, and return one row per run.

    ``seeds``: a count (seeds 1..n) or consecutive seeds. ``grid``: dotted keys to lists of
    values, crossed (``{"agent.strategy": ["NC", "SSGIKF"]}``). ``results``: a CSV file to
    append the rows to and resume from (default: a temporary file). Any family's scenario: the
    rows are its experiment rows (``swarmloc experiment`` writes the same).

    >>> df = swarmloc.batch("ES1", seeds=3, strategy="NC", duration_s=120)  # doctest: +SKIP
    """
    from swarmloc.deploy.lab.experiment import ExperimentSpec, GroupSpec
    from swarmloc.deploy.scenario import load_any

    loaded = load_any(scenario)
    overrides = _overrides(loaded.family, settings)
    load_any(scenario, None, overrides)  # every setting checked here, as --set is
    first, replications = _seeds(seeds)
    fixed = {}
    for item in overrides:
        key, _, text = item.partition("=")
        fixed[key] = json.loads(text)
    family = loaded.family
    spec = ExperimentSpec(name="batch", description=f"swarmloc.batch({scenario!r})", replications=replications,
                          seed=first, family=family,
                          group=(GroupSpec(name="batch", scenarios=(scenario,), grid=dict(grid or {}) or None,
                                           set=fixed or None),))
    return _run_spec(spec, results, workers=workers, progress=progress)


def experiment(spec: str | Path, *, out: str | Path | None = None, workers: int | None = None,
               executor: str = "local", scheduler: str | None = None, replications: int | None = None,
               duration_s: float | None = None, progress: bool | str = True,
               **settings: Any) -> pd.DataFrame:
    """``swarmloc experiment SPEC``: run every job of a shipped spec or a ``.toml`` file not yet
    in ``out`` (default ``results/<name>.csv``), then return every row of ``out``. Interrupt and
    call again: it resumes. ``settings`` (dotted, or with ``__``) are fixed in every group, as
    ``--set``; ``executor="dask"`` with ``scheduler="tcp://HOST:8786"`` runs on a cluster."""
    from swarmloc.deploy.lab.experiment import default_results_path, load_spec, with_overrides

    fixed = [f"{k.replace('__', '.')}={json.dumps(v)}" for k, v in settings.items()]
    loaded = with_overrides(load_spec(spec), replications=replications, duration_s=duration_s, fixed=fixed)
    path = Path(out) if out is not None else default_results_path(loaded, duration_s)
    return _run_spec(loaded, path, workers=workers, progress=progress, executor=executor, scheduler=scheduler)


def _run_spec(spec, results, *, workers, progress, executor: str = "local",
              scheduler: str | None = None) -> pd.DataFrame:
    from swarmloc.deploy.lab.experiment import run_experiment

    if executor == "local" and workers == 1:
        executor = "inline"  # one job at a time: in this process, no pool to spawn

    if results is None:
        with tempfile.TemporaryDirectory(prefix="swarmloc-batch-") as folder:
            path = Path(folder) / "results.csv"
            run_experiment(spec, path, workers=workers, progress=progress, executor=executor,
                           scheduler=scheduler)
            return read_results(path)
    run_experiment(spec, results, workers=workers, progress=progress, executor=executor, scheduler=scheduler)
    return read_results(results)


def run(scenario: str = "ES1", *, out: str | Path = "runs", run_name: str | None = None, realtime: bool = False,
        record: str | Path | None = None, **settings: Any) -> pd.DataFrame:
    """``swarmloc run``: a router, the world-server and one process per robot over Zenoh, on this
    machine; returns one row (scenario, seed, robots, every metric, the transport's figures,
    the run folder). Raises ``RuntimeError`` if the world-server fails."""
    import pandas as pd

    from swarmloc.deploy.run import run_local
    from swarmloc.deploy.scenario import load_any

    family = load_any(scenario).family
    loaded = load_any(scenario, None, _overrides(family, settings))
    name = run_name or f"{loaded.name}-api-s{loaded.seed}-{_token()}"
    code = run_local(loaded, run_name=name, out_root=Path(out), realtime=realtime, quiet=True,
                     record=str(record) if record is not None else None)
    folder = Path(out) / name
    if code != 0:
        raise RuntimeError(f"swarmloc.run: the run failed (exit {code}); see {folder / 'logs'}")
    result = json.loads((folder / "results.json").read_text())
    row = {"scenario": loaded.name, "family": family, "seed": loaded.seed, "robots": loaded.robots,
           **result.get("metrics", {}),
           **{f"transport_{k}": v for k, v in result.get("transport", {}).items()},
           "rejected_messages": sum(result.get("rejected", {}).values()), "folder": str(folder)}
    return pd.DataFrame([row])


def _token() -> str:
    import secrets

    return secrets.token_hex(3)


def replay(dataset: str | Path | Any, *, algorithm: str = "ekf", cooperative: bool = False, seed: int = 0,
           duration_s: float | None = None, every_s: float = 1.0, **options: Any) -> pd.DataFrame:
    """``swarmloc mrclam DATA``: replay a multi-robot data set (an MRCLAM folder, or a loaded
    ``swarmloc.world.replay.mrclam.MrclamDataset``) to a localizer and
    return one row per robot and time (every ``every_s`` seconds of the replay): ``robot``,
    ``t_s`` (since the start), the estimate ``x_m, y_m, theta_rad``, the ground truth
    ``true_x_m, true_y_m, true_theta_rad`` and ``error_m`` (NaN where the data has no truth).
    ``options`` are ``swarmloc.deploy.lab.replay.mrclam.ReplayConfig`` fields (``params``,
    ``calibration``, ``start``, ``kidnap_s``, ...)."""
    import numpy as np
    import pandas as pd

    from swarmloc.config import ConfigError
    from swarmloc.deploy.lab.replay.mrclam import ReplayConfig, load_dataset, run_replay
    from swarmloc.world.replay.mrclam import MrclamDataset

    try:
        config = ReplayConfig(algorithm=algorithm, cooperative=cooperative, seed=seed, duration_s=duration_s,
                              **options)
    except TypeError as exc:
        raise ConfigError(f"replay: {exc}") from None
    except ValueError as exc:
        raise ConfigError(str(exc)) from None
    data = dataset if isinstance(dataset, MrclamDataset) else load_dataset(dataset)
    result = run_replay(data, config)
    t_s = result.times_s - result.times_s[0]
    step = max(1, round(every_s / config.dt_s)) if every_s > 0 else 1
    keep = np.arange(0, t_s.size, step)
    error = result.position_error_m()
    frames = []
    for k, rid in enumerate(result.robot_ids):
        frames.append(pd.DataFrame({
            "algorithm": config.label, "robot": rid, "t_s": t_s[keep],
            "x_m": result.estimates[keep, k, 0], "y_m": result.estimates[keep, k, 1],
            "theta_rad": result.estimates[keep, k, 2],
            "true_x_m": result.truth[keep, k, 0], "true_y_m": result.truth[keep, k, 1],
            "true_theta_rad": result.truth[keep, k, 2], "error_m": error[keep, k]}))
    return pd.concat(frames, ignore_index=True)


def read_recording(path: str | Path) -> pd.DataFrame:
    """A recording (``swarmloc run --record``, ``swarmloc batch --record``, ``swarmloc record``)
    as one row per robot and recorded frame: ``tick``, ``t_s``, ``robot``, the true pose
    ``x_m, y_m, theta_rad`` and, where the frame has them, the robot's own estimate
    ``est_x_m, est_y_m, est_theta_rad``. A file cut short is read up to its last whole message
    (``frame.attrs["truncated"]`` says what was wrong)."""
    import pandas as pd

    from swarmloc.deploy.observe.record import read_recording as read

    rec = read(path)
    rows = []
    for frame in rec.frames:  # deploy/observe/frames.py: "truth" and "estimates", world frame
        truth = frame.get("truth") or (frame.get("state") or {}).get("poses") or []
        estimates = frame.get("estimates") or []
        for robot, pose in enumerate(truth):
            est = estimates[robot] if robot < len(estimates) and estimates[robot] is not None else (None,) * 3
            rows.append({"tick": frame.get("tick"), "t_s": frame.get("time_s"), "robot": robot,
                         "x_m": pose[0], "y_m": pose[1], "theta_rad": pose[2],
                         "est_x_m": est[0], "est_y_m": est[1], "est_theta_rad": est[2]})
    df = pd.DataFrame(rows, columns=["tick", "t_s", "robot", "x_m", "y_m", "theta_rad", "est_x_m", "est_y_m",
                                     "est_theta_rad"])
    df.attrs["truncated"] = rec.truncated
    df.attrs["scene"] = rec.scene
    return df


def report(results: str | Path | Iterable[str | Path], *, out: str | Path, title: str | None = None,
           variant: str | None = None, reasons: str | Path | None = None) -> Path:
    """``swarmloc report``: the page (README.md with box plots) of one or more results files in
    ``out``; returns the page's path."""
    from swarmloc.deploy.lab.report import main as report_main

    paths = [results] if isinstance(results, (str, Path)) else list(results)
    argv = ["report", *map(str, paths), "--out", str(out)]
    if title is not None:
        argv += ["--title", title]
    if variant is not None:
        argv += ["--variant", variant]
    if reasons is not None:
        argv += ["--reasons", str(reasons)]
    code = report_main(argv[1:])
    if code != 0:
        raise RuntimeError(f"swarmloc.report: the report failed (exit {code})")
    return Path(out) / "README.md"
