"""Two independent readers of a ROS 2-format recording, for the tests: rclpy's deserializer
(the ROS 2 wheels' own type support; no DDS, no `rclpy.init`) and `rosbags` (its MCAP reader
and a type store built from the definitions the file carries)."""

from __future__ import annotations

from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from rclpy.serialization import deserialize_message
from rosbags.rosbag2.storage_mcap import McapReader
from rosbags.typesys import Stores, get_types_from_msg, get_typestore


def rclpy_class(ros_type: str) -> Any:
    """The rclpy message class of `pkg/msg/Name`."""
    pkg, _, name = ros_type.split("/")
    return getattr(__import__(f"{pkg}.msg", fromlist=[name]), name)


def rclpy_messages(path: Path) -> list[tuple[str, int, Any]]:
    """(topic, publish time, rclpy message) of every message, in file order."""
    out = []
    with path.open("rb") as f:
        for schema, channel, message in make_reader(f).iter_messages(log_time_order=False):
            assert schema is not None
            assert channel.message_encoding == "cdr"
            ros = deserialize_message(message.data, rclpy_class(schema.name))
            out.append((channel.topic, message.publish_time, ros))
    return out


def rosbags_messages(path: Path) -> list[tuple[str, str, Any]]:
    """(topic, ROS type, rosbags message) of every message, as rosbags reads the file."""
    reader = McapReader(path)
    reader.open()
    try:
        store = get_typestore(Stores.EMPTY)
        for conn in reader.connections:
            assert conn.msgdef.format.name == "MSG"
            store.register(get_types_from_msg(conn.msgdef.data, conn.msgtype))
        return [
            (conn.topic, conn.msgtype, store.deserialize_cdr(data, conn.msgtype))
            for conn, _, data in reader.messages(reader.connections)
        ]
    finally:
        reader.close()
