"""Typed values as rosbag2 channels (sdrpeer.ros2.bag) and recordings in ROS 2 format
(sdrpeer.ports.mcapfile): every mapped type's CDR decodes with rclpy and with rosbags to the
value, and back; the shipped definitions are the ROS wheels' own; topic names; a file that is
not a recording of either format is refused by name before anything is read out."""

from __future__ import annotations

import importlib.util
import math
import sys
from pathlib import Path
from typing import Any

import msgpack
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer
from rclpy.serialization import deserialize_message
from rosbags.typesys import Stores, get_types_from_msg, get_typestore

from sdrpeer.ports.mcapfile import (
    RecordingWriter,
    is_ros2,
    read_recording,
    recorded_channels,
    refusal,
)
from sdrpeer.ros2.bag import codec_for, topic_for
from sdrpeer.ros2.msgdefs import DEFINITIONS
from sdrpeer.ros2.types import MAPPED
from sdrpeer.sdk.robot_types import BatteryState, Image, Odometry, Pose, RangeScan, Velocity
from sdrpeer.sdk.typed import message_type
from tests.ros2_readers import rclpy_class, rclpy_messages, rosbags_messages

_SPEC = importlib.util.spec_from_file_location(
    "gen_ros2_msgdefs", Path(__file__).resolve().parent.parent / "tools" / "gen_ros2_msgdefs.py"
)
assert _SPEC is not None
assert _SPEC.loader is not None
_GEN = importlib.util.module_from_spec(_SPEC)
_SPEC.loader.exec_module(_GEN)
full_text = _GEN.full_text


VALUES: list[Any] = [
    Pose(1.5, "map", 1.0, 2.0, 3.0, 0.0, 0.0, 0.6, 0.8),
    Velocity(2.25, "base", 0.5, 0.0, 0.0, 0.0, 0.0, 0.1),
    Odometry(3.0, "odom", "base", Pose(3.0, "odom", 4.0, 5.0), Velocity(3.0, "base", 0.25)),
    RangeScan(4.0, "laser", -1.0, 0.5, 0.25, 10.0, [1.0, 2.5, 3.0]),  # float32 there: exact
    Image(5.0, "cam", 2, 2, "mono8", 2, b"\x01\x02\x03\x04"),
    BatteryState(6.0, 12.5, -1.25, 50.0, True),
]


def _wire(value: Any) -> Any:
    info = message_type(type(value))
    assert info is not None
    return msgpack.unpackb(msgpack.packb(info.flat(value)))  # as the tap gives it


@pytest.mark.parametrize("value", VALUES, ids=lambda v: type(v).__name__)
def test_each_mapped_type_decodes_with_rclpy_and_rosbags_and_comes_back(value: Any) -> None:
    info = message_type(type(value))
    assert info is not None
    codec = codec_for(info.type_id)
    assert codec is not None
    data = codec.encode(_wire(value))
    ros = deserialize_message(data, rclpy_class(codec.ros_type))
    assert MAPPED[type(value)].from_ros(ros) == value
    store = get_typestore(Stores.EMPTY)
    store.register(get_types_from_msg(codec.definition, codec.ros_type))
    assert MAPPED[type(value)].from_ros(store.deserialize_cdr(data, codec.ros_type)) == value
    back = msgpack.unpackb(msgpack.packb(codec.decode(data)))
    assert info.decode(back) == value


def test_an_unmapped_or_untyped_port_has_no_codec_and_the_refusal_names_it() -> None:
    assert codec_for(None) is None
    assert codec_for("sdrpeer/Pose#00000000") is None  # another layout of the name
    why = refusal("ros2", [("A.out", None), ("B.pose", "mylab/Thing#1234abcd")])
    assert why is not None
    assert "A.out (untyped), B.pose (mylab/Thing#1234abcd) have none" in why
    assert "Pose (geometry_msgs/msg/PoseStamped)" in why
    assert "Odometry (nav_msgs/msg/Odometry)" in why
    assert refusal("ros2", [("C.pose", message_type(Pose).type_id)]) is None  # type: ignore[union-attr]
    assert refusal("sdrpeer", [("A.out", None)]) is None


@pytest.mark.parametrize(
    ("ref", "topic"),
    [
        ("Odom.pose", "/Odom/pose"),
        ("cam-1.image", "/cam_1/image"),
        ("2nd.out", "/_2nd/out"),
        ("a.b.c", "/a_b/c"),
    ],
)
def test_topic_names_are_ros_names(ref: str, topic: str) -> None:
    assert topic_for(ref) == topic


def test_the_shipped_definitions_are_the_ros_wheels_own() -> None:
    share = Path(sys.prefix) / "share"
    for ros_type, text in DEFINITIONS.items():
        assert full_text(ros_type, share) == text
    odom = DEFINITIONS["nav_msgs/msg/Odometry"]
    assert odom.startswith((share / "nav_msgs/msg/Odometry.msg").read_text())
    assert "\n" + "=" * 80 + "\nMSG: std_msgs/Header\n" in odom
    assert odom.count("MSG: builtin_interfaces/Time\n") == 1  # each dependency once


def _ros2_file(path: Path, n: int) -> list[Pose]:
    sent = [Pose(float(i + 1), "map", float(i), 0.5) for i in range(n)]
    with path.open("wb") as f:
        writer = RecordingWriter(f, fmt="ros2")
        channel = writer.add_port("Odo.pose", message_type(Pose).type_id, [], "robot-1")  # type: ignore[union-attr]
        for i, pose in enumerate(sent):
            data = writer.encode(channel, _wire(pose))
            writer.write(channel, 1000 + i, int(pose.stamp * 1e9), i + 1, data)
        writer.finish()
    return sent


def test_a_ros2_recording_is_rosbag2s_and_reads_back_as_the_sdrpeer_format(tmp_path):
    path = tmp_path / "r.mcap"
    sent = _ros2_file(path, 5)
    with path.open("rb") as f:
        reader = make_reader(f)
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary is not None
        [channel] = summary.channels.values()
        schema = summary.schemas[channel.schema_id]
    assert (channel.topic, channel.message_encoding) == ("/Odo/pose", "cdr")
    assert (schema.name, schema.encoding) == ("geometry_msgs/msg/PoseStamped", "ros2msg")
    assert schema.data.decode() == DEFINITIONS["geometry_msgs/msg/PoseStamped"]
    assert channel.metadata["instance"] == "Odo"
    assert channel.metadata["port"] == "pose"
    by_rosbags = rosbags_messages(path)
    assert [(t, r) for t, r, _ in by_rosbags] == [
        ("/Odo/pose", "geometry_msgs/msg/PoseStamped")
    ] * 5
    assert [MAPPED[Pose].from_ros(m) for *_, m in by_rosbags] == sent
    by_rclpy = rclpy_messages(path)
    assert [MAPPED[Pose].from_ros(m) for *_, m in by_rclpy] == sent
    assert [p for _, p, _ in by_rclpy] == [int(s.stamp * 1e9) for s in sent]
    assert is_ros2(path)
    pose_id = message_type(Pose).type_id  # type: ignore[union-attr]
    assert recorded_channels(path) == {"Odo.pose": pose_id}
    got = list(read_recording(path))
    assert [(m.topic, m.schema) for m in got] == [("Odo.pose", pose_id)] * 5
    assert [Pose(*msgpack.unpackb(m.data)) for m in got] == sent


def _foreign(path: Path, encoding: str, schema_name: str, schema_encoding: str, text: str) -> None:
    with path.open("wb") as f:
        writer = Writer(f)
        writer.start(profile="ros2", library="test")
        sid = writer.register_schema(schema_name, schema_encoding, text.encode())
        cid = writer.register_channel("/thing", encoding, sid)
        writer.add_message(cid, 1, b"\x00\x01\x00\x00\x03\x00\x00\x00hi\x00", 1, 0)
        writer.finish()


def test_a_file_of_another_kind_is_refused_by_name(tmp_path):
    json_file = tmp_path / "json.mcap"
    _foreign(json_file, "json", "Thing", "jsonschema", "{}")
    with pytest.raises(
        ValueError, match=r"channel '/thing' is 'json' with schema encoding 'jsonschema'"
    ):
        recorded_channels(json_file)
    string = tmp_path / "string.mcap"
    _foreign(string, "cdr", "std_msgs/msg/String", "ros2msg", "string data\n")
    with pytest.raises(
        ValueError, match=r"std_msgs/msg/String, which no sdrpeer type maps to \(mapped: Pose"
    ):
        recorded_channels(string)
    with pytest.raises(ValueError, match="which no sdrpeer type maps to"):
        list(read_recording(string))


def test_a_damaged_message_of_a_ros2_recording_is_an_error_naming_the_file(tmp_path):
    path = tmp_path / "r.mcap"
    _ros2_file(path, 3)
    damaged = tmp_path / "damaged.mcap"
    with path.open("rb") as f, damaged.open("wb") as out:
        reader = make_reader(f)
        writer = Writer(out)
        writer.start(profile="ros2", library="test")
        summary = reader.get_summary()
        assert summary is not None
        [channel] = summary.channels.values()
        schema = summary.schemas[channel.schema_id]
        sid = writer.register_schema(schema.name, schema.encoding, schema.data)
        cid = writer.register_channel(channel.topic, "cdr", sid, dict(channel.metadata))
        for i, (_, _, m) in enumerate(reader.iter_messages()):
            writer.add_message(cid, m.log_time, m.data[: 10 if i == 2 else None], m.publish_time, i)
        writer.finish()
    assert set(recorded_channels(damaged)) == {"Odo.pose"}  # the summary is fine
    got = read_recording(damaged)
    next(got), next(got)
    with pytest.raises(ValueError, match=r"damaged.mcap: channel '/Odo/pose': a message is not a"):
        next(got)


def test_a_battery_percentage_is_a_fraction_there(tmp_path):
    codec = codec_for(message_type(BatteryState).type_id)  # type: ignore[union-attr]
    assert codec is not None
    ros = deserialize_message(codec.encode(_wire(VALUES[-1])), rclpy_class(codec.ros_type))
    assert math.isclose(ros.percentage, 0.5)
    assert ros.power_supply_status == 1
