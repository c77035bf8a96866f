"""The world-server's observer tap: every tick to the recording, a bounded stream to the view.

The world-server (world/server.py) calls :meth:`WorldTap.sensed` with the Senses it published and
:meth:`WorldTap.stepped` with the Acts it stepped the world with. The tap

- writes every tick's frame (and with ``record_messages`` every Sense and Act) to an MCAP file
  in-process, so a lockstep recording is exact and misses no tick;
- publishes a frame (msgpack, the recording's frame encoding: JSON of a 100-robot frame took 580
  us, msgpack 40) on ``swarmloc/<run>/world/frame`` at most ``max_hz`` times per *wall-clock*
  second, and only while someone subscribes (Zenoh's matching status), so a view never costs the
  lockstep more than a bounded few frames a second;
- answers ``swarmloc/<run>/world/scene`` with the static scene (a view that attaches late asks).
"""

from __future__ import annotations

import logging
import time
from pathlib import Path

import msgpack
import zenoh

from swarmloc.deploy.observe.frames import frame_source
from swarmloc.deploy.observe.record import RecordingWriter, dumps
from swarmloc.protocol.keys import Keys
from swarmloc.protocol.messages import encode

log = logging.getLogger("swarmloc.observe")

#: Default ceiling of the world's frame stream, frames per wall-clock second.
FRAME_HZ = 25.0


def frame_key(keys: Keys) -> str:
    return f"{keys.prefix}/world/frame"


def scene_key(keys: Keys) -> str:
    return f"{keys.prefix}/world/scene"


class WorldTap:
    def __init__(self, service, *, session=None, keys: Keys | None = None,
                 record: str | Path | None = None, record_messages: bool = False,
                 max_hz: float = FRAME_HZ, labels: dict | None = None) -> None:
        self.service = service
        self.source = frame_source(service)
        self.scene = {**self.source.scene(), **(labels or {})}
        self._scene_bytes = dumps(self.scene)
        self.writer = None
        if record:
            self.writer = RecordingWriter(record, messages=record_messages, metadata=labels)
            self.writer.scene(self.scene)
        self.record_messages = bool(record and record_messages)
        self._decls = []
        self._pub = None
        self.period_s = 1.0 / max_hz if max_hz > 0 else None
        if session is not None and keys is not None and self.period_s is not None:
            self._pub = session.declare_publisher(frame_key(keys))
            # Whether a view subscribes, kept by Zenoh's matching listener: polling the
            # publisher's matching_status walks the routing tables of every connected session,
            # 7 ms a tick on the main thread with 600 agents connected (issue 47, py-spy).
            self._watched = self._pub.matching_status.matching
            self._decls.append(self._pub.declare_matching_listener(
                zenoh.handlers.Callback(self._on_matching, indirect=False)))
            self._decls.append(self._pub)
            self._decls.append(session.declare_queryable(scene_key(keys), self._on_scene))
        self.published = 0
        self._next_at = 0.0
        self._rate_t, self._rate_tick = time.monotonic(), service.tick
        self._rate = None
        self._frame = None
        self._pack = msgpack.Packer().pack  # the world's thread only
        if self.writer is not None:
            self._frame = self.source.frame()
            self.writer.frame(self._frame)  # tick 0, before any step

    def _on_matching(self, status) -> None:
        self._watched = bool(status.matching)

    def _on_scene(self, query) -> None:
        try:
            query.reply(query.key_expr, self._scene_bytes)
        except Exception as exc:  # noqa: BLE001 -- a callback must not raise (ZENOH.md)
            log.warning("scene query: %s", exc)

    def sensed(self, senses: list) -> None:
        if self.record_messages:
            tick = self.service.tick
            for _, data in senses:
                self.writer.sense(tick, data)

    def stepped(self, acts: list) -> None:
        self.source.note(acts)
        self._frame = None
        if self.writer is not None:
            if self.record_messages:
                tick = self.service.tick - 1
                for act in acts:
                    if act is not None:
                        self.writer.act(tick, encode(act))
            self._frame = self.source.frame()
            self.writer.frame(self._frame)
        if self._pub is not None:
            now = time.monotonic()
            if now >= self._next_at or self.service.done:
                self._next_at = now + self.period_s
                self._publish(now)

    def _publish(self, now: float) -> None:
        tick = self.service.tick
        if now > self._rate_t + 0.5:
            self._rate = (tick - self._rate_tick) / (now - self._rate_t)
            self._rate_t, self._rate_tick = now, tick
        if not self._watched:
            return
        frame = self._frame if self._frame is not None else self.source.frame()
        metrics = {**frame["metrics"], "ticks_per_s": self._rate}
        self._pub.put(self._pack({**frame, "metrics": metrics, "done": bool(self.service.done)}))
        self.published += 1

    def close(self) -> None:
        if self.writer is not None:
            self.writer.close()
        for d in self._decls:
            try:
                d.undeclare()
            except Exception as exc:  # noqa: BLE001 -- gone with the session already
                log.debug("undeclare: %s", exc)
        self._decls = []
