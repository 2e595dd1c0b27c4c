"""Serialized (CDR) ROS 2 messages of the fixed-layout standard types read straight into sdrpeer
values, without rclpy's message objects (pure).

How it works: a `FromRos` bridge of `Pose`, `Velocity` or `Odometry` subscribes to the raw
bytes DDS delivers and decodes them here, in rclpy's thread: one `struct` unpack per block
instead of building rclpy's Python message (and its nested messages) and reading it back field by
field, which took most of a bridge's time per message. The layout is XCDR1 as ROS 2's rmw
implementations write it: a 4-byte encapsulation header (its second byte 1: little-endian, 0:
big-endian), then the fields, each aligned to its own size counted from the end of that header
(a string: a uint32 length with its terminating NUL, the bytes, no alignment of its own). Types
with sequences (`RangeScan`, `Image`) or many optional fields (`BatteryState`) keep rclpy's own
deserializer (`decoder_for` is None for them). Bytes that are not such a message are a ValueError.
"""

from __future__ import annotations

import struct
from collections.abc import Callable
from typing import Any, Final

from sdrpeer.sdk.robot_types import Odometry, Pose, Velocity

__all__ = ["decoder_for"]

_HEAD: Final = 4
_STAMP = {"<": struct.Struct("<iI"), ">": struct.Struct(">iI")}
_U32 = {"<": struct.Struct("<I"), ">": struct.Struct(">I")}
_POSE = {"<": struct.Struct("<7d"), ">": struct.Struct(">7d")}
_TWIST = {"<": struct.Struct("<6d"), ">": struct.Struct(">6d")}
_COVARIANCE: Final = 36 * 8


def _order(data: bytes) -> str:
    if len(data) < _HEAD + 12:
        raise ValueError(f"a serialized message of {len(data)} bytes is too short")
    return "<" if data[1] == 1 else ">"


def _string(data: bytes, at: int, order: str) -> tuple[str, int]:
    """The string at `at` (aligned to 4 first) and where the field after it starts."""
    at += -(at - _HEAD) % 4
    (n,) = _U32[order].unpack_from(data, at)
    start = at + 4
    end = start + n
    if n == 0 or end > len(data):
        raise ValueError("a string runs past the end of the message")
    return data[start : end - 1].decode("utf-8", "replace"), end


def _align8(at: int) -> int:
    return at + (-(at - _HEAD) % 8)


def _header(data: bytes, order: str) -> tuple[float, str, int]:
    sec, nanosec = _STAMP[order].unpack_from(data, _HEAD)
    frame, at = _string(data, _HEAD + 8, order)
    return sec + nanosec * 1e-9, frame, at


def _pose(data: bytes) -> Pose:
    order = _order(data)
    stamp, frame, at = _header(data, order)
    x, y, z, qx, qy, qz, qw = _POSE[order].unpack_from(data, _align8(at))
    return Pose(stamp, frame, x, y, z, qx, qy, qz, qw)


def _velocity(data: bytes) -> Velocity:
    order = _order(data)
    stamp, frame, at = _header(data, order)
    vx, vy, vz, wx, wy, wz = _TWIST[order].unpack_from(data, _align8(at))
    return Velocity(stamp, frame, vx, vy, vz, wx, wy, wz)


def _odometry(data: bytes) -> Odometry:
    order = _order(data)
    stamp, frame, at = _header(data, order)
    child, at = _string(data, at, order)
    at = _align8(at)
    x, y, z, qx, qy, qz, qw = _POSE[order].unpack_from(data, at)
    at += 7 * 8 + _COVARIANCE
    vx, vy, vz, wx, wy, wz = _TWIST[order].unpack_from(data, at)
    return Odometry(
        stamp,
        frame,
        child,
        Pose(stamp, frame, x, y, z, qx, qy, qz, qw),
        Velocity(stamp, child, vx, vy, vz, wx, wy, wz),
    )


_DECODERS: Final[dict[type, Callable[[bytes], Any]]] = {
    Pose: _pose,
    Velocity: _velocity,
    Odometry: _odometry,
}


def decoder_for(kind: type | None) -> Callable[[bytes], Any] | None:
    """The raw decoder of a standard type with a fixed layout (ValueError for bytes that are
    not one), None for the others."""
    decode = None if kind is None else _DECODERS.get(kind)
    if decode is None:
        return None

    def checked(data: bytes) -> Any:
        try:
            return decode(data)
        except struct.error as exc:
            raise ValueError(f"not a serialized {kind.__name__ if kind else ''}: {exc}") from None

    return checked
