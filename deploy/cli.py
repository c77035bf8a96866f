"""The ``swarmloc`` command.

- ``swarmloc run [SCENARIO]``: router + world-server + N agent processes on this machine;
  progress, metrics at the end, a run folder with configuration, seed and results.
- ``swarmloc world SCENARIO`` / ``swarmloc agent --robot ID`` / ``swarmloc router``: one piece
  each, to run on different machines with ``-e/--connect``.
- ``swarmloc batch [SCENARIO]``: the same run in one process with no Zenoh (batch engine).
- ``swarmloc scenarios``: the shipped scenarios.

Each subcommand is ``main_X(args) -> int``; parsing is separate. Options override the scenario; a
bad scenario file or option stops the command before anything starts, naming the problem.
"""

from __future__ import annotations

import argparse
import json
import logging
import os
import signal
import sys
import threading
import time
from pathlib import Path

from swarmloc.config import ConfigError

log = logging.getLogger("swarmloc")

DEFAULT_SCENARIO = "ES1"
#: Simulated seconds of the default ``swarmloc run`` (ES1 itself lasts 1800 s).
DEFAULT_RUN_DURATION_S = 600.0


# -- shared option groups ---------------------------------------------------------------------


def _scenario_args(p: argparse.ArgumentParser, positional: bool = True) -> None:
    if positional:
        p.add_argument("scenario", nargs="?", default=None,
                       help="shipped scenario name (see `swarmloc scenarios`) or a .toml/.json file; "
                            "default ES1 (for `swarmloc run`: ES1 shortened to 600 s)")
    g = p.add_argument_group("scenario overrides")
    g.add_argument("--robots", type=int, help="number of robots")
    from swarmloc.agents.epuck.social_odometry import STRATEGIES

    batch_only = [n for n, s in STRATEGIES.items() if s.central]
    others = [n for n in STRATEGIES if n not in batch_only]
    g.add_argument("--strategy", help=f"e-puck scenarios: {', '.join(others)}; {' or '.join(batch_only)} "
                                      "(batch engine only)")
    g.add_argument("--beta", type=float, help="Fermi beta of the SGIFFs")
    g.add_argument("--algorithm", help="laser scenarios: ssga, simple_ga, cfsga or amcl")
    g.add_argument("--seed", type=int, help="run seed")
    g.add_argument("--duration-s", type=float, help="simulated duration in seconds")
    g.add_argument("--set", action="append", default=[], metavar="KEY=VALUE",
                   help="any scenario value, e.g. --set world.medium.range_m=0.25 (repeatable)")
    g.add_argument("--variant", default=None, metavar="NAME",
                   help="a named set of overrides, applied before --set (e-puck): v0-defaults "
                        "(the defaults before issue 18's readings of the seeds), v1-defaults "
                        "(issue 18's first readings), v2-defaults (one message per encounter, "
                        "before issue 42), top-speed (cruise at the e-puck's 1,000 steps/s), "
                        "goals-25 (nest and prey at 25 / 75 %% of the long side)")


def load_from_args(args, any_family: bool = False, refuse_central: bool = True):
    """The scenario named by the arguments, with every override applied and validated: an e-puck
    :class:`Scenario`, or with ``any_family`` an :class:`AnyScenario` of any robot family (an
    e-puck strategy shared by a central system refused unless ``refuse_central`` is False: only
    the batch engine runs those)."""
    from swarmloc.deploy.scenario import load_any, variant_overrides

    overrides = variant_overrides(getattr(args, "variant", None)) + list(args.set)
    if args.scenario is None:
        args.scenario = DEFAULT_SCENARIO
        if getattr(args, "command", None) == "run" and args.duration_s is None:
            # The default demo finishes in about a minute on two cores; the full ES1 is 1800 s.
            overrides.insert(0, f"world.duration_s={DEFAULT_RUN_DURATION_S}")
    flags = {flag: getattr(args, flag, None)
             for flag in ("robots", "strategy", "beta", "seed", "duration_s", "algorithm")}
    loaded = load_any(args.scenario, flags, overrides)
    if any_family:
        if refuse_central:
            _refuse_central(loaded)
        return loaded
    if loaded.family != "foraging":
        raise ConfigError(f"scenario '{args.scenario}' is a {loaded.family} scenario; "
                          f"this command runs e-puck foraging scenarios")
    return loaded.scenario


def _refuse_central(loaded) -> None:
    """Processes cannot run a strategy whose sharing is done by a central system that knows the
    true poses (seed 001's global imitation): say so before anything starts."""
    if loaded.family != "foraging":
        return
    from swarmloc.agents.epuck.social_odometry import STRATEGIES

    name = loaded.scenario.agent.strategy
    if STRATEGIES[name].central:
        raise ConfigError(f"agent.strategy: {name} is shared by a central system that knows every "
                          f"robot's true pose; only the batch engine has one (swarmloc batch, "
                          f"swarmloc experiment), not a swarm of processes")


def _transport(p: argparse.ArgumentParser) -> None:
    from swarmloc.protocol.session import add_transport_args

    add_transport_args(p)


def _run_name(p: argparse.ArgumentParser, required: bool = False) -> None:
    p.add_argument("--run", required=required, default=None if required else "local",
                   help="run name: the key prefix swarmloc/<run>/ that keeps runs apart")


def _compile_kernels(family: str | None = None) -> None:
    """Compile the kernels if this machine's cache lacks them (deploy/warm.py), saying so on
    stderr; a few milliseconds when the cache is warm. Nothing for a family that runs none
    (``Family.compiled_kernels``); ``None``: the family is not known yet, compile."""
    from swarmloc.families import needs_kernels

    if not needs_kernels(family):
        return
    from swarmloc.deploy.warm import ensure_compiled

    ensure_compiled(lambda line: print(f"swarmloc: {line}", file=sys.stderr, flush=True))


def _install_stop() -> threading.Event:
    stop = threading.Event()

    def handler(signum, frame):
        stop.set()

    signal.signal(signal.SIGINT, handler)
    signal.signal(signal.SIGTERM, handler)
    return stop


# -- subcommands ------------------------------------------------------------------------------


def main_scenarios(args) -> int:
    from swarmloc.deploy.scenario import builtin_names, scenario_data

    for name in builtin_names(None):
        data = scenario_data(name)
        print(f"{name:30s} {data.get('family', 'foraging'):9s} {data.get('description', '')}")
    return 0


def main_router(args) -> int:
    from swarmloc.protocol.session import (
        ROUTER_MIN_SESSIONS,
        bound_endpoints,
        open_session,
        session_config,
    )

    stop = _install_stop()
    config = session_config(mode="router", listen=args.listen or ["tcp/127.0.0.1:7447"],
                            connect=args.connect or (), config_file=args.config,
                            min_sessions=ROUTER_MIN_SESSIONS)
    with open_session(config) as session:
        endpoints = bound_endpoints(session)
        if args.announce:
            print(json.dumps({"endpoints": endpoints}), flush=True)
        else:
            print(f"router listening on {', '.join(endpoints)}", flush=True)
        stop.wait()
    return 0


def main_world(args) -> int:
    from swarmloc.protocol.keys import Keys
    from swarmloc.protocol.session import (
        SESSION_MARGIN,
        bound_endpoints,
        config_from_args,
        open_session,
    )
    from swarmloc.world.server import WorldServer
    from swarmloc.world.service import served_world

    scenario = load_from_args(args, any_family=True)
    keys = Keys(args.run)
    from swarmloc.deploy.run import ensure_open_files

    ensure_open_files(scenario.robots)  # a connection per agent: refused here, not after start-up
    stop = _install_stop()
    _compile_kernels(scenario.family)  # before the join queryable: the join timeout never races a compiler
    out = Path(args.out) if args.out else None
    if out:
        out.mkdir(parents=True, exist_ok=True)
        (out / "scenario.json").write_text(json.dumps(scenario.to_dict(), indent=2))
    labels = {"scenario": scenario.name, "family": scenario.family, "seed": scenario.seed,
              "run": args.run, "strategy": scenario.label, "robots": scenario.robots,
              "mode": "realtime" if args.realtime else "lockstep"}

    def write_results(result: dict) -> None:
        # Atomic: a reader, or a crash mid-write, never sees half a file.
        tmp = out / "results.json.tmp"
        tmp.write_text(json.dumps({**result, **labels}, indent=2))
        os.replace(tmp, out / "results.json")

    from swarmloc.deploy.launch import WORLD_ZENOH_RUNTIME

    os.environ.setdefault("ZENOH_RUNTIME", WORLD_ZENOH_RUNTIME)  # read when the first session opens
    with open_session(config_from_args(args, min_sessions=scenario.robots + SESSION_MARGIN)) as session:
        from swarmloc.deploy.observe.tap import WorldTap
        from swarmloc.families import FAMILIES

        served = served_world(scenario)
        viewable = FAMILIES.get(scenario.family).frames is not None
        if args.record and not viewable:
            raise ConfigError(f"--record: family {scenario.family!r} has no frame source (Family.frames), "
                              "so its runs cannot be recorded")
        tap = WorldTap(served, session=session, keys=keys, record=args.record,
                       record_messages=args.record_messages, max_hz=args.frame_hz,
                       labels={"run": args.run, "scenario": scenario.name}) if viewable else None
        server = WorldServer(session, keys, served, scenario.to_dict(),
                             realtime=args.realtime, act_timeout_s=args.act_timeout_s,
                             join_timeout_s=args.join_timeout_s,
                             checkpoint=write_results if out else None,
                             checkpoint_every_s=args.checkpoint_s, tap=tap,
                             samples=args.particles)
        server.declare()
        if args.announce:
            print(json.dumps({"endpoints": bound_endpoints(session)}), flush=True)
        watcher = threading.Thread(target=lambda: (stop.wait(), server.stop()), daemon=True)
        watcher.start()
        try:
            if not server.wait_for_agents():
                result = server.finish("agents missing")
                code = 3
            else:
                log.info("all %d agents joined; running", scenario.robots)
                result = server.run()
                code = 0 if result["reason"] == "completed" else 4
        finally:
            server.close()
            if tap is not None:
                tap.close()
    if out:
        write_results(result)
    else:
        print(json.dumps({**result, **labels}))
    return code


def main_agent(args) -> int:
    stop = _install_stop()
    if args.nice:
        os.nice(args.nice)
    _compile_kernels(args.family)  # before joining: a joined agent is ready to answer its first Sense
    return serve_agent(args, stop)


def serve_agent(args, stop: threading.Event) -> int:
    """One agent's session and run, from ``swarmloc agent``'s arguments: what ``swarmloc
    agent`` does once its kernels are compiled, and what each agent forked by ``swarmloc agents``
    does (deploy/fork/server.py)."""
    from swarmloc.agents.node import run_agent
    from swarmloc.protocol.keys import Keys
    from swarmloc.protocol.session import config_from_args, open_session

    with open_session(config_from_args(args)) as session:
        return run_agent(session, Keys(args.run), args.robot, stop, join_timeout_s=args.join_timeout_s,
                         world_timeout_s=args.world_timeout_s, world_grace_s=args.world_grace_s,
                         null_brain=args.null_brain)


def main_batch(args) -> int:
    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.run import print_metrics

    loaded = load_from_args(args, any_family=True, refuse_central=False)
    if loaded.family != "foraging":
        return _batch_other_family(args, loaded)
    scenario = loaded.scenario
    _compile_kernels()
    t0 = time.perf_counter()
    if args.record:
        from swarmloc.deploy.observe.batch_record import run_batch_recorded

        result = run_batch_recorded(scenario, args.record)
    else:
        result = run_batch(scenario)
    summary = {"scenario": scenario.name, "strategy": scenario.agent.strategy,
               "seed": scenario.world.seed, "robots": scenario.world.robots,
               "wall_s": round(time.perf_counter() - t0, 2), "metrics": result.metrics}
    if args.json:
        print(json.dumps(summary))
    else:
        print_metrics(summary)
    return 0


def _batch_other_family(args, loaded) -> int:
    """``swarmloc batch`` of a laser, vision or replay scenario (any family with experiment
    hooks): one seeded run in this process by the family's experiment hooks, as ``swarmloc
    experiment`` runs a job; prints its row (``--json``: as JSON). ``--record`` is the e-puck
    batch engine's only."""
    from swarmloc.config import parse_assignment
    from swarmloc.deploy.lab.experiment import ExperimentSpec, GroupSpec, _rows, plan, run_job
    from swarmloc.deploy.scenario import variant_overrides
    from swarmloc.families import FAMILIES

    if args.record:
        raise ConfigError(f"--record: the batch engine records e-puck runs; record a {loaded.family} run "
                          f"with `swarmloc run {args.scenario} --record FILE.mcap`")
    fixed = {}
    flags = {flag: getattr(args, flag, None) for flag in ("robots", "strategy", "beta", "duration_s", "algorithm")}
    keys = FAMILIES.get(loaded.family).flags
    for flag, value in flags.items():
        if value is not None:
            fixed[keys[flag]] = value  # load_from_args already refused a flag the family has no use for
    for item in variant_overrides(getattr(args, "variant", None)) + list(args.set):
        key, value = parse_assignment(item)
        fixed[key] = value
    seed = loaded.seed
    spec = ExperimentSpec(name="batch", description=f"swarmloc batch {args.scenario}", replications=1, seed=seed,
                          family=loaded.family,
                          group=(GroupSpec(name="batch", scenarios=(args.scenario,), set=fixed or None),))
    (job,) = plan(spec)
    t0 = time.perf_counter()
    row = dict(zip(spec.columns(), _rows(spec, job, run_job(job))[0], strict=True))
    row["wall_s"] = round(time.perf_counter() - t0, 2)
    if args.json:
        print(json.dumps(row, default=str))
    else:
        print(f"scenario {loaded.name}  {loaded.family}  {loaded.label}  seed {seed}  robots {loaded.robots}")
        for key, value in row.items():
            if key in ("experiment", "group", "setting", "scenario", "seed", "replication", "config_hash"):
                continue
            text = str(value)
            print(f"  {key:29s}: {text if len(text) <= 60 else '(a series: see --json)'}")
    return 0


def main_run(args) -> int:
    from swarmloc.deploy.run import run_local

    scenario = load_from_args(args, any_family=True)
    if args.null_brains and scenario.family != "foraging":
        raise ConfigError(f"--null-brains stands in for e-puck brains only; scenario "
                          f"'{scenario.name}' is a {scenario.family} scenario")
    return run_local(scenario, run_name=args.run, out_root=Path(args.out), realtime=args.realtime,
                     quiet=args.quiet, join_timeout_s=args.join_timeout_s, null_brains=args.null_brains,
                     view=args.view, view_http=args.view_http, record=args.record,
                     record_messages=args.record_messages, particles=args.particles)


#: Verbs that became experiment specs (issue 16): what to run instead.
RETIRED_VERBS = {
    "laser-experiment": (
        "the laser experiments are specs of `swarmloc experiment`: run\n"
        "  swarmloc experiment laser-table3 --out results/laser-table3.csv   (and laser-kidnap, "
        "laser-collab, laser-robustness)\n"
        "  swarmloc report results/laser-table3.csv results/laser-kidnap.csv "
        "results/laser-collab.csv results/laser-robustness.csv --out docs/laser"),
    "vision-experiment": (
        "the vision experiments are the spec `vision` of `swarmloc experiment`: run\n"
        "  swarmloc experiment vision            (groups: main, heading-error, "
        "heading-error-prior, box-body, robot-count; --replications N for fewer runs)\n"
        "  swarmloc report results/vision.csv --out docs/vision"),
    "mrclam --all": (
        "every MRCLAM configuration is the spec `mrclam6` of `swarmloc experiment`: run\n"
        "  swarmloc experiment mrclam6 [--set dataset=PATH]\n"
        "  swarmloc report results/mrclam6.csv --out docs/mrclam"),
}


def refuse_retired(verb: str):
    def main_retired(args) -> int:
        raise ConfigError(f"`swarmloc {verb}` is retired; {RETIRED_VERBS[verb]}")

    return main_retired


def main_mrclam(args) -> int:
    from swarmloc.deploy.lab.replay.mrclam import main as run

    if args.all:
        return refuse_retired("mrclam --all")(args)
    return run(args)


# -- parsing ----------------------------------------------------------------------------------


def _agent_args(p: argparse.ArgumentParser) -> None:
    """The options of ``swarmloc agent`` but ``--robot``, shared with ``swarmloc agents``."""
    _run_name(p)
    _transport(p)
    p.add_argument("--join-timeout-s", type=float, default=180.0)
    p.add_argument("--world-timeout-s", type=float, default=60.0,
                   help="exit when no Sense came for this long")
    p.add_argument("--world-grace-s", type=float, default=10.0,
                   help="how long to wait for a world-server that went away to come back (exit code 3)")
    p.add_argument("--nice", type=int, default=0, choices=range(20), metavar="0..19",
                   help="lower this agent's CPU priority: on a machine with fewer cores than agents, "
                        "the world-server (the lockstep's serial part) then runs first")
    p.add_argument("--family", default=None, metavar="NAME",
                   help="the robot family the world serves, if known (swarmloc run passes it): "
                        "an agent of a family without compiled kernels skips compiling them "
                        "(default: compile them, as an e-puck agent needs)")
    p.add_argument("--null-brain", action="store_true",
                   help="transport benchmark: answer each Sense with a standstill Act instead of "
                        "running the brain (e-puck scenarios)")


def build_parser() -> argparse.ArgumentParser:
    from swarmloc.deploy import warm
    from swarmloc.deploy.lab import experiment, report
    from swarmloc.deploy.observe import cli as observe_cli

    parser = argparse.ArgumentParser(prog="swarmloc", description=__doc__.splitlines()[0])
    parser.add_argument("-v", "--verbose", action="store_true", help="log more")
    parser.add_argument("--plugin", action="append", default=[], metavar="MODULE_OR_FILE.py",
                        help="import a plugin (a new localizer, strategy, family...: "
                             "docs/extending.md) in this command and every process it starts "
                             "(repeatable; also SWARMLOC_PLUGINS)")
    sub = parser.add_subparsers(dest="command", required=True)

    p = sub.add_parser("run", help="launch a swarm of processes on this machine")
    _scenario_args(p)
    p.add_argument("--run", default=None, help="run name (default: scenario-strategy-seed-random)")
    p.add_argument("--out", default="runs", help="folder for run folders (default: runs/)")
    p.add_argument("--realtime", action="store_true", help="tick on the wall clock instead of lockstep")
    p.add_argument("--quiet", action="store_true", help="no progress bar")
    p.add_argument("--join-timeout-s", type=float, default=180.0)
    p.add_argument("--null-brains", action="store_true",
                   help="transport benchmark: e-puck agents answer each Sense with a standstill Act "
                        "instead of running their brains")
    observe_cli.add_run_arguments(p)
    p.set_defaults(func=main_run)

    p = sub.add_parser("world", help="run the world-server")
    _scenario_args(p)
    _run_name(p)
    _transport(p)
    p.add_argument("--out", default=None, help="folder for scenario.json and results.json")
    p.add_argument("--announce", action="store_true",
                   help="print the endpoints this world listens on as one JSON line once it serves")
    p.add_argument("--realtime", action="store_true")
    p.add_argument("--act-timeout-s", type=float, default=10.0)
    p.add_argument("--checkpoint-s", type=float, default=5.0,
                   help="write the results so far to --out this often (wall seconds)")
    p.add_argument("--join-timeout-s", type=float, default=180.0,
                   help="give up when no new agent joined for this long (agents still arriving: wait)")
    observe_cli.add_world_arguments(p)
    p.set_defaults(func=main_world)

    p = sub.add_parser("agent", help="run one robot's agent")
    p.add_argument("--robot", type=int, required=True, help="robot id")
    _agent_args(p)
    p.set_defaults(func=main_agent)

    from swarmloc.deploy.fork import server as fork_server

    fork_server.add_parser(sub, _agent_args)

    p = sub.add_parser("router", help="run a Zenoh router (no zenohd needed)")
    _transport(p)
    p.add_argument("--announce", action="store_true", help="print the bound endpoints as one JSON line")
    p.set_defaults(func=main_router)

    p = sub.add_parser("batch", help="run a scenario in one process, no Zenoh (e-puck: the batch engine; "
                                     "other families: one run as an experiment job)")
    _scenario_args(p)
    p.add_argument("--json", action="store_true")
    p.add_argument("--record", default=None, metavar="FILE.mcap",
                   help="write every tick's world state and the brains' estimates to FILE.mcap")
    p.set_defaults(func=main_batch)

    experiment.add_parser(sub)
    report.add_parser(sub)
    observe_cli.add_parsers(sub)
    warm.add_parser(sub)
    from swarmloc import checker

    checker.add_parser(sub)
    from swarmloc.protocol import tls

    tls.add_parser(sub)

    for verb in ("laser-experiment", "vision-experiment"):
        p = sub.add_parser(verb, help=f"retired: see `swarmloc {verb}` (now a spec of "
                                      f"`swarmloc experiment`)", add_help=False)
        p.add_argument("ignored", nargs=argparse.REMAINDER)
        p.set_defaults(func=refuse_retired(verb))
    from swarmloc.deploy.observe import status

    status.add_parser(sub)

    p = sub.add_parser("mrclam", help="run a localizer on an MRCLAM data set (real robots' "
                                      "data) and score it against the ground truth")
    from swarmloc.deploy.lab.replay.mrclam import add_arguments as mrclam_arguments

    mrclam_arguments(p)
    p.set_defaults(func=main_mrclam)

    p = sub.add_parser("scenarios", help="list the shipped scenarios")
    p.set_defaults(func=main_scenarios)
    return parser


def _take_plugins(argv: list[str]) -> tuple[list[str], list[str]]:
    """``--plugin X`` / ``--plugin=X`` wherever they stand (before or after the verb): the
    plugins and the other arguments. Plugins load before the parser is built, so that every
    command sees their names (issue 48: after the verb, ``--plugin`` was "unrecognized")."""
    plugins, rest = [], []
    it = iter(argv)
    for arg in it:
        if arg == "--plugin":
            value = next(it, None)
            if value is None:
                raise ConfigError("--plugin: expected a module or a .py file after it")
            plugins.append(value)
        elif arg.startswith("--plugin="):
            plugins.append(arg.partition("=")[2])
        else:
            rest.append(arg)
    return plugins, rest


def main(argv: list[str] | None = None) -> int:
    try:
        from swarmloc.registry import add_plugins

        plugins, argv = _take_plugins(sys.argv[1:] if argv is None else list(argv))
        add_plugins(plugins)  # and those of SWARMLOC_PLUGINS / entry points
    except (ConfigError, ValueError) as exc:
        print(f"swarmloc: error: {exc}", file=sys.stderr)
        return 2
    parser = build_parser()
    args = parser.parse_args(argv)
    logging.basicConfig(level=logging.INFO if args.verbose else logging.WARNING,
                        format="%(asctime)s %(name)s %(levelname)s %(message)s")
    try:
        return args.func(args)
    except ConfigError as exc:
        print(f"swarmloc: error: {exc}", file=sys.stderr)
        return 2
    except ValueError as exc:  # a bad transport flag, run name, ...
        print(f"swarmloc: error: {exc}", file=sys.stderr)
        return 2


def console_main() -> None:
    """The ``swarmloc`` command as a process (the console script and ``python -m swarmloc``):
    :func:`main`, then an immediate exit. Once a piece has closed its session and written its
    results, Python's own teardown of the loaded libraries (numba's compiler, Zenoh's runtime,
    OpenCV...) took 0.8-1.0 s more on two cores, 2.7 s once under load: a world asked to stop took
    that long to go. Streams and logs are flushed first; files are closed by then (``main`` and
    the pieces close what they open), and nothing in swarmloc registers atexit work."""
    try:
        code = main()
    except SystemExit as exc:  # argparse's errors, `swarmloc run` unwinding on SIGTERM
        code = exc.code if isinstance(exc.code, int) else (0 if exc.code is None else 1)
        if exc.code is not None and not isinstance(exc.code, int):
            print(exc.code, file=sys.stderr)
    logging.shutdown()
    for stream in (sys.stdout, sys.stderr):
        try:
            stream.flush()
        except (OSError, ValueError):
            pass
    os._exit(code if isinstance(code, int) else 1)


if __name__ == "__main__":
    console_main()
