"""``swarmloc status``: which world-servers and agents of a run (or of every run) are live.

Connects as a client (the shared transport flags, default ``-e tcp/127.0.0.1:7447``) and asks
the liveliness space, with ``liveliness().get(...)``, for the tokens of ``swarmloc/<run>/alive/*``
(``swarmloc/*/alive/*`` when no run is given): ``alive/world`` is the world-server's token,
``alive/<id>`` an agent's (keys: :mod:`swarmloc.protocol.keys`). Prints one row per run (run,
world live?, agents live, their ids) and exits 0 if a world was found, 1 otherwise.

Readiness, and why a one-shot query was flaky: one ``liveliness().get`` fired right after the
swarm started raced with the tokens' propagation. An agent declares its token only after its
join has been answered and its brain built, and the router that ``status`` asks learns the token
from the world's own session (``start_swarm``: agents are clients of the world's router session,
which links to the standalone router), a hop later. A single query could therefore find none, or
only some, of the agents that were about to be live. So the query is repeated (every
``RETRY_S``) until the answer is what the caller waits for (a world, and with ``--expect-agents N``
exactly N agents in every run shown) or until ``--timeout-s``; the last answer is printed.
"""

from __future__ import annotations

import argparse
import sys
import time
from collections.abc import Iterable
from dataclasses import dataclass, field

from swarmloc.protocol.keys import ROOT, validate_run_name
from swarmloc.protocol.messages import MAX_ROBOT_ID, NAME_RE

#: Pause between two liveliness queries while waiting for the expected answer.
RETRY_S = 0.2
#: How long one liveliness query waits for its replies.
QUERY_TIMEOUT_S = 1.0
DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"


@dataclass
class RunStatus:
    """What the liveliness space says about one run."""

    run: str
    world: bool = False
    agents: set[int] = field(default_factory=set)


def summarise(keys: Iterable[str]) -> dict[str, RunStatus]:
    """Group liveliness token keys (``swarmloc/<run>/alive/<id>|world``) by run.

    Keys that are not swarmloc liveliness tokens (another root, a bad run name, an id that is not
    a canonical integer in 0..65535) are ignored: the liveliness space is shared with anyone.
    """
    runs: dict[str, RunStatus] = {}
    for key in keys:
        chunks = str(key).split("/")
        if len(chunks) != 4 or chunks[0] != ROOT or chunks[2] != "alive":
            continue
        run, who = chunks[1], chunks[3]
        if NAME_RE.fullmatch(run) is None:
            continue
        if who == "world":
            runs.setdefault(run, RunStatus(run)).world = True
        elif who.isascii() and who.isdigit() and str(int(who)) == who and int(who) <= MAX_ROBOT_ID:
            runs.setdefault(run, RunStatus(run)).agents.add(int(who))
    return dict(sorted(runs.items()))


def id_ranges(ids: Iterable[int]) -> str:
    """``[0, 1, 2, 5, 7, 8]`` -> ``"0-2,5,7-8"``; ``"-"`` for none."""
    ordered = sorted(set(ids))
    if not ordered:
        return "-"
    parts, start, prev = [], ordered[0], ordered[0]
    for i in ordered[1:] + [None]:
        if i is not None and i == prev + 1:
            prev = i
            continue
        parts.append(str(start) if start == prev else f"{start}-{prev}")
        if i is not None:
            start = prev = i
    return ",".join(parts)


def format_table(runs: dict[str, RunStatus]) -> str:
    """The status table: one row per run."""
    header = ("run", "world", "agents", "ids")
    rows = [(s.run, "live" if s.world else "-", str(len(s.agents)), id_ranges(s.agents))
            for s in runs.values()]
    widths = [max(len(r[c]) for r in [header, *rows]) for c in range(3)]
    lines = ["  ".join(cell.ljust(w) for cell, w in zip(r[:3], widths)) + "  " + r[3]
             for r in [header, *rows]]
    if not rows:
        lines.append("(no live world or agent)")
    return "\n".join(lines)


def selector(run: str | None) -> str:
    """The liveliness key expression to query: one run's tokens or every run's."""
    return f"{ROOT}/{validate_run_name(run) if run is not None else '*'}/alive/*"


def satisfied(runs: dict[str, RunStatus], expect_agents: int | None) -> bool:
    """Whether an answer is the one to wait for: a world, and exactly ``expect_agents`` agents
    in every run shown (if given)."""
    if not any(s.world for s in runs.values()):
        return False
    return expect_agents is None or all(len(s.agents) == expect_agents for s in runs.values())


def query_once(session, run: str | None, timeout_s: float = QUERY_TIMEOUT_S) -> dict[str, RunStatus]:
    """One liveliness query: the runs and their live tokens as the router sees them now."""
    replies = session.liveliness().get(selector(run), timeout=timeout_s)
    return summarise(str(r.ok.key_expr) for r in replies if r.ok is not None)


def query_status(session, run: str | None, *, timeout_s: float,
                 expect_agents: int | None = None) -> dict[str, RunStatus]:
    """Repeat :func:`query_once` until :func:`satisfied` or ``timeout_s``; the last answer."""
    if timeout_s < 0:
        raise ValueError(f"--timeout-s: must be >= 0, got {timeout_s}")
    if expect_agents is not None and not 0 <= expect_agents <= MAX_ROBOT_ID + 1:
        raise ValueError(f"--expect-agents: must be in 0..{MAX_ROBOT_ID + 1}, got {expect_agents}")
    deadline = time.monotonic() + timeout_s
    while True:
        left = deadline - time.monotonic()
        runs = query_once(session, run, min(QUERY_TIMEOUT_S, max(left, 0.1)))
        if satisfied(runs, expect_agents) or time.monotonic() + RETRY_S >= deadline:
            return runs
        time.sleep(RETRY_S)  # pacing between two queries, bounded by the deadline


def main_status(args: argparse.Namespace) -> int:
    from swarmloc.protocol.session import open_session, session_config

    if args.run is not None:
        validate_run_name(args.run)
    config = session_config(mode=args.mode or "client",
                            connect=args.connect or ([DEFAULT_ENDPOINT] if not args.config else ()),
                            listen=args.listen or (), config_file=args.config)
    # A client waits for its router by default; status must not wait for ever.
    config.insert_json5("connect/timeout_ms", str(max(1, int(args.timeout_s * 1000))))
    try:
        session = open_session(config)
    except Exception as exc:  # noqa: BLE001 -- zenoh.ZError: no router answered
        print(f"swarmloc status: cannot connect: {exc}", file=sys.stderr)
        return 1
    try:
        runs = query_status(session, args.run, timeout_s=args.timeout_s,
                            expect_agents=args.expect_agents)
    finally:
        session.close()
    print(format_table(runs))
    return 0 if any(s.world for s in runs.values()) else 1


def add_parser(subparsers) -> None:
    """Register ``swarmloc status`` on the CLI's subparsers."""
    from swarmloc.protocol.session import add_transport_args

    p = subparsers.add_parser(
        "status", help="list the live world and agents of a run (from liveliness)",
        description="List, from the liveliness tokens a router knows, the live world-server and "
                    "agents of a run (or of every run). Exit 0 if a world was found, else 1.")
    p.add_argument("--run", default=None, help="run name (default: every run under swarmloc/*)")
    p.add_argument("--timeout-s", type=float, default=3.0,
                   help="wait up to this long for a world (and --expect-agents) to be seen")
    p.add_argument("--expect-agents", type=int, default=None, metavar="N",
                   help="keep asking until exactly N agents are live in each run shown")
    add_transport_args(p)
    p.set_defaults(func=main_status)
