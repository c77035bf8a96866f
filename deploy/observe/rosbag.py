"""A recording as a ROS 2 bag (issue 44): ``swarmloc export RUN.mcap --to rosbag2 OUT``.

Users of the field's other tools record and exchange rosbag2; this writes one from any swarmloc
recording (any robot family), with standard message types and no ROS installation, on the
pure-Python ``rosbags`` package (rosbag2 version 9, MCAP storage, CDR, the ROS 2 Humble type
definitions rosbags ships):

- ``/tf`` (``tf2_msgs/msg/TFMessage``), every frame: ``world`` -> ``robot_<i>``, each robot's true
  pose (the recording's ``truth``);
- ``/robot_<i>/odom`` (``nav_msgs/msg/Odometry``), every frame: the robot's own pose belief
  (``estimates``), in frame ``world`` (an e-puck's is its dead reckoning laid in the world frame,
  as the recording holds it); no message at a tick where the robot had no belief;
- ``/swarmloc/estimates`` (``geometry_msgs/msg/PoseArray``), every frame: all beliefs at once, a
  robot without one as a NaN pose (PoseArray has no other way to keep the indices);
- ``/swarmloc/arena`` (``visualization_msgs/msg/MarkerArray``), once at time 0: the walls as a
  line list, the discs (nest, prey, ball, obstacles) as cylinders, the landmarks as spheres.

Stamps are simulated time (tick x tick length), as in the recording. What the recording does
not hold is not invented: the range-and-bearing observations (the frames keep who heard whom,
not the measured range and bearing) are not exported; the tests read every message back with
rosbags and with Foxglove's ROS 2 decoder (``mcap-ros2-support``).
"""

from __future__ import annotations

import math
import shutil
from pathlib import Path

ROS_DISTRO_TYPES = "ROS2_HUMBLE"
TF_TOPIC = "/tf"
ESTIMATES_TOPIC = "/swarmloc/estimates"
ARENA_TOPIC = "/swarmloc/arena"


def odom_topic(robot: int) -> str:
    return f"/robot_{robot}/odom"


def _quaternion(T, yaw_rad: float):
    return T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=math.sin(yaw_rad / 2.0), w=math.cos(yaw_rad / 2.0))


def export_rosbag2(recording: str | Path, out: str | Path) -> dict[str, int]:
    """Write the recording ``recording`` as the rosbag2 folder ``out`` (which must not exist);
    returns the messages written per topic. A folder half-written by an error is removed."""
    import numpy as np
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    from swarmloc.deploy.observe.record import RecordingError, read_recording

    out = Path(out)
    if out.exists():
        raise RecordingError(f"{out}: already exists (rosbag2 writes a new folder)")
    rec = read_recording(recording)
    store = get_typestore(getattr(Stores, ROS_DISTRO_TYPES))
    T = store.types
    tick_ns = round(rec.scene["tick_s"] * 1e9)
    n_robots = int(rec.scene.get("n_robots") or (len(rec.frames[0]["truth"]) if rec.frames else 0))

    def stamp(ns: int):
        return T["builtin_interfaces/msg/Time"](sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)

    def header(ns: int, frame_id: str = "world"):
        return T["std_msgs/msg/Header"](stamp=stamp(ns), frame_id=frame_id)

    def pose(x: float, y: float, yaw: float):
        return T["geometry_msgs/msg/Pose"](position=T["geometry_msgs/msg/Point"](x=float(x), y=float(y), z=0.0),
                                           orientation=_quaternion(T, float(yaw)))

    counts: dict[str, int] = {}
    try:
        with Writer(out, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
            def connection(topic: str, msgtype: str):
                return writer.add_connection(topic, msgtype, typestore=store)

            def write(conn, ns: int, msg, msgtype: str) -> None:
                writer.write(conn, ns, store.serialize_cdr(msg, msgtype))
                counts[conn.topic] = counts.get(conn.topic, 0) + 1

            c_tf = connection(TF_TOPIC, "tf2_msgs/msg/TFMessage")
            c_est = connection(ESTIMATES_TOPIC, "geometry_msgs/msg/PoseArray")
            c_arena = connection(ARENA_TOPIC, "visualization_msgs/msg/MarkerArray")
            c_odom = [connection(odom_topic(i), "nav_msgs/msg/Odometry") for i in range(n_robots)]
            write(c_arena, 0, _arena_markers(T, rec.scene, header(0)), "visualization_msgs/msg/MarkerArray")
            zero_cov = np.zeros(36)
            for frame in rec.frames:
                ns = frame["tick"] * tick_ns
                truth = frame.get("truth") or []
                tfs = [T["geometry_msgs/msg/TransformStamped"](
                    header=header(ns), child_frame_id=f"robot_{i}",
                    transform=T["geometry_msgs/msg/Transform"](
                        translation=T["geometry_msgs/msg/Vector3"](x=float(p[0]), y=float(p[1]), z=0.0),
                        rotation=_quaternion(T, float(p[2]))))
                    for i, p in enumerate(truth)]
                write(c_tf, ns, T["tf2_msgs/msg/TFMessage"](transforms=tfs), "tf2_msgs/msg/TFMessage")
                estimates = frame.get("estimates") or []
                poses = [pose(*e) if e is not None else pose(math.nan, math.nan, math.nan) for e in estimates]
                write(c_est, ns, T["geometry_msgs/msg/PoseArray"](header=header(ns), poses=poses),
                      "geometry_msgs/msg/PoseArray")
                for i, e in enumerate(estimates[:n_robots]):
                    if e is None:
                        continue
                    odom = T["nav_msgs/msg/Odometry"](
                        header=header(ns), child_frame_id=f"robot_{i}",
                        pose=T["geometry_msgs/msg/PoseWithCovariance"](pose=pose(*e), covariance=zero_cov),
                        twist=T["geometry_msgs/msg/TwistWithCovariance"](
                            twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0),
                                                              angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)),
                            covariance=zero_cov))
                    write(c_odom[i], ns, odom, "nav_msgs/msg/Odometry")
    except BaseException:
        shutil.rmtree(out, ignore_errors=True)
        raise
    return counts


def _arena_markers(T, scene: dict, head):
    """The scene's walls (one line list), discs (cylinders) and landmarks (spheres)."""
    import numpy as np

    Marker = T["visualization_msgs/msg/Marker"]
    Point = T["geometry_msgs/msg/Point"]
    Vector3 = T["geometry_msgs/msg/Vector3"]

    def colour(hex_text: str | None, alpha: float = 1.0):
        h = (hex_text or "#888888").lstrip("#")
        r, g, b = (int(h[k:k + 2], 16) / 255.0 for k in (0, 2, 4))
        return T["std_msgs/msg/ColorRGBA"](r=r, g=g, b=b, a=alpha)

    def marker(mid: int, kind: int, ns: str, x: float, y: float, scale, points=(), rgba=None):
        return Marker(header=head, ns=ns, id=mid, type=kind, action=0,
                      pose=T["geometry_msgs/msg/Pose"](position=Point(x=float(x), y=float(y), z=0.0),
                                                       orientation=T["geometry_msgs/msg/Quaternion"](x=0.0, y=0.0, z=0.0, w=1.0)),
                      scale=scale, color=rgba or colour(None),
                      lifetime=T["builtin_interfaces/msg/Duration"](sec=0, nanosec=0), frame_locked=False,
                      points=list(points), colors=[], texture_resource="",
                      texture=T["sensor_msgs/msg/CompressedImage"](header=head, format="", data=np.zeros(0, np.uint8)),
                      uv_coordinates=[], text="", mesh_resource="",
                      mesh_file=T["visualization_msgs/msg/MeshFile"](filename="", data=np.zeros(0, np.uint8)),
                      mesh_use_embedded_materials=False)

    markers = []
    walls = scene.get("walls") or []
    if walls:
        pts = [Point(x=float(v[0]), y=float(v[1]), z=0.0) for w in walls for v in ((w[0], w[1]), (w[2], w[3]))]
        markers.append(marker(0, 5, "walls", 0.0, 0.0, Vector3(x=0.02, y=0.0, z=0.0), pts))  # LINE_LIST
    for k, disc in enumerate(scene.get("discs") or []):
        d = 2.0 * float(disc["radius_m"])
        markers.append(marker(100 + k, 3, str(disc.get("label", "disc")), disc["x"], disc["y"],
                              Vector3(x=d, y=d, z=0.01), rgba=colour(disc.get("colour"))))  # CYLINDER
    for k, mark in enumerate(scene.get("landmarks") or []):
        x, y = (mark["x"], mark["y"]) if isinstance(mark, dict) else (mark[0], mark[1])
        markers.append(marker(1000 + k, 2, "landmarks", x, y, Vector3(x=0.1, y=0.1, z=0.1)))  # SPHERE
    return T["visualization_msgs/msg/MarkerArray"](markers=markers)
