"""Scale on one machine (issue 20): the tiled ES3 family, the O(N) initial placement, and the
guards that refuse swarms the protocol or the machine cannot hold."""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import threading
import time
import uuid
from pathlib import Path

import numpy as np
import pytest
from processes import run_swarmloc

from swarmloc.config import ConfigError
from swarmloc.deploy.fork.server import parse_robot_ids
from swarmloc.deploy.lab.epuck.batch import run_batch
from swarmloc.deploy.launch import supervised
from swarmloc.deploy.run import check_memory, memory_estimate_mib, start_swarm
from swarmloc.deploy.scenario import load_scenario
from swarmloc.protocol.keys import Keys
from swarmloc.protocol.messages import WorldState, decode
from swarmloc.protocol.session import open_session, session_config
from swarmloc.world.epuck import kernels
from swarmloc.world.epuck.arena import area_at, arena_discs, resolve_collisions
from swarmloc.world.epuck.foraging import ForagingWorld, WorldConfig, initial_poses, tile_grid


def _initial_poses_numpy(config: WorldConfig, rng: np.random.Generator) -> np.ndarray:
    """The placement as it was written before the grid kernel (O(N^2) numpy): the reference."""
    n, radius = config.robots, config.body.body_radius_m
    centre = np.array([config.arena.width_m / 2, config.arena.height_m / 2])
    spread = config.arena.initial_radius_m
    pose = np.zeros((n, 3))
    placed = 0
    for _ in range(200):
        r = spread * np.sqrt(rng.random(n))
        a = rng.uniform(-np.pi, np.pi, n)
        cand = centre + np.stack((r * np.cos(a), r * np.sin(a)), axis=1)
        for c in cand:
            if placed == n:
                break
            if placed == 0 or np.min(np.hypot(*(pose[:placed, :2] - c).T)) >= 2 * radius:
                pose[placed, :2] = c
                placed += 1
        if placed == n:
            break
    if placed < n:
        extra = centre + rng.uniform(-spread, spread, (n - placed, 2))
        pose[placed:, :2] = extra
        pose[:, :2] = resolve_collisions(pose[:, :2], radius, config.arena.arena(), iterations=20)
    pose[:, 2] = rng.uniform(-np.pi, np.pi, n)
    return pose


@pytest.mark.parametrize("name, overrides", [
    ("ES1", []), ("ES2", []), ("ES3", []), ("SO-3.0x3.0", []),
    ("ES1", ["world.robots=30"]),  # denser than the start disc holds: the collisions' fallback
])
@pytest.mark.parametrize("seed", [1, 7])
def test_initial_poses_are_those_of_the_numpy_placement(name, overrides, seed):
    config = load_scenario(name, [*overrides, f"world.seed={seed}"]).world
    got = initial_poses(config, np.random.default_rng([seed, 0]))
    want = _initial_poses_numpy(config, np.random.default_rng([seed, 0]))
    assert np.array_equal(got, want)


def test_tile_grid_fills_tiles_and_keeps_the_arena_squarish():
    assert tile_grid(1, 6.0, 8.5) == (1, 1)
    assert tile_grid(1000, 6.0, 8.5) == (40, 25)  # 240 x 212.5 m, no tile empty
    assert tile_grid(100, 6.0, 8.5) == (10, 10)
    for tiles in (2, 3, 7, 10, 13, 97, 250):
        cols, rows = tile_grid(tiles, 6.0, 8.5)
        assert cols * rows >= tiles
        assert max(cols * 6.0, rows * 8.5) / min(cols * 6.0, rows * 8.5) <= 3.0 or cols * rows == tiles


def test_es3_tiled_keeps_es3_density_and_is_es3_at_100_robots():
    for n in (100, 1000, 10_000, 100_000):
        w = load_scenario("ES3-tiled", [f"world.robots={n}"]).world
        arena = w.arena_model()
        cols, rows = w.tiles
        assert cols * rows == -(-n // 100)
        assert n / (arena.width_m * arena.height_m) == pytest.approx(100 / (6.0 * 8.5))
    short = ["world.duration_s=30"]
    tiled = run_batch(load_scenario("ES3-tiled", short))
    es3 = run_batch(load_scenario("ES3", short))
    assert np.array_equal(tiled.final_pose, es3.final_pose)
    assert tiled.metrics == es3.metrics


def test_tiled_floor_areas_agree_between_numpy_and_the_kernels():
    arena = load_scenario("ES3-tiled", ["world.robots=1200"]).world.arena_model()
    assert arena.tile_m == (6.0, 8.5) and arena_discs(arena).shape == (8,)
    rng = np.random.default_rng(3)
    points = rng.uniform(0, 1, (20_000, 2)) * [arena.width_m, arena.height_m]
    # and points on every tile's nest and prey
    tiles = np.stack(np.meshgrid(np.arange(arena.width_m // 6), np.arange(arena.height_m // 8.5)), -1).reshape(-1, 2)
    centres = np.concatenate([tiles * [6.0, 8.5] + arena.nest.centre_m, tiles * [6.0, 8.5] + arena.prey.centre_m])
    points = np.concatenate([points, centres])
    codes = area_at(points, arena)
    assert np.array_equal(codes, kernels.area_codes(points, arena_discs(arena)))
    assert (codes[-2 * len(tiles):-len(tiles)] == 1).all() and (codes[-len(tiles):] == 2).all()


def test_tiled_world_starts_each_tile_s_robots_in_its_disc_and_forages():
    scenario = load_scenario("ES3-tiled", ["world.robots=400", "world.duration_s=2"])
    world = ForagingWorld(scenario.world)
    cols, rows = scenario.world.tiles
    assert cols * rows == 4
    for t in range(4):
        centre = np.array([(t % cols + 0.5) * 6.0, (t // cols + 0.5) * 8.5])
        xy = world.pose[t * 100:(t + 1) * 100, :2]
        assert (np.hypot(*(xy - centre).T) <= 0.5 + 1e-12).all()
    d = np.hypot(*(world.pose[:, None, :2] - world.pose[None, :, :2]).transpose(2, 0, 1))
    assert d[np.triu_indices(400, 1)].min() >= 2 * scenario.world.body.body_radius_m
    result = run_batch(scenario)
    assert result.final_pose.shape == (400, 3)


def test_batch_engine_takes_more_robots_than_the_wire_carries():
    scenario = load_scenario("ES3-tiled", ["world.robots=70000", "world.duration_s=0.2"])
    assert scenario.world.robots > 65536
    with pytest.raises(ValueError, match="robots"):
        load_scenario("ES3-tiled", [f"world.robots={2**20 + 1}"])


# -- agents forked from one warm agent server (deploy/fork/server.py) ----------------------------


def test_robot_id_lists():
    assert parse_robot_ids("0-3,7") == [0, 1, 2, 3, 7]
    assert parse_robot_ids("5") == [5]
    for bad in ("3-1", "a", "1,1", "-2", "0-", "65530-65536"):
        with pytest.raises(ValueError, match="--robots"):
            parse_robot_ids(bad)


_ORPHAN = """
import os, signal, sys, time
from swarmloc.deploy.fork.server import die_with_parent
out, late = sys.argv[1], sys.argv[2] == "late"
parent = os.getpid()
if os.fork():
    if late:
        os._exit(0)          # the parent dies before its child asks for a signal
    time.sleep(60)           # killed by the test once the child has asked
    os._exit(0)
with open(out + ".pid", "w") as f:  # read only after the answer, which is renamed into place
    f.write(str(os.getpid()))
def on_term(signum, frame):
    with open(out + ".term.tmp", "w") as f:  # whole or not at all: the test reads it at once
        f.write("SIGTERM")
    os.rename(out + ".term.tmp", out + ".term")
    os._exit(0)
signal.signal(signal.SIGTERM, on_term)
while late and os.getppid() == parent:
    time.sleep(0.01)
if late:  # the forked agent's own first step: it must give up, not start an agent
    from swarmloc.deploy.fork.server import _child
    answer = f"_child returned {_child(None, 7, None, parent)}"
else:
    answer = str(die_with_parent(signal.SIGTERM, parent_pid=parent))
with open(out + ".tmp", "w") as f:
    f.write(answer)
os.rename(out + ".tmp", out)
time.sleep(60)
"""


def _wait_file(path: Path, timeout_s: float = 30) -> str:
    deadline = time.monotonic() + timeout_s
    while not path.exists():
        assert time.monotonic() < deadline, f"{path} never appeared"
        time.sleep(0.01)
    return path.read_text()


@pytest.mark.parametrize("late", [False, True])
def test_a_forked_agent_whose_server_died_first_does_not_start(tmp_path, late):
    """An agent forked by the server asks for SIGTERM on its server's death (early: the kernel
    sends it). If the server died first (late: the race CI once lost, the server killed right
    after its last fork), no signal will ever come: the agent must end instead of outliving it."""
    out = tmp_path / "answer"
    parent = subprocess.Popen([sys.executable, "-c", _ORPHAN, str(out), "late" if late else "early"])
    child = None
    try:
        answer = _wait_file(out)
        child = int((tmp_path / "answer.pid").read_text())
        if late:
            assert answer == "_child returned 1", answer
        else:
            assert answer == "True"
            parent.kill()
            parent.wait(timeout=10)
            assert _wait_file(tmp_path / "answer.term") == "SIGTERM", "the kernel signals the death"
    finally:
        for pid in ([child] if child else []):
            try:
                os.kill(pid, signal.SIGKILL)
            except ProcessLookupError:
                pass
        parent.kill()
        parent.wait(timeout=10)
    assert not _wait_gone([child], 10)


def test_an_agent_server_whose_launcher_is_already_gone_starts_nothing(tmp_path):
    """``--die-with-parent PID`` (what ``swarmloc run`` passes, its own pid): a server whose
    launcher died before the server asked for its signal ends at once instead of forking agents
    that nothing would stop. Here the named launcher (pid 1) is not this server's parent."""
    done = run_swarmloc(["agents", "--robots", "0-1", "-m", "client", "-e", "tcp/127.0.0.1:9", "--run",
                         "gone", "--die-with-parent", "1", "--log-dir", str(tmp_path)], cwd=tmp_path, timeout_s=60)
    assert done.returncode == 1, done.stderr
    assert "the process that started this one (pid 1) is gone; not starting" in done.stderr
    assert not list(tmp_path.glob("agent-*.log")), "no agent was forked"


def _tcp_sockets_to(port: int) -> dict[int, str]:
    """inode -> local address of every IPv4 TCP connection to 127.0.0.1:``port``."""
    found = {}
    with open("/proc/net/tcp", encoding="ascii") as f:
        for line in f.readlines()[1:]:
            fields = line.split()
            local, remote, inode = fields[1], fields[2], int(fields[9])
            if remote == f"0100007F:{port:04X}":
                found[inode] = local
    return found


def _socket_inodes(pid: int) -> set[int]:
    inodes = set()
    for fd in os.listdir(f"/proc/{pid}/fd"):
        try:
            target = os.readlink(f"/proc/{pid}/fd/{fd}")
        except OSError:
            continue
        if target.startswith("socket:["):
            inodes.add(int(target[8:-1]))
    return inodes


def _ppid(pid: int) -> int:
    with open(f"/proc/{pid}/stat", encoding="ascii") as f:
        return int(f.read().rsplit(")", 1)[1].split()[1])


def _alive(pid: int) -> bool:
    """True while ``pid`` exists and is not a zombie."""
    try:
        with open(f"/proc/{pid}/stat", encoding="ascii") as f:
            return f.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:
        return False


def _wait_gone(pids, timeout_s: float) -> list[int]:
    """The pids still alive after ``timeout_s`` (polled: a process ending has no signal to wait on
    for a non-parent)."""
    deadline = time.monotonic() + timeout_s
    while (left := [p for p in pids if _alive(p)]) and time.monotonic() < deadline:
        time.sleep(0.05)
    return left


def _es1_file(tmp_path, robots: int, duration_s: float) -> Path:
    """An ES1 scenario file, and a logs/ folder beside it."""
    (tmp_path / "logs").mkdir()
    scenario = load_scenario("ES1", [f"world.robots={robots}", f"world.duration_s={duration_s}"])
    path = tmp_path / "scenario.json"
    path.write_text(json.dumps(scenario.to_dict()))
    return path


class _States:
    """A client following a run's world states: the tests' readiness signal."""

    def __init__(self, endpoint: str, run: str):
        self.session = open_session(session_config(mode="client", connect=[endpoint]))
        self.states: list[WorldState] = []
        self._cond = threading.Condition()
        self.session.declare_subscriber(Keys(run).world_state, self._on_state)

    def _on_state(self, sample):
        with self._cond:
            self.states.append(decode(sample.payload.to_bytes(), WorldState))
            self._cond.notify_all()

    def wait_for(self, predicate, timeout_s: float = 60.0) -> bool:
        with self._cond:
            return self._cond.wait_for(lambda: any(predicate(s) for s in self.states), timeout_s)

    def close(self):
        self.session.close()


def _python_threads(pid: int) -> int:
    """Threads of ``pid`` named as its main thread (Python's threads, not Zenoh's named ones)."""
    def name(tid: str) -> str:
        with open(f"/proc/{pid}/task/{tid}/comm", encoding="utf-8") as f:
            return f.read().strip()

    main = name(str(pid))
    return sum(name(tid) == main for tid in os.listdir(f"/proc/{pid}/task"))


@pytest.mark.integration
def test_forked_agents_are_processes_with_their_own_sessions(tmp_path):
    path = _es1_file(tmp_path, robots=4, duration_s=120.0)
    run = "fork" + uuid.uuid4().hex[:8]
    with supervised() as sup:
        swarm = start_swarm(sup, path, run=run, robots=4, out=tmp_path / "out", log_dir=tmp_path / "logs",
                            realtime=True, join_timeout_s=60)
        states = _States(swarm.router_endpoint, run)
        try:
            assert states.wait_for(lambda s: s.tick > 0), "the run never started"
            server = next(p for p in sup.procs if "agents" in p.args)
            pids = [a.pid for a in swarm.agents]
            assert len(set(pids)) == 4 and server.pid not in pids and swarm.world.pid not in pids
            assert all(_ppid(p) == server.pid for p in pids), "each agent is a child of the agent server"
            # Each agent holds its own TCP connection to the world's session: its own Zenoh session.
            port = int(swarm.world_endpoint.rsplit(":", 1)[1])
            to_world = _tcp_sockets_to(port)
            mine = [_socket_inodes(p) & to_world.keys() for p in pids]
            assert all(len(m) >= 1 for m in mine), mine
            assert len(set().union(*mine)) == sum(len(m) for m in mine), "no connection is shared"
            assert not _socket_inodes(server.pid) & to_world.keys(), "the server has no session"
            assert all((tmp_path / "logs" / f"agent-{i}.log").exists() for i in range(4)), "a log each"
            # One Python thread each, the main one: Zenoh's worker runs the callbacks
            # (agents/node.py: direct callbacks), no Python thread per subscriber. Threads a
            # process starts share its name; Zenoh names its own (app-0, ...).
            assert [_python_threads(p) for p in pids] == [1] * 4
            # An agent killed outright is seen dead by the world and by its handle; the run goes on.
            os.kill(pids[1], signal.SIGKILL)
            assert swarm.agents[1].wait(timeout=10) == -signal.SIGKILL
            assert states.wait_for(lambda s: not s.alive[1], 30), "the world never saw the dead agent"
            tick = states.states[-1].tick
            assert states.wait_for(lambda s: s.tick >= tick + 20 and s.alive[0] and s.alive[3], 30)
            assert swarm.agents[0].poll() is None
        finally:
            states.close()
    assert not _wait_gone(pids, 10), "every agent ended with the run"


@pytest.mark.integration
def test_an_agent_killed_under_respawn_is_forked_again_and_its_robot_moves(tmp_path):
    # Issue 47: a restarted `swarmloc agent` took 4.6-7 s to be live (imports, kernels); the
    # warm server forks it again at once. The run completes with the robot back, and the world
    # counts the rejoin.
    path = _es1_file(tmp_path, robots=3, duration_s=16.0)  # real time: the test lasts the run
    run = "resp" + uuid.uuid4().hex[:8]
    with supervised() as sup:
        swarm = start_swarm(sup, path, run=run, robots=3, out=tmp_path / "out", log_dir=tmp_path / "logs",
                            realtime=True, join_timeout_s=60, agent_args=("--respawn",))
        states = _States(swarm.router_endpoint, run)
        try:
            assert states.wait_for(lambda s: s.tick > 0), "the run never started"
            killed_at = states.states[-1].tick
            os.kill(swarm.agents[1].pid, signal.SIGKILL)
            assert swarm.agents[1].wait(timeout=10) == -signal.SIGKILL
            assert swarm.world.wait(timeout=120) == 0
        finally:
            states.close()
    result = json.loads((tmp_path / "out" / "results.json").read_text())
    assert result["reason"] == "completed" and result["dead_robots"] == []
    # back so fast that the world states (one a second) may never show it dead: the world's count
    assert result["transport"]["rejoins"] == 1 and result["transport"]["rejoin_away_s_max"] < 20
    after = [s for s in states.states if s.tick > killed_at + 100 and s.alive[1]]
    assert len(after) >= 2 and after[-1].poses[1] != after[0].poses[1], "the respawned agent drives its robot"
    assert "robot 1's agent was killed (signal 9); forked again" in (tmp_path / "logs" / "agent-server.log").read_text()


@pytest.mark.integration
def test_killed_agent_server_takes_its_agents_along(tmp_path):
    path = _es1_file(tmp_path, robots=3, duration_s=120.0)
    with supervised() as sup:
        swarm = start_swarm(sup, path, run="forkk" + uuid.uuid4().hex[:8], robots=3, out=tmp_path / "out",
                            log_dir=tmp_path / "logs", realtime=True, join_timeout_s=60)
        pids = [a.pid for a in swarm.agents]
        assert all(_alive(p) for p in pids)
        server = next(p for p in sup.procs if "agents" in p.args)
        os.kill(server.pid, signal.SIGKILL)  # the server, with no chance to pass a stop on
        # PR_SET_PDEATHSIG: each agent gets SIGTERM from the kernel, closes its session and exits.
        assert not _wait_gone(pids, 20), "agents outlived their server"


@pytest.mark.integration
def test_sigterm_to_swarmloc_run_leaves_no_agent_alive(tmp_path):
    run = "forkt" + uuid.uuid4().hex[:8]
    proc = subprocess.Popen([sys.executable, "-m", "swarmloc", "run", "ES1", "--robots", "5", "--realtime",
                             "--duration-s", "300", "--out", str(tmp_path), "--run", run],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            stdin=subprocess.DEVNULL, start_new_session=True)
    try:
        endpoint = None
        for line in proc.stderr:  # "router on ENDPOINT; run ..." once every piece is started
            if line.startswith("router on "):
                endpoint = line.split()[2].rstrip(";")
                break
        assert endpoint, "swarmloc run never said where its router is"
        states = _States(endpoint, run)
        try:
            assert states.wait_for(lambda s: s.tick > 0), "the run never started"
        finally:
            states.close()
        pieces = [int(p) for p in os.listdir("/proc") if p.isdigit() and _descends_from(int(p), proc.pid)]
        agents = [p for p in pieces if _ppid(p) in pieces and "agents" in _cmdline(_ppid(p))]
        assert len(agents) == 5, (pieces, agents)
        proc.send_signal(signal.SIGTERM)
        assert proc.wait(timeout=30) != 0
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
        proc.stderr.close()
        proc.stdout.close()
    assert not _wait_gone(pieces, 10), "a piece outlived swarmloc run's SIGTERM"


def _cmdline(pid: int) -> list[str]:
    with open(f"/proc/{pid}/cmdline", "rb") as f:
        return [a.decode() for a in f.read().split(b"\0") if a]


def _descends_from(pid: int, root: int) -> bool:
    try:
        while pid > 1:
            pid = _ppid(pid)
            if pid == root:
                return True
    except OSError:
        return False
    return False


# -- a swarm the machine's memory cannot hold ----------------------------------------------------


def test_memory_check_refuses_what_does_not_fit_and_names_the_estimate():
    check_memory(100, "foraging", available_mib=24 * 1024)  # fits: no error
    with pytest.raises(ConfigError) as refused:
        check_memory(100, "foraging", available_mib=1000)
    text = str(refused.value)
    per_agent = memory_estimate_mib(100, "foraging")[0]
    assert per_agent >= 6.9, "at least what a forked agent measured (bench_scale.py --memory 100)"
    assert f"100 agents x {per_agent:.0f} MiB" in text and "1.0 GiB available" in text and "MemAvailable" in text
    # a process agent costs more than a forked one
    assert memory_estimate_mib(100, "laser")[0] > per_agent
    check_memory(10 ** 6, "foraging", available_mib=None)  # nothing known: nothing refused


def test_swarmloc_run_refuses_robots_beyond_memory_before_starting(tmp_path):
    with open("/proc/meminfo", encoding="ascii") as f:
        available_mib = next(int(ln.split()[1]) for ln in f if ln.startswith("MemAvailable:")) / 1024
    robots = 60000  # needs far more than this machine has, even at 1 MiB an agent
    assert robots > available_mib
    done = run_swarmloc(["run", "ES3-tiled", "--robots", str(robots), "--out", str(tmp_path / "runs")],
                        cwd=tmp_path, timeout_s=120)
    assert done.returncode == 2
    assert f"--robots {robots}" in done.stderr and "MemAvailable" in done.stderr
    assert "GiB available" in done.stderr and "at most about" in done.stderr
    assert not (tmp_path / "runs").exists(), "nothing started: not even a run folder"


def test_swarmloc_run_refuses_robots_beyond_the_open_file_limit_before_starting(tmp_path):
    # a system whose hard limit is 512 open files: 600 agents cannot connect to one world (the
    # default soft limit of 1,024 is what stopped a 1,000-agent world after start-up, issue 47)
    import resource
    import subprocess
    import sys

    def low_limit():
        resource.setrlimit(resource.RLIMIT_NOFILE, (512, 512))

    done = subprocess.run([sys.executable, "-m", "swarmloc", "run", "ES3-tiled", "--robots", "600",
                           "--out", str(tmp_path / "runs")], cwd=tmp_path, capture_output=True, text=True,
                          timeout=120, preexec_fn=low_limit, check=False)
    assert done.returncode == 2, done.stderr[-2000:]
    assert "--robots 600" in done.stderr and "this system allows 512 (ulimit -Hn)" in done.stderr
    assert "at most about 256 robots fit" in done.stderr
    assert not (tmp_path / "runs").exists(), "nothing started: not even a run folder"
    # below the hard limit the soft one is raised for the pieces, which inherit it
    code = ("import resource; resource.setrlimit(resource.RLIMIT_NOFILE, (300, 4096)); "
            "from swarmloc.deploy.run import ensure_open_files; print(ensure_open_files(600), "
            "resource.getrlimit(resource.RLIMIT_NOFILE)[0])")
    raised = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, timeout=120, check=True)
    assert raised.stdout.split() == ["4096", "4096"]


def test_agent_server_stopped_before_it_forks_exits_and_forks_nothing(tmp_path):
    # `swarmloc run` starts the server before the world and hands it the world's endpoint on
    # stdin; a run stopped before that (the world failed to start, Ctrl-C) must not leave it waiting.
    proc = subprocess.Popen([sys.executable, "-m", "swarmloc", "agents", "--robots", "0-1", "-m", "client",
                             "--run", "nofork", "--announce", "--connect-from-stdin", "--log-dir", str(tmp_path)],
                            stdin=subprocess.PIPE, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                            start_new_session=True)
    try:
        proc.send_signal(signal.SIGTERM)
        out, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            os.killpg(proc.pid, signal.SIGKILL)
            proc.wait()
    assert proc.returncode in (128 + signal.SIGTERM, -signal.SIGTERM)
    assert b"pid" not in out and not list(tmp_path.glob("agent-*.log"))
