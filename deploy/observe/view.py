"""``swarmloc view``: the browser page of a live run or of a recording (aiohttp + one WebSocket).

The page (``static/``: plain HTML, JS and CSS, nothing fetched from elsewhere) opens ``/ws``; the
server sends ``{"type": "hello", "mode": "live" | "recording", "scene": ...}`` and then frames
``{"type": "frame", "frame": {...}}``. The page may send ``{"cmd": "pause"}``, ``{"cmd": "play"}``,
``{"cmd": "seek", "tick": N}`` and ``{"cmd": "speed", "x": X}``; anything else is counted
(``bad_messages`` on ``/stats``) and ignored.

Every client has a latest-wins slot: a new frame replaces one not yet sent (``frames_dropped``),
so a slow or vanished browser holds up only its own sender task, never the Zenoh callback that
feeds the hub and never the run. Live frames come from the world's bounded frame stream
(deploy/observe/tap.py); a recording is read once and played per client (pause, seek, speed).
"""

from __future__ import annotations

import asyncio
import bisect
import json
import logging
import threading
import time
from importlib import resources
from pathlib import Path

import msgpack
from aiohttp import WSMsgType, web

from swarmloc.deploy.observe.record import dumps

log = logging.getLogger("swarmloc.view")

STATIC = resources.files("swarmloc.deploy.observe") / "static"
#: How often a playing recording sends a frame to its client (frames per wall second).
PLAY_HZ = 30.0
MAX_SPEED = 1000.0


def _text(obj) -> str:
    """JSON for the page (JSON.parse knows no NaN: non-finite floats go as null)."""
    return dumps(obj).decode()


class Stats:
    def __init__(self) -> None:
        self.frames_in = 0
        self.frames_sent = 0
        self.frames_dropped = 0
        self.bad_messages = 0
        self.clients = 0
        self.connections = 0
        self.disconnects = 0

    def as_dict(self) -> dict:
        return dict(vars(self))


class Client:
    """One browser: a latest-wins slot and the task that empties it."""

    def __init__(self, ws: web.WebSocketResponse, stats: Stats) -> None:
        self.ws = ws
        self.stats = stats
        self.latest: str | None = None
        self.ready = asyncio.Event()
        self.paused = False
        # recordings: this client's playback
        self.cursor = 0
        self.speed = 1.0
        self.playing = True
        self.changed = asyncio.Event()

    def offer(self, text: str) -> None:
        if self.latest is not None:
            self.stats.frames_dropped += 1
        self.latest = text
        self.ready.set()

    async def pump(self) -> None:
        while not self.ws.closed:
            await self.ready.wait()
            self.ready.clear()
            text, self.latest = self.latest, None
            if text is None:
                continue
            try:
                await self.ws.send_str(text)
                self.stats.frames_sent += 1
            except (ConnectionError, RuntimeError):
                return


class ViewServer:
    """The web side, fed either live (:meth:`feed`, any thread) or from a recording."""

    def __init__(self, *, recording=None, title: str = "swarmloc") -> None:
        self.recording = recording
        self.title = title
        self.stats = Stats()
        self.clients: set[Client] = set()
        self.scene: dict | None = recording.scene if recording is not None else None
        self.last_frame: str | None = None
        self.loop: asyncio.AbstractEventLoop | None = None
        if recording is not None:
            self._ticks = [f["tick"] for f in recording.frames]
            self._texts = [_text({"type": "frame", "frame": f, "index": i})
                           for i, f in enumerate(recording.frames)]

    # -- live feed (called from Zenoh's threads) ---------------------------------------------

    def feed(self, payload: bytes) -> None:
        """A frame (msgpack) from the world's stream; bad ones are counted, never raised (ZENOH.md)."""
        try:
            frame = msgpack.unpackb(payload, strict_map_key=False)
            if not isinstance(frame, dict) or "tick" not in frame:
                raise ValueError("not a frame")
        except (ValueError, TypeError, msgpack.UnpackException):
            self.stats.bad_messages += 1
            return
        text = _text({"type": "frame", "frame": frame})
        if self.loop is not None:
            self.loop.call_soon_threadsafe(self._broadcast, text)

    def set_scene(self, scene: dict) -> None:
        if self.loop is not None:
            self.loop.call_soon_threadsafe(self._new_scene, scene)

    def _new_scene(self, scene: dict) -> None:
        self.scene = scene
        text = _text({"type": "scene", "scene": scene})
        for c in self.clients:
            asyncio.ensure_future(self._send_now(c, text))

    async def _send_now(self, c: Client, text: str) -> None:
        try:
            await c.ws.send_str(text)
        except (ConnectionError, RuntimeError):
            pass

    def _broadcast(self, text: str) -> None:
        self.stats.frames_in += 1
        self.last_frame = text
        for c in self.clients:
            if not c.paused:
                c.offer(text)

    # -- HTTP --------------------------------------------------------------------------------

    def app(self) -> web.Application:
        app = web.Application()
        app.router.add_get("/", self._index)
        app.router.add_get("/ws", self._ws)
        app.router.add_get("/stats", self._stats)
        app.router.add_get("/static/{name}", self._static)
        return app

    async def _index(self, request) -> web.Response:
        return web.Response(text=(STATIC / "index.html").read_text(), content_type="text/html")

    async def _static(self, request) -> web.Response:
        name = request.match_info["name"]
        types = {".js": "application/javascript", ".css": "text/css"}
        suffix = Path(name).suffix
        if "/" in name or name.startswith(".") or suffix not in types:
            raise web.HTTPNotFound()
        f = STATIC / name
        if not f.is_file():
            raise web.HTTPNotFound()
        return web.Response(text=f.read_text(), content_type=types[suffix])

    async def _stats(self, request) -> web.Response:
        return web.json_response(self.stats.as_dict())

    def _hello(self) -> str:
        hello = {"type": "hello", "mode": "live" if self.recording is None else "recording",
                 "title": self.title, "scene": self.scene}
        if self.recording is not None:
            hello.update(n_frames=len(self._ticks), first_tick=self._ticks[0] if self._ticks else 0,
                         last_tick=self._ticks[-1] if self._ticks else 0,
                         truncated=self.recording.truncated)
        return _text(hello)

    async def _ws(self, request) -> web.WebSocketResponse:
        ws = web.WebSocketResponse(heartbeat=20.0, max_msg_size=1 << 16)
        await ws.prepare(request)
        client = Client(ws, self.stats)
        self.stats.connections += 1
        self.stats.clients += 1
        self.clients.add(client)
        tasks = [asyncio.ensure_future(client.pump())]
        try:
            await ws.send_str(self._hello())
            if self.recording is not None:
                tasks.append(asyncio.ensure_future(self._play(client)))
            elif self.last_frame is not None:
                client.offer(self.last_frame)
            async for msg in ws:
                if msg.type == WSMsgType.TEXT:
                    self._command(client, msg.data)
                elif msg.type in (WSMsgType.BINARY,):
                    self.stats.bad_messages += 1
                elif msg.type == WSMsgType.ERROR:
                    break
        except (ConnectionError, RuntimeError, asyncio.CancelledError):
            pass
        finally:
            self.clients.discard(client)
            self.stats.clients -= 1
            self.stats.disconnects += 1
            for t in tasks:
                t.cancel()
            client.ready.set()
        return ws

    def _command(self, client: Client, text: str) -> None:
        try:
            cmd = json.loads(text)
            if not isinstance(cmd, dict):
                raise ValueError("not an object")  # noqa: TRY004 -- counted like any bad command
            name = cmd.get("cmd")
            if name == "pause":
                client.paused, client.playing = True, False
            elif name == "play":
                client.paused, client.playing = False, True
            elif name == "seek" and self.recording is not None:
                tick = cmd["tick"]
                if isinstance(tick, bool) or not isinstance(tick, int):
                    raise ValueError("tick: not an integer")
                i = bisect.bisect_left(self._ticks, tick)
                client.cursor = min(max(i, 0), len(self._ticks) - 1)
            elif name == "speed":
                x = float(cmd["x"])
                if not 0 < x <= MAX_SPEED:
                    raise ValueError("speed out of range")
                client.speed = x
            else:
                raise ValueError(f"unknown command {name!r}")
        except (ValueError, KeyError, TypeError):
            self.stats.bad_messages += 1
            return
        client.changed.set()

    async def _play(self, client: Client) -> None:
        """Play the recording to one client: its cursor advances by speed x wall time."""
        texts, ticks = self._texts, self._ticks
        if not texts:
            return
        tick_s = (self.scene or {}).get("tick_s") or 0.1
        position = float(ticks[client.cursor])
        last_sent = -1
        t = time.monotonic()
        while not client.ws.closed:
            now = time.monotonic()
            if client.changed.is_set():
                client.changed.clear()
                position = float(ticks[client.cursor])
                last_sent = -1
            elif client.playing:
                position += (now - t) * client.speed / tick_s
                i = bisect.bisect_right(ticks, position) - 1
                client.cursor = min(max(i, 0), len(ticks) - 1)
                if client.cursor == len(ticks) - 1:
                    client.playing = False
            t = now
            if client.cursor != last_sent:
                last_sent = client.cursor
                client.offer(texts[client.cursor])
            try:
                await asyncio.wait_for(client.changed.wait(), 1.0 / PLAY_HZ)
            except TimeoutError:
                pass


def parse_http(address: str) -> tuple[str, int]:
    host, sep, port = address.rpartition(":")
    if not sep or not port.isdigit() or not host:
        raise ValueError(f"--http: expected HOST:PORT, e.g. 127.0.0.1:8765, got {address!r}")
    return host.strip("[]"), int(port)


async def serve(server: ViewServer, address: str, announce, stop: threading.Event) -> None:
    """Serve until ``stop`` is set; ``announce(url)`` once listening."""
    server.loop = asyncio.get_running_loop()
    host, port = parse_http(address)
    runner = web.AppRunner(server.app(), access_log=None)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    await site.start()
    sock = site._server.sockets[0]  # the bound port, when 0 was asked for
    bound = sock.getsockname()
    shown = f"[{bound[0]}]" if ":" in bound[0] else bound[0]
    announce(f"http://{shown}:{bound[1]}/")
    try:
        while not stop.is_set():
            await asyncio.sleep(0.1)
    finally:
        for c in list(server.clients):
            await c.ws.close()
        await runner.cleanup()
