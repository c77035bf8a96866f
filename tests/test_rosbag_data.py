"""Robots' data as a ROS 2 bag, both ways (world/replay/rosbag.py, issue 44): a data set written
as a bag reads back equal, through our reader and through Foxglove's independent ROS 2 decoder
(``mcap-ros2-support``, which knows our message types only from the definitions in the bag); a
bag replays as the folder it came from; what cannot be used is refused naming topic and message."""

from __future__ import annotations

import dataclasses
import math
from collections import Counter
from pathlib import Path

import numpy as np
import pytest

pytest.importorskip("rosbags")

from swarmloc.deploy.lab.replay.mrclam import ReplayConfig, run_replay, score
from swarmloc.world.replay.mrclam import Measurements, MrclamFormatError, load_dataset
from swarmloc.world.replay.rosbag import read_rosbag2, write_rosbag2


@pytest.fixture(scope="module")
def bag(tmp_path_factory, synthetic):
    path = tmp_path_factory.mktemp("bags") / "synthetic"
    counts = write_rosbag2(synthetic, path)
    return path, counts


def _same_measurements(a: Measurements, b: Measurements) -> None:
    oa, ob = np.lexsort((a.subject, a.time_s)), np.lexsort((b.subject, b.time_s))
    np.testing.assert_allclose(a.time_s[oa], b.time_s[ob], atol=1e-6)
    np.testing.assert_array_equal(a.subject[oa], b.subject[ob])
    np.testing.assert_array_equal(a.range_m[oa], b.range_m[ob])
    np.testing.assert_array_equal(a.bearing_rad[oa], b.bearing_rad[ob])


def test_a_data_set_written_as_a_bag_reads_back_equal(bag, synthetic):
    path, counts = bag
    back = load_dataset(path)  # a bag folder is a data set folder
    assert back.robot_ids == synthetic.robot_ids and back.barcodes == synthetic.barcodes
    np.testing.assert_array_equal(back.landmarks.ids, synthetic.landmarks.ids)
    np.testing.assert_array_equal(back.landmarks.xy_m, synthetic.landmarks.xy_m)
    np.testing.assert_array_equal(back.landmarks.std_m, synthetic.landmarks.std_m)
    assert math.isclose(back.epoch_s, synthetic.epoch_s, abs_tol=1e-6)
    for rid in synthetic.robot_ids:
        a, b = back.robots[rid], synthetic.robots[rid]
        np.testing.assert_allclose(a.groundtruth_time_s, b.groundtruth_time_s, atol=1e-6)
        np.testing.assert_allclose(a.groundtruth_pose, b.groundtruth_pose, atol=1e-12)  # yaw via a quaternion
        np.testing.assert_allclose(a.odometry_time_s, b.odometry_time_s, atol=1e-6)
        np.testing.assert_array_equal(a.odometry_v_mps, b.odometry_v_mps)
        np.testing.assert_array_equal(a.odometry_omega_rad_s, b.odometry_omega_rad_s)
        _same_measurements(a.landmark_measurements, b.landmark_measurements)
        _same_measurements(a.robot_measurements, b.robot_measurements)
        assert counts[f"/robot_{rid}/range_bearing"] == len(b.landmark_measurements) + len(b.robot_measurements)


def test_foxgloves_decoder_reads_every_message_from_the_definitions_in_the_bag(bag, synthetic):
    from mcap.reader import make_reader
    from mcap_ros2.decoder import DecoderFactory

    path, counts = bag
    (mcap_file,) = path.glob("*.mcap")
    seen: Counter = Counter()
    first_reading = {}
    with open(mcap_file, "rb") as f:
        for _, channel, _, msg in make_reader(f, decoder_factories=[DecoderFactory()]).iter_decoded_messages():
            seen[channel.topic] += 1
            if channel.topic.endswith("range_bearing") and channel.topic not in first_reading:
                first_reading[channel.topic] = msg
            if channel.topic == "/landmarks":
                assert [m.id for m in msg.landmarks] == synthetic.landmarks.ids.tolist()
    assert dict(seen) == counts
    rid = synthetic.robot_ids[0]
    rec = synthetic.robots[rid]
    times = np.concatenate([rec.landmark_measurements.time_s, rec.robot_measurements.time_s])
    msg = first_reading[f"/robot_{rid}/range_bearing"]
    t_s = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9 - synthetic.epoch_s
    assert abs(t_s - times.min()) < 1e-6 and msg.range >= 0.0


def test_a_bag_replays_as_the_folder_it_came_from(bag, synthetic):
    config = ReplayConfig(algorithm="ekf", cooperative=True, duration_s=30.0, calibration="none")
    from_bag = score(run_replay(load_dataset(bag[0]), config))
    direct = score(run_replay(synthetic, config))
    for rid in synthetic.robot_ids:
        assert from_bag[rid]["position_rmse_m"] == pytest.approx(direct[rid]["position_rmse_m"], rel=1e-6, abs=1e-9)
        assert from_bag[rid]["scored_ticks"] == direct[rid]["scored_ticks"] > 100


def _spoilt(synthetic, tmp_path: Path, name: str, **robot_changes):
    rid = synthetic.robot_ids[0]
    robots = dict(synthetic.robots)
    robots[rid] = dataclasses.replace(robots[rid], **robot_changes)
    path = tmp_path / name
    write_rosbag2(dataclasses.replace(synthetic, robots=robots), path)
    return path, rid


def test_what_cannot_be_used_is_refused_naming_topic_and_message(tmp_path, synthetic):
    empty = np.zeros(0)
    path, rid = _spoilt(synthetic, tmp_path, "no-odometry", odometry_time_s=empty, odometry_v_mps=empty,
                        odometry_omega_rad_s=empty)
    with pytest.raises(MrclamFormatError, match=rf"robot {rid} has no odometry \(/robot_{rid}/cmd_vel"):
        read_rosbag2(path)
    m = synthetic.robots[synthetic.robot_ids[0]].landmark_measurements
    bad = Measurements(m.time_s, m.subject, np.where(np.arange(len(m)) == 3, -1.0, m.range_m), m.bearing_rad)
    path, rid = _spoilt(synthetic, tmp_path, "negative-range", landmark_measurements=bad)
    with pytest.raises(MrclamFormatError, match=rf"topic /robot_{rid}/range_bearing, message \d+: negative range -1.0"):
        read_rosbag2(path)
    path, rid = _spoilt(synthetic, tmp_path, "no-truth", groundtruth_time_s=empty, groundtruth_pose=np.zeros((0, 3)))
    with pytest.raises(MrclamFormatError, match=rf"robot {rid} has no /robot_{rid}/ground_truth message"):
        read_rosbag2(path)
    with pytest.raises(MrclamFormatError, match="not a readable rosbag2 folder"):
        (tmp_path / "broken").mkdir()
        (tmp_path / "broken" / "metadata.yaml").write_text("rosbag2_bagfile_information: {version: 9}\n")
        load_dataset(tmp_path / "broken")


def test_export_takes_data_both_ways_from_the_command_line(tmp_path, synthetic):
    from processes import run_swarmloc

    from swarmloc.world.replay.mrclam import write_dataset

    folder = write_dataset(synthetic, tmp_path / "Synthetic")
    done = run_swarmloc(["export", str(folder), "--to", "rosbag2", str(tmp_path / "bag")], cwd=tmp_path, timeout_s=300)
    assert done.returncode == 0, done.stderr
    done = run_swarmloc(["export", str(tmp_path / "bag"), "--to", "mrclam", str(tmp_path / "again")],
                        cwd=tmp_path, timeout_s=300)
    assert done.returncode == 0, done.stderr
    for name in ("Barcodes.dat", "Landmark_Groundtruth.dat", *(f"Robot{r}_{k}.dat" for r in synthetic.robot_ids
                                                               for k in ("Groundtruth", "Odometry", "Measurement"))):
        assert (tmp_path / "again" / name).read_bytes() == (folder / name).read_bytes(), name
    done = run_swarmloc(["export", str(tmp_path / "nothing.mcap"), "--to", "mrclam", str(tmp_path / "x")],
                        cwd=tmp_path, timeout_s=60)
    assert done.returncode != 0 and "--to mrclam takes a data set folder or a bag" in done.stderr


def test_a_topic_of_the_wrong_type_is_named_and_a_failed_write_leaves_nothing(tmp_path, synthetic):
    from rosbags.rosbag2 import StoragePlugin, Writer
    from rosbags.typesys import Stores, get_typestore

    store = get_typestore(Stores.ROS2_HUMBLE)
    path = tmp_path / "wrong-type"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/robot_1/cmd_vel", "std_msgs/msg/String", typestore=store)
        writer.write(conn, 1, store.serialize_cdr(store.types["std_msgs/msg/String"](data="go"), "std_msgs/msg/String"))
    with pytest.raises(MrclamFormatError, match=r"topic /robot_1/cmd_vel has type std_msgs/msg/String, expected "
                                                r"geometry_msgs/msg/TwistStamped"):
        load_dataset(path)
    # a bag of robots' topics without the landmark map
    path = tmp_path / "no-map"
    with Writer(path, version=9, storage_plugin=StoragePlugin.MCAP) as writer:
        conn = writer.add_connection("/robot_1/cmd_vel", "geometry_msgs/msg/TwistStamped", typestore=store)
        T = store.types
        msg = T["geometry_msgs/msg/TwistStamped"](
            header=T["std_msgs/msg/Header"](stamp=T["builtin_interfaces/msg/Time"](sec=1, nanosec=0), frame_id="r"),
            twist=T["geometry_msgs/msg/Twist"](linear=T["geometry_msgs/msg/Vector3"](x=0.1, y=0.0, z=0.0),
                                               angular=T["geometry_msgs/msg/Vector3"](x=0.0, y=0.0, z=0.0)))
        writer.write(conn, 1, store.serialize_cdr(msg, "geometry_msgs/msg/TwistStamped"))
    with pytest.raises(MrclamFormatError, match=r"no /landmarks message: the landmark map is needed"):
        load_dataset(path)
    # a data set that cannot be written (a subject id beyond int32) leaves no folder behind
    rid = synthetic.robot_ids[0]
    m = synthetic.robots[rid].landmark_measurements
    bad = Measurements(m.time_s, np.full(len(m), 2**40), m.range_m, m.bearing_rad)
    spoilt = dataclasses.replace(synthetic, robots={**synthetic.robots,
                                                    rid: dataclasses.replace(synthetic.robots[rid], landmark_measurements=bad)})
    with pytest.raises(Exception):  # noqa: B017 -- whichever error the CDR encoder raises
        write_rosbag2(spoilt, tmp_path / "half")
    assert not (tmp_path / "half").exists()
