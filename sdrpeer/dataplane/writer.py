"""The sender's frame writer, without I/O: values in, numbered frames out to a `write` callable.

How it works: `offer` packs a value once, when it is offered (a bytes value of 64 KiB or more
is kept as it is, behind a 5-byte bin prefix: no copy) and queues it in `queue` (a
`PendingQueue`, which applies the connector policy); offered with the idle link's `write`
while nothing is pending, a small value under all/fifo is numbered and written at once instead
(the latency path). `flush(write, paused, ring)` numbers what is pending and writes it: many
small values become one joined buffer (the headers and the join are C-level `map`s, no Python
loop per frame); a big value is copied into the link's shared-memory ring when it has one (the
socket gets a small ``[seq, pos, length]`` frame; when the ring is full the value and those
after it wait, unnumbered, for a credit), else written as its header, then its bytes in 1 MiB
slices, each only while `paused()` is false, so the socket's buffer, not ours, holds what the
kernel has not taken. seq is given when a frame is written (starting at 1), so values dropped
by the policy leave no gap; frames lost with a broken link do.

When the link's receiver acknowledges, `retention` (sdrpeer.dataplane.retention) keeps every
frame written until it is acknowledged, and is the sender's window: while it is full nothing more
is written. `replay(write)` writes the frames it holds again, with their seqs, to a new link."""

from __future__ import annotations

import struct
from collections import deque
from collections.abc import Callable
from functools import partial
from typing import Final

import msgpack

from sdrpeer.dataplane.frames import FRAME_OVERHEAD, frame_header
from sdrpeer.dataplane.pending import PendingQueue, PolicyLike
from sdrpeer.dataplane.retention import Retention
from sdrpeer.dataplane.shm import SenderRing, ref_frame
from sdrpeer.errors import FrameError
from sdrpeer.sdk.typed import WireBlob

BIG: Final = 64 * 1024
"""Bytes values at least this large are queued and written without a copy."""
SLICE: Final = 1024 * 1024
"""A big value is handed to the transport this much at a time."""
_SEQ32: Final = 0x1_0000_0000
_HEADER32: Final = partial(struct.Struct(">BBI").pack, 0x92, 0xCE)

Write = Callable[[bytes | memoryview], None]


class _Big:
    """A large bytes value queued without copying: its msgpack bin prefix, then the bytes."""

    __slots__ = ("data", "prefix")

    def __init__(self, data: bytes, prefix: bytes | None = None) -> None:
        self.data = data
        self.prefix = b"\xc6" + len(data).to_bytes(4, "big") if prefix is None else prefix

    def __len__(self) -> int:
        return len(self.prefix) + len(self.data)


Item = bytes | _Big


class FrameWriter:
    """Pending values of one connection and the numbering of its frames."""

    def __init__(self, policy: PolicyLike, max_frame: int) -> None:
        self.queue: PendingQueue[Item] = PendingQueue(policy)
        self.max_frame = max_frame
        self._max_value = max_frame - FRAME_OVERHEAD
        self._queue_offer = self.queue.offer
        self.seq = 0
        """The seq of the last frame written."""
        self.frames_out = 0
        """Frames written."""
        self.bytes_out = 0
        """Bytes of those frames."""
        self._taken: deque[Item] = deque()  # taken from the queue, not yet written
        self._rest: memoryview | None = None  # the unwritten tail of a big value
        self._pack = msgpack.Packer().pack
        self.retention: Retention[Item] | None = None
        """Frames written and not acknowledged (None: the receiver does not acknowledge)."""
        self.replayed = 0
        """Frames written again to a new link (they had not been acknowledged)."""

    @property
    def window_full(self) -> bool:
        """True while unacknowledged frames fill the window (nothing more is written)."""
        return self.retention is not None and self.retention.full

    def replay(self, write: Write) -> int:
        """Write every unacknowledged frame again, with its seq; returns how many."""
        retention = self.retention
        if retention is None or not len(retention):
            return 0
        parts: list[bytes] = []
        for seq, item in retention.unacked():
            parts.append(frame_header(seq))
            if isinstance(item, _Big):
                parts.append(item.prefix)
                write(b"".join(parts))
                parts = []
                write(item.data)
            else:
                parts.append(item)
        if parts:
            write(b"".join(parts))
        n = len(retention)
        self.replayed += n
        return n

    @property
    def pending(self) -> int:
        """Values not fully written yet (a big one half written counts)."""
        return len(self.queue) + len(self._taken) + (self._rest is not None)

    def offer(self, value: object) -> bool:
        """Encode a value and queue it per the policy (False: not queued); FrameError when it
        cannot be encoded or its frame would be over the maximum."""
        item: Item
        if type(value) is bytes and len(value) >= BIG:
            item = _Big(value)
        elif type(value) is WireBlob:  # a typed value carrying a big blob (sdrpeer.sdk.typed)
            item = _Big(value.data, value.prefix)
        else:
            try:
                item = self._pack(value)
            except (TypeError, ValueError, OverflowError) as exc:
                raise FrameError("unencodable", f"{type(value).__name__}: {exc}") from None
        if len(item) > self._max_value:
            raise self._oversized(len(item))
        queue = self.queue
        if queue.simple and len(queue.items) < queue.limit:  # the hot path, inlined
            queue.items.append(item)
            return True
        return self._queue_offer(item)

    def offer_now(self, value: object, write: Write) -> bool:
        """`offer`, except that with nothing pending under push all/fifo a small value is
        numbered and written at once (the latency path: `write` is an idle link's)."""
        queue = self.queue
        if (
            not queue.simple
            or queue.items
            or self._taken
            or self._rest is not None
            or self.seq + 1 >= _SEQ32
            or (type(value) is bytes and len(value) >= BIG)
            or type(value) is WireBlob
            or self.window_full
        ):
            return self.offer(value)
        try:
            item = self._pack(value)
        except (TypeError, ValueError, OverflowError) as exc:
            raise FrameError("unencodable", f"{type(value).__name__}: {exc}") from None
        if len(item) > self._max_value:
            raise self._oversized(len(item))
        if len(item) >= BIG:
            queue.items.append(item)  # the queue is empty: room for one at least
            return True
        seq = self.seq = self.seq + 1
        data = _HEADER32(seq) + item
        write(data)
        if self.retention is not None:
            self.retention.wrote(item)
        self.frames_out += 1
        self.bytes_out += len(data)
        return True

    def _oversized(self, encoded: int) -> FrameError:
        size = encoded + FRAME_OVERHEAD
        detail = f"a frame of {size} bytes exceeds the maximum {self.max_frame}"
        return FrameError("oversized", detail)

    def flush(
        self, write: Write, paused: Callable[[], bool], ring: SenderRing | None = None
    ) -> None:
        """Write everything pending, as long as `paused()` is false (big values into `ring`
        when there is one and they fit)."""
        while not paused():
            rest = self._rest
            if rest is not None:
                self._rest = rest[SLICE:] if len(rest) > SLICE else None
                write(rest[:SLICE])
            elif self._taken:
                items = list(self._taken)
                self._taken.clear()
                self._write(write, items, ring)
            elif len(self.queue):
                self._write(write, self.queue.take(), ring)
            else:
                return

    def finish_frame(self, write: Write) -> None:
        """Write the rest of a big value now (before its link is closed for a repoint)."""
        if self._rest is not None:
            write(self._rest)
            self._rest = None

    def drop_frame(self) -> None:
        """Forget the rest of a big value (its link broke: the frame is lost)."""
        self._rest = None

    def _write(self, write: Write, items: list[Item], ring: SenderRing | None) -> None:
        """Number and write `items`, stopping after the first big one (its tail in _rest)."""
        seq, n = self.seq, len(items)
        if n == 1 and seq + 1 < _SEQ32 and type(items[0]) is bytes and len(items[0]) < BIG:
            data = _HEADER32(seq + 1) + items[0]  # one small value (latency): no join
        elif seq + n < _SEQ32 and max(map(len, items)) < BIG:  # the common case
            parts: list[bytes] = [b""] * (2 * n)
            parts[::2] = map(_HEADER32, range(seq + 1, seq + n + 1))
            parts[1::2] = items  # type: ignore[assignment]
            data = b"".join(parts)
        else:
            self._write_slowly(write, items, ring)
            return
        write(data)
        if self.retention is not None:
            self.retention.written(items)
        self.seq, self.frames_out, self.bytes_out = (
            seq + n,
            self.frames_out + n,
            self.bytes_out + len(data),
        )

    def _write_slowly(self, write: Write, items: list[Item], ring: SenderRing | None) -> None:
        seq, size, parts = self.seq, 0, []
        n = len(items)
        for index, item in enumerate(items):
            if ring is not None and BIG <= len(item) <= ring.size:
                head, body = (item.prefix, item.data) if isinstance(item, _Big) else (b"", item)
                pos = ring.place(head, body)
                if pos is None:  # the ring is full: this value and the rest wait for credit
                    self._taken.extend(items[index:])
                    n = index
                    break
                seq += 1
                parts.append(ref_frame(seq, pos, len(item)))
                size += len(parts[-1]) + len(item)
                continue
            seq += 1
            parts.append(frame_header(seq))
            size += len(parts[-1]) + len(item)
            if isinstance(item, _Big):
                parts.append(item.prefix)
                payload: bytes = item.data
            elif len(item) >= BIG:
                payload = item
            else:
                parts.append(item)
                continue
            write(b"".join(parts))
            parts = []
            self._rest = memoryview(payload)
            self._taken.extend(items[index + 1 :])
            n = index + 1
            break
        if parts:
            write(b"".join(parts))
        if self.retention is not None:
            self.retention.written(items[:n])
        self.seq, self.frames_out, self.bytes_out = seq, self.frames_out + n, self.bytes_out + size
