"""Values too big for one control message travel as `part` messages (docs/protocol.md, section 1).

How it works: a control message is at most 1 MiB; a component's state may be bigger (the agent
allows 16 MiB by default). The sender encodes the value with msgpack once, cuts the bytes into
`PART_SIZE` pieces (`parts`: `Part` messages, `{"t": "part", "of": ID, "data": piece}` on the wire)
and writes them right before the message they belong to, in the same write, so nothing comes between
them: the command `{"id": ID, ...}` (agent to host) or the `reply` to command ID (host to agent).
That message carries `"size"`, the total number of bytes. The receiver's `PartAssembler` collects
one transfer at a time (a part of another id drops the unfinished one), holds at most the limit it
is given (past it, the transfer is remembered as too big and its bytes dropped), and `take(ID,
size)` returns the bytes or raises PartError saying what was wrong. `encode_value`/`decode_value`
are the value codec both ends use (exactly one msgpack value; map keys of any type). Pure: no I/O,
no clock.
"""

from __future__ import annotations

from typing import Any, Final

import msgpack

from sdrpeer.control.messages import Part
from sdrpeer.errors import PartError

__all__ = [
    "MAX_BLOB",
    "PART_SIZE",
    "PartAssembler",
    "PartError",
    "decode_value",
    "encode_value",
    "parts",
]

PART_SIZE: Final = 256 * 1024
"""Bytes of payload per `part` message (well under the 1 MiB message limit)."""
MAX_BLOB: Final = 64 << 20
"""The most a host holds for one transfer (the agent's own limit is usually lower)."""


def parts(ident: int, blob: bytes) -> list[Part]:
    """The `part` messages carrying `blob` for message `ident` (none for an empty blob)."""
    return [Part(ident, blob[i : i + PART_SIZE]) for i in range(0, len(blob), PART_SIZE)]


class PartAssembler:
    """Collects the parts of one transfer at a time."""

    def __init__(self) -> None:
        self._id: int | None = None
        self._buf = bytearray()
        self._too_big: tuple[int, int] | None = None  # (id, limit) of a transfer past its limit
        self.dropped = 0
        """Transfers dropped unfinished (a part of another id came first)."""

    def add(self, ident: int, data: bytes, limit: int) -> None:
        """Add one part of transfer `ident`, holding at most `limit` bytes for it."""
        if ident != self._id:
            if self._buf:
                self.dropped += 1
            self._id, self._buf = ident, bytearray()
        if self._too_big is not None and self._too_big[0] == ident:
            return
        if len(self._buf) + len(data) > limit:
            self._too_big, self._buf = (ident, limit), bytearray()
            return
        self._buf += data

    def drop(self, ident: int) -> None:
        """Forget transfer `ident` (its message was refused before its bytes were taken)."""
        if ident == self._id:
            self._id, self._buf = None, bytearray()
        if self._too_big is not None and self._too_big[0] == ident:
            self._too_big = None

    def take(self, ident: int, size: object) -> bytes:
        """The bytes of transfer `ident`, which must be `size` long; PartError otherwise."""
        too_big, self._too_big = self._too_big, None
        got = bytes(self._buf) if ident == self._id else b""
        if ident == self._id:
            self._id, self._buf = None, bytearray()
        if too_big is not None and too_big[0] == ident:
            raise PartError(f"over the limit of {too_big[1]} bytes")
        if type(size) is not int or size < 0:
            raise PartError(f"'size' must be a non-negative integer, got {size!r}")
        if len(got) != size:
            raise PartError(f"got {len(got)} bytes in parts, 'size' says {size}")
        return got


def encode_value(value: Any) -> bytes:
    """`value` as msgpack; PartError naming the cause if msgpack cannot encode it."""
    try:
        return bytes(msgpack.packb(value, use_bin_type=True))
    except (TypeError, ValueError, OverflowError) as exc:
        raise PartError(f"msgpack cannot encode it: {exc}") from None


def decode_value(blob: bytes) -> Any:
    """The one msgpack value in `blob`; PartError if it is not exactly one value."""
    try:
        return msgpack.unpackb(blob, raw=False, strict_map_key=False)
    except Exception as exc:
        raise PartError(f"not one msgpack value ({type(exc).__name__}: {exc})") from None
