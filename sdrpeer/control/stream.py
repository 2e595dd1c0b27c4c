"""The control channel's framing, shared by both ends (the agent and each component host).

How it works: the channel is a stream of msgpack maps, each with a string "t" (docs/protocol.md).
`MessageStream.feed(bytes)` returns the complete maps received so far. Incoming bytes are fed to
the unpacker in pieces, so a message over the limit fails before it is buffered; each message's
size is measured exactly (`Unpacker.tell()`), so `max_message` bytes pass and one more fails.
Anything else — undecodable bytes, a value that is not a map, a map without a string "t" — raises
`ProtocolError`, and the caller closes the channel. The maps go on to the codec (codec.py), which
makes messages of them. Pure: no I/O, no clock. Kept free of heavy imports: the host process
imports it.
"""

from __future__ import annotations

from typing import Any

import msgpack

from sdrpeer.errors import ProtocolError

MAX_MESSAGE = 1 << 20
"""Largest control message accepted, in bytes."""
_PIECE = 64 * 1024
"""Incoming bytes are fed to the unpacker in pieces of at most this size (bounds its buffer)."""

Map = dict[str, Any]
"""One message as the framing delivers it (a map with a str "t"), before the codec reads it."""


class MessageStream:
    """Cuts a msgpack byte stream into maps with a string "t", enforcing the size limit."""

    def __init__(self, max_message: int = MAX_MESSAGE) -> None:
        self.max_message = max_message
        self._unpacker = msgpack.Unpacker(raw=False, max_buffer_size=max_message + _PIECE)
        self._offset = 0

    def feed(self, data: bytes) -> list[Map]:
        """Consume `data`; return the complete messages in it; raise ProtocolError."""
        out: list[Map] = []
        view = memoryview(data)
        for start in range(0, len(view), _PIECE):
            try:
                self._unpacker.feed(view[start : start + _PIECE])
            except msgpack.BufferFull:
                raise ProtocolError(f"message over the size limit {self.max_message}") from None
            self._drain(out)
        return out

    def _drain(self, out: list[Map]) -> None:
        while True:
            try:
                value = self._unpacker.unpack()
            except msgpack.OutOfData:
                return
            except Exception as exc:
                raise ProtocolError(f"undecodable msgpack: {type(exc).__name__}") from exc
            end = self._unpacker.tell()
            size, self._offset = end - self._offset, end
            if size > self.max_message:
                raise ProtocolError(
                    f"message of {size} bytes over the size limit {self.max_message}"
                )
            if not isinstance(value, dict):
                raise ProtocolError(f"expected a map, got {type(value).__name__}")
            if not isinstance(value.get("t"), str):
                raise ProtocolError("map without a str 't'")
            out.append(value)
