"""Port recordings as MCAP files (the `mcap` package): what `sdrpeer port record` writes and
`sdrpeer port replay` reads, in two formats: `sdrpeer` (below; Foxglove shows it as JSON-like
data) and `ros2` (rosbag2's own: `ros2msg` schemas, `cdr` messages, sdrpeer.ros2.bag), which
rosbag2, rclpy, `rosbags` and Foxglove's ROS panels decode.

How it works (format `sdrpeer`): one MCAP channel per recorded port, its topic `Instance.port`,
its metadata the instance, port, robot and type id. Its schema (encoding `jsonschema`, named
after the port's type id, `sdrpeer/any` for an untyped port) is a JSON Schema of the value: a
typed value is an array of its fields in order (`prefixItems`, each titled with the field's
name), and the schema carries the type id and the field list as `x-sdrpeer-type` and
`x-sdrpeer-fields` as well. Each message's data is the value's msgpack encoding (message
encoding `msgpack`): a typed value is the array of its fields, exactly as it travels between
hosts, and bytes (an image's pixels) stay bytes. Log time is when the agent's tap received the
frame; publish time is the frame's own time when it has one (a typed value's `stamp` field, an
untyped map's `stamp` or `ts`, in seconds), else the receive time; `sequence` is the frame's seq
on the tap's connection. Messages are written in the order they arrived and read back in file
order, so a replay gives the same bytes in the same order.

Format `ros2`: one channel per port of a mapped type (topic `/Instance/port`, the same metadata),
its messages the CDR of the ROS 2 message (sdrpeer.ros2.bag); times and sequence as above.
Reading tells the formats apart by each channel's message encoding and gives every message as
the `sdrpeer` format does (`Recorded.data` the msgpack of the value's field array, `schema` its
type id), so replay is the same for both; a channel of another encoding, or `cdr` of a type
without a mapping, makes the file unreadable as a recording (`recorded_channels` says so before
anything is replayed).
"""

from __future__ import annotations

import json
import struct
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

import msgpack
from mcap.exceptions import EndOfFile, McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.records import Channel, Schema
from mcap.writer import Writer

from sdrpeer import __version__
from sdrpeer.ros2 import bag

FORMATS = ("sdrpeer", "ros2")
"""What `record --format` takes; the first is the default."""
SCHEMA_ENCODING = "jsonschema"
MESSAGE_ENCODING = "msgpack"
UNTYPED = "sdrpeer/any"
"""The schema name of an untyped port's channel."""
_JSON_TYPES: dict[str, dict[str, Any]] = {
    "float": {"type": "number"},
    "int": {"type": "integer"},
    "bool": {"type": "boolean"},
    "str": {"type": "string"},
    "bytes": {"description": "msgpack bin"},
    "list[float]": {"type": "array", "items": {"type": "number"}},
    "list[int]": {"type": "array", "items": {"type": "integer"}},
    "list[str]": {"type": "array", "items": {"type": "string"}},
    "any": {},
}


def schema_for(type_id: str | None, fields: list[list[str]]) -> dict[str, Any]:
    """The JSON Schema of a port's values (see the module's doc)."""
    if type_id is None:
        return {"title": UNTYPED, "x-sdrpeer-type": None, "x-sdrpeer-fields": []}
    items = [
        {"title": name, **_JSON_TYPES.get(kind, {"x-sdrpeer-type": kind})} for name, kind in fields
    ]
    return {
        "title": type_id,
        "type": "array",
        "prefixItems": items,
        "items": False,
        "x-sdrpeer-type": type_id,
        "x-sdrpeer-fields": fields,
    }


def publish_ns(value: Any, fields: list[list[str]], received: int) -> int:
    """The frame's own time in ns (a `stamp` field, or an untyped map's `stamp`/`ts`), else
    `received`."""
    stamp: Any = None
    if fields and isinstance(value, list) and len(value) == len(fields):
        names = [f[0] for f in fields]
        if "stamp" in names:
            stamp = value[names.index("stamp")]
    elif not fields and isinstance(value, dict):
        stamp = value.get("stamp", value.get("ts"))
    if isinstance(stamp, int | float) and not isinstance(stamp, bool) and stamp > 0:
        return int(stamp * 1e9)
    return received


def refusal(fmt: str, ports: list[tuple[str, str | None]]) -> str | None:
    """Why ports `(ref, type id)` cannot be recorded in format `fmt`, None when they can."""
    if fmt not in FORMATS:
        return f"--format {fmt!r}: expected one of {', '.join(FORMATS)}"
    return bag.refusal(ports) if fmt == "ros2" else None


class RecordingWriter:
    """Writes one MCAP recording in format `fmt` (`sdrpeer` or `ros2`)."""

    def __init__(self, out: IO[bytes], chunk_size: int = 1024 * 1024, fmt: str = "sdrpeer") -> None:
        self._ros2 = fmt == "ros2"
        self._writer = Writer(out, chunk_size=chunk_size)
        profile = bag.PROFILE if self._ros2 else ""
        self._writer.start(profile=profile, library=f"sdrpeer {__version__}")
        self._schemas: dict[str, int] = {}
        self._encoders: dict[int, Callable[[Any], bytes]] = {}
        self._pack = msgpack.Packer().pack
        self.messages = 0
        self.bytes = 0

    def add_port(self, ref: str, type_id: str | None, fields: list[list[str]], robot: str) -> int:
        """Register a port's channel (and its type's schema, once); its channel id. In format
        `ros2`, ValueError for a port of a type without a ROS 2 mapping."""
        instance, _, port = ref.rpartition(".")
        metadata = {"instance": instance, "port": port, "robot": robot, "type": type_id or ""}
        if not self._ros2:
            name = type_id or UNTYPED
            if name not in self._schemas:
                data = json.dumps(schema_for(type_id, fields), sort_keys=True).encode()
                self._schemas[name] = self._writer.register_schema(name, SCHEMA_ENCODING, data)
            channel = self._writer.register_channel(
                ref, MESSAGE_ENCODING, self._schemas[name], metadata=metadata
            )
            self._encoders[channel] = self._pack
            return channel
        codec = bag.codec_for(type_id)
        if codec is None:
            raise ValueError(bag.refusal([(ref, type_id)]))
        if codec.ros_type not in self._schemas:
            self._schemas[codec.ros_type] = self._writer.register_schema(
                codec.ros_type, bag.SCHEMA_ENCODING, codec.definition.encode()
            )
        channel = self._writer.register_channel(
            bag.topic_for(ref),
            bag.MESSAGE_ENCODING,
            self._schemas[codec.ros_type],
            metadata=metadata,
        )
        self._encoders[channel] = codec.encode
        return channel

    def encode(self, channel: int, value: Any) -> bytes:
        """A value (as the tap gives it) as the message data of `channel`: its msgpack, or in
        format `ros2` the CDR of its ROS 2 message (PortTypeError: not a value of the type)."""
        return self._encoders[channel](value)

    def write(self, channel: int, log_ns: int, publish: int, seq: int, data: bytes) -> None:
        """Add one message."""
        self._writer.add_message(channel, log_ns, data, publish, seq & 0xFFFFFFFF)
        self.messages += 1
        self.bytes += len(data)

    def finish(self) -> None:
        """Write the summary and the footer (the file is complete only then)."""
        self._writer.finish()  # type: ignore[no-untyped-call]


@dataclass(frozen=True, slots=True)
class Recorded:
    """One message read back."""

    topic: str
    """'Instance.port'."""
    schema: str
    """The port's type id, or `sdrpeer/any`."""
    log_time: int
    publish_time: int
    sequence: int
    data: bytes
    """The value's msgpack encoding."""


@dataclass(frozen=True, slots=True)
class _Reading:
    """How one channel of a recording reads back."""

    topic: str
    """The port ('Instance.port'), or a bag's ROS topic when the channel does not name one."""
    schema: str
    """The type id, or `sdrpeer/any`."""
    decode: Callable[[bytes], bytes] | None
    """Message data -> the value's msgpack (None: the data is that already)."""


def _reading(path: Path, schema: Schema | None, channel: Channel) -> _Reading:
    """How `channel` reads back; ValueError naming the file and the channel when it cannot."""
    encoding = channel.message_encoding
    if encoding == MESSAGE_ENCODING:
        return _Reading(channel.topic, schema.name if schema is not None else UNTYPED, None)
    where = f"{path}: channel {channel.topic!r}"
    if encoding != bag.MESSAGE_ENCODING or schema is None or schema.encoding != "ros2msg":
        kind = "no schema" if schema is None else f"schema encoding {schema.encoding!r}"
        raise ValueError(
            f"{where} is {encoding!r} with {kind}: a recording is {MESSAGE_ENCODING!r} with "
            f"{SCHEMA_ENCODING!r} schemas (format sdrpeer) or {bag.MESSAGE_ENCODING!r} with "
            f"{bag.SCHEMA_ENCODING!r} schemas (format ros2)"
        )
    try:
        codec = bag.codec_for_ros(schema.name, schema.data.decode("utf-8", "replace"))
    except ValueError as e:
        raise ValueError(f"{where}: {e}") from None
    if codec is None:
        raise ValueError(
            f"{where} is {schema.name}, which no sdrpeer type maps to "
            f"(mapped: {bag.mapped_names()})"
        )
    meta = channel.metadata
    ref = f"{meta['instance']}.{meta['port']}" if meta.get("instance") and meta.get("port") else ""
    pack = msgpack.Packer().pack

    def decode(data: bytes) -> bytes:
        try:
            return pack(codec.decode(data))  # type: ignore[no-any-return]
        except Exception as e:  # whatever the CDR decoder makes of bad bytes
            raise ValueError(f"{where}: a message is not a {schema.name}: {e!r:.80}") from None

    return _Reading(ref or channel.topic, codec.type_id, decode)


def recorded_channels(path: Path) -> dict[str, str]:
    """Port (or a bag's ROS topic) -> type id (`sdrpeer/any` untyped) of every channel of a
    recording of either format, from its summary (a file cut short, without one, is read
    through); ValueError naming the file when it is not MCAP or not a recording (see the
    module's doc)."""
    try:
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
    except (McapError, struct.error):
        summary = None  # cut short (no footer): read through, which says what is wrong
    if summary is None:
        return {m.topic: m.schema for m in read_recording(path)}
    readings = [
        _reading(path, summary.schemas.get(c.schema_id), c) for c in summary.channels.values()
    ]
    return {r.topic: r.schema for r in readings}


def is_ros2(path: Path) -> bool:
    """Whether a recording is in format `ros2` (its profile, or a `cdr` channel)."""
    with path.open("rb") as f:
        try:
            reader = make_reader(f)
            if reader.get_header().profile == bag.PROFILE:
                return True
            summary = reader.get_summary()
        except (McapError, struct.error):
            return False
    if summary is None:
        return False
    return any(c.message_encoding == bag.MESSAGE_ENCODING for c in summary.channels.values())


def read_recording(path: Path) -> Iterator[Recorded]:
    """Every message of a recording of either format, in file order (the order they were
    recorded), its data the value's msgpack; a file cut short (a recording killed before it
    finished) gives the messages of its complete chunks. ValueError naming the file when it is
    not MCAP or not a recording, or a message is damaged."""
    readings: dict[int, _Reading] = {}
    with path.open("rb") as f:
        try:
            messages = NonSeekingReader(f).iter_messages(log_time_order=False)
            for schema, channel, message in messages:
                reading = readings.get(channel.id)
                if reading is None:
                    reading = readings[channel.id] = _reading(path, schema, channel)
                data = message.data if reading.decode is None else reading.decode(message.data)
                yield Recorded(
                    reading.topic,
                    reading.schema,
                    message.log_time,
                    message.publish_time,
                    message.sequence,
                    data,
                )
        except (EndOfFile, struct.error):
            return  # cut short: what was written before is all there is
        except McapError as e:
            raise ValueError(f"{path}: not a readable MCAP recording: {e}") from None
