"""The sending side of one data stream: an OutPort's sink that writes frames to a receiver.

How it works: `offer(value)` packs the value at once (so an oversized or unencodable value is
refused right there, with an error naming the connection) and queues the bytes in a
`PendingQueue` that applies the connector policy. Writing is not a task per frame: the first
offer in a loop iteration writes its frame immediately when the link is idle (low latency), and
schedules one `call_soon` flush that numbers and joins everything offered meanwhile into a
single `transport.write` (high throughput; headers and joins are C-level `map`s, no Python loop
per frame). Big bytes values are queued as they are (no copy) and handed to the transport in
256 KiB slices. The transport keeps no backlog of its own (high-water mark 0): when the kernel's
socket buffer is full, writing pauses until it has drained and values wait in the queue, where
the policy decides (so `new` really sends the newest value, not one stuck in a user buffer).

A supervisor task owns the socket: it dials `to`, writes the hello, waits for the ok, then sleeps
until the link drops, `repoint` changes the address, or `close` is called. A drop is redialed
with exponential backoff (pending values stay queued, up to the buffer; frames lost inside the
dead socket show up as a gap in seq at the receiver). `repoint` detaches the link at once, so
later frames wait for the new peer, and closes the old transport, which still flushes what it
was handed. seq counts frames written to this connection, starting at 1, across redials.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
import struct
from collections import deque
from collections.abc import Callable
from functools import partial
from typing import Final

import msgpack

from sdrpeer.dataplane.address import parse_address
from sdrpeer.dataplane.frames import (
    DEFAULT_MAX_FRAME,
    FRAME_OVERHEAD,
    FrameDecoder,
    FrameError,
    Hello,
    encode_hello,
    frame_header,
    parse_reply,
)
from sdrpeer.dataplane.pending import PendingQueue, PolicyLike

log = logging.getLogger("sdrpeer.dataplane")
_SNDBUF: Final = 4 * 1024 * 1024
_BIG: Final = 64 * 1024  # values at least this large are written without joining (no copy)
_SLICE: Final = 256 * 1024  # a big value is handed to the transport this much at a time
_SEQ32: Final = 0x1_0000_0000
_HEADER32: Final = partial(struct.Struct(">BBI").pack, 0x92, 0xCE)


class _Big:
    """A large bytes value queued without copying: its msgpack bin prefix, then the bytes."""

    __slots__ = ("data", "prefix")

    def __init__(self, data: bytes) -> None:
        self.data = data
        self.prefix = b"\xc6" + len(data).to_bytes(4, "big")

    def __len__(self) -> int:
        return 5 + len(self.data)


Item = bytes | _Big


def next_backoff(delay: float, initial: float, cap: float) -> float:
    """The redial delay after `delay` failed: doubled, at least `initial`, at most `cap`."""
    return min(cap, max(initial, delay * 2))


class Connection:
    """A FrameSink that sends an OutPort's values to one InPort, per a connector policy."""

    def __init__(
        self,
        conn_id: str,
        to: str,
        in_port: str,
        from_: str,
        policy: PolicyLike,
        *,
        max_frame: int = DEFAULT_MAX_FRAME,
        backoff: tuple[float, float] = (0.05, 2.0),
        hello_timeout: float = 5.0,
    ) -> None:
        parse_address(to)
        self.conn_id = conn_id
        self.to = to
        self.in_port = in_port
        self.from_ = from_
        self.policy = policy
        self.max_frame = max_frame
        self.backoff = backoff
        self.hello_timeout = hello_timeout
        self.frames_out = 0
        """Frames handed to a socket."""
        self.bytes_out = 0
        """Bytes of those frames."""
        self.reconnects = 0
        """Successful redials after a dropped link."""
        self.refused = 0
        """Values refused at `offer` because they were oversized or unencodable."""
        self.seq = 0
        """The seq of the last frame written."""
        self.last_error: str | None = None
        """Why the last dial or link failed."""
        self._queue: PendingQueue[Item] = PendingQueue(policy)
        self._taken: deque[Item] = deque()  # taken from the queue, not yet written
        self._rest: memoryview | None = None  # the unwritten tail of a big value
        self._pack = msgpack.Packer().pack
        self._link: _Link | None = None
        self._scheduled = False
        self._closing = False
        self._wake = asyncio.Event()
        self._room = asyncio.Event()
        self._task: asyncio.Task[None] | None = None

    @property
    def dropped(self) -> int:
        """Values discarded by the policy."""
        return self._queue.dropped

    @property
    def pending(self) -> int:
        """Values waiting for the socket (a big one half written counts too)."""
        return len(self._queue) + len(self._taken) + (self._rest is not None)

    @property
    def connected(self) -> bool:
        """True while a link has said ok and not dropped."""
        return self._link is not None

    def start(self) -> None:
        """Start dialing (needs a running event loop); `offer` may be called before or after."""
        if self._task is None:
            self._task = asyncio.get_running_loop().create_task(self._run(), name=self.conn_id)

    def offer(self, value: object) -> bool:
        """Queue a value per the policy; False when dropped or (full=block) not queued yet."""
        if self._closing:
            return False
        item: Item
        if type(value) is bytes and len(value) >= _BIG:
            item = _Big(value)
        else:
            try:
                item = self._pack(value)
            except (TypeError, ValueError, OverflowError) as exc:
                self.refused += 1
                detail = f"{type(value).__name__}: {exc}"
                raise FrameError("unencodable", f"connection {self.conn_id}: {detail}") from None
        if len(item) + FRAME_OVERHEAD > self.max_frame:
            self.refused += 1
            raise FrameError(
                "oversized",
                f"connection {self.conn_id} ({self.from_} -> {self.in_port}): a frame of "
                f"{len(item) + FRAME_OVERHEAD} bytes exceeds the maximum {self.max_frame}",
            )
        if not self._queue.offer(item):
            return False
        if not self._scheduled and self._link is not None:
            self._scheduled = True
            asyncio.get_running_loop().call_soon(self._flush_soon)
            self._flush()  # idle link: this frame goes out now
        return True

    async def drain(self) -> None:
        """Wait until the queue has room (returns at once when it has, or when closing)."""
        while not self._queue.has_room and not self._closing:
            self._room.clear()
            await self._room.wait()

    def repoint(self, to: str) -> None:
        """Send later frames to `to`; frames already written still reach the old receiver."""
        parse_address(to)
        self.to = to
        link, self._link = self._link, None
        if link is not None:
            if self._rest is not None:  # a frame half written: the old receiver gets all of it
                link.transport.write(self._rest)
                self._rest = None
            link.transport.close()
        self._wake.set()

    async def wait_connected(self) -> None:
        """Wait until a link is up (bound it with `asyncio.timeout`)."""
        while self._link is None:
            self._wake.clear()
            await self._wake.wait()

    async def flushed(self) -> None:
        """Wait until nothing is pending (everything was handed to a socket)."""
        while self.pending and not self._closing:
            self._room.clear()
            await self._room.wait()

    async def close(self, linger: float = 1.0) -> None:
        """Flush what is pending (for up to `linger` seconds if connected) and close the link."""
        if self._link is not None and self.pending:
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(linger):
                    await self.flushed()
        self._closing = True
        self._room.set()
        self._wake.set()
        link, self._link = self._link, None
        if self._task is not None:
            self._task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await self._task
        if link is not None:
            link.transport.close()
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(linger):
                    await link.closed

    def _flush_soon(self) -> None:
        self._scheduled = False
        self._flush()

    def _flush(self) -> None:
        link = self._link
        if link is None:
            return
        write = link.transport.write
        while not link.paused:
            rest = self._rest
            if rest is not None:
                self._rest = rest[_SLICE:] if len(rest) > _SLICE else None
                write(rest[:_SLICE])
                continue
            if self._taken:
                items = list(self._taken)
                self._taken.clear()
            elif len(self._queue):
                items = self._queue.take()
                self._room.set()
            else:
                self._room.set()  # all written: wakes `flushed`
                return
            self._write(write, items)

    def _write(self, write: Callable[[bytes | memoryview], None], items: list[Item]) -> None:
        """Number and write `items`, stopping after the first big one (its tail goes to _rest)."""
        seq, n = self.seq, len(items)
        if n == 1 and seq + 1 < _SEQ32 and type(items[0]) is bytes and len(items[0]) < _BIG:
            data = _HEADER32(seq + 1) + items[0]  # one small value (latency): no join
            write(data)
            self.seq, self.frames_out, self.bytes_out = (
                seq + 1,
                self.frames_out + 1,
                self.bytes_out + len(data),
            )
            return
        if seq + n < _SEQ32 and max(map(len, items)) < _BIG:  # the common case, no Python loop
            parts: list[bytes] = [b""] * (2 * n)
            parts[::2] = map(_HEADER32, range(seq + 1, seq + n + 1))
            parts[1::2] = items  # type: ignore[assignment]
            data = b"".join(parts)
            write(data)
            self.seq, self.frames_out, self.bytes_out = (
                seq + n,
                self.frames_out + n,
                self.bytes_out + len(data),
            )
            return
        parts = []
        size = 0
        for index, item in enumerate(items):
            seq += 1
            parts.append(frame_header(seq))
            size += len(parts[-1]) + len(item)
            if isinstance(item, _Big):
                parts.append(item.prefix)
                payload: bytes = item.data
            elif len(item) >= _BIG:
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
        self.seq, self.frames_out, self.bytes_out = seq, self.frames_out + n, self.bytes_out + size

    def _resume(self, link: _Link) -> None:
        if link is self._link:
            self._flush()

    def _lost(self, link: _Link) -> None:
        if link is self._link:
            self._link = None
            self._rest = None  # the frame being written is lost with the link (a seq gap)
            self._wake.set()

    async def _run(self) -> None:
        initial, cap = self.backoff
        delay = initial
        dropped = False
        while not self._closing:
            to = self.to
            try:
                link = await self._dial(to)
            except (OSError, TimeoutError, FrameError, ValueError) as exc:
                self.last_error = f"{to}: {exc}"
                log.debug("data connection %s: dial failed: %s", self.conn_id, self.last_error)
                self._wake.clear()
                with contextlib.suppress(TimeoutError):
                    async with asyncio.timeout(delay):
                        await self._wake.wait()  # a repoint or close cuts the wait short
                delay = next_backoff(delay, initial, cap)
                continue
            if self.to != to or self._closing:  # repointed while dialing
                link.transport.close()
                continue
            delay = initial
            if dropped:
                self.reconnects += 1
            self._link = link
            self._wake.set()
            self._flush()
            while self._link is link:
                self._wake.clear()
                await self._wake.wait()
            dropped = self.to == to

    async def _dial(self, to: str) -> _Link:
        kind, host, port = parse_address(to)
        loop = asyncio.get_running_loop()
        async with asyncio.timeout(self.hello_timeout):
            if kind == "tcp":
                _, link = await loop.create_connection(lambda: _Link(self), host, port)
            else:
                _, link = await loop.create_unix_connection(lambda: _Link(self), host)
                sock = link.transport.get_extra_info("socket")
                with contextlib.suppress(OSError):
                    sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, _SNDBUF)
            hello = Hello(self.conn_id, self.in_port, self.from_, self.policy.to_map())
            link.transport.write(encode_hello(hello))
            try:
                error = await link.reply
            except BaseException:
                link.transport.abort()
                raise
        if error is not None:
            link.transport.close()
            raise FrameError("refused", error)
        return link


class _Link(asyncio.Protocol):
    """One socket of a Connection."""

    def __init__(self, owner: Connection) -> None:
        self.owner = owner
        loop = asyncio.get_running_loop()
        self.reply: asyncio.Future[str | None] = loop.create_future()
        self.closed: asyncio.Future[None] = loop.create_future()
        self.paused = False
        self.transport: asyncio.Transport
        self._decoder: FrameDecoder | None = FrameDecoder(4096)

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        transport.set_write_buffer_limits(high=0)  # pause as soon as the kernel is full

    def data_received(self, data: bytes) -> None:
        if self._decoder is None:
            return  # nothing is expected after the reply
        try:
            self._decoder.feed(data)
            obj = self._decoder.next_map()
            if obj is None:
                return
            self.reply.set_result(parse_reply(obj))
        except FrameError as exc:
            self.reply.set_exception(exc)
        self._decoder = None

    def pause_writing(self) -> None:
        self.paused = True

    def resume_writing(self) -> None:
        self.paused = False
        self.owner._resume(self)

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.reply.done():
            self.reply.set_exception(exc or ConnectionError("closed before the reply"))
            self.reply.exception()  # retrieved: nobody may be waiting any more
        if not self.closed.done():
            self.closed.set_result(None)
        self.owner._lost(self)
