"""ROS 2 bags out (deploy/observe/rosbag.py, issue 44): a recording exported as rosbag2 is read
back by rosbags and by Foxglove's ROS 2 decoder (mcap-ros2-support, an implementation of its
own), every message decoding to the recorded poses."""

from __future__ import annotations

import math

import numpy as np
import pytest

from swarmloc.deploy.cli import main as cli
from swarmloc.deploy.observe.batch_record import run_batch_recorded
from swarmloc.deploy.observe.record import read_recording
from swarmloc.deploy.scenario import load_scenario


@pytest.fixture(scope="module")
def exported(tmp_path_factory):
    folder = tmp_path_factory.mktemp("bag")
    recording = folder / "es1.mcap"
    run_batch_recorded(load_scenario("ES1", ["world.robots=3", "world.duration_s=4.0"]), recording)
    out = folder / "bag"
    assert cli(["export", str(recording), "--to", "rosbag2", str(out)]) == 0
    return read_recording(recording), out


def _yaw(q) -> float:
    return 2.0 * math.atan2(q.z, q.w)


def test_rosbags_reads_the_recorded_poses(exported):
    from rosbags.rosbag2 import Reader
    from rosbags.typesys import Stores, get_typestore

    rec, out = exported
    store = get_typestore(Stores.ROS2_HUMBLE)
    tf, odom = [], {}
    with Reader(out) as reader:
        topics = {c.topic: c.msgtype for c in reader.connections}
        assert topics["/tf"] == "tf2_msgs/msg/TFMessage" and topics["/robot_0/odom"] == "nav_msgs/msg/Odometry"
        assert topics["/swarmloc/arena"] == "visualization_msgs/msg/MarkerArray"
        for conn, stamp_ns, raw in reader.messages():
            msg = store.deserialize_cdr(raw, conn.msgtype)
            if conn.topic == "/tf":
                tf.append((stamp_ns, [[t.transform.translation.x, t.transform.translation.y,
                                       _yaw(t.transform.rotation)] for t in msg.transforms]))
            elif conn.topic.endswith("/odom"):
                odom.setdefault(conn.topic, []).append([msg.pose.pose.position.x, msg.pose.pose.position.y])
            elif conn.topic == "/swarmloc/arena":
                assert {m.ns for m in msg.markers} == {"walls", "nest", "prey"}
    assert len(tf) == len(rec.frames)
    tick_ns = round(rec.scene["tick_s"] * 1e9)
    for (stamp_ns, poses), frame in zip(tf, rec.frames, strict=True):
        assert stamp_ns == frame["tick"] * tick_ns
        truth = np.array(frame["truth"])
        np.testing.assert_allclose(np.array(poses)[:, :2], truth[:, :2], rtol=0, atol=1e-12)
        np.testing.assert_allclose(np.cos(np.array(poses)[:, 2] - truth[:, 2]), 1.0, atol=1e-12)
    beliefs = [f["estimates"][1] for f in rec.frames if f["estimates"][1] is not None]
    np.testing.assert_allclose(np.array(odom["/robot_1/odom"]), np.array(beliefs)[:, :2], rtol=0, atol=1e-12)


def test_foxgloves_ros2_decoder_reads_every_message(exported):
    from mcap_ros2.reader import read_ros2_messages

    rec, out = exported
    (bag,) = out.glob("*.mcap")
    counts: dict[str, int] = {}
    last_tf = None
    for m in read_ros2_messages(str(bag)):
        counts[m.channel.topic] = counts.get(m.channel.topic, 0) + 1
        if m.channel.topic == "/tf":
            last_tf = m.ros_msg
    assert counts["/tf"] == counts["/swarmloc/estimates"] == len(rec.frames)
    assert counts["/swarmloc/arena"] == 1
    final = rec.frames[-1]["truth"]
    assert [[t.transform.translation.x, t.transform.translation.y] for t in last_tf.transforms] == \
        [[p[0], p[1]] for p in final]


def test_export_refuses_an_existing_folder_and_leaves_nothing_half_written(exported, tmp_path, capsys):
    rec, out = exported
    assert cli(["export", str(rec.path), "--to", "rosbag2", str(out)]) == 2
    assert "already exists" in capsys.readouterr().err
    bad = tmp_path / "not.mcap"
    bad.write_bytes(b"nothing")
    target = tmp_path / "bag"
    assert cli(["export", str(bad), "--to", "rosbag2", str(target)]) == 2
    assert not target.exists()
