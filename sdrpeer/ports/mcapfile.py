"""Port recordings as MCAP files (the `mcap` package): what `sdrpeer port record` writes and
`sdrpeer port replay` reads; Foxglove and the ROS 2 tools open the same files.

How it works: one MCAP channel per recorded port, its topic `Instance.port`, its metadata the
instance, port, robot and type id. Its schema (encoding `jsonschema`, named after the port's
type id, `sdrpeer/any` for an untyped port) is a JSON Schema of the value: a typed value is an
array of its fields in order (`prefixItems`, each titled with the field's name), and the schema
carries the type id and the field list as `x-sdrpeer-type` and `x-sdrpeer-fields` as well. Each
message's data is the value's msgpack encoding (message encoding `msgpack`): a typed value is
the array of its fields, exactly as it travels between hosts, and bytes (an image's pixels) stay
bytes. Log time is when the agent's tap received the frame; publish time is the frame's own time
when it has one (a typed value's `stamp` field, an untyped map's `stamp` or `ts`, in seconds),
else the receive time; `sequence` is the frame's seq on the tap's connection. Messages are
written in the order they arrived and read back in file order, so a replay gives the same bytes
in the same order.
"""

from __future__ import annotations

import json
import struct
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import IO, Any

from mcap.exceptions import EndOfFile, McapError
from mcap.reader import NonSeekingReader, make_reader
from mcap.writer import Writer

from sdrpeer import __version__

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


class RecordingWriter:
    """Writes one MCAP recording."""

    def __init__(self, out: IO[bytes], chunk_size: int = 1024 * 1024) -> None:
        self._writer = Writer(out, chunk_size=chunk_size)
        self._writer.start(profile="", library=f"sdrpeer {__version__}")
        self._schemas: dict[str, int] = {}
        self.messages = 0
        self.bytes = 0

    def add_port(self, ref: str, type_id: str | None, fields: list[list[str]], robot: str) -> int:
        """Register a port's channel (and its type's schema, once); its channel id."""
        name = type_id or UNTYPED
        if name not in self._schemas:
            data = json.dumps(schema_for(type_id, fields), sort_keys=True).encode()
            self._schemas[name] = self._writer.register_schema(name, SCHEMA_ENCODING, data)
        instance, _, port = ref.rpartition(".")
        metadata = {"instance": instance, "port": port, "robot": robot, "type": type_id or ""}
        return self._writer.register_channel(
            ref, MESSAGE_ENCODING, self._schemas[name], metadata=metadata
        )

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


def recorded_channels(path: Path) -> dict[str, str]:
    """Topic -> schema name of every channel of a recording, from its summary (a file cut
    short, without one, is read through); ValueError naming the file when it is not MCAP."""
    try:
        with path.open("rb") as f:
            summary = make_reader(f).get_summary()
    except (McapError, struct.error):
        summary = None  # cut short (no footer): read through, which says what is wrong
    if summary is None:
        return {m.topic: m.schema for m in read_recording(path)}
    return {
        c.topic: summary.schemas[c.schema_id].name if c.schema_id in summary.schemas else UNTYPED
        for c in summary.channels.values()
    }


def read_recording(path: Path) -> Iterator[Recorded]:
    """Every message of a recording, in file order (the order they were recorded); a file cut
    short (a recording killed before it finished) gives the messages of its complete chunks.
    ValueError naming the file when it is not MCAP or a message is damaged."""
    with path.open("rb") as f:
        try:
            messages = NonSeekingReader(f).iter_messages(log_time_order=False)
            for schema, channel, message in messages:
                encoding = channel.message_encoding
                if encoding != MESSAGE_ENCODING:
                    raise ValueError(
                        f"{path}: channel {channel.topic!r} is {encoding!r}, "
                        f"not {MESSAGE_ENCODING!r}"
                    )
                yield Recorded(
                    channel.topic,
                    schema.name if schema is not None else UNTYPED,
                    message.log_time,
                    message.publish_time,
                    message.sequence,
                    message.data,
                )
        except (EndOfFile, struct.error):
            return  # cut short: what was written before is all there is
        except McapError as e:
            raise ValueError(f"{path}: not a readable MCAP recording: {e}") from None
