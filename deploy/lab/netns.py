"""A multi-host lab on one machine: hosts in Linux network namespaces, lossy links between them.

Each host (``router``, ``world``, ``agent-0`` ...) is a network namespace with one interface,
``eth0``, a veth whose other end is a port of a bridge in a ``switch`` namespace: a star of
point-to-point links, as hosts on one lab switch. Nothing is created in the machine's own
namespace, so labs of concurrent tests never collide (namespace names carry the creating pid).

Packet loss (ISSUE 6, ZENOH.md "Lossy links between hosts"): this kernel has no netem, and its tc
has neither the ``gact`` action nor the ``matchall``/``basic`` classifiers, so ``tc ... action
gact drop random`` is not available. Loss is an nftables rule in every host's *input* hook::

    iifname "eth0" numgen random mod 1000000 < loss*1e6 counter drop

so a packet is dropped with probability ``loss`` at the host that receives it: each direction of
each host-to-host path loses ``loss`` of its packets (a message from an agent to the world through
the router crosses two such links). Dropping in the output hook instead makes ``send`` fail with
EPERM and Zenoh closes the link. The rule has counters: :meth:`NetnsLab.drop_counters` reads how
many packets arrived and how many were dropped, and :meth:`NetnsLab.probe_udp_loss` measures the
loss a counted UDP probe really sees.

TCP over lossy links (docs/deploy.md, "Lossy links"): Linux retransmits after at least 200 ms and
doubles the wait each time, and lockstep traffic (one small message at a time) recovers nearly
every loss by timeout. ``NetnsLab(..., tcp_rto_min_ms=10, tcp_thin_linear_timeouts=True)`` sets
the hosts' route ``rto_min`` (with ``quickack``) and the thin-stream linear timeouts;
:func:`start_lab_swarm` with ``lease_s`` gives every piece a longer Zenoh lease.

Needs root, ``ip`` (iproute2) and ``nft`` (Debian package ``nftables``); :func:`unavailable`
says why a lab cannot be built here. Processes started in a host (:meth:`NetnsLab.start`) run
``ip netns exec NS python -m swarmloc ...`` in their own process group under a
:class:`~swarmloc.deploy.launch.Supervisor`, which stops them by id.
"""

from __future__ import annotations

import json
import os
import re
import shutil
import signal
import subprocess
import sys
import textwrap
import threading
import uuid
from dataclasses import dataclass
from pathlib import Path
from typing import Self

from swarmloc.deploy.launch import CHILD_ENV, PYTHON, Supervisor

NS_PREFIX = "slns"
SUBNET = "10.77.0"  # hosts are 10.77.0.1 ... (only inside the lab's namespaces)
IFACE = "eth0"
NFT_TABLE = "swarmloc_loss"
#: Loss probabilities are set in millionths.
LOSS_SCALE = 1_000_000
ZENOH_PORT = 7447
_HOST_RE = re.compile(r"[a-z][a-z0-9-]{0,15}")


def unavailable() -> str | None:
    """Why a lab cannot be built on this machine, or None if it can."""
    if sys.platform != "linux":
        return "network namespaces need Linux"
    if os.geteuid() != 0:
        return "network namespaces need root"
    for tool, package in (("ip", "iproute2"), ("nft", "nftables")):
        if shutil.which(tool) is None:
            return f"`{tool}` not found (Debian package {package})"
    probe = f"{NS_PREFIX}-probe-{os.getpid()}-{uuid.uuid4().hex[:6]}"
    try:
        _run(["ip", "netns", "add", probe])
    except RuntimeError as exc:
        return f"cannot create a network namespace: {exc}"
    try:
        _run(["ip", "netns", "exec", probe, "nft", "-f", "-"],
             stdin=f"table inet {NFT_TABLE} {{\n chain input {{\n type filter hook input priority raw;\n"
                   f" numgen random mod 100 < 10 drop\n }}\n}}\n")
    except RuntimeError as exc:
        return f"nftables cannot drop packets in a namespace: {exc}"
    finally:
        subprocess.run(["ip", "netns", "del", probe], check=False, capture_output=True)
    return None


def _run(argv: list[str], stdin: str | None = None) -> str:
    proc = subprocess.run(argv, input=stdin, capture_output=True, text=True, check=False, timeout=30)
    if proc.returncode != 0:
        raise RuntimeError(f"`{' '.join(argv)}` failed ({proc.returncode}): {proc.stderr.strip()}")
    return proc.stdout


def remove_stale_labs() -> list[str]:
    """Delete lab namespaces left by processes that no longer exist (a test killed mid-way);
    labs of live processes, e.g. other tests running now, are left alone. Returns those deleted."""
    out = subprocess.run(["ip", "netns", "list"], capture_output=True, text=True, check=False).stdout
    removed = []
    for line in out.splitlines():
        name = line.split()[0] if line.split() else ""
        m = re.fullmatch(rf"{NS_PREFIX}-(\d+)-[0-9a-f]+-.+", name)
        if m and not Path(f"/proc/{m.group(1)}").exists():
            subprocess.run(["ip", "netns", "del", name], check=False, capture_output=True)
            removed.append(name)
    return removed


@dataclass(frozen=True)
class ProbeResult:
    """A counted UDP probe across the lab: ``sent`` datagrams, ``received`` of them arrived."""

    sent: int
    received: int
    rcvbuf_errors: int  #: datagrams the receiver's socket buffer dropped (not the link's loss)

    @property
    def loss(self) -> float:
        return 1.0 - self.received / self.sent


class NetnsLab:
    """Hosts in network namespaces on one bridge. Use as a context manager: leaving it deletes
    every namespace it made (and with them their links), also on an error."""

    def __init__(self, hosts: list[str], *, tcp_rto_min_ms: int | None = None,
                 tcp_thin_linear_timeouts: bool = False):
        if len(set(hosts)) != len(hosts) or not hosts:
            raise ValueError(f"hosts: need distinct names, got {hosts!r}")
        if len(hosts) > 250:
            raise ValueError(f"hosts: at most 250 in one /24, got {len(hosts)}")
        for h in hosts:
            if type(h) is not str or _HOST_RE.fullmatch(h) is None:
                raise ValueError(f"hosts: bad host name {h!r} (expected {_HOST_RE.pattern})")
        if tcp_rto_min_ms is not None and (type(tcp_rto_min_ms) is not int or not 1 <= tcp_rto_min_ms <= 1000):
            raise ValueError(f"tcp_rto_min_ms: an int in 1..1000 ms, got {tcp_rto_min_ms!r}")
        self.hosts = list(hosts)
        self.tcp_rto_min_ms = tcp_rto_min_ms
        self.tcp_thin_linear_timeouts = bool(tcp_thin_linear_timeouts)
        self.tag = f"{NS_PREFIX}-{os.getpid()}-{uuid.uuid4().hex[:6]}"
        self.switch = f"{self.tag}-switch"
        self._made: list[str] = []
        self.loss = 0.0

    # -- topology ----------------------------------------------------------------------------

    def ns(self, host: str) -> str:
        self._check(host)
        return f"{self.tag}-{host}"

    def ip(self, host: str) -> str:
        self._check(host)
        return f"{SUBNET}.{self.hosts.index(host) + 1}"

    def _check(self, host: str) -> None:
        if host not in self.hosts:
            raise ValueError(f"host: {host!r} is not a host of this lab ({self.hosts})")

    def up(self) -> Self:
        """Create the switch, the hosts and their links (no loss yet)."""
        try:
            self._add_ns(self.switch)
            sw = ["ip", "-n", self.switch]
            _run([*sw, "link", "set", "lo", "up"])
            _run([*sw, "link", "add", "br0", "type", "bridge"])
            _run([*sw, "link", "set", "br0", "up"])
            for i, host in enumerate(self.hosts):
                ns = self.ns(host)
                self._add_ns(ns)
                port = f"p{i}"
                _run([*sw, "link", "add", port, "type", "veth", "peer", "name", IFACE, "netns", ns])
                _run([*sw, "link", "set", port, "master", "br0"])
                _run([*sw, "link", "set", port, "up"])
                _run(["ip", "-n", ns, "addr", "add", f"{self.ip(host)}/24", "dev", IFACE])
                _run(["ip", "-n", ns, "link", "set", IFACE, "up"])
                _run(["ip", "-n", ns, "link", "set", "lo", "up"])
                # IPv4 only: no IPv6 neighbour discovery chatter in the counters and the probes.
                _run(["ip", "netns", "exec", ns, "sysctl", "-qw", "net.ipv6.conf.all.disable_ipv6=1"])
                if self.tcp_rto_min_ms is not None:
                    _run(["ip", "-n", ns, "route", "replace", f"{SUBNET}.0/24", "dev", IFACE, "proto",
                          "kernel", "scope", "link", "src", self.ip(host), "rto_min",
                          f"{self.tcp_rto_min_ms}ms", "quickack", "1"])
                if self.tcp_thin_linear_timeouts:
                    _run(["ip", "netns", "exec", ns, "sysctl", "-qw", "net.ipv4.tcp_thin_linear_timeouts=1"])
            self.set_loss(0.0)
        except BaseException:
            self.down()
            raise
        return self

    def _add_ns(self, name: str) -> None:
        _run(["ip", "netns", "add", name])
        self._made.append(name)

    def down(self) -> None:
        """Delete every namespace this lab made (their veths go with them). Idempotent."""
        while self._made:
            subprocess.run(["ip", "netns", "del", self._made.pop()], check=False, capture_output=True)

    def __enter__(self) -> Self:
        return self.up()

    def __exit__(self, *exc) -> None:
        self.down()

    # -- loss --------------------------------------------------------------------------------

    def set_loss(self, loss: float) -> None:
        """Drop ``loss`` (0..1) of the packets every host receives on its link (input hook)."""
        if type(loss) not in (int, float) or not 0.0 <= loss < 1.0:
            raise ValueError(f"loss: must be a fraction in [0, 1), got {loss!r}")
        threshold = round(loss * LOSS_SCALE)
        rules = textwrap.dedent(f"""\
            table inet {NFT_TABLE}
            delete table inet {NFT_TABLE}
            table inet {NFT_TABLE} {{
              chain input {{
                type filter hook input priority raw; policy accept;
                iifname "{IFACE}" counter
                iifname "{IFACE}" numgen random mod {LOSS_SCALE} < {threshold} counter drop
              }}
            }}
            """)
        for host in self.hosts:
            _run(["ip", "netns", "exec", self.ns(host), "nft", "-f", "-"], stdin=rules)
        self.loss = float(loss)

    def drop_counters(self) -> dict[str, tuple[int, int]]:
        """Per host: (packets that arrived on its link, packets its loss rule dropped)."""
        counts = {}
        for host in self.hosts:
            out = _run(["ip", "netns", "exec", self.ns(host), "nft", "-j", "list", "table", "inet", NFT_TABLE])
            packets = [e["counter"]["packets"] for r in json.loads(out)["nftables"] if "rule" in r
                       for e in r["rule"]["expr"] if "counter" in e]
            counts[host] = (packets[0], packets[1])
        return counts

    # -- processes ---------------------------------------------------------------------------

    def command(self, host: str, argv: list[str]) -> list[str]:
        return ["ip", "netns", "exec", self.ns(host), *argv]

    def start(self, sup: Supervisor, host: str, args: list[str], *, log_path: Path | None = None,
              stdout=None) -> subprocess.Popen:
        """Start ``swarmloc ARGS`` in ``host``, in its own process group, owned by ``sup``
        (``ip netns exec`` execs the command: the process id is the Python process's)."""
        log = open(log_path, "ab") if log_path else None  # noqa: SIM115 -- closed below
        sink = log if log is not None else subprocess.DEVNULL
        try:
            proc = subprocess.Popen(self.command(host, PYTHON + args),
                                    stdout=stdout if stdout is not None else sink, stderr=sink,
                                    stdin=subprocess.DEVNULL, start_new_session=True,
                                    env={**os.environ, **CHILD_ENV})
        finally:
            if log is not None:
                log.close()
        sup.procs.append(proc)
        return proc

    def start_announcing(self, sup: Supervisor, host: str, args: list[str], *,
                         log_path: Path | None = None, timeout_s: float = 60.0) -> subprocess.Popen:
        """Start a piece that prints its endpoints as one JSON line once it listens; return once
        that line came (readiness), RuntimeError if it did not within ``timeout_s``."""
        proc = self.start(sup, host, args, log_path=log_path, stdout=subprocess.PIPE)
        box: dict = {}
        reader = threading.Thread(target=lambda: box.setdefault("line", proc.stdout.readline()), daemon=True)
        reader.start()
        reader.join(timeout_s)
        if not box.get("line"):
            raise RuntimeError(f"`swarmloc {args[0]}` in {host} did not announce within {timeout_s:.0f} s")
        json.loads(box["line"])
        return proc

    # -- measuring the loss ------------------------------------------------------------------

    def probe_udp_loss(self, src: str, dst: str, n: int = 4000, timeout_s: float = 30.0) -> ProbeResult:
        """Send ``n`` numbered UDP datagrams from ``src`` to ``dst`` and count those that arrive.

        The receiver has a 4 MB socket buffer and reports its host's ``RcvbufErrors`` (from the
        namespace's ``/proc/net/snmp``), so that a loss of the receiver's own making shows.
        """
        if n <= 0:
            raise ValueError(f"n: must be > 0, got {n}")
        port = 9000
        receiver = subprocess.Popen(
            self.command(dst, [sys.executable, "-c", _PROBE_RECEIVER, self.ip(dst), str(port)]),
            stdin=subprocess.PIPE, stdout=subprocess.PIPE, text=True, start_new_session=True)
        try:
            if receiver.stdout.readline().strip() != "ready":
                raise RuntimeError(f"the UDP probe receiver in {dst} did not start")
            _run(self.command(src, [sys.executable, "-c", _PROBE_SENDER, self.ip(dst), str(port), str(n)]))
            out, _ = receiver.communicate("", timeout=timeout_s)  # stdin EOF: drain, then report
            received, rcvbuf_errors = map(int, out.split())
        finally:
            if receiver.poll() is None:
                os.killpg(receiver.pid, signal.SIGKILL)
                receiver.wait()
        return ProbeResult(n, received, rcvbuf_errors)


_PROBE_RECEIVER = textwrap.dedent("""\
    import select, socket, sys
    def rcvbuf_errors():
        lines = [l.split() for l in open("/proc/net/snmp") if l.startswith("Udp:")]
        return int(lines[1][lines[0].index("RcvbufErrors")])
    before = rcvbuf_errors()
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4 << 20)
    s.bind((sys.argv[1], int(sys.argv[2])))
    seen = set()
    print("ready", flush=True)
    draining = False
    while True:
        ready, _, _ = select.select([s] + ([] if draining else [sys.stdin]), [], [], 0.3 if draining else None)
        if not ready:
            break  # stdin closed (the sender is done) and the socket quiet for 0.3 s
        if s in ready:
            seen.add(int.from_bytes(s.recv(64)[:4], "big"))
        elif not sys.stdin.read(1):
            draining = True
    print(len(seen), rcvbuf_errors() - before)
    """)

_PROBE_SENDER = textwrap.dedent("""\
    import socket, sys, time
    host, port, n = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])
    s = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    for i in range(n):
        s.sendto(i.to_bytes(4, "big") + bytes(28), (host, port))
        if i % 50 == 49:
            time.sleep(0.001)  # pacing: stay well below what the receiver drains
    """)


# -- a swarm in the lab ------------------------------------------------------------------------


@dataclass
class LabSwarm:
    """The processes of one swarm in a lab: router, world and agents each in their own host."""

    router: subprocess.Popen
    world: subprocess.Popen
    agents: list[subprocess.Popen]
    endpoint: str  # the router's, as the world and the agents connect to it


#: A small arena (0.5 x 0.6 m, nest and prey 0.36 m apart) where seed 000's foraging metrics
#: move within 20 simulated seconds, so that a short run can tell two runs apart.
SMALL_ARENA = ("world.arena.width_m=0.5", "world.arena.height_m=0.6",
               "world.arena.nest_centre_m=[0.25, 0.12]", "world.arena.prey_centre_m=[0.25, 0.48]",
               "world.arena.initial_radius_m=0.1", "world.arena.nest_radius_m=0.08",
               "world.arena.prey_radius_m=0.08")


def lab_scenario(robots: int, duration_s: float, seed: int):
    """ES1's robots and controller (seed 000 table 2) in :data:`SMALL_ARENA`."""
    from swarmloc.deploy.scenario import load_scenario

    return load_scenario("ES1", [f"world.robots={robots}", f"world.duration_s={duration_s}",
                                 f"world.seed={seed}", *SMALL_ARENA])


def lab_hosts(robots: int) -> list[str]:
    """The hosts of a lab for ``robots`` agents: router, world, agent-0 ... agent-(N-1)."""
    return ["router", "world", *(f"agent-{i}" for i in range(robots))]


def start_lab_swarm(lab: NetnsLab, sup: Supervisor, scenario_file: Path, *, run: str, robots: int,
                    out: Path, log_dir: Path, protocol: str = "tcp", join_timeout_s: float = 120.0,
                    lease_s: float | None = None, world_args: tuple[str, ...] = (),
                    agent_args: tuple[str, ...] = ()) -> LabSwarm:
    """The multi-host topology of docs/deploy.md in ``lab``: a router in host ``router``, the
    world in ``world`` and agent i in ``agent-i``, every piece a client of the router over
    ``protocol`` (``tcp``: reliable; ``udp``: best effort, lost packets stay lost)."""
    if protocol not in ("tcp", "udp"):
        raise ValueError(f"protocol: 'tcp' or 'udp', got {protocol!r}")
    endpoint = f"{protocol}/{lab.ip('router')}:{ZENOH_PORT}"
    config = []
    if lease_s is not None:
        config = ["-c", str(write_lease_config(log_dir / "zenoh-lease.json5", lease_s))]
    router = lab.start_announcing(sup, "router", ["router", "-l", endpoint, "--announce", *config],
                                  log_path=log_dir / "router.log")
    client = ["-m", "client", "-e", endpoint, "--run", run, "--join-timeout-s", str(join_timeout_s),
              *config]
    world = lab.start(sup, "world", ["world", str(scenario_file), *client, "--out", str(out),
                                     *world_args], log_path=log_dir / "world.log")
    agents = [lab.start(sup, f"agent-{i}", ["agent", "--robot", str(i), *client, *agent_args],
                        log_path=log_dir / f"agent-{i}.log") for i in range(robots)]
    return LabSwarm(router, world, agents, endpoint)


def write_lease_config(path: Path, lease_s: float) -> Path:
    """A Zenoh configuration file that sets the link lease (Zenoh's default: 10 s).

    A link on which nothing arrived for a lease is closed. Over lossy TCP links, retransmission
    back-off can stall a stream for longer than 10 s at 30 % loss: the link closes, the world
    loses the agent's liveliness and its robot stands still, which changes the run. A longer
    lease keeps the link (keep-alives go out every lease/4)."""
    if type(lease_s) not in (int, float) or not 1.0 <= lease_s <= 3600.0:
        raise ValueError(f"lease_s: seconds in [1, 3600], got {lease_s!r}")
    path.write_text(json.dumps({"transport": {"link": {"tx": {"lease": int(lease_s * 1000)}}}}) + "\n")
    return path
