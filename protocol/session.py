"""Zenoh session configuration from the conventional transport flags.

Every swarmloc command takes the same flags, with Zenoh's own names (STYLE.md item 6):
``-m/--mode``, ``-e/--connect``, ``-l/--listen``, ``-c/--config``. :func:`session_config` turns
them into a ``zenoh.Config`` with the settings that ZENOH.md measured to matter:

- multicast scouting and gossip off (``zenoh.open`` then takes about 1 ms instead of 500 ms, and
  tests cannot discover each other), explicit endpoints instead;
- scouting delay 0 while multicast is off (otherwise a router waits 500 ms in ``zenoh.open``
  scouting for nobody);
- a client that connects to explicit endpoints waits for its router (``connect/timeout_ms: -1``)
  instead of failing at once when the router is not up yet;
- the shared-memory transport off: swarmloc never allocates shared-memory buffers, and with it
  on (Zenoh's default) every session polled for hand-overs about 20 times a second, idle or not:
  750 µs of CPU a second per process, 75 µs per 10 Hz tick of each agent (measured with 20 idle
  clients, benchmarks/bench_zenoh_floor.py --idle); off, 1.4 wake-ups a second and no
  measurable CPU. A link between a session with it and one without simply does not use it;
- a session that listens has its (read-only) admin space enabled, so that
  :func:`bound_endpoints` can read the port it actually got for ``tcp/127.0.0.1:0``;
- a session with a ``tls/`` endpoint has its certificates checked first
  (:func:`swarmloc.protocol.tls.check_tls`): Zenoh only says "Unable to connect".

Explicit arguments override the config file; an argument left at None leaves the file's value.
"""

from __future__ import annotations

import argparse
import ctypes
import functools
import ipaddress
import json
import os
import re
import threading
from collections.abc import Iterable

import zenoh

MODES = ("peer", "client", "router")
#: Protocols whose address is ``host:port``.
IP_PROTOCOLS = ("tcp", "udp", "tls", "quic", "ws")
#: Protocols whose address is a path or device name.
OTHER_PROTOCOLS = ("unixsock-stream", "unixpipe", "serial", "vsock")

_HOSTNAME_RE = re.compile(r"[A-Za-z0-9]([A-Za-z0-9.-]{0,251}[A-Za-z0-9])?")


def add_transport_args(parser: argparse.ArgumentParser) -> None:
    """Add ``-m/--mode``, ``-e/--connect``, ``-l/--listen``, ``-c/--config`` to ``parser``."""
    group = parser.add_argument_group("Zenoh transport")
    group.add_argument(
        "-m", "--mode", choices=MODES, default=None,
        help="Zenoh session mode (default: the config file's, else client)",
    )  # fmt: skip
    group.add_argument(
        "-e", "--connect", action="append", default=None, metavar="ENDPOINT",
        help="endpoint to connect to, e.g. tcp/127.0.0.1:7447 (repeatable)",
    )  # fmt: skip
    group.add_argument(
        "-l", "--listen", action="append", default=None, metavar="ENDPOINT",
        help="endpoint to listen on, e.g. tcp/127.0.0.1:0 for a free port (repeatable)",
    )  # fmt: skip
    group.add_argument(
        "-c", "--config", default=None, metavar="FILE", help="Zenoh configuration file (JSON5)"
    )


def validate_endpoint(endpoint: str, flag: str = "-e/--connect") -> str:
    """Return ``endpoint`` if it looks like a Zenoh endpoint, else ValueError naming ``flag``.

    ``tcp|udp|tls|quic|ws/<host>:<port>`` (host a name, an IPv4 address or a bracketed IPv6
    address, port 0..65535), or ``unixsock-stream|unixpipe|serial|vsock/<address>``; Zenoh's
    ``?metadata`` and ``#config`` suffixes are allowed.
    """
    if type(endpoint) is not str:
        raise ValueError(f"{flag}: endpoint must be a str, got {type(endpoint).__name__}")
    protocol, sep, rest = endpoint.partition("/")
    address = re.split(r"[?#]", rest, maxsplit=1)[0]
    problem = None
    if not sep or protocol not in IP_PROTOCOLS + OTHER_PROTOCOLS:
        problem = (
            f"unknown protocol {protocol!r} (expected one of {IP_PROTOCOLS + OTHER_PROTOCOLS})"
        )
    elif protocol in OTHER_PROTOCOLS:
        if not address:
            problem = "missing address"
    else:
        problem = _host_port_problem(address)
    if problem is not None:
        raise ValueError(f"{flag}: bad endpoint {endpoint!r}: {problem}")
    return endpoint


def _host_port_problem(address: str) -> str | None:
    host, sep, port = address.rpartition(":")
    if not sep or not host:
        return "expected <host>:<port>"
    if not (port.isascii() and port.isdigit()) or int(port) > 65535:
        return f"bad port {port!r}"
    if host.startswith("["):
        if not host.endswith("]"):
            return f"bad IPv6 address {host!r}"
        try:
            ipaddress.IPv6Address(host[1:-1])
        except ValueError:
            return f"bad IPv6 address {host!r}"
    elif _HOSTNAME_RE.fullmatch(host) is None:
        return f"bad host {host!r}"
    return None


def session_config(
    mode: str | None = "client",
    connect: Iterable[str] = (),
    listen: Iterable[str] = (),
    config_file: str | os.PathLike | None = None,
    multicast_scouting: bool | None = False,
    admin_space: bool | None = None,
    shared_memory: bool | None = False,
    min_sessions: int | None = None,
) -> zenoh.Config:
    """A ``zenoh.Config`` for the transport flags.

    Starts from ``config_file`` (JSON5) if given, else from Zenoh's defaults, then:

    - ``mode``: ``"peer"``, ``"client"`` or ``"router"``; None keeps the file's mode, or
      ``"client"`` if the file sets none;
    - ``connect``/``listen``: endpoints, replacing the file's when non-empty;
    - ``multicast_scouting``: False turns multicast scouting and gossip off and the scouting
      delay to 0; True turns multicast scouting on; None leaves the file's scouting settings;
    - ``admin_space``: True enables the read-only admin space (needed by
      :func:`bound_endpoints`), False disables it; None enables it when ``listen`` is given and
      otherwise leaves the file's setting;
    - ``shared_memory``: the shared-memory transport on or off (default off); None leaves the
      file's setting;
    - a client with connect endpoints waits for its router (``connect/timeout_ms: -1``) unless
      the file sets a timeout;
    - ``min_sessions``: Zenoh's ``transport/unicast/max_sessions`` raised to at least this. Its
      default, 1,000, refused the 1,000th connection to a world-server ("close message (reason
      INVALID) in response to an OpenSyn"): a 1,000-agent run lost an agent at start-up and
      ended with exit 3 (issue 47). The world asks for its robots and a margin, a router for
      :data:`ROUTER_MIN_SESSIONS`.

    Raises ValueError naming the flag (``-m/--mode``, ``-e/--connect``, ``-l/--listen``,
    ``-c/--config``) for a bad value.
    """
    if isinstance(connect, str) or isinstance(listen, str):
        raise TypeError("connect and listen take a sequence of endpoints, not a str")
    connect = [validate_endpoint(e, "-e/--connect") for e in connect]
    listen = [validate_endpoint(e, "-l/--listen") for e in listen]
    if mode is not None and mode not in MODES:
        raise ValueError(f"-m/--mode: {mode!r} is not one of {MODES}")

    config = _load_config_file(config_file) if config_file is not None else zenoh.Config()
    if mode is None:
        mode = json.loads(config.get_json("mode")) or "client"
    _insert(config, "mode", mode)
    if connect:
        _insert(config, "connect/endpoints", connect)
    if listen:
        _insert(config, "listen/endpoints", listen)
    if multicast_scouting is not None:
        _insert(config, "scouting/multicast/enabled", bool(multicast_scouting))
        if not multicast_scouting:
            _insert(config, "scouting/gossip/enabled", False)
            _insert(config, "scouting/delay", 0)
    if shared_memory is not None:
        _insert(config, "transport/shared_memory/enabled", bool(shared_memory))
    if admin_space is None and listen:
        admin_space = True
    if admin_space is not None:
        _insert(config, "adminspace/enabled", bool(admin_space))
        _insert(config, "adminspace/permissions", {"read": True, "write": False})
    if (
        mode == "client"
        and _has_endpoints(config, "connect/endpoints", mode)
        and json.loads(config.get_json("connect/timeout_ms")) is None
    ):
        _insert(config, "connect/timeout_ms", -1)
    if min_sessions is not None:
        current = json.loads(config.get_json("transport/unicast/max_sessions")) or 0
        if current < min_sessions:
            _insert(config, "transport/unicast/max_sessions", int(min_sessions))
    if _uses_tls(config):
        from swarmloc.protocol.tls import check_tls

        try:
            check_tls(config)
        except ValueError as exc:
            raise ValueError(f"-c/--config: {exc}") from None
    return config


def _uses_tls(config: zenoh.Config) -> bool:
    """Whether a connect or listen endpoint is ``tls/...`` (Zenoh reads the TLS files then)."""
    for key in ("connect/endpoints", "listen/endpoints"):
        endpoints = json.loads(config.get_json(key)) or []
        if isinstance(endpoints, dict):
            endpoints = [e for side in endpoints.values() for e in side or []]
        if any(str(e).startswith("tls/") for e in endpoints):
            return True
    return False


def _insert(config: zenoh.Config, key: str, value: object) -> None:
    config.insert_json5(key, json.dumps(value))  # JSON is valid JSON5


def _has_endpoints(config: zenoh.Config, key: str, mode: str) -> bool:
    endpoints = json.loads(config.get_json(key))
    if isinstance(endpoints, dict):  # Zenoh allows per-mode lists: {"client": [...], ...}
        endpoints = endpoints.get(mode)
    return bool(endpoints)


def _load_config_file(config_file: str | os.PathLike) -> zenoh.Config:
    path = os.fspath(config_file)
    if not os.path.isfile(path):
        raise ValueError(f"-c/--config: no such file {path!r}")
    try:
        return zenoh.Config.from_file(path)
    except zenoh.ZError as error:
        raise ValueError(f"-c/--config: cannot load {path!r}: {error}") from None


#: Sessions a standalone router accepts at least (Zenoh's default is 1,000): every agent of a
#: deployment through a router is one.
ROUTER_MIN_SESSIONS = 20_000
#: Sessions a world-server accepts beside one per robot (observers, the router, restarts).
SESSION_MARGIN = 64


def config_from_args(args: argparse.Namespace, min_sessions: int | None = None) -> zenoh.Config:
    """The session configuration for flags added by :func:`add_transport_args`."""
    return session_config(
        min_sessions=min_sessions,
        mode=args.mode,
        connect=args.connect or (),
        listen=args.listen or (),
        config_file=args.config,
        # --announce prints the bound endpoints, read from the admin space: on for it in every
        # mode (a client listens on none, and announces an empty list; issue 47: it crashed).
        admin_space=True if getattr(args, "announce", False) else None,
    )


@functools.cache
def _init_logging() -> None:
    # Zenoh logs nothing unless asked; RUST_LOG, when set, wins over "error".
    zenoh.init_log_from_env_or("error")


def open_session(config: zenoh.Config) -> zenoh.Session:
    """Open a Zenoh session (initialising Zenoh's logging once per process).

    Close it (``with open_session(...) as session:`` or ``session.close()``): a process with an
    open session does not exit.
    """
    _init_logging()
    return zenoh.open(config)


def bound_endpoints(session: zenoh.Session, timeout_s: float = 2.0) -> list[str]:
    """The locators this session actually listens on, e.g. ``["tcp/127.0.0.1:40693"]``.

    For ``listen tcp/127.0.0.1:0`` this gives the port the OS chose. Read from the session's own
    admin space, key ``@/<zid>/<mode>`` (a JSON object with a ``locators`` list), which is
    answered locally; the session must have been opened with the admin space enabled
    (:func:`session_config` does so when it listens). Raises RuntimeError if no answer came.
    """
    zid = str(session.info.zid())
    for reply in session.get(f"@/{zid}/*", timeout=timeout_s):
        if reply.ok is None:
            continue
        info = json.loads(reply.ok.payload.to_bytes())
        if isinstance(info, dict) and info.get("zid") == zid:
            return [str(locator) for locator in info.get("locators", [])]
    raise RuntimeError(
        f"no admin space answer from session {zid}: open it with the admin space enabled "
        "(session_config(..., admin_space=True))"
    )


_pinned = threading.local()


def keep_thread_state() -> None:
    """Keep the calling thread's Python thread state alive after this callback returns.

    For a callback that Zenoh runs on its own (Rust) thread (``zenoh.handlers.Callback(...,
    indirect=False)``). Each such call takes the GIL through ``PyGILState_Ensure``; on a thread
    Python does not know, that creates a thread state and ``PyGILState_Release`` deletes it at
    the end, so every message paid for a new thread state and its frame stack (an mmap and a
    munmap, whose TLB shootdown interrupts the other core). One extra ``PyGILState_Ensure``,
    never released, keeps the count above zero: later calls reuse the state (the C API's own
    idiom for foreign threads that call into Python repeatedly). Cheap after the first call: a
    thread-local lookup. Measured in issue 47 (benchmarks/bench_scale.py, 300 real-time agents,
    two pairs of runs: the agents' CPU 0.56-0.58 -> 0.52-0.53 cores; a one-thread world-server
    decoding its Acts on Zenoh's thread, 250 -> 200 ms a second).
    """
    if not getattr(_pinned, "done", False):
        ctypes.pythonapi.PyGILState_Ensure()
        _pinned.done = True


def direct_callback(callback) -> zenoh.handlers.Callback:
    """``callback`` run on the Zenoh thread that received the sample (``indirect=False``: no
    Python thread of its own, no hand-over per message); for callbacks that return at once.
    That thread keeps its Python thread state between calls (:func:`keep_thread_state`). Used
    by the agents (agents/node.py) and by the world-server for its Acts (world/server.py)."""
    def pinned(sample: zenoh.Sample) -> None:
        keep_thread_state()
        callback(sample)

    return zenoh.handlers.Callback(pinned, indirect=False)
