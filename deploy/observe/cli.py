"""The observers' commands: ``swarmloc view``, ``swarmloc record``, ``swarmloc replay``, and the
flags they add to ``swarmloc run``, ``world`` and ``batch`` (registered by deploy/cli.py).

- ``swarmloc view --run RUN [-e ROUTER]``: the live page of a run (any host);
  ``swarmloc view FILE.mcap``: the same page playing a recording;
- ``swarmloc record --run RUN FILE.mcap``: a standalone observer that records the frames it
  receives (the world's bounded stream, so not every tick of a fast run: for that, ``--record`` on
  ``run``/``world``, which the world-server writes itself);
- ``swarmloc replay FILE.mcap [--speed X | --lockstep]``: republish a recording on Zenoh (world
  state, frames, scene, liveliness, run end) so that any observer sees it as if live.
"""

from __future__ import annotations

import json
import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

DEFAULT_ENDPOINT = "tcp/127.0.0.1:7447"
DEFAULT_HTTP = "127.0.0.1:8765"
#: ``--particles`` alone: poses of each laser robot's population per Act (MAX_SAMPLES at most).
PARTICLES = 100


# -- flags on existing commands ----------------------------------------------------------------

def add_world_arguments(p) -> None:
    from swarmloc.deploy.observe.tap import FRAME_HZ

    g = p.add_argument_group("observers")
    g.add_argument("--record", default=None, metavar="FILE.mcap",
                   help="write every tick's world state and the agents' estimates to FILE.mcap")
    g.add_argument("--record-messages", action="store_true",
                   help="with --record: also every Sense and Act (the protocol's bytes)")
    add_particles_argument(g)
    g.add_argument("--frame-hz", type=float, default=FRAME_HZ,
                   help=f"most frames per wall-clock second streamed to views (default {FRAME_HZ:g}; "
                        f"0: none)")


def particles_count(text: str) -> int:
    """``--particles N``: 0..MAX_SAMPLES, else an argparse error naming the bound."""
    import argparse

    from swarmloc.protocol.messages import MAX_SAMPLES

    try:
        n = int(text)
    except ValueError:
        raise argparse.ArgumentTypeError(f"expected an integer, got {text!r}") from None
    if not 0 <= n <= MAX_SAMPLES:
        raise argparse.ArgumentTypeError(f"must be within 0..{MAX_SAMPLES} (the protocol's bound on "
                                         f"the poses one Act may log), got {n}")
    return n


def add_particles_argument(g) -> None:
    g.add_argument("--particles", type=particles_count, default=0, nargs="?", const=PARTICLES,
                   metavar="N",
                   help=f"ask the agents to log up to N poses of their population or particles in "
                        f"each Act (laser robots), for the view and the recording (N default "
                        f"{PARTICLES} when the flag is given alone; 0, the default: none)")


def add_run_arguments(p) -> None:
    g = p.add_argument_group("observers")
    g.add_argument("--view", action="store_true", help="serve the live page of the run and print its URL")
    g.add_argument("--view-http", default=DEFAULT_HTTP, metavar="HOST:PORT",
                   help=f"where the page listens (default {DEFAULT_HTTP}; port 0: any free port)")
    g.add_argument("--record", default=None, metavar="FILE.mcap",
                   help="the world-server writes every tick to FILE.mcap")
    g.add_argument("--record-messages", action="store_true",
                   help="with --record: also every Sense and Act")
    add_particles_argument(g)


def record_world_args(record: str | None, record_messages: bool, particles: int = 0) -> tuple[str, ...]:
    """The world-server's flags for what ``swarmloc run`` was asked to record and show."""
    out: tuple[str, ...] = ("--particles", str(particles)) if particles else ()
    if not record:
        return out
    return (*out, "--record", str(Path(record).resolve()),
            *(("--record-messages",) if record_messages else ()))


def start_view(sup, endpoint: str, run: str, http: str, log_path: Path | None = None,
               timeout_s: float = 60.0) -> tuple[subprocess.Popen, str]:
    """Start ``swarmloc view`` for a run under ``sup``; return it and its URL (its readiness)."""
    proc = sup.start(["view", "--run", run, "-e", endpoint, "--http", http, "--announce"],
                     stdout=subprocess.PIPE, log_path=log_path)
    box: dict = {}
    reader = threading.Thread(target=lambda: box.setdefault("line", proc.stdout.readline()), daemon=True)
    reader.start()
    reader.join(timeout_s)
    line = box.get("line", b"")
    if not line:
        raise RuntimeError(f"`swarmloc view` did not announce its URL within {timeout_s:.0f} s")
    return proc, json.loads(line)["url"]


# -- helpers -----------------------------------------------------------------------------------

def _stop_event() -> threading.Event:
    stop = threading.Event()
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda *_: stop.set())
    return stop


def _session(args):
    from swarmloc.protocol.session import open_session, session_config

    config = session_config(mode=args.mode or "client",
                            connect=args.connect or ([DEFAULT_ENDPOINT] if not args.config else ()),
                            listen=args.listen or (), config_file=args.config)
    return open_session(config)


def _query_scene(session, keys, stop: threading.Event, timeout_s: float | None = None) -> dict | None:
    """Ask the world for its scene until it answers (the world may start later)."""
    from swarmloc.deploy.observe.tap import scene_key

    deadline = None if timeout_s is None else time.monotonic() + timeout_s
    while not stop.is_set():
        for reply in session.get(scene_key(keys), timeout=1.0):
            if reply.ok is not None:
                try:
                    return json.loads(reply.ok.payload.to_bytes())
                except ValueError:
                    pass
        if deadline is not None and time.monotonic() > deadline:
            return None
        stop.wait(0.2)  # retry pacing while no world answers
    return None


def _fail(message: str) -> int:
    print(f"swarmloc: error: {message}", file=sys.stderr)
    return 2


# -- swarmloc view -----------------------------------------------------------------------------

def main_view(args) -> int:
    import asyncio

    from swarmloc.deploy.observe.record import RecordingError, read_recording
    from swarmloc.deploy.observe.view import ViewServer, parse_http, serve

    parse_http(args.http)
    stop = _stop_event()

    def announce(url: str) -> None:
        if args.announce:
            print(json.dumps({"url": url}), flush=True)
        else:
            print(f"view: {url}", flush=True)

    if args.file:
        try:
            recording = read_recording(args.file)
        except RecordingError as exc:
            return _fail(str(exc))
        if recording.truncated:
            print(f"swarmloc view: warning: {recording.truncated}", file=sys.stderr)
        server = ViewServer(recording=recording, title=Path(args.file).name)
        asyncio.run(serve(server, args.http, announce, stop))
        return 0
    if not args.run:
        return _fail("swarmloc view: give a recording (FILE.mcap) or --run RUN")
    from swarmloc.deploy.observe.tap import frame_key
    from swarmloc.protocol.keys import Keys

    keys = Keys(args.run)
    server = ViewServer(title=args.run)
    session = _session(args)
    try:
        sub = session.declare_subscriber(frame_key(keys), lambda s: server.feed(s.payload.to_bytes()))

        def scene():
            found = _query_scene(session, keys, stop)
            if found is not None:
                while server.loop is None and not stop.is_set():
                    stop.wait(0.05)  # the page's loop starts in the main thread
                server.set_scene(found)

        threading.Thread(target=scene, daemon=True).start()
        asyncio.run(serve(server, args.http, announce, stop))
        sub.undeclare()
    finally:
        stop.set()
        session.close()
    return 0


# -- swarmloc export ---------------------------------------------------------------------------

def main_export(args) -> int:
    source = Path(args.file)
    if source.is_dir():  # robots' data: an MRCLAM folder or a rosbag2 folder, either way
        from swarmloc.world.replay.mrclam import MrclamFormatError, load_dataset, write_dataset

        try:
            dataset = load_dataset(source)
            if args.to == "mrclam":
                write_dataset(dataset, args.out)
                print(f"wrote {args.out}: MRCLAM folder, robots {', '.join(map(str, dataset.robot_ids))}")
                return 0
            from swarmloc.world.replay.rosbag import write_rosbag2

            counts = write_rosbag2(dataset, args.out)
        except MrclamFormatError as exc:
            return _fail(str(exc))
    else:
        if args.to != "rosbag2":
            return _fail(f"--to {args.to}: a recording ({source}) exports to rosbag2 only; "
                         "--to mrclam takes a data set folder or a bag")
        try:
            import rosbags  # noqa: F401 -- only to say what is missing
        except ImportError:
            return _fail("export --to rosbag2 needs the rosbags package: pip install 'swarmloc[ros]'")
        from swarmloc.deploy.observe.rosbag import export_rosbag2

        counts = export_rosbag2(args.file, args.out)
    print(f"wrote {args.out}: " + ", ".join(f"{t} {n}" for t, n in counts.items()))
    return 0


# -- swarmloc record ---------------------------------------------------------------------------

def main_record(args) -> int:
    if args.recover is not None:
        from swarmloc.deploy.observe.record import rewrite

        rec = rewrite(args.recover, args.file)
        lost = f"; {rec.truncated}" if rec.truncated else "; the input was whole"
        print(f"wrote {args.file}: {len(rec.frames)} frames, {len(rec.sense_act)} Senses and Acts{lost}")
        return 0
    if args.run is None:
        return _fail("record: give --run RUN (a live run to record) or --recover IN.mcap")
    import msgpack

    from swarmloc.deploy.observe.record import RecordingWriter
    from swarmloc.deploy.observe.tap import frame_key
    from swarmloc.protocol.keys import Keys

    keys = Keys(args.run)
    stop = _stop_event()
    session = _session(args)
    try:
        scene = _query_scene(session, keys, stop, args.timeout_s)
        if scene is None:
            return _fail(f"no world of run {args.run!r} answered within {args.timeout_s:.0f} s")
        writer = RecordingWriter(args.file, metadata={"run": args.run, "recorder": "swarmloc record"})
        writer.scene(scene)
        lock = threading.Lock()
        state = {"last": -1, "bad": 0}

        def on_frame(sample):
            try:
                frame = msgpack.unpackb(sample.payload.to_bytes(), strict_map_key=False)
                frame.pop("done", None)
                with lock:
                    if frame["tick"] > state["last"] and not writer._file.closed:
                        writer.frame({k: v for k, v in frame.items()})
                        state["last"] = frame["tick"]
                if sample and frame.get("tick", 0) >= scene.get("n_ticks", 1 << 62):
                    stop.set()
            except Exception:  # noqa: BLE001 -- counted; a callback must not raise
                state["bad"] += 1

        subs = [session.declare_subscriber(frame_key(keys), on_frame),
                session.declare_subscriber(keys.run_end, lambda s: stop.set())]
        print(json.dumps({"recording": str(args.file), "run": args.run}), flush=True)
        stop.wait()
        for s in subs:
            s.undeclare()
        with lock:
            writer.close()
        print(f"swarmloc record: {writer.frames} frames (received, not every tick) to {args.file}"
              + (f"; {state['bad']} unreadable" if state["bad"] else ""), file=sys.stderr)
    finally:
        session.close()
    return 0


# -- swarmloc replay ---------------------------------------------------------------------------

def main_replay(args) -> int:
    import msgpack
    import zenoh

    from swarmloc.deploy.observe.record import RecordingError, dumps, read_recording
    from swarmloc.deploy.observe.tap import FRAME_HZ, frame_key, scene_key
    from swarmloc.protocol.keys import Keys
    from swarmloc.protocol.messages import RunEnd, WorldState, encode

    if args.speed is not None and not args.speed > 0:
        return _fail(f"--speed: must be > 0, got {args.speed}")
    try:
        recording = read_recording(args.file)
    except RecordingError as exc:
        return _fail(str(exc))
    if recording.truncated:
        print(f"swarmloc replay: warning: {recording.truncated}", file=sys.stderr)
    scene = recording.scene
    run = args.run or scene.get("run") or "replay"
    keys = Keys(run)
    stop = _stop_event()
    scene_bytes = dumps(scene)
    session = _session(args)
    try:
        block = zenoh.CongestionControl.BLOCK
        state_pub = session.declare_publisher(keys.world_state, congestion_control=block)
        frame_pub = session.declare_publisher(frame_key(keys))
        end_pub = session.declare_publisher(keys.run_end, congestion_control=block)
        queryable = session.declare_queryable(scene_key(keys), lambda q: q.reply(q.key_expr, scene_bytes))
        token = session.liveliness().declare_token(keys.world_alive)
        if args.wait_subscriber_s > 0:
            deadline = time.monotonic() + args.wait_subscriber_s
            while not state_pub.matching_status.matching and time.monotonic() < deadline:
                if stop.wait(0.05):  # polling Zenoh's matching status, bounded by the deadline
                    break
        print(json.dumps({"replaying": str(args.file), "run": run, "frames": len(recording.frames)}),
              flush=True)
        tick_s = scene.get("tick_s") or 0.1
        period = 1.0 / FRAME_HZ
        pack = msgpack.Packer().pack
        start = time.monotonic()
        first_tick = recording.frames[0]["tick"] if recording.frames else 0
        next_frame_at = 0.0
        last = None
        for frame in recording.frames:
            if stop.is_set():
                break
            if not args.lockstep:
                due = start + (frame["tick"] - first_tick) * tick_s / (args.speed or 1.0)
                if stop.wait(max(0.0, due - time.monotonic())):
                    break
            s = frame["state"]
            state_pub.put(encode(WorldState(
                tick=s["tick"], time_s=s["time_s"], poses=tuple(tuple(p) for p in s["poses"]),
                alive=tuple(s["alive"]), round_trips=s["round_trips"])))
            now = time.monotonic()
            if now >= next_frame_at:
                next_frame_at = now + period
                frame_pub.put(pack(frame))
            last = frame
        if last is not None:
            frame_pub.put(pack({**last, "done": True}))
            end_pub.put(encode(RunEnd(tick=last["tick"], reason="replayed", metrics={})))
        for d in (state_pub, frame_pub, end_pub, queryable, token):
            d.undeclare()
    finally:
        session.close()
    return 0


# -- parsers -----------------------------------------------------------------------------------

def add_parsers(sub) -> None:
    from swarmloc.protocol.session import add_transport_args

    p = sub.add_parser("view", help="watch a live run (--run) or a recording (FILE.mcap) in the browser",
                       description="Serve the page of a live run or of a recording on --http "
                                   "(loopback by default) and print its URL.")
    p.add_argument("file", nargs="?", default=None, metavar="FILE.mcap", help="a recording to play")
    p.add_argument("--run", default=None, help="the live run to follow")
    p.add_argument("--http", default=DEFAULT_HTTP, metavar="HOST:PORT",
                   help=f"where the page listens (default {DEFAULT_HTTP}, loopback; port 0: any free "
                        f"port). Not -l/--listen: that is Zenoh's")
    p.add_argument("--announce", action="store_true", help="print the URL as one JSON line")
    add_transport_args(p)
    p.set_defaults(func=main_view)

    p = sub.add_parser("record", help="record the frames a live run streams to FILE.mcap",
                       description="A standalone observer: records the frames it receives (at most "
                                   "the world's --frame-hz per second, not every tick; for every "
                                   "tick use `swarmloc run/world --record`). Stops at the run's end "
                                   "or on Ctrl-C. With --recover IN: rewrite a recording cut short "
                                   "(a crash) as a complete indexed file FILE.mcap.")
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("--run", default=None, help="the run to record")
    p.add_argument("--recover", default=None, metavar="IN.mcap",
                   help="instead of recording: read IN.mcap up to its last whole chunk and write "
                        "what it holds to FILE.mcap, indexed (as `mcap recover` does)")
    p.add_argument("--timeout-s", type=float, default=60.0, help="how long to wait for the world")
    add_transport_args(p)
    p.set_defaults(func=main_record)

    p = sub.add_parser("export", help="write a recording or robots' data in another format (ROS 2 bag, MRCLAM)",
                       description="Write FILE.mcap (a swarmloc recording) as a rosbag2 folder OUT "
                                   "(MCAP storage, CDR, standard ROS 2 message types: /tf, "
                                   "/robot_<i>/odom, /swarmloc/estimates, /swarmloc/arena; "
                                   "docs/recording.md); or a real-data set (an MRCLAM folder, or a "
                                   "bag) as a rosbag2 folder or an MRCLAM folder (docs/mrclam/bags.md). "
                                   "Bags need the rosbags package (pip install 'swarmloc[ros]'), no "
                                   "ROS installation.")
    p.add_argument("file", metavar="FILE.mcap|DATASET")
    p.add_argument("--to", required=True, choices=["rosbag2", "mrclam"], help="the format")
    p.add_argument("out", metavar="OUT", help="the folder to write (must not exist)")
    p.set_defaults(func=main_export)

    p = sub.add_parser("replay", help="republish a recording on Zenoh as if live",
                       description="Publish a recording's world states, frames, scene, liveliness "
                                   "and run end under swarmloc/<run>/ (the recorded run's name "
                                   "unless --run).")
    p.add_argument("file", metavar="FILE.mcap")
    p.add_argument("--run", default=None, help="run name to publish under")
    g = p.add_mutually_exclusive_group()
    g.add_argument("--speed", type=float, default=None, help="times the recorded speed (default 1)")
    g.add_argument("--lockstep", action="store_true",
                   help="as fast as subscribers take it, every tick (blocking publishers)")
    p.add_argument("--wait-subscriber-s", type=float, default=0.0,
                   help="first wait up to this long for a subscriber of the world state")
    add_transport_args(p)
    p.set_defaults(func=main_replay)
