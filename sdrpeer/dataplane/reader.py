"""A data connection's receive buffer: where the socket reads into, and how frames come out.

How it works: one reused bytearray per connection (1 MiB, or the largest big frame seen) is what
the transport reads into, so a read allocates nothing. (A larger buffer measured slower: the
bytes are copied out while they are still in the CPU cache.) A read that is exactly one small
frame (the latency case: a ping, a command) is decoded by one `msgpack.unpackb`; anything else
that call cannot take alone goes the general way. `frames()` walks the bytes received:
- at a frame boundary, a frame whose value is a bin of 64 KiB or more (an image, a point cloud)
  skips msgpack: its header is parsed here, and once all of it is in the buffer the value is
  copied out once into the delivered bytes (what a plain socket loop does). An incomplete one
  stays in place (moved to the front of the buffer, or the buffer grown, only when it would not
  fit) and the socket reads exactly the rest straight behind it, so the next frame starts at
  the front of the buffer again;
- everything else is fed to the `FrameDecoder`, which checks and decodes it. If what it is left
  holding is the beginning of a big frame (and those bytes are still in the buffer), the reader
  takes them back, so big values after small ones in the same read skip msgpack too.
Errors keep the decoder's rule: good frames before a bad one come out first, then `failed` is
set and the next `frames()` raises the FrameError.
"""

from __future__ import annotations

from typing import Any, Final

import msgpack

from sdrpeer.dataplane.frames import INCOMPLETE, FrameDecoder, big_frame_header
from sdrpeer.errors import FrameError

READ_SIZE: Final = 1024 * 1024
BIG: Final = 64 * 1024
"""Bin values at least this large skip msgpack on the way in."""
_GROWN_MAX: Final = 32 * 1024 * 1024
_PEEK: Final = 16  # the longest big-frame header is 15 bytes
_unpackb: Final = msgpack.unpackb
_ONE: Final = 4096
"""A read shorter than this may be one small frame alone (the latency path tries it)."""


class FrameReader:
    """The receive buffer and decoder of one connection."""

    def __init__(self, max_frame: int) -> None:
        self.decoder = FrameDecoder(max_frame)
        self._one_max = min(_ONE, max_frame + 1)
        self._array = bytearray(READ_SIZE)
        self._view = memoryview(self._array)
        self._start = 0  # first byte not yet consumed
        self._end = 0  # end of the bytes received
        self._need = 0  # end of the big frame arriving, else 0
        self._error: FrameError | None = None

    def buffer(self) -> memoryview:
        """Free space to receive into (never empty): up to the end of a big frame if one is
        arriving (so the next one starts at the front, where it fits), else all of it."""
        return self._view[self._end : self._need or None]

    @property
    def big_frame(self) -> bool:
        """True while a big frame is arriving."""
        return self._need > 0

    @property
    def awaiting(self) -> int:
        """Bytes still to come of a big frame that is arriving (0 between frames)."""
        return self._need - self._end if self._need else 0

    def received(self, nbytes: int) -> None:
        """`nbytes` were written into the start of the last `buffer()`."""
        self._end += nbytes

    def first_map(self) -> object | None:
        """The hello: everything received goes to the decoder, which returns its first map."""
        self.decoder.feed(self._view[self._start : self._end])
        self._start = self._end = 0
        return self.decoder.next_map()

    @property
    def failed(self) -> bool:
        """True when the stream is broken: the next `frames()` raises the FrameError."""
        return self._error is not None or self.decoder.failed

    def frames(self) -> list[list[Any]]:
        """Every complete frame received so far, each ``[seq, value]``, oldest first."""
        if self._error is not None:
            raise self._error
        view, start, end, decoder = self._view, self._start, self._end, self.decoder
        if not start and 0 < end < self._one_max and not self._need and decoder.at_boundary:
            try:  # the latency path: one small frame received alone
                obj = _unpackb(view[:end], raw=False, strict_map_key=False)
            except Exception:  # more than one frame, part of one, a bad one: the walk below
                pass
            else:
                if type(obj) is list and len(obj) == 2 and type(obj[0]) is int and obj[0] >= 0:
                    self._end = 0
                    return [obj]
                if type(obj) is list and len(obj) == 3 and decoder.refs is not None:
                    self._end = 0
                    try:
                        return [decoder.refs(obj)]
                    except FrameError as exc:
                        self._error = exc
                        raise
        out: list[list[Any]] = []
        look = end - start >= BIG or self._need > 0  # else a big frame cannot be complete yet
        self._need = 0
        try:
            while start < end or not decoder.at_boundary:
                if look and decoder.at_boundary:
                    head = big_frame_header(view[start : start + _PEEK], BIG)
                    if head is INCOMPLETE:
                        break
                    if head is not None:
                        seq, header, size = head
                        total = header + size
                        if total > decoder.max_frame:
                            raise FrameError(
                                "oversized", f"frame of {total} bytes, max {decoder.max_frame}"
                            )
                        if end - start < total:
                            start, end = self._make_room(start, end, total)
                            self._need = start + total
                            break
                        out.append([seq, bytes(view[start + header : start + total])])
                        start += total
                        continue
                fed, start = start, end
                decoder.feed(view[fed:end])
                out.extend(decoder.frames())
                partial = decoder.partial
                at = end - partial  # where the incomplete frame starts in the buffer
                if (
                    0 < partial <= end - fed
                    and not decoder.failed
                    and big_frame_header(view[at : at + _PEEK], BIG) is not None  # or INCOMPLETE
                ):
                    decoder.drop_partial()  # a big frame begins here: take it back
                    start, look = at, True
                    continue
                break
        except FrameError as exc:
            if not out:
                raise
            self._error = exc
        if start == end:
            start = end = 0
        elif len(self._array) - end < BIG and not self._need:  # a header's first bytes wait
            self._view[: end - start] = self._view[start:end]  # move them to the front
            start, end = 0, end - start
        self._start, self._end = start, end
        return out

    def _make_room(self, start: int, end: int, total: int) -> tuple[int, int]:
        """Ensure a frame of `total` bytes starting at `start` fits; returns the new start, end."""
        if len(self._array) - start >= total:
            return start, end
        kept = end - start
        size = max(total, READ_SIZE)
        if len(self._array) < size:
            array = bytearray(size)
            array[:kept] = self._view[start:end]
            self._array, self._view = array, memoryview(array)
        else:
            self._view[:kept] = self._view[start:end]
        return 0, kept
