"""Typed port values as the channels of a rosbag2 MCAP recording, and back (pure; no ROS needed).

How it works: a recording in ROS 2 format (`sdrpeer port record --format ros2`) is what
rosbag2's MCAP storage writes: profile `ros2`, one channel per port with message encoding `cdr`,
its schema named after the ROS 2 type (`geometry_msgs/msg/PoseStamped`) with encoding `ros2msg`
and the type's full definition as data (sdrpeer.ros2.msgdefs, generated from the ROS wheels'
.msg files, so a robot without ROS records all the same). `RosCodec` turns a typed port's wire
value (the msgpack array of its fields, as the agent's tap gives it) into CDR bytes: the array
into the sdrpeer value (sdrpeer.sdk.typed), that into the ROS message's fields
(sdrpeer.ros2.types.to_ros), those into CDR (mcap-ros2-support's encoder); `decode` is the way
back, with the decoder built from the definition the file carries (a bag recorded by ROS itself
decodes with its own definitions). Only the mapped types have a codec (`codec_for`); an untyped
port or one of another type cannot be recorded in this format (`refusal` says which and what is
mapped).

Topics: port `Instance.port` is topic `/Instance/port` (`topic_for`); a character a ROS name
cannot hold (anything but letters, digits and `_`) becomes `_`, and a part that starts with a
digit gets a leading `_`. The channel's metadata keeps the port (`instance`, `port`), its robot
and its type id, so replay maps each channel back to its port; a channel without them (a bag
recorded by ROS) is known by its ROS topic, which `--map` must then point at a port.
"""

from __future__ import annotations

import re
from collections.abc import Callable, Iterable
from dataclasses import dataclass
from typing import Any, Final

from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

from sdrpeer.ros2.msgdefs import DEFINITIONS
from sdrpeer.ros2.types import MAPPED, RosMapping
from sdrpeer.sdk.typed import MessageType, message_type

__all__ = [
    "MESSAGE_ENCODING",
    "PROFILE",
    "SCHEMA_ENCODING",
    "RosCodec",
    "codec_for",
    "codec_for_ros",
    "mapped_names",
    "refusal",
    "topic_for",
]

PROFILE: Final = "ros2"
"""The MCAP profile rosbag2 writes."""
SCHEMA_ENCODING: Final = "ros2msg"
MESSAGE_ENCODING: Final = "cdr"
_NOT_NAME: Final = re.compile(r"[^A-Za-z0-9_]")


def topic_for(ref: str) -> str:
    """The ROS 2 topic of port `Instance.port`: `/Instance/port` (see the module's doc)."""
    parts = [_NOT_NAME.sub("_", part) or "_" for part in ref.rsplit(".", 1)]
    return "/" + "/".join(f"_{p}" if p[0].isdigit() else p for p in parts)


@dataclass(frozen=True, slots=True)
class RosCodec:
    """How one mapped type's wire values become CDR bytes and back."""

    mapping: RosMapping
    info: MessageType
    definition: str
    """The full `ros2msg` definition (the schema's data)."""
    _encode: Callable[[Any], bytes]
    _decode: Callable[[bytes], Any]

    @property
    def ros_type(self) -> str:
        """`pkg/msg/Name`."""
        return self.mapping.ros_type

    @property
    def type_id(self) -> str:
        """The sdrpeer type id (`sdrpeer/Pose#digest`)."""
        return self.info.type_id

    def encode(self, wire: Any) -> bytes:
        """A wire value (the array of its fields) as the CDR of its ROS 2 message;
        PortTypeError when it is not a value of this type."""
        value = self.info.decode(list(wire) if isinstance(wire, tuple) else wire)
        return bytes(self._encode(self.mapping.to_ros(value)))

    def decode(self, data: bytes) -> tuple[Any, ...]:
        """CDR bytes of the ROS 2 message as the wire value (nested tuples, as msgpack packs)."""
        return self.info.flat(self.mapping.from_ros(self._decode(data)))


def _codec(mapping: RosMapping, definition: str) -> RosCodec:
    info = message_type(mapping.cls)
    assert info is not None, mapping.cls  # every mapped type is a @message
    name = mapping.ros_type
    return RosCodec(
        mapping,
        info,
        definition,
        serialize_dynamic(name, definition)[name],
        generate_dynamic(name, definition)[name],
    )


_BY_TYPE_ID: Final[dict[str, RosMapping]] = {}
for _m in MAPPED.values():
    _info = message_type(_m.cls)
    if _info is not None:
        _BY_TYPE_ID[_info.type_id] = _m
_CODECS: dict[str, RosCodec] = {}


def codec_for(type_id: str | None) -> RosCodec | None:
    """The codec of a port's type id (built once), None when untyped or unmapped."""
    mapping = _BY_TYPE_ID.get(type_id or "")
    if mapping is None:
        return None
    codec = _CODECS.get(mapping.ros_type)
    if codec is None:
        codec = _CODECS[mapping.ros_type] = _codec(mapping, DEFINITIONS[mapping.ros_type])
    return codec


def codec_for_ros(ros_type: str, definition: str) -> RosCodec | None:
    """The codec of a ROS 2 type as a recording names it, decoding with the definition the
    recording carries; None when no sdrpeer type maps to it. ValueError (the parser's) when
    the definition cannot be read."""
    mapping = next((m for m in MAPPED.values() if m.ros_type == ros_type), None)
    if mapping is None:
        return None
    try:
        return _codec(mapping, definition)
    except (KeyError, IndexError, TypeError) as e:  # what the definition parser raises
        raise ValueError(f"its {ros_type} definition cannot be read: {e}") from None


def mapped_names() -> str:
    """What can be recorded in ROS 2 format: `Pose (geometry_msgs/msg/PoseStamped), ...`."""
    return ", ".join(f"{m.cls.__name__} ({m.ros_type})" for m in MAPPED.values())


def refusal(ports: Iterable[tuple[str, str | None]]) -> str | None:
    """Why ports `(ref, type id)` cannot be recorded in ROS 2 format, None when they can."""
    bad = [
        f"{ref} ({type_id or 'untyped'})" for ref, type_id in ports if codec_for(type_id) is None
    ]
    if not bad:
        return None
    return (
        f"--format ros2 records only ports of a type with a ROS 2 mapping; "
        f"{', '.join(bad)} {'has' if len(bad) == 1 else 'have'} none "
        f"(mapped: {mapped_names()}); record {'it' if len(bad) == 1 else 'them'} "
        f"with --format sdrpeer"
    )
