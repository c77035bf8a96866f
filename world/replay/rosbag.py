"""Robots' data as a ROS 2 bag, both ways (issue 44: bring your own robots' data).

The real-data family replays data sets in MRCLAM's layout (:mod:`swarmloc.world.replay.mrclam`).
A team that logs its own robots with ROS 2 has rosbag2 folders instead; this module reads one into
the same :class:`~swarmloc.world.replay.mrclam.MrclamDataset`, so every command that takes a data
set folder takes a bag folder (``load_dataset`` sees ``metadata.yaml`` and comes here), and writes
any data set as such a bag (``swarmloc export DATASET --to rosbag2 OUT``), so the same data travels
both ways. Pure Python on the ``rosbags`` package (``pip install 'swarmloc[ros]'``), no ROS
installation; MCAP storage, CDR.

The bag's layout (``<r>`` is a robot's subject id, e.g. ``/robot_1/...``):

- ``/robot_<r>/cmd_vel`` (``geometry_msgs/msg/TwistStamped``): the velocity commands the robot's
  odometry is (``linear.x`` m/s, ``angular.z`` rad/s), held until the next one, as MRCLAM's
  odometry files hold them. A bag with ``nav_msgs/msg/Odometry`` on ``/robot_<r>/odom`` instead is
  read too (its ``twist``); a robot needs one of the two;
- ``/robot_<r>/ground_truth`` (``geometry_msgs/msg/PoseStamped``, frame ``world``): the robot's
  true pose, planar (x, y, yaw from the quaternion). At least one message, the initial pose
  (the family's "no ground truth but the first pose" setting needs no more); more are used for
  scoring only;
- ``/robot_<r>/range_bearing`` (``swarmloc_msgs/msg/RangeBearing``): one reading of the robot's
  camera: ``subject`` (a landmark's or another robot's id), ``range`` (m), ``bearing`` (rad,
  counter-clockwise from the robot's heading). A reading of an AprilTag detection maps to it as
  ``subject`` = the tag's id, ``range`` = the tag's distance in the camera's ground plane,
  ``bearing`` = ``atan2`` of its lateral and forward offsets;
- ``/landmarks`` (``swarmloc_msgs/msg/LandmarkMap``), once: each landmark's ``id``, position
  ``x``, ``y`` (m, frame ``world``) and their standard deviations ``x_std``, ``y_std``;
- ``/barcodes`` (``swarmloc_msgs/msg/SubjectCodes``), optional: MRCLAM's subject -> barcode
  table (written so that a bag converts back to the identical MRCLAM folder; without it every
  subject is its own code).

The ``swarmloc_msgs`` definitions (:data:`MSG_DEFINITIONS`) are stored in the bag, so readers
without swarmloc (Foxglove's ``mcap-ros2-support``, rosbags) decode it; the tests read it back with
both. Stamps are absolute (the data set's ``epoch_s`` + its relative times), nanoseconds.
What a bag cannot say is not invented: MRCLAM readings of barcodes that its table does not list
(``RobotRecord.unknown_barcodes``) have no subject and are not written.
"""

from __future__ import annotations

import math
import shutil
from collections import defaultdict
from pathlib import Path

import numpy as np

from swarmloc.world.replay.mrclam import (
    Landmarks,
    Measurements,
    MrclamDataset,
    MrclamFormatError,
    RobotRecord,
)

ROS_DISTRO_TYPES = "ROS2_HUMBLE"
LANDMARKS_TOPIC = "/landmarks"
BARCODES_TOPIC = "/barcodes"

#: The message types of readings ROS has no standard message for, as ``.msg`` text.
MSG_DEFINITIONS = {
    "swarmloc_msgs/msg/RangeBearing": "std_msgs/Header header\nint32 subject\nfloat64 range\nfloat64 bearing\n",
    "swarmloc_msgs/msg/Landmark": "int32 id\nfloat64 x\nfloat64 y\nfloat64 x_std\nfloat64 y_std\n",
    "swarmloc_msgs/msg/LandmarkMap": "std_msgs/Header header\nswarmloc_msgs/Landmark[] landmarks\n",
    "swarmloc_msgs/msg/SubjectCodes": "int32[] subjects\nint32[] codes\n",
}


def robot_topic(robot: int, what: str) -> str:
    """``/robot_<robot>/<what>``."""
    return f"/robot_{robot}/{what}"


def is_rosbag2(path: str | Path) -> bool:
    """Whether ``path`` is a rosbag2 folder (it holds ``metadata.yaml``)."""
    return (Path(path) / "metadata.yaml").is_file()


def _typestore():
    try:
        from rosbags.typesys import Stores, get_types_from_msg, get_typestore
    except ImportError:
        raise MrclamFormatError("reading or writing a ROS 2 bag needs the rosbags package: "
                                "pip install 'swarmloc[ros]'") from None
    store = get_typestore(getattr(Stores, ROS_DISTRO_TYPES))
    types = {}
    for name, text in MSG_DEFINITIONS.items():
        types.update(get_types_from_msg(text, name))
    store.register(types)
    return store


def _ns(epoch_s: float, time_s: float) -> int:
    return round((epoch_s + float(time_s)) * 1e9)


def write_rosbag2(dataset: MrclamDataset, out: str | Path) -> dict[str, int]:
    """Write ``dataset`` as the rosbag2 folder ``out`` (replaced if it exists; removed again if
    writing fails); returns the messages written per topic."""
    store = _typestore()
    T = store.types
    out = Path(out)
    if out.exists():
        shutil.rmtree(out)
    try:
        return _write(dataset, out, store, T)
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)  # nothing half-written is left behind
        raise


def _write(dataset: MrclamDataset, out: Path, store, T) -> dict[str, int]:
    from rosbags.rosbag2 import StoragePlugin, Writer

    counts: dict[str, int] = defaultdict(int)

    def stamp(ns: int):
        return T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def header(ns: int, frame: str):
        return T["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame)

    Vector3 = T["geometry_msgs/msg/Vector3"]
    epoch = dataset.epoch_s
    first_ns = _ns(epoch, 0.0)
    with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conns = {}

        def write(topic: str, msgtype: str, ns: int, msg) -> None:
            if topic not in conns:
                conns[topic] = writer.add_connection(topic, msgtype, typestore=store)
            writer.write(conns[topic], ns, store.serialize_cdr(msg, msgtype))
            counts[topic] += 1

        lm = dataset.landmarks
        marks = [T["swarmloc_msgs/msg/Landmark"](id=int(i), x=float(x), y=float(y), x_std=float(sx), y_std=float(sy))
                 for i, (x, y), (sx, sy) in zip(lm.ids, lm.xy_m, lm.std_m, strict=True)]
        write(LANDMARKS_TOPIC, "swarmloc_msgs/msg/LandmarkMap", first_ns,
              T["swarmloc_msgs/msg/LandmarkMap"](header=header(first_ns, "world"), landmarks=marks))
        subjects = sorted(dataset.barcodes)
        write(BARCODES_TOPIC, "swarmloc_msgs/msg/SubjectCodes", first_ns, T["swarmloc_msgs/msg/SubjectCodes"](
            subjects=np.array(subjects, np.int32), codes=np.array([dataset.barcodes[s] for s in subjects], np.int32)))
        for r, rec in dataset.robots.items():
            frame = f"robot_{r}"
            for t, (x, y, yaw) in zip(rec.groundtruth_time_s, rec.groundtruth_pose, strict=True):
                ns = _ns(epoch, t)
                pose = T["geometry_msgs/msg/Pose"](
                    position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
                    orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw / 2.0),
                                                                  w=math.cos(yaw / 2.0)))
                write(robot_topic(r, "ground_truth"), "geometry_msgs/msg/PoseStamped", ns,
                      T["geometry_msgs/msg/PoseStamped"](header=header(ns, "world"), pose=pose))
            for t, v, w in zip(rec.odometry_time_s, rec.odometry_v_mps, rec.odometry_omega_rad_s, strict=True):
                ns = _ns(epoch, t)
                twist = T["geometry_msgs/msg/Twist"](linear=Vector3(x=float(v), y=0.0, z=0.0),
                                                     angular=Vector3(x=0.0, y=0.0, z=float(w)))
                write(robot_topic(r, "cmd_vel"), "geometry_msgs/msg/TwistStamped", ns,
                      T["geometry_msgs/msg/TwistStamped"](header=header(ns, frame), twist=twist))
            meas = [rec.landmark_measurements, rec.robot_measurements]
            time_s = np.concatenate([m.time_s for m in meas])
            subject = np.concatenate([m.subject for m in meas])
            range_m = np.concatenate([m.range_m for m in meas])
            bearing = np.concatenate([m.bearing_rad for m in meas])
            for k in np.argsort(time_s, kind="stable"):
                ns = _ns(epoch, time_s[k])
                write(robot_topic(r, "range_bearing"), "swarmloc_msgs/msg/RangeBearing", ns,
                      T["swarmloc_msgs/msg/RangeBearing"](header=header(ns, frame), subject=int(subject[k]),
                                                          range=float(range_m[k]), bearing=float(bearing[k])))
    return dict(counts)


def _robot_of(topic: str) -> tuple[int, str] | None:
    parts = topic.strip("/").split("/")
    if len(parts) != 2 or not parts[0].startswith("robot_"):
        return None
    try:
        return int(parts[0][len("robot_"):]), parts[1]
    except ValueError:
        return None


#: The types this module reads, by topic (a robot's topics by their last part).
_TYPES = {
    LANDMARKS_TOPIC: {"swarmloc_msgs/msg/LandmarkMap"},
    BARCODES_TOPIC: {"swarmloc_msgs/msg/SubjectCodes"},
    "ground_truth": {"geometry_msgs/msg/PoseStamped"},
    "cmd_vel": {"geometry_msgs/msg/TwistStamped"},
    "odom": {"nav_msgs/msg/Odometry"},
    "range_bearing": {"swarmloc_msgs/msg/RangeBearing"},
}


def _expected_type(topic: str) -> set[str] | None:
    if topic in _TYPES:
        return _TYPES[topic]
    robot = _robot_of(topic)
    return _TYPES.get(robot[1]) if robot is not None else None


def _yaw(q) -> float:
    return math.atan2(2.0 * (q.w * q.z + q.x * q.y), 1.0 - 2.0 * (q.y * q.y + q.z * q.z))


def read_rosbag2(path: str | Path, name: str | None = None) -> MrclamDataset:
    """Read a rosbag2 folder in this module's layout as a data set. Raises
    :class:`~swarmloc.world.replay.mrclam.MrclamFormatError` naming the topic (and the message's
    index in it) for what cannot be used: no robot, a robot without odometry or ground truth,
    a non-finite number, a negative range, a landmark id listed twice or shared with a robot."""
    from rosbags.rosbag2 import Reader

    path = Path(path)
    store = _typestore()
    rows: dict[tuple[int, str], list] = defaultdict(list)
    landmarks = None
    codes: dict[int, int] = {}
    try:
        reader = Reader(path)
        reader.open()
    except Exception as exc:  # noqa: BLE001 -- rosbags' errors are many classes
        raise MrclamFormatError(f"{path}: not a readable rosbag2 folder ({exc})") from None
    try:
        from rosbags.typesys import get_types_from_msg

        for conn in reader.connections:
            want = _expected_type(conn.topic)
            if want is not None and conn.msgtype not in want:
                raise MrclamFormatError(f"{path.name}: topic {conn.topic} has type {conn.msgtype}, "
                                        f"expected {' or '.join(sorted(want))} (docs/mrclam/bags.md)")
            if conn.msgtype not in store.types and conn.msgdef:  # a type the bag defines: its definition
                store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        seen: dict[str, int] = defaultdict(int)
        for conn, ns, raw in reader.messages():
            topic = conn.topic
            index = seen[topic]
            seen[topic] += 1
            where = f"{path.name}: topic {topic}, message {index}"
            try:
                msg = store.deserialize_cdr(raw, conn.msgtype)
            except Exception as exc:  # noqa: BLE001 -- a malformed message: name it
                raise MrclamFormatError(f"{where}: does not decode as {conn.msgtype} ({exc})") from None
            if topic == LANDMARKS_TOPIC:
                if landmarks is not None:
                    raise MrclamFormatError(f"{where}: a second landmark map (give one)")
                landmarks = [(m.id, m.x, m.y, m.x_std, m.y_std) for m in msg.landmarks]
                continue
            if topic == BARCODES_TOPIC:
                codes = {int(s): int(c) for s, c in zip(msg.subjects, msg.codes, strict=True)}
                continue
            robot = _robot_of(topic)
            if robot is None:
                continue  # a topic of the user's own: not ours to read
            r, what = robot
            t_s = (msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9) if hasattr(msg, "header") else ns * 1e-9
            if what == "ground_truth":
                p = msg.pose
                values = (t_s, p.position.x, p.position.y, _yaw(p.orientation))
            elif what == "cmd_vel":
                values = (t_s, msg.twist.linear.x, msg.twist.angular.z)
            elif what == "odom":
                values = (t_s, msg.twist.twist.linear.x, msg.twist.twist.angular.z)
            elif what == "range_bearing":
                if msg.range < 0.0:
                    raise MrclamFormatError(f"{where}: negative range {msg.range}")
                values = (t_s, msg.subject, msg.range, msg.bearing)
            else:
                continue
            if not all(math.isfinite(v) for v in values):
                raise MrclamFormatError(f"{where}: a value is not finite: {values}")
            rows[(r, what)].append(values)
    finally:
        reader.close()
    return _dataset(path, name, rows, landmarks, codes)


def _dataset(path: Path, name, rows, landmarks, codes) -> MrclamDataset:
    robots_seen = sorted({r for r, _ in rows})
    if not robots_seen:
        raise MrclamFormatError(f"{path}: no /robot_<id>/... topics: no robot to replay")
    if landmarks is None:
        raise MrclamFormatError(f"{path}: no {LANDMARKS_TOPIC} message: the landmark map is needed")
    lm = np.array(landmarks, dtype=np.float64).reshape(-1, 5)
    lm_ids = lm[:, 0].astype(np.int64)
    uniq, counts = np.unique(lm_ids, return_counts=True)
    if np.any(counts > 1):
        raise MrclamFormatError(f"{path.name}: topic {LANDMARKS_TOPIC}: landmark {uniq[counts > 1][0]} is listed twice")
    clash = set(lm_ids.tolist()) & set(robots_seen)
    if clash:
        raise MrclamFormatError(f"{path.name}: subject {min(clash)} is both a landmark and a robot (/robot_{min(clash)})")

    def table(r: int, what: str, width: int) -> np.ndarray:
        t = np.array(rows.get((r, what), []), dtype=np.float64).reshape(-1, width)
        return t[np.argsort(t[:, 0], kind="stable")]

    tables = {}
    for r in robots_seen:
        gt = table(r, "ground_truth", 4)
        odo = table(r, "cmd_vel", 3) if (r, "cmd_vel") in rows else table(r, "odom", 3)
        if gt.shape[0] == 0:
            raise MrclamFormatError(f"{path.name}: robot {r} has no {robot_topic(r, 'ground_truth')} message "
                                    f"(its initial pose comes from the first)")
        if odo.shape[0] == 0:
            raise MrclamFormatError(f"{path.name}: robot {r} has no odometry ({robot_topic(r, 'cmd_vel')} "
                                    f"or {robot_topic(r, 'odom')})")
        tables[r] = (gt, odo, table(r, "range_bearing", 4))
    epoch = min(float(gt[0, 0]) for gt, _, _ in tables.values())
    robot_set, landmark_set = set(robots_seen), set(lm_ids.tolist())
    robots = {}
    for r, (gt, odo, meas) in tables.items():
        subject = meas[:, 1].astype(np.int64)
        all_meas = Measurements(meas[:, 0] - epoch, subject, meas[:, 2].copy(), meas[:, 3].copy())
        robots[r] = RobotRecord(
            robot_id=r, groundtruth_time_s=gt[:, 0] - epoch, groundtruth_pose=gt[:, 1:4].copy(),
            odometry_time_s=odo[:, 0] - epoch, odometry_v_mps=odo[:, 1].copy(), odometry_omega_rad_s=odo[:, 2].copy(),
            landmark_measurements=all_meas.take(np.isin(subject, list(landmark_set))),
            robot_measurements=all_meas.take(np.isin(subject, list(robot_set - {r}))))
    barcodes = codes or {int(s): int(s) for s in sorted(landmark_set | robot_set)}
    return MrclamDataset(name=name or path.name, epoch_s=epoch, barcodes=barcodes,
                         landmarks=Landmarks(lm_ids, lm[:, 1:3].copy(), lm[:, 3:5].copy()), robots=robots)
