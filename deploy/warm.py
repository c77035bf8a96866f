"""Compile swarmloc's kernels once per machine, in one process, before any piece waits on another.

The e-puck world, brain, agent tick and batch engine run in numba kernels cached on disk
(:mod:`swarmloc.kernel_cache` says where). On a machine where the cache is cold, compiling them
takes 15-25 s of one core. Left to each piece, a world-server and ten agents started together
compile the same kernels at once, on two cores, for longer than the world's join timeout: the
first ``swarmloc run`` of every new machine failed that way. So compiling is a step of its own:

- :func:`ensure_compiled` compiles (or finds compiled) every kernel a run calls, under an
  exclusive lock in the cache folder, then writes a stamp. A process that finds the stamp current
  returns at once (a few milliseconds: it reads the stamp and stats the kernel sources); one that
  finds the lock taken waits for it, then finds the stamp current. Hence one compile per machine,
  never two at once, whatever starts first.
- ``swarmloc run`` calls it before it starts the router, saying so when it compiles; ``swarmloc
  world`` before it declares its join queryable (its join timeout starts after); ``swarmloc
  agent`` before it joins; ``swarmloc batch`` and ``swarmloc experiment`` before their workers
  start. ``swarmloc warm`` runs it alone, for deployment scripts and systemd's ``ExecStartPre=``.

The stamp holds what numba keys its cache entries by: each kernel source's path, modification
time and size (the files of the package that declare ``cache=True``), the versions of Python,
numba and numpy, and the CPU; also the swarmloc modules a kernel source imports from, whose
constants the kernels freeze. A checkout that touches one of those, an upgrade or another CPU
sharing the home folder makes it stale, and the next piece compiles again, once, after
:func:`forget_cached` has deleted this install's entries: numba checks an entry against its own
source file only, so a kernel whose callee in another file changed (or a constant it imports) would
otherwise load its old machine code, silently (``tests/test_warm.py`` shows it on two small files).

What "every kernel a run calls" means is :func:`exercise`: a few ticks of a served e-puck world
answered by agents on both of their paths (bytes to bytes, and decode-step-encode), for every
strategy, and a short batch run of each. numba compiles one machine-code version per argument
types, so running the real call sites is what covers them; ``tests/test_warm.py`` holds that a
run after :func:`ensure_compiled` adds nothing to the cache.
"""

from __future__ import annotations

import fcntl
import hashlib
import json
import os
import platform
import sys
import time
from collections.abc import Callable
from contextlib import contextmanager
from pathlib import Path

from swarmloc.kernel_cache import cache_dir

LOCK_NAME = "swarmloc-kernels.lock"
#: What the user is told while the kernels compile (measured on the project's 2-core machine).
COMPILING_MESSAGE = "compiling kernels, once per machine (under a minute)"


def _packages() -> list:
    """swarmloc's root package and its four mapped subpackages, wherever the install put them
    (an editable install maps them to the repository's top-level folders)."""
    import swarmloc
    import swarmloc.agents
    import swarmloc.deploy
    import swarmloc.protocol
    import swarmloc.world

    return [swarmloc, swarmloc.agents, swarmloc.deploy, swarmloc.protocol, swarmloc.world]


def _package_dirs() -> list[Path]:
    """The folders of swarmloc's subpackages."""
    return sorted({Path(p).resolve() for m in _packages() for p in m.__path__})


def kernel_sources() -> list[Path]:
    """The package's source files that declare a cached numba kernel (a decorator line with
    ``cache=True``; files that only mention it, this one included, are not kernels, and counting
    them made every edit of theirs a full recompile)."""
    import re

    decorator = re.compile(r"^\s*@.*\bcache=True", flags=re.MULTILINE)
    found = []
    for folder in _package_dirs():
        for path in sorted(folder.rglob("*.py")):
            try:
                if decorator.search(path.read_text(encoding="utf-8")):
                    found.append(path)
            except OSError:
                continue
    return found


def _imported_modules(sources: list[Path]) -> list[Path]:
    """The swarmloc modules the kernel sources import from (``from swarmloc.x import NAME``),
    found by reading the sources, without importing anything (a regular expression: parsing
    them took 60 ms, at every piece's start)."""
    import re

    roots = {m.__name__: Path(next(iter(m.__path__))).resolve() for m in _packages()}
    found = set()
    for path in sources:
        for module in re.findall(r"^\s*from\s+(swarmloc(?:\.\w+)*)\s+import\b",
                                 path.read_text(encoding="utf-8"), flags=re.MULTILINE):
            root = max((r for r in roots if module == r or module.startswith(r + ".")), key=len)
            base = roots[root].joinpath(*module[len(root):].split(".")[1:])
            for candidate in (base.with_suffix(".py"), base / "__init__.py"):
                if candidate.is_file():
                    found.add(candidate)
                    break
    return sorted(found - set(sources))


def forget_cached(folder: Path, sources: list[Path]) -> int:
    """Delete numba's entries for ``sources`` from the cache ``folder`` (where numba's
    ``NUMBA_CACHE_DIR`` locator puts them); returns how many files went. The next import compiles
    them from today's sources."""
    from numba.core.caching import UserProvidedCacheLocator

    removed = 0
    for source in sources:
        sub = folder / UserProvidedCacheLocator.get_suitable_cache_subpath(str(source))
        for entry in sub.glob(f"{source.stem}.*"):
            if entry.suffix in (".nbi", ".nbc"):
                entry.unlink(missing_ok=True)
                removed += 1
    return removed


def _cpu() -> str:
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            lines = [ln for ln in f.read().splitlines()[:40] if ln.startswith(("model name", "flags"))]
        return "\n".join(lines) or platform.processor()
    except OSError:
        return platform.processor() or platform.machine()


def fingerprint() -> str:
    """What the cache must have been compiled for (see the module docstring), as JSON."""
    from importlib.metadata import version

    sources = []
    kernels = kernel_sources()
    for path in kernels + _imported_modules(kernels):
        st = path.stat()
        sources.append([str(path), st.st_mtime_ns, st.st_size])
    return json.dumps({
        "python": sys.version, "numba": version("numba"), "numpy": version("numpy"),
        "machine": platform.machine(), "cpu": _cpu(), "sources": sources,
    }, indent=1)


def stamp_path(folder: Path) -> Path:
    """This install's stamp in the cache ``folder``. One per install, named by where its sources
    are: numba keys its entries by source path, so two checkouts or installs sharing a cache
    folder never share entries, and with one stamp between them each took the other's for stale
    and both recompiled in turn, waiting on each other's lock."""
    key = hashlib.sha256("\n".join(map(str, _package_dirs())).encode()).hexdigest()[:12]
    return folder / f"swarmloc-kernels-{key}.stamp"


def is_warm(folder: Path | None = None) -> bool:
    """True if ``folder`` (default: this process's cache folder) has a current stamp."""
    stamp = stamp_path(folder or cache_dir())
    try:
        return stamp.read_text(encoding="utf-8") == fingerprint()
    except OSError:
        return False


@contextmanager
def _locked(folder: Path, on_wait: Callable[[], None]):
    folder.mkdir(parents=True, exist_ok=True)
    with open(folder / LOCK_NAME, "a+") as lock:
        try:
            fcntl.flock(lock, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            on_wait()
            fcntl.flock(lock, fcntl.LOCK_EX)
        try:
            yield
        finally:
            fcntl.flock(lock, fcntl.LOCK_UN)


def ensure_compiled(say: Callable[[str], None] | None = None, *, force: bool = False) -> bool:
    """Compile every kernel into the cache unless its stamp is current; returns True if this
    process compiled. ``say`` gets one line before a compile (and one while waiting for another
    process's). ``force``: exercise the kernels even with a current stamp (numba then loads what
    is cached and compiles only what is missing)."""
    say = say or (lambda line: None)
    folder = cache_dir()
    if not force and is_warm(folder):
        return False
    with _locked(folder, lambda: say(f"waiting for another process compiling kernels into {folder}")):
        if not force and is_warm(folder):  # the process we waited for did it
            return False
        say(f"{COMPILING_MESSAGE} into {folder}")
        t0 = time.perf_counter()
        if not force:  # stale: nothing of this install's cache may survive (module docstring)
            forget_cached(folder, kernel_sources())
        compile_all()
        stamp = stamp_path(folder)
        tmp = stamp.with_name(f"{stamp.name}.{os.getpid()}.tmp")
        tmp.write_text(fingerprint(), encoding="utf-8")
        os.replace(tmp, stamp)
        say(f"kernels ready ({time.perf_counter() - t0:.0f} s)")
    return True


def _load_world_kernels() -> None:
    """The world's kernels (one served world's first ticks); run in a process of its own by
    :func:`compile_all`, beside the brain's."""
    from swarmloc.deploy.scenario import load_any
    from swarmloc.world.service import served_world

    world = served_world(load_any("ES1", {"seed": 1}, ["world.robots=6"]))
    for _ in range(3):
        world.senses()
        world.step([None] * world.n_robots)


def _load_brain_kernels() -> None:
    """The brain's kernels and the agent's packed tick: building an agent loads them."""
    from swarmloc.agents.epuck.agent import ForagingAgent
    from swarmloc.agents.epuck.foraging import ForagingBrain, agent_rng
    from swarmloc.deploy.scenario import load_any

    sc = load_any("ES1", {"seed": 1}, ["world.robots=1"]).scenario
    ForagingAgent(ForagingBrain(sc.agent, sc.world.body, [0], [agent_rng(1, 0)], sc.world.tick_s), 0)


def compile_all() -> None:
    """Compile what the cache lacks, on two cores: the world's kernels in a child process while
    this one compiles the brain's (neither calls the other's), then :func:`exercise`, which finds
    both cached and compiles the rest (the batch engine's tick, which calls both). Measured cold
    on the project's 2-core machine: world 22 s, brain 33 s, batch 5 s; 60 s one after the other."""
    import subprocess

    code = "from swarmloc.deploy.warm import _load_world_kernels as f; f()"
    child = subprocess.Popen([sys.executable, "-c", code], stdin=subprocess.DEVNULL)
    try:
        _load_brain_kernels()
    finally:
        if child.wait() != 0:
            raise RuntimeError(f"compiling the world's kernels failed (exit {child.returncode})")
    exercise()


def exercise(ticks: int = 40) -> None:
    """Call every compiled kernel as runs call it (compiling what the cache lacks): a served
    ES1 world answered by agents on both their paths, for every strategy a process runs, and a
    short batch run of every strategy."""
    from swarmloc.agents.epuck.social_odometry import STRATEGIES
    from swarmloc.deploy.lab.epuck.batch import run_batch
    from swarmloc.deploy.scenario import load_any

    for name in STRATEGIES:
        loaded = load_any("ES1", {"seed": 1}, [f'agent.strategy="{name}"', "world.robots=6",
                                               f"world.duration_s={ticks / 10}"])
        run_batch(loaded.scenario)
    exercise_agents(ticks)


def exercise_agents(ticks: int) -> None:
    """The agents' part of :func:`exercise`: a served ES1 world answered by agents on both their
    paths, for every strategy a process runs. Also what the agent fork server runs once, so that
    every agent it forks finds the kernels loaded (deploy/fork/server.py)."""
    from swarmloc.agents.epuck.agent import ForagingAgent
    from swarmloc.agents.epuck.foraging import ForagingBrain, agent_rng
    from swarmloc.agents.epuck.social_odometry import STRATEGIES
    from swarmloc.deploy.scenario import load_any
    from swarmloc.protocol.errors import ErrorCounter
    from swarmloc.protocol.messages import EpuckAct, EpuckSense, decode
    from swarmloc.world.service import served_world

    for name, strategy in STRATEGIES.items():
        if strategy.central:
            continue  # batch engine only
        loaded = load_any("ES1", {"seed": 1}, [f'agent.strategy="{name}"', "world.robots=6",
                                               f"world.duration_s={ticks / 10}"])
        sc, world, errors = loaded.scenario, served_world(loaded), ErrorCounter()
        agents = [ForagingAgent(ForagingBrain(sc.agent, sc.world.body, [rid], [agent_rng(sc.world.seed, rid)],
                                              sc.world.tick_s), rid)
                  for rid in range(sc.world.robots)]
        for tick in range(ticks):
            acts = []
            for rid, data in world.senses():
                if tick % 2:  # the agent's common path: Sense bytes to Act bytes
                    wire = agents[rid].act_wire(data, errors)
                    act = decode(wire, EpuckAct) if wire is not None else None
                else:
                    act = None
                if act is None:  # the reference path: decode, step, encode
                    act = agents[rid].act(decode(data, EpuckSense), errors)
                acts.append(act)
            world.step(acts)
        world.state(), world.summary()


def add_parser(sub) -> None:
    p = sub.add_parser("warm", help="compile the kernels into this machine's cache (once per "
                                    "machine; for deployment scripts and ExecStartPre=)")
    p.add_argument("--force", action="store_true",
                   help="exercise every kernel even if the cache's stamp is current")
    p.add_argument("--check", action="store_true",
                   help="compile nothing: exit 0 if the cache is warm, 1 if not")
    p.set_defaults(func=main)


def main(args) -> int:
    folder = cache_dir()
    if args.check:
        warm = is_warm(folder)
        print(f"kernel cache {folder}: {'warm' if warm else 'cold'}")
        return 0 if warm else 1
    compiled = ensure_compiled(lambda line: print(line, flush=True), force=args.force)
    if not compiled:
        print(f"kernel cache {folder}: warm")
    return 0
