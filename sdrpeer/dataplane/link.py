"""One socket of a sending data connection: dial, hello, reply, then flow control.

How it works: `dial` opens a TCP or Unix socket, writes the hello and waits for the reply. On a
Unix socket (sender and receiver on one machine) it also offers a shared-memory ring
(sdrpeer.dataplane.shm) in the hello; when the receiver takes it, big values go through the ring
and the socket carries small frames one way and the receiver's credits the other. The segment's
name is removed as soon as the reply came (the receiver removed it already), whether or not the
ring was taken: from then on only the two mappings keep it alive.

A `Link` tells its owner when writing may go on (`on_resume`: the kernel's buffer drained, or a
credit made room in the ring) and when it is gone (`on_lost`). `shut` ends a link whose frames
must still all arrive (a repoint, a close): a plain socket is closed after its buffer is written;
a socket with a ring is only half-closed, so the receiver can still send credits while it reads
the rest (a write to a closed socket would make it drop what it has not read), and closes when
it reaches the end.
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import Callable
from typing import Any, Final

import msgpack

from sdrpeer.dataplane.address import parse_address
from sdrpeer.dataplane.frames import FrameDecoder, FrameError, Hello, encode_hello, parse_reply
from sdrpeer.dataplane.shm import SenderRing

_SNDBUF: Final = 4 * 1024 * 1024


class Link(asyncio.Protocol):
    """One socket of a Connection (and its ring, if the receiver took one)."""

    def __init__(self, on_resume: Callable[[Link], None], on_lost: Callable[[Link], None]) -> None:
        self.on_resume = on_resume
        self.on_lost = on_lost
        loop = asyncio.get_running_loop()
        self.reply: asyncio.Future[tuple[str | None, bool]] = loop.create_future()
        """The receiver's answer: (error or None, whether it took the ring)."""
        self.closed: asyncio.Future[None] = loop.create_future()
        self.paused = False
        """True while the kernel's buffer is full."""
        self.ring: SenderRing | None = None
        """The shared-memory ring big values go through, if any."""
        self.transport: asyncio.Transport
        self.write: Callable[[bytes | memoryview], None]
        self._decoder: FrameDecoder | None = FrameDecoder(4096)
        self._credits: msgpack.Unpacker | None = None

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.write = transport.write
        transport.set_write_buffer_limits(high=0)  # pause as soon as the kernel is full

    def use_ring(self, ring: SenderRing) -> None:
        """Send big values through `ring` (the receiver took it)."""
        self.ring = ring
        self._credits = msgpack.Unpacker(max_buffer_size=64 * 1024)

    def data_received(self, data: bytes) -> None:
        if self._decoder is None:
            if self._credits is not None:
                self._credit(data)
            return  # nothing else is expected after the reply
        try:
            self._decoder.feed(data)
            obj = self._decoder.next_map()
            if obj is None:
                return
            error = parse_reply(obj)
            self.reply.set_result((error, isinstance(obj, dict) and obj.get("shm") is True))
        except FrameError as exc:
            self.reply.set_exception(exc)
        self._decoder = None

    def _credit(self, data: bytes) -> None:
        ring = self.ring
        if ring is None:
            return  # shut: credits for frames already written, nothing waits for them
        assert self._credits is not None
        try:
            self._credits.feed(data)
            for consumed in self._credits:
                ring.credit(consumed)
        except Exception:  # a bad credit: the receiver is broken, so is the link
            self.transport.abort()
            return
        self.on_resume(self)

    def is_paused(self) -> bool:
        """True while the kernel's buffer is full or the ring has no room for the next value."""
        return self.paused or (self.ring is not None and self.ring.blocked)

    def pause_writing(self) -> None:
        self.paused = True

    def resume_writing(self) -> None:
        self.paused = False
        self.on_resume(self)

    def shut(self) -> None:
        """End the link once what was written has arrived (see the module docstring)."""
        ring, self.ring = self.ring, None
        if ring is None:
            self.transport.close()
            return
        ring.close()  # our mapping only: the receiver's stays
        if not self.transport.is_closing():
            self.transport.write_eof()

    def connection_lost(self, exc: Exception | None) -> None:
        if not self.reply.done():
            self.reply.set_exception(exc or ConnectionError("closed before the reply"))
            self.reply.exception()  # retrieved: nobody may be waiting any more
        if self.ring is not None:
            self.ring.close()
            self.ring = None
        if not self.closed.done():
            self.closed.set_result(None)
        self.on_lost(self)


async def dial(
    to: str,
    hello: Hello,
    on_resume: Callable[[Link], None],
    on_lost: Callable[[Link], None],
    *,
    shm_size: int,
) -> Link:
    """Open a link to `to` and get the receiver's ok (bound it with `asyncio.timeout`);
    FrameError("refused") with the receiver's error, OSError when it cannot be reached."""
    kind, host, port = parse_address(to)
    loop = asyncio.get_running_loop()
    ring: SenderRing | None = None
    link: Link | None = None
    try:
        if kind == "tcp":
            _, link = await loop.create_connection(lambda: Link(on_resume, on_lost), host, port)
        else:
            _, link = await loop.create_unix_connection(lambda: Link(on_resume, on_lost), host)
            sock = link.transport.get_extra_info("socket")
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, _SNDBUF)
            ring = SenderRing.create(shm_size) if shm_size > 0 else None
        offer: Any = None if ring is None else ring.offer_map()
        link.transport.write(encode_hello(_with_shm(hello, offer)))
        error, took_ring = await link.reply
    except BaseException:
        if link is not None:
            link.transport.abort()
        if ring is not None:
            ring.close()
        raise
    if ring is not None:
        ring.unlink()
        if took_ring and error is None:
            link.use_ring(ring)
        else:
            ring.close()
    if error is not None:
        link.transport.close()
        raise FrameError("refused", error)
    return link


def _with_shm(hello: Hello, offer: object) -> Hello:
    return Hello(hello.conn, hello.in_port, hello.from_, hello.policy, hello.version, offer)
