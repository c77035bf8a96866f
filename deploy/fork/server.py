"""``swarmloc agents``: many e-puck agent processes forked from one warm process (issue 20).

An e-puck agent started on its own (``swarmloc agent``) imports numpy, numba and the e-puck
kernels and loads their machine code: about 57 MiB of proportional memory each at 100 agents
(125 MiB resident), and a hundred of them starting at once on two cores took over a minute to
join. This server does that work once, then forks one child per robot. Each child is an agent
exactly as ``swarmloc agent --robot ID`` runs it (deploy/cli.py: serve_agent): its own OS
process and pid, its own Zenoh session, its own log file. What the children share is what they
only read: the imported modules and the loaded kernels, copy-on-write pages of the server.

Rules the design keeps:

- **The server never opens a Zenoh session** (ZENOH.md: a child that opens a session after its
  parent had one hangs). It imports zenoh (``swarmloc.agents.node`` does), which only loads the
  library: Zenoh builds its runtime, and reads ``ZENOH_RUNTIME`` for it, when a process opens its
  first session, so each child builds its own after the fork with the environment the launcher
  gave the server (deploy/launch.py: ONE_THREAD_ZENOH_RUNTIME). The server checks it runs one
  thread when it forks: a fork copies only the forking thread, and a lock held by another one
  would stay held in the child forever.
- **Every agent ends with the run.** The server is the leader of its process group and its
  children stay in it, so the launcher's ``killpg`` (deploy/launch.py: Supervisor.stop_all)
  stops them all. A SIGTERM/SIGINT to the server is passed to every child, which closes its
  session and exits; children still there after ``STOP_GRACE_S`` are killed. Each child asks the
  kernel for SIGTERM when the server dies (``PR_SET_PDEATHSIG``), and with ``--die-with-parent
  PID`` (what ``swarmloc run`` passes, with its own pid) so does the server when its own parent
  dies: a launcher killed with SIGKILL leaves no agent behind. A parent can die before its child
  has asked (the kernel then has nothing left to signal): each checks, once it has asked, that
  its parent is still the one it was started by, and ends at once if not.
- **The launcher sees each agent.** With ``--announce`` the server prints one JSON line per
  child, ``{"robot": ID, "pid": PID}`` once forked and ``{"robot": ID, "exit": CODE}`` once
  reaped (CODE as ``subprocess`` gives it: negative for a signal). :class:`ForkedAgents` reads
  them into handles that answer ``pid``, ``poll()`` and ``wait()`` as ``subprocess.Popen`` does.

``swarmloc agent`` on another host is unchanged; ``swarmloc agents --robots 0-49 -e ...`` runs
fifty agents on a host from one warm server in the same way.
"""

from __future__ import annotations

import argparse
import ctypes
import gc
import json
import os
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

#: Seconds the server gives its children to close their sessions after SIGTERM, then SIGKILL.
STOP_GRACE_S = 5.0
_PR_SET_PDEATHSIG = 1


def parse_robot_ids(text: str) -> list[int]:
    """``"0-3,7"`` -> ``[0, 1, 2, 3, 7]``; a clear ValueError for anything else."""
    ids: list[int] = []
    for part in text.split(","):
        lo, sep, hi = part.strip().partition("-")
        try:
            first = int(lo)
            last = int(hi) if sep else first
        except ValueError:
            raise ValueError(f"--robots: '{part}' is not a robot id or a range such as 0-99") from None
        if first < 0 or last < first:
            raise ValueError(f"--robots: '{part}' is not an ascending range of ids >= 0")
        ids.extend(range(first, last + 1))
    if len(set(ids)) != len(ids):
        raise ValueError(f"--robots: '{text}' names a robot twice")
    from swarmloc.protocol.messages import MAX_ROBOT_ID

    if max(ids) > MAX_ROBOT_ID:
        raise ValueError(f"--robots: robot ids go up to {MAX_ROBOT_ID} (the protocol's limit)")
    return ids


def die_with_parent(sig: int = signal.SIGTERM, parent_pid: int | None = None) -> bool:
    """Ask Linux to send ``sig`` to this process when its parent dies; False if the parent is
    already gone (we were orphaned before asking) or the call is unavailable.

    ``parent_pid``: the parent's pid as known before this process existed (a forked child is
    given its server's). Without it the parent is whoever ``getppid`` names now, which is already
    the reaper (1, or a subreaper) if the parent died between our start and this call: the
    kernel then has no death left to signal, so the caller must act on False itself.
    """
    parent = os.getppid() if parent_pid is None else parent_pid
    try:
        libc = ctypes.CDLL(None, use_errno=True)
        if libc.prctl(_PR_SET_PDEATHSIG, int(sig), 0, 0, 0) != 0:
            return False
    except (OSError, AttributeError):
        return False
    return os.getppid() == parent != 1


def _preload() -> None:
    """What every agent would otherwise load itself: the modules of an agent process and the
    e-puck kernels' machine code (a few ticks of every strategy an agent runs, deploy/warm.py)."""
    import swarmloc.agents.node  # noqa: F401 -- the shell, and zenoh's library (no session)
    from swarmloc.deploy.warm import exercise_agents

    exercise_agents(ticks=4)


def _child(args, robot: int, log_dir: Path | None, server_pid: int) -> int:
    """The forked agent: its log, its signals, then ``swarmloc agent``'s own code."""
    from swarmloc.deploy.cli import _install_stop, serve_agent

    if log_dir is not None:
        fd = os.open(log_dir / f"agent-{robot}.log", os.O_WRONLY | os.O_CREAT | os.O_APPEND, 0o644)
        os.dup2(fd, 1)
        os.dup2(fd, 2)
        os.close(fd)
    # Our own stop first: until then a SIGTERM runs the handler inherited from the server, which
    # would swallow the kernel's signal of the server's death (CI saw an agent outlive it).
    stop = _install_stop()
    if not die_with_parent(signal.SIGTERM, parent_pid=server_pid):
        # The server died between our fork and this call (a launcher that kills it as soon as
        # the last agent is announced can do that): no SIGTERM will ever come, so end now.
        print(f"swarmloc agent {robot}: the agent server (pid {server_pid}) is gone; not starting",
              file=sys.stderr)
        return 1
    agent_args = argparse.Namespace(**{**vars(args), "robot": robot})
    return serve_agent(agent_args, stop)


def serve(args) -> int:
    """Fork one agent per robot id, reap them, pass a stop on; returns 0 if every agent did."""
    from swarmloc.deploy.cli import _compile_kernels
    from swarmloc.deploy.run import check_memory, mem_available_mib
    from swarmloc.protocol.session import config_from_args

    robots = parse_robot_ids(args.robots)
    config_from_args(args)  # a bad transport flag stops us here, once, not in every child
    check_memory(len(robots), "foraging", mem_available_mib())  # before anything is forked
    stopping = threading.Event()
    children: dict[int, int] = {}  # pid -> robot id

    forking = threading.Event()

    def on_signal(signum, frame):
        stopping.set()
        if not forking.is_set():  # still loading or reading stdin: nothing to pass on, just go
            raise SystemExit(128 + signum)
        for pid in list(children):
            try:
                os.kill(pid, signal.SIGTERM)
            except ProcessLookupError:
                pass

    signal.signal(signal.SIGTERM, on_signal)
    signal.signal(signal.SIGINT, on_signal)
    if args.die_with_parent is not None:
        parent = None if args.die_with_parent < 0 else args.die_with_parent
        if not die_with_parent(signal.SIGTERM, parent_pid=parent):
            print(f"swarmloc agents: the process that started this one (pid "
                  f"{parent if parent is not None else os.getppid()}) is gone; not starting", file=sys.stderr)
            return 1
    if args.nice:
        os.nice(args.nice)  # inherited by every child
    log_dir = Path(args.log_dir) if args.log_dir else None
    if log_dir is not None:
        log_dir.mkdir(parents=True, exist_ok=True)
    _compile_kernels()
    _preload()
    if args.connect_from_stdin:  # the launcher started us before the world: its endpoint now
        line = sys.stdin.readline().strip()
        if not line:
            raise ValueError("--connect-from-stdin: no endpoint came on stdin")
        args.connect = [*(args.connect or ()), line]
        config_from_args(args)
    # Objects that exist now are never collected, so that no collection in a child writes to
    # (and unshares) the pages that hold them.
    gc.collect()
    gc.freeze()
    if threading.active_count() != 1 or len(os.listdir("/proc/self/task")) != 1:
        raise RuntimeError("the agent server runs more than one thread: it must not fork")
    say = (lambda line: print(json.dumps(line), flush=True)) if args.announce else (lambda line: None)
    server_args = argparse.Namespace(**{k: v for k, v in vars(args).items() if k != "func"})
    forking.set()
    server_pid = os.getpid()

    def fork_agent(robot: int) -> int:
        sys.stdout.flush()
        sys.stderr.flush()
        pid = os.fork()
        if pid == 0:
            children.clear()  # a SIGTERM before the child's own handler must not reach siblings
            code = 1
            try:
                code = _child(server_args, robot, log_dir, server_pid)
            except BaseException as exc:  # noqa: BLE001 -- a child must never return into the loop
                print(f"swarmloc agent {robot}: {exc!r}", file=sys.stderr)
            finally:
                import logging

                logging.shutdown()
                sys.stdout.flush()
                sys.stderr.flush()
                os._exit(code if isinstance(code, int) else 1)
        children[pid] = robot
        return pid

    for robot in robots:
        if stopping.is_set():
            break
        say({"robot": robot, "pid": fork_agent(robot)})
    return _reap(children, stopping, say, fork_agent if args.respawn else None)


#: Respawns of one robot's agent at most (``--respawn``): an agent killed again and again by
#: something on the host is not hidden for ever.
MAX_RESPAWNS = 20


def _reap(children: dict[int, int], stopping: threading.Event, say, respawn=None) -> int:
    """Wait for every child; after a stop, SIGKILL those left after ``STOP_GRACE_S``.
    ``respawn(robot) -> pid``, if given: an agent killed by a signal while the server is not
    stopping is forked again at once from this warm server (``--respawn``; about a fork and a
    Zenoh session, against the seconds of imports and kernel loading of ``swarmloc agent``),
    at most ``MAX_RESPAWNS`` times a robot."""
    failed = 0
    respawned: dict[int, int] = {}
    kill_at = None
    while children:
        pid, status = os.waitpid(-1, os.WNOHANG)
        if pid == 0:
            if stopping.is_set():
                kill_at = kill_at or time.monotonic() + STOP_GRACE_S
                if time.monotonic() > kill_at:
                    for left in list(children):
                        try:
                            os.kill(left, signal.SIGKILL)
                        except ProcessLookupError:
                            pass
            time.sleep(0.05)
            continue
        robot = children.pop(pid, None)
        if robot is None:
            continue
        code = os.waitstatus_to_exitcode(status)
        say({"robot": robot, "exit": code})
        if (respawn is not None and code < 0 and not stopping.is_set()
                and respawned.get(robot, 0) < MAX_RESPAWNS):
            respawned[robot] = respawned.get(robot, 0) + 1
            print(f"swarmloc agents: robot {robot}'s agent was killed (signal {-code}); forked again "
                  f"({respawned[robot]} of at most {MAX_RESPAWNS})", file=sys.stderr, flush=True)
            say({"robot": robot, "pid": respawn(robot), "respawn": respawned[robot]})
            continue
        failed += code != 0
    return 0 if failed == 0 else 1


class ForkedAgent:
    """One agent forked by the server, as the launcher sees it: ``Popen``'s ``pid``,
    ``returncode``, ``poll()`` and ``wait()``."""

    def __init__(self, robot_id: int, pid: int, owner: ForkedAgents) -> None:
        self.robot_id, self.pid = robot_id, pid
        self.returncode: int | None = None
        self._ended = threading.Event()
        self._owner = owner

    def _end(self, code: int) -> None:
        self.returncode = code
        self._ended.set()

    def poll(self) -> int | None:
        if self.returncode is None and self._owner.server.poll() is not None:
            self._owner.finish_reading()  # the server is gone: its last lines are in the pipe
        return self.returncode

    def wait(self, timeout: float | None = None) -> int:
        if not self._ended.wait(timeout):
            raise subprocess.TimeoutExpired(f"agent {self.robot_id} (pid {self.pid})", timeout)
        return self.returncode


class ForkedAgents:
    """Reads an announcing server's stdout into one :class:`ForkedAgent` per robot."""

    def __init__(self, server: subprocess.Popen, robots: list[int]) -> None:
        self.server = server
        self._wanted = len(robots)
        self._by_robot: dict[int, ForkedAgent] = {}
        self._all_forked = threading.Event()
        self._reader = threading.Thread(target=self._read, daemon=True)
        self._reader.start()

    def _read(self) -> None:
        for line in self.server.stdout:
            try:
                msg = json.loads(line)
            except ValueError:
                continue
            if "pid" in msg:
                self._by_robot[msg["robot"]] = ForkedAgent(msg["robot"], msg["pid"], self)
                if len(self._by_robot) == self._wanted:
                    self._all_forked.set()
            elif "exit" in msg and msg["robot"] in self._by_robot:
                self._by_robot[msg["robot"]]._end(msg["exit"])
        # The server is gone: it reported every child it reaped; the rest died with it
        # (PR_SET_PDEATHSIG) or were killed by the launcher with its process group.
        self.server.wait()
        for agent in self._by_robot.values():
            if agent.returncode is None:
                agent._end(-signal.SIGKILL)
        self._all_forked.set()

    def finish_reading(self, timeout_s: float = 10.0) -> None:
        """Once the server has exited: read what it printed last (each agent's exit)."""
        self._reader.join(timeout_s)

    def wait_forked(self, timeout_s: float) -> list[ForkedAgent]:
        """The handles, in robot order, once every agent is forked."""
        if not self._all_forked.wait(timeout_s) or len(self._by_robot) != self._wanted:
            code = self.server.poll()
            raise RuntimeError(f"the agent server forked {len(self._by_robot)} of {self._wanted} agents "
                               f"within {timeout_s:.0f} s" + (f" and exited ({code})" if code is not None else ""))
        return [self._by_robot[r] for r in sorted(self._by_robot)]


def add_parser(sub, agent_args) -> None:
    p = sub.add_parser("agents", help="run many e-puck agents on this host, forked from one warm "
                                      "process (each its own process and Zenoh session)")
    p.add_argument("--robots", required=True, metavar="IDS", help="robot ids, e.g. 0-99 or 0-9,20")
    agent_args(p)
    p.add_argument("--log-dir", default=None,
                   help="write each agent's log to LOG_DIR/agent-ID.log (default: this stderr)")
    p.add_argument("--announce", action="store_true",
                   help="print one JSON line per agent forked and per agent ended")
    p.add_argument("--connect-from-stdin", action="store_true",
                   help="read one more -e endpoint from stdin once loaded, before forking (so a "
                        "launcher can start this server while the world is still starting)")
    p.add_argument("--die-with-parent", nargs="?", type=int, const=-1, default=None, metavar="PID",
                   help="stop every agent when the process that started this one dies; give its "
                        "PID if known (a launcher's own pid), so that a launcher that died before "
                        "this process asked is noticed too")
    p.add_argument("--respawn", action="store_true",
                   help="fork an agent killed by a signal again at once (live again in about a "
                        f"second; at most {MAX_RESPAWNS} times a robot)")
    p.set_defaults(func=serve)
