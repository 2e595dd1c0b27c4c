"""The raw CDR decoders of the fixed-layout types (sdrpeer.ros2.cdr) read what rclpy serializes
exactly as rclpy's own deserializer and the type mapping read it, whatever the frame names'
lengths do to the alignment; a big-endian message too; a short one is a ValueError."""

from __future__ import annotations

import struct

import pytest
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry as RosOdometry
from rclpy.serialization import serialize_message

from sdrpeer.ros2.cdr import decoder_for
from sdrpeer.ros2.types import fill, from_ros, to_ros
from sdrpeer.sdk.robot_types import Image, Odometry, Pose, RangeScan, Velocity

FRAMES = ["", "m", "map", "odom", "base_link", "a_frame_name_of_seventeen"]


@pytest.mark.parametrize("frame", FRAMES)
@pytest.mark.parametrize("child", ["", "base", "base_footprint"])
def test_the_raw_decoders_read_what_rclpy_writes(frame: str, child: str) -> None:
    pose = Pose(1700000000.25, frame, 1.5, -2.0, 3.0, 0.1, 0.2, 0.6, 0.77)
    twist = Velocity(12.5, frame, 1.0, 2.0, 3.0, -4.0, -5.0, -6.0)
    odom = Odometry(
        42.125,
        frame,
        child,
        Pose(42.125, frame, 9.0, 8.0, 7.0, 0.0, 0.0, 0.0, 1.0),
        Velocity(42.125, child, 0.5, 0.25, 0.0, 0.0, 0.0, -0.75),
    )
    for value, cls in ((pose, PoseStamped), (twist, TwistStamped), (odom, RosOdometry)):
        msg = fill(cls(), to_ros(value))
        decode = decoder_for(type(value))
        assert decode is not None
        # as the type mapping reads rclpy's message (a stamp in float seconds keeps no exact
        # nanoseconds: both read the same integers the same way)
        assert decode(serialize_message(msg)) == from_ros(type(value), msg)


def test_a_big_endian_message_is_read_too() -> None:
    frame = b"map\x00"
    body = struct.pack(">iII", 5, 500_000_000, len(frame)) + frame
    body += b"\x00" * (-len(body) % 8)  # doubles align to 8 from the end of the header
    body += struct.pack(">7d", 1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0)
    decode = decoder_for(Pose)
    assert decode is not None
    assert decode(b"\x00\x00\x00\x00" + body) == Pose(5.5, "map", 1.0, 2.0, 3.0, 0.0, 0.0, 0.0, 1.0)


def test_a_short_or_cut_message_is_a_value_error() -> None:
    decode = decoder_for(Pose)
    assert decode is not None
    raw = serialize_message(fill(PoseStamped(), to_ros(Pose(1.0, "map", 1.0, 2.0))))
    with pytest.raises(ValueError, match="too short"):
        decode(raw[:10])
    with pytest.raises((ValueError, struct.error)):
        decode(raw[:-8])


def test_types_with_sequences_keep_rclpys_deserializer() -> None:
    assert decoder_for(RangeScan) is None
    assert decoder_for(Image) is None
    assert decoder_for(None) is None
