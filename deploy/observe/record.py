"""Recordings of a run in MCAP: writer, tolerant reader, and the schemas (docs/recording.md).

Channels of a swarmloc recording :

- ``/swarmloc/scene`` (``swarmloc.Scene``): what does not move, once at the start;
- ``/swarmloc/frame`` (``swarmloc.Frame``, *msgpack*): every tick's world state, estimates,
  beliefs, links; floats as float64, the world's bits;
- ``/foxglove/scene`` (``foxglove.SceneUpdate``): the map once, then the robots every
  ``FOXGLOVE_PERIOD_S`` of simulated time, so that Foxglove or Lichtblick draws them in a 3D panel;
  at the same times ``/foxglove/tf`` (``foxglove.FrameTransforms``: ``world`` to ``robot_<i>``, each
  robot's true pose), ``/foxglove/estimates`` (``foxglove.PosesInFrame``: every robot's own pose
  belief) and, when the frames carry populations (``--particles``), ``/foxglove/samples``
  (``foxglove.PosesInFrame``: every robot's population). Their schemas are Foxglove's own text;
- ``/swarmloc/sense`` and ``/swarmloc/act`` (``--record-messages``): every Sense and Act as the
  protocol's msgpack bytes (message encoding ``swarmloc-msgpack``, no schema: the codec in
  protocol/messages.py is the schema).

Log times are *simulated* time (tick x tick length), so a player's clock is the run's clock.

The file is indexed (issue 44): messages go into lz4-compressed chunks, each closed and written
out after ``CHUNK_S`` of simulated time (:meth:`RecordingWriter.frame`), with message indexes
after each chunk and a summary (chunk indexes, statistics) at the end, so that Foxglove,
Lichtblick and the mcap readers seek in it instead of reading it whole (unchunked, as before
issue 44, the TypeScript ``@mcap/core`` indexed reader found no chunk index and read no
message). A file cut short (a crash, a full disk) loses at most the chunk in progress: it still
reads up to its last whole chunk, and ``swarmloc record --recover IN OUT`` rewrites what it
holds as an indexed file. :func:`read_recording` reads it front to back and names what is wrong:
not an MCAP file, a record cut short (the messages before it are kept), a channel with the wrong
schema, a message that is not the JSON its schema says. Unchunked files of earlier versions read
alike.
"""

from __future__ import annotations

import io
import json
import math
import struct
from dataclasses import dataclass, field
from pathlib import Path

import msgpack

SCENE_TOPIC = "/swarmloc/scene"
FRAME_TOPIC = "/swarmloc/frame"
FOXGLOVE_TOPIC = "/foxglove/scene"
TF_TOPIC = "/foxglove/tf"
ESTIMATES_TOPIC = "/foxglove/estimates"
SAMPLES_TOPIC = "/foxglove/samples"
SENSE_TOPIC = "/swarmloc/sense"
ACT_TOPIC = "/swarmloc/act"
PROFILE = "swarmloc"
#: The first bytes of every MCAP file.
MCAP_MAGIC = b"\x89MCAP0\r\n"
MSGPACK = "swarmloc-msgpack"


# -- schemas (JSON Schema, draft 2020-12) ------------------------------------------------------

def _num() -> dict:
    return {"type": "number"}


def _obj(props: dict, required: list | None = None, title: str | None = None) -> dict:
    out = {"type": "object", "properties": props}
    if title:
        out["title"] = title
    if required:
        out["required"] = required
    return out


def _arr(items: dict) -> dict:
    return {"type": "array", "items": items}


_POSE3 = {"type": "array", "items": _num(), "minItems": 3, "maxItems": 3,
          "description": "(x_m, y_m, theta_rad)"}
_POSE3_OR_NULL = {"oneOf": [_POSE3, {"type": "null"}]}

FRAME_SCHEMA = _obj({
    "tick": {"type": "integer", "minimum": 0},
    "time_s": _num(),
    "family": {"type": "string"},  # a family of swarmloc.families (plugins' too)
    "state": _obj({"tick": {"type": "integer"}, "time_s": _num(), "poses": _arr(_POSE3),
                   "alive": _arr({"type": "boolean"}), "round_trips": {"type": "integer"}},
                  ["tick", "time_s", "poses", "alive", "round_trips"]),
    "truth": _arr(_POSE3_OR_NULL),
    "estimates": _arr(_POSE3_OR_NULL),
    "beliefs": _arr(_arr(_obj({"label": {"type": "string"}, "x": _num(), "y": _num(),
                               "radius_m": _num()}, ["label", "x", "y", "radius_m"]))),
    "links": _arr({"type": "array", "items": {"type": "integer"}, "minItems": 2, "maxItems": 2}),
    "metrics": {"type": "object"},
    "samples": _arr(_arr(_POSE3)),
}, ["tick", "time_s", "family", "state", "truth", "estimates", "beliefs", "links", "metrics"],
    "swarmloc.Frame")

SCENE_SCHEMA = _obj({
    "family": {"type": "string"}, "run": {"type": "string"}, "scenario": {"type": "string"},
    "bounds_m": {"type": "array", "items": _num(), "minItems": 4, "maxItems": 4},
    "walls": _arr({"type": "array", "items": _num(), "minItems": 4, "maxItems": 4}),
    "discs": _arr(_obj({"label": {"type": "string"}, "x": _num(), "y": _num(), "radius_m": _num(),
                        "colour": {"type": "string"}}, ["label", "x", "y", "radius_m"])),
    "landmarks": _arr(_obj({"id": {"type": "integer"}, "x": _num(), "y": _num()})),
    "robot_radius_m": _num(), "n_robots": {"type": "integer"}, "tick_s": _num(),
    "n_ticks": {"type": "integer"},
}, ["family", "bounds_m", "walls", "discs", "landmarks", "robot_radius_m", "n_robots", "tick_s"],
    "swarmloc.Scene")

def _foxglove_schemas() -> dict:
    """Foxglove's well-known JSON Schemas, as ``@foxglove/schemas`` 2.1.0 (MIT, generated by
    https://github.com/foxglove/foxglove-sdk) exports them in ``dist/jsonschema``: the schema text a
    recording declares for its Foxglove channels, and what tests/test_observe.py validates every
    Foxglove message of a recording against."""
    from importlib import resources

    return json.loads((resources.files("swarmloc.deploy.observe") / "foxglove_schemas.json").read_text())


FOXGLOVE_SCHEMAS = _foxglove_schemas()

SCHEMAS = {"swarmloc.Scene": SCENE_SCHEMA, "swarmloc.Frame": FRAME_SCHEMA, **FOXGLOVE_SCHEMAS}
#: Foxglove's channels: what its 3D panel draws (the frame channel holds the exact figures).
FOXGLOVE_TOPICS = {FOXGLOVE_TOPIC: "foxglove.SceneUpdate", TF_TOPIC: "foxglove.FrameTransforms",
                   ESTIMATES_TOPIC: "foxglove.PosesInFrame", SAMPLES_TOPIC: "foxglove.PosesInFrame"}
TOPIC_SCHEMAS = {SCENE_TOPIC: "swarmloc.Scene", FRAME_TOPIC: "swarmloc.Frame", **FOXGLOVE_TOPICS}
#: The frame channel is msgpack: its floats are the world's float64 bits, and it is written every
#: tick (msgpack packs a frame in a few microseconds; JSON took 130 us for 10 robots).
TOPIC_ENCODINGS = {SCENE_TOPIC: "json", FRAME_TOPIC: "msgpack", **dict.fromkeys(FOXGLOVE_TOPICS, "json")}
#: Foxglove's scene is for the eye: at most one per FOXGLOVE_PERIOD_S of simulated time.
FOXGLOVE_PERIOD_S = 0.5
WRITE_BUFFER_BYTES = 1 << 18
#: Simulated seconds per chunk: what a crash may lose, and the unit a reader seeks by.
CHUNK_S = 1.0
#: A chunk is also closed when its messages pass this size (a very large swarm's second).
CHUNK_BYTES = 8 << 20


# -- Foxglove scene ----------------------------------------------------------------------------

def _time(ns: int) -> dict:
    return {"sec": ns // 1_000_000_000, "nsec": ns % 1_000_000_000}


_ZERO = {"sec": 0, "nsec": 0}
_IDENTITY = {"position": {"x": 0.0, "y": 0.0, "z": 0.0}, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0}}
_TRUE = {"r": 0.84, "g": 0.15, "b": 0.16, "a": 1.0}
_DEAD = {"r": 0.4, "g": 0.4, "b": 0.4, "a": 1.0}
_EST = {"r": 0.12, "g": 0.47, "b": 0.71, "a": 0.6}
_BELIEF = {"r": 0.17, "g": 0.63, "b": 0.17, "a": 0.5}


def _pose(x: float, y: float, th: float, z: float = 0.0) -> dict:
    return {"position": {"x": x, "y": y, "z": z},
            "orientation": {"x": 0.0, "y": 0.0, "z": math.sin(th / 2), "w": math.cos(th / 2)}}


def foxglove_map(scene: dict) -> dict:
    """The static map as one Foxglove entity (walls as a line list, discs, landmarks)."""
    points = []
    for x1, y1, x2, y2 in scene["walls"]:
        points += [{"x": x1, "y": y1, "z": 0.0}, {"x": x2, "y": y2, "z": 0.0}]
    grey = {"r": 0.1, "g": 0.1, "b": 0.1, "a": 1.0}
    lines = [{"type": 2, "pose": _IDENTITY, "thickness": 0.02, "scale_invariant": False,
              "points": points, "color": grey, "colors": [], "indices": []}] if points else []
    cylinders = [{"pose": _pose(d["x"], d["y"], 0.0, 0.001),
                  "size": {"x": 2 * d["radius_m"], "y": 2 * d["radius_m"], "z": 0.002},
                  "bottom_scale": 1.0, "top_scale": 1.0, "color": {"r": 0.3, "g": 0.3, "b": 0.3, "a": 0.6}}
                 for d in scene["discs"]]
    cylinders += [{"pose": _pose(lm["x"], lm["y"], 0.0, 0.15), "size": {"x": 0.1, "y": 0.1, "z": 0.3},
                   "bottom_scale": 1.0, "top_scale": 1.0, "color": {"r": 0.5, "g": 0.3, "b": 0.7, "a": 1.0}}
                  for lm in scene["landmarks"]]
    return {"deletions": [], "entities": [{
        "timestamp": _ZERO, "frame_id": "world", "id": "map", "lifetime": _ZERO, "frame_locked": False,
        "metadata": [], "arrows": [], "cubes": [], "spheres": [], "cylinders": cylinders, "lines": lines,
        "triangles": [], "texts": [], "models": []}]}


def _arrow(x: float, y: float, th: float, length: float, colour: str) -> str:
    # Formatted by hand: this runs in the world's tick, and json.dumps of the nested dicts cost
    # ten times more. Four decimals (0.1 mm) are plenty for a picture.
    return ('{"pose":{"position":{"x":%.4f,"y":%.4f,"z":%.4f},"orientation":{"x":0,"y":0,"z":%.5f,"w":%.5f}},'
            '"shaft_length":%.4f,"shaft_diameter":%.4f,"head_length":%.4f,"head_diameter":%.4f,"color":%s}'
            % (x, y, length / 4, math.sin(th / 2), math.cos(th / 2), length, length / 3, length / 2,
               length / 1.5, colour))


def _colour(c: dict) -> str:
    return '{"r":%g,"g":%g,"b":%g,"a":%g}' % (c["r"], c["g"], c["b"], c["a"])


_TRUE_S, _DEAD_S, _EST_S, _BELIEF_S = (_colour(c) for c in (_TRUE, _DEAD, _EST, _BELIEF))


def foxglove_robots(frame: dict, radius_m: float, log_time_ns: int) -> bytes:
    """One tick's robots as a ``foxglove.SceneUpdate`` (JSON bytes): an arrow at each true pose
    (red, grey when dead), one at each own-pose estimate (blue), a flat sphere at each belief."""
    d = 2 * radius_m
    alive = frame["state"]["alive"]
    arrows = [_arrow(p[0], p[1], p[2], d, _TRUE_S if alive[i] else _DEAD_S)
              for i, p in enumerate(frame["truth"]) if _finite3(p)]
    arrows += [_arrow(e[0], e[1], e[2], d, _EST_S) for e in frame["estimates"] if _finite3(e)]
    spheres = ['{"pose":{"position":{"x":%.4f,"y":%.4f,"z":0},"orientation":{"x":0,"y":0,"z":0,"w":1}},'
               '"size":{"x":%.4f,"y":%.4f,"z":0.01},"color":%s}'
               % (m["x"], m["y"], max(2 * m["radius_m"], radius_m), max(2 * m["radius_m"], radius_m), _BELIEF_S)
               for marks in frame["beliefs"] for m in marks]
    t = _time(log_time_ns)
    return ('{"deletions":[],"entities":[{"timestamp":{"sec":%d,"nsec":%d},"frame_id":"world",'
            '"id":"robots","lifetime":{"sec":0,"nsec":0},"frame_locked":false,"metadata":[],'
            '"arrows":[%s],"cubes":[],"spheres":[%s],"cylinders":[],"lines":[],"triangles":[],'
            '"texts":[],"models":[]}]}' % (t["sec"], t["nsec"], ",".join(arrows), ",".join(spheres))).encode()


def _finite3(p) -> bool:
    return p is not None and math.isfinite(p[0]) and math.isfinite(p[1]) and math.isfinite(p[2])


def _pose_text(p) -> str:
    # By hand, like _arrow: four decimals (0.1 mm) for x and y, five for the quaternion.
    return ('{"position":{"x":%.4f,"y":%.4f,"z":0},"orientation":{"x":0,"y":0,"z":%.5f,"w":%.5f}}'
            % (p[0], p[1], math.sin(p[2] / 2), math.cos(p[2] / 2)))


def foxglove_transforms(frame: dict, log_time_ns: int) -> bytes:
    """One tick's ``foxglove.FrameTransforms`` (JSON bytes): ``world`` to ``robot_<i>`` at each
    robot's true pose (robots whose truth is unknown, a replay's before Vicon sees them, left out)."""
    t = _time(log_time_ns)
    stamp = '{"sec":%d,"nsec":%d}' % (t["sec"], t["nsec"])
    items = [('{"timestamp":%s,"parent_frame_id":"world","child_frame_id":"robot_%d",'
              '"translation":{"x":%.4f,"y":%.4f,"z":0},"rotation":{"x":0,"y":0,"z":%.5f,"w":%.5f}}'
              % (stamp, i, p[0], p[1], math.sin(p[2] / 2), math.cos(p[2] / 2)))
             for i, p in enumerate(frame["truth"]) if _finite3(p)]
    return ('{"transforms":[%s]}' % ",".join(items)).encode()


def foxglove_poses(poses, log_time_ns: int) -> bytes:
    """``foxglove.PosesInFrame`` (JSON bytes) of ``poses`` ([x, y, theta] or None) in ``world``."""
    t = _time(log_time_ns)
    return ('{"timestamp":{"sec":%d,"nsec":%d},"frame_id":"world","poses":[%s]}'
            % (t["sec"], t["nsec"], ",".join(_pose_text(p) for p in poses if _finite3(p)))).encode()


# -- writer ------------------------------------------------------------------------------------

_dumps = json.JSONEncoder(ensure_ascii=False, allow_nan=False, separators=(",", ":")).encode


def _finite(value):
    """JSON has no NaN: non-finite floats become null (a frame's NaN means 'unknown')."""
    if isinstance(value, float):
        return value if math.isfinite(value) else None
    if isinstance(value, list):
        return [_finite(v) for v in value]
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    return value


def dumps(obj) -> bytes:
    try:
        return _dumps(obj).encode()
    except ValueError:  # a NaN somewhere: the slow path, only then
        return _dumps(_finite(obj)).encode()


class RecordingWriter:
    """Writes one run: :meth:`scene` once, then :meth:`frame` per tick (and, with
    ``messages``, :meth:`sense` / :meth:`act` with the protocol's bytes)."""

    def __init__(self, path: str | Path, *, messages: bool = False, foxglove: bool = True,
                 metadata: dict | None = None, chunked: bool = True) -> None:
        self.path = Path(path)
        # A large buffer: one system call per quarter megabyte, not per message (a write per
        # message cost 95 us here). A crash loses at most that tail; the rest reads as whole messages.
        self._file = open(self.path, "wb", buffering=WRITE_BUFFER_BYTES)  # noqa: SIM115 -- closed in close()
        from mcap.writer import CompressionType, Writer  # only when recording: a world without
        # --record never imports mcap (it would add 0.1 s to its start)

        # chunked=False: the layout before issue 44 (one top-level record per message), kept for
        # benchmarks/bench_record.py's comparison.
        # lz4, not zstd: at 100 robots zstd made files 25 % smaller than lz4 but cost the writer
        # 1.2-1.3x the unchunked one's time per tick, lz4 1.1x (benchmarks/bench_record.py).
        self._w = Writer(self._file, use_chunking=chunked, chunk_size=CHUNK_BYTES,
                         compression=CompressionType.LZ4 if chunked else CompressionType.NONE,
                         enable_crcs=True)
        self.chunked = chunked
        self._next_chunk_ns = 0
        self._w.start(profile=PROFILE, library="swarmloc")
        ids = {name: self._w.register_schema(name=name, encoding="jsonschema", data=dumps(schema))
               for name, schema in SCHEMAS.items()}
        self._ch = {topic: self._w.register_channel(topic=topic, message_encoding=TOPIC_ENCODINGS[topic],
                                                     schema_id=ids[schema])
                    for topic, schema in TOPIC_SCHEMAS.items() if foxglove or topic not in FOXGLOVE_TOPICS}
        if messages:
            for topic in (SENSE_TOPIC, ACT_TOPIC):
                self._ch[topic] = self._w.register_channel(topic=topic, message_encoding=MSGPACK, schema_id=0)
        if metadata:
            self._w.add_metadata("swarmloc", {str(k): str(v) for k, v in metadata.items()})
        self.foxglove = foxglove
        self.messages = messages
        self.tick_ns = 0
        self.radius_m = 0.05
        self.frames = 0
        self._seq = 0
        self._next_foxglove_ns = 0
        self._pack = msgpack.Packer().pack

    def _add(self, topic: str, log_time_ns: int, data: bytes) -> None:
        self._seq += 1
        self._w.add_message(self._ch[topic], log_time=log_time_ns, data=data,
                            publish_time=log_time_ns, sequence=self._seq)

    def scene(self, scene: dict) -> None:
        self.tick_ns = round(scene["tick_s"] * 1e9)
        self.radius_m = scene["robot_radius_m"]
        self._add(SCENE_TOPIC, 0, dumps(scene))
        if self.foxglove:
            self._add(FOXGLOVE_TOPIC, 0, dumps(foxglove_map(scene)))

    def frame(self, frame: dict) -> None:
        t = frame["tick"] * self.tick_ns
        if self.chunked and t >= self._next_chunk_ns:
            # close the chunk of the last CHUNK_S and write it out: a crash loses at most this
            self._next_chunk_ns = t + round(CHUNK_S * 1e9)
            self._w.flush()
        self._add(FRAME_TOPIC, t, self._pack(frame))
        if self.foxglove and t >= self._next_foxglove_ns:
            self._next_foxglove_ns = t + round(FOXGLOVE_PERIOD_S * 1e9)
            self._add(FOXGLOVE_TOPIC, t, foxglove_robots(frame, self.radius_m, t))
            self._add(TF_TOPIC, t, foxglove_transforms(frame, t))
            self._add(ESTIMATES_TOPIC, t, foxglove_poses(frame["estimates"], t))
            samples = frame.get("samples")
            if samples:
                self._add(SAMPLES_TOPIC, t, foxglove_poses([p for own in samples for p in own], t))
        self.frames += 1

    def sense(self, tick: int, data: bytes) -> None:
        self._add(SENSE_TOPIC, tick * self.tick_ns, bytes(data))

    def act(self, tick: int, data: bytes) -> None:
        self._add(ACT_TOPIC, tick * self.tick_ns, bytes(data))

    def close(self) -> None:
        if self._file.closed:
            return
        self._w.finish()
        self._file.close()


# -- reader ------------------------------------------------------------------------------------

class RecordingError(ValueError):
    """A recording that cannot be read; the message says what and where."""


@dataclass
class Recording:
    """What a recording holds: the scene, every frame in order, and what was wrong with the file
    if it was cut short (``truncated``: a sentence, else None)."""

    path: Path
    scene: dict | None
    frames: list[dict]
    topics: dict[str, int] = field(default_factory=dict)  # messages per topic
    schemas: dict[str, str] = field(default_factory=dict)  # topic -> schema name
    encodings: dict[str, str] = field(default_factory=dict)  # topic -> message encoding
    truncated: str | None = None
    sense_act: list[tuple[str, int, bytes]] = field(default_factory=list)  # (topic, log ns, bytes)


class _Counting(io.RawIOBase):
    """A file that counts the bytes read from it (to say where a record went wrong)."""

    def __init__(self, f) -> None:
        self.f, self.offset = f, 0

    def readable(self) -> bool:
        return True

    def readinto(self, b) -> int:
        n = self.f.readinto(b)
        self.offset += n or 0
        return n

    def read(self, n: int = -1) -> bytes:
        data = self.f.read(n)
        self.offset += len(data)
        return data


def read_recording(path: str | Path, *, keep_messages: bool = False) -> Recording:
    """Read a swarmloc recording front to back.

    Raises :class:`RecordingError` naming the problem for a file that is not an MCAP file, that
    holds no ``swarmloc.Frame`` channel, whose channel has the wrong schema, or whose message is
    not valid JSON. A file cut short mid-record keeps every whole message before the cut and says
    so in :attr:`Recording.truncated`.
    """
    from mcap import records as R
    from mcap.exceptions import EndOfFile, InvalidMagic, McapError
    from mcap.stream_reader import StreamReader

    path = Path(path)
    try:
        raw = open(path, "rb")  # noqa: SIM115
    except OSError as exc:
        raise RecordingError(f"{path}: cannot open: {exc.strerror}") from None
    size = path.stat().st_size
    counting = _Counting(raw)
    schemas: dict[int, str] = {}
    channels: dict[int, tuple[str, str]] = {}  # id -> (topic, schema name)
    rec = Recording(path, None, [])
    footer = False
    n = 0
    try:
        reader = StreamReader(io.BufferedReader(counting, buffer_size=1 << 16), record_size_limit=1 << 28)
        try:
            for record in reader.records:
                if isinstance(record, R.Schema):
                    schemas[record.id] = record.name
                elif isinstance(record, R.Channel):
                    name = schemas.get(record.schema_id, "") if record.schema_id else ""
                    expected = TOPIC_SCHEMAS.get(record.topic)
                    encoding = TOPIC_ENCODINGS.get(record.topic)
                    if expected is not None and (name != expected or record.message_encoding != encoding):
                        raise RecordingError(
                            f"{path}: channel {record.topic} has schema {name!r} / encoding "
                            f"{record.message_encoding!r}; expected {expected!r} / {encoding!r}")
                    channels[record.id] = (record.topic, name)
                    rec.schemas[record.topic] = name
                    rec.encodings[record.topic] = record.message_encoding
                elif isinstance(record, R.Message):
                    n += 1
                    topic, _ = channels.get(record.channel_id, (None, None))
                    if topic is None:
                        raise RecordingError(f"{path}: message {n} is on channel {record.channel_id}, "
                                             f"which no Channel record declared")
                    rec.topics[topic] = rec.topics.get(topic, 0) + 1
                    if topic in (SCENE_TOPIC, FRAME_TOPIC):
                        try:
                            if topic == SCENE_TOPIC:
                                value = json.loads(record.data)
                            else:
                                value = msgpack.unpackb(record.data, strict_map_key=False)
                        except (ValueError, UnicodeDecodeError, msgpack.UnpackException) as exc:
                            raise RecordingError(
                                f"{path}: message {n} on {topic} (log time {record.log_time} ns) is "
                                f"not valid {TOPIC_ENCODINGS[topic]}: {type(exc).__name__}: {exc}") from None
                        if not isinstance(value, dict) or (topic == FRAME_TOPIC and not _is_frame(value)):
                            raise RecordingError(f"{path}: message {n} on {topic} is not a "
                                                 f"{TOPIC_SCHEMAS[topic]} (missing fields)")
                        if topic == SCENE_TOPIC:
                            rec.scene = value
                        else:
                            rec.frames.append(value)
                    elif keep_messages and topic in (SENSE_TOPIC, ACT_TOPIC):
                        rec.sense_act.append((topic, record.log_time, record.data))
                elif isinstance(record, R.Footer):
                    footer = True
        except InvalidMagic:
            if n == 0 and not schemas:
                raise RecordingError(f"{path}: not an MCAP file (its first bytes are not the MCAP "
                                     f"magic)") from None
            raise RecordingError(f"{path}: corrupt: bad closing magic after byte "
                                 f"{counting.offset} of {size}") from None
        except EndOfFile:
            if n == 0 and not schemas:
                raw.seek(0)
                if raw.read(len(MCAP_MAGIC)) == MCAP_MAGIC:
                    raise RecordingError(f"{path}: cut short at byte {size}, before its first whole "
                                         f"chunk: no frame to read") from None
                raise RecordingError(f"{path}: not an MCAP file: it ends at byte {size}, before "
                                     f"its first record") from None
            rec.truncated = (f"{path}: truncated at byte {size}: the file ends inside a record; "
                             f"kept the {len(rec.frames)} frames before it")
        except RecordingError:
            raise
        except (McapError, ValueError, KeyError, IndexError, EOFError, OverflowError, struct.error) as exc:
            what = type(exc).__name__
            rec.truncated = (f"{path}: corrupt record near byte {counting.offset} of {size} "
                             f"({what}: {exc}); kept the {len(rec.frames)} frames before it")
        else:
            if not footer:
                rec.truncated = f"{path}: truncated: no footer; kept the {len(rec.frames)} frames"
    finally:
        raw.close()
    if FRAME_TOPIC not in rec.schemas:
        raise RecordingError(f"{path}: no {FRAME_TOPIC} channel: not a swarmloc recording"
                             + (f" ({rec.truncated})" if rec.truncated else ""))
    if rec.scene is None:
        raise RecordingError(f"{path}: no scene message on {SCENE_TOPIC}")
    return rec


def rewrite(src: str | Path, dst: str | Path, *, chunked: bool = True) -> Recording:
    """``swarmloc record --recover SRC DST``: read ``src`` as far as it is whole (a file cut
    short by a crash keeps every chunk before the cut) and write what it holds to ``dst`` as a
    complete indexed file: the scene, every frame (the Foxglove channels made again from them),
    every Sense and Act. Returns what was read (``truncated`` says what was lost). ``chunked``
    False writes the layout before issue 44 (one record per message)."""
    rec = read_recording(src, keep_messages=True)
    if Path(dst).resolve() == Path(src).resolve():
        raise RecordingError(f"{dst}: the output must be another file than the input")
    writer = RecordingWriter(dst, messages=bool(rec.sense_act), foxglove=FOXGLOVE_TOPIC in rec.topics,
                             metadata={"recovered_from": str(src)}, chunked=chunked)
    try:
        writer.scene(rec.scene)
        pending = sorted(rec.sense_act, key=lambda m: m[1])
        k = 0
        for frame in rec.frames:
            t = frame["tick"] * writer.tick_ns
            while k < len(pending) and pending[k][1] <= t:
                topic, log_ns, data = pending[k]
                writer._add(topic, log_ns, data)
                k += 1
            writer.frame(frame)
        for topic, log_ns, data in pending[k:]:
            writer._add(topic, log_ns, data)
    finally:
        writer.close()
    return rec


_FRAME_KEYS = set(FRAME_SCHEMA["required"])


def _is_frame(value: dict) -> bool:
    return _FRAME_KEYS <= value.keys() and isinstance(value.get("tick"), int)
