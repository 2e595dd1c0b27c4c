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

A receiver that acknowledges (it said ``"ack": true`` in its reply) writes ``[seq]`` or
``[seq, dropped]`` on the same reverse direction as the credits (a credit is a bare uint):
`on_ack` gets each seq and how many more frames the receiving InPort dropped on a full buffer
since the previous ack (0 from `[seq]`). Such a link
is also only half-closed by `shut`, so the acknowledgements of what the old receiver still takes
arrive; it closes once it has acknowledged everything or its instance stops.

An authenticated TCP link is encrypted (`encrypt`, on by default; sdrpeer.dataplane.seal): the
hello asks for it, the receiver agrees in its reply, and after the sender's proof `write` seals
what it is given into records and what comes back is opened before it is read. An authenticated
TCP link told not to encrypt says so in its hello's policy (``encrypt: false``: a receiver
refuses a clear stream without it); both proofs cover the choice (sdrpeer.dataplane.auth).
"""

from __future__ import annotations

import asyncio
import contextlib
import socket
from collections.abc import Callable
from dataclasses import replace
from typing import Any, Final

import msgpack

from sdrpeer.dataplane.address import parse_address
from sdrpeer.dataplane.auth import DataAuth, proof_names, proof_parts
from sdrpeer.dataplane.frames import FrameDecoder, Hello, encode_hello, parse_reply, reply_auth
from sdrpeer.dataplane.seal import Opener, sealed_writer
from sdrpeer.dataplane.shm import SenderRing
from sdrpeer.errors import FrameError
from sdrpeer.keys.derive import stream_keys

_SNDBUF: Final = 4 * 1024 * 1024
MAX_RECORD: Final = 2 * 1024 * 1024
"""Longest encrypted record accepted from a receiver (acks are a few bytes)."""


class Link(asyncio.Protocol):
    """One socket of a Connection (and its ring, if the receiver took one)."""

    def __init__(
        self,
        on_resume: Callable[[Link], None],
        on_lost: Callable[[Link], None],
        on_ack: Callable[[int, int], None] | None = None,
        on_reply: Callable[[list[Any]], None] | None = None,
    ) -> None:
        self.on_resume = on_resume
        self.on_lost = on_lost
        self.on_ack = on_ack
        self.on_reply = on_reply
        """Takes each ``[call_id, ok, value]`` of a service binding (sdrpeer.dataplane.service);
        raising breaks the link."""
        loop = asyncio.get_running_loop()
        self.reply: asyncio.Future[tuple[str | None, dict[str, Any]]] = loop.create_future()
        """The receiver's answer: (error or None, the reply map)."""
        self.acks = False
        """True when the receiver acknowledges frames."""
        self.closed: asyncio.Future[None] = loop.create_future()
        self.paused = False
        """True while the kernel's buffer is full."""
        self.ring: SenderRing | None = None
        """The shared-memory ring big values go through, if any."""
        self.transport: asyncio.Transport
        self.write: Callable[[bytes | memoryview], None]
        self._decoder: FrameDecoder | None = FrameDecoder(4096)
        self._reverse: msgpack.Unpacker | None = None  # credits and acks, after the reply
        self._early = b""  # bytes that came in the same read as the reply
        self._opener: Opener | None = None
        """Opens the receiver's records, when the link is encrypted."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self.write = transport.write
        transport.set_write_buffer_limits(high=0)  # pause as soon as the kernel is full

    def use_ring(self, ring: SenderRing) -> None:
        """Send big values through `ring` (the receiver took it)."""
        self.ring = ring
        self._listen()

    def use_acks(self) -> None:
        """The receiver acknowledges frames: read its `[seq]`s."""
        self.acks = True
        self._listen()

    def encrypt(self, send_key: bytes, receive_key: bytes, max_record: int) -> None:
        """From now on seal what is written and open what comes back."""
        self.write = sealed_writer(send_key, self.transport.write)
        self._opener = Opener(receive_key, max_record)

    def use_replies(self, max_reply: int) -> None:
        """The receiver answers calls (a service binding): read its replies."""
        self._reverse = msgpack.Unpacker(
            raw=False, strict_map_key=False, max_buffer_size=max_reply + 64 * 1024
        )

    def _listen(self) -> None:
        if self._reverse is None:
            self._reverse = msgpack.Unpacker(max_buffer_size=64 * 1024)

    def data_received(self, data: bytes) -> None:
        if self._decoder is None:
            if self._reverse is not None:
                self._back(data)
            return  # nothing else is expected after the reply
        decoder = self._decoder
        try:
            decoder.feed(data)
            obj = decoder.next_map()
            if obj is None:
                return
            error = parse_reply(obj)
            assert isinstance(obj, dict)  # parse_reply checked it
            self.reply.set_result((error, obj))
        except FrameError as exc:
            self.reply.set_exception(exc)
            self._decoder = None
            return
        self._decoder = None
        if decoder.partial:  # credits or acks right behind the reply: kept for _back
            self._early = bytes(data[len(data) - decoder.partial :])

    def take_early(self) -> None:
        """Read what came right behind the reply (once `use_ring`/`use_acks` said how)."""
        early, self._early = self._early, b""
        if early and self._reverse is not None:
            self._back(early)

    def _back(self, data: bytes) -> None:
        """Credits (uints) and acks (``[seq]`` or ``[seq, dropped]``) from the receiver."""
        assert self._reverse is not None
        ring = self.ring
        credited = False
        try:
            if self._opener is not None:
                data = b"".join(self._opener.open(data))
            self._reverse.feed(data)
            for obj in self._reverse:
                if type(obj) is int:
                    if ring is not None:  # else shut: nothing waits for credits
                        ring.credit(obj)
                        credited = True
                elif type(obj) is list and self.acks and _is_ack(obj):
                    if self.on_ack is not None:
                        self.on_ack(obj[0], obj[1] if len(obj) == 2 else 0)
                elif type(obj) is list and len(obj) == 3 and self.on_reply is not None:
                    self.on_reply(obj)
                else:
                    raise ValueError(f"unexpected {obj!r:.40}")
        except Exception:  # a bad credit or ack: the receiver is broken, so is the link
            self.transport.abort()
            return
        if credited or self.acks:
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
        if ring is None and not self.acks:
            self.transport.close()
            return
        if ring is not None:
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
    on_ack: Callable[[int, int], None] | None = None,
    auth: DataAuth | None = None,
    encrypt: bool = True,
    max_record: int = MAX_RECORD,
    on_reply: Callable[[list[Any]], None] | None = None,
    max_reply: int = 64 * 1024,
) -> Link:
    """Open a link to `to` and get the receiver's ok (bound it with `asyncio.timeout`);
    FrameError("refused") with the receiver's error (or when it does not prove it holds a data
    key, with `auth`, or does not encrypt a TCP link `encrypt` asks for), OSError when it
    cannot be reached. With `on_reply` (a service binding, sdrpeer.dataplane.service) the
    receiver's replies of up to `max_reply` bytes go there."""
    nonce = auth.nonce() if auth is not None and auth.enabled else None
    kind, host, port = parse_address(to)
    enc = encrypt and nonce is not None and kind == "tcp"
    policy = hello.policy
    if nonce is not None and kind == "tcp" and not enc and policy.get("encrypt") is not False:
        policy = {**policy, "encrypt": False}  # said, or the receiver refuses a clear stream
    hello = replace(hello, auth=nonce, enc=enc, policy=policy)
    loop = asyncio.get_running_loop()
    ring: SenderRing | None = None
    link: Link | None = None

    def protocol() -> Link:
        return Link(on_resume, on_lost, on_ack, on_reply)

    try:
        if kind == "tcp":
            _, link = await loop.create_connection(protocol, host, port)
        else:
            _, link = await loop.create_unix_connection(protocol, host)
            sock = link.transport.get_extra_info("socket")
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, _SNDBUF)
            ring = SenderRing.create(shm_size) if shm_size > 0 else None
        offer: Any = None if ring is None else ring.offer_map()
        link.transport.write(encode_hello(replace(hello, shm=offer)))
        error, reply = await link.reply
    except BaseException:
        if link is not None:
            link.transport.abort()
        if ring is not None:
            ring.close()
        raise
    took_ring = reply.get("shm") is True
    if ring is not None:
        ring.unlink()
        if took_ring and error is None:
            link.use_ring(ring)
        else:
            ring.close()
    if error is None and auth is not None and nonce is not None:
        error, keys = _prove(link, auth, nonce, hello, reply)
        if error is None and reply.get("enc", False) is not hello.enc:
            error = (
                "the receiver does not encrypt the stream"
                if hello.enc
                else "the receiver encrypts a stream we asked in clear"
            )
        elif error is None and keys is not None:
            link.encrypt(*keys, max_record)
    if error is not None:
        link.transport.close()
        raise FrameError("refused", error)
    if reply.get("ack") is True and hello.ack is not None:
        link.use_acks()
    if on_reply is not None:
        link.use_replies(max_reply)
    link.take_early()
    return link


def _prove(
    link: Link, auth: DataAuth, nonce: bytes, hello: Hello, reply: dict[str, Any]
) -> tuple[str | None, tuple[bytes, bytes] | None]:
    """Check the receiver's proof and write ours: (None, the stream's keys, sender's first), or
    (the error, None) when the receiver's proof does not hold."""
    try:
        theirs = reply_auth(reply)
    except FrameError as exc:
        return str(exc), None
    if theirs is None:
        return "the receiver did not authenticate (it has no data key)", None
    parts = proof_parts(hello, hello.enc)
    key = auth.check_receiver(nonce, theirs[0], parts, theirs[1])
    if key is None:
        return (
            "the receiver's proof does not hold under our data keys (or the hello was altered"
            " on the way)"
        ), None
    if reply.get("enc", False) is not hello.enc:
        return None, None  # refused by the caller: no proof of ours is written
    proof = auth.sender_proof(key, theirs[0], nonce, parts)
    link.transport.write(msgpack.packb({"auth": proof}))
    if not hello.enc:
        return None, None
    return None, stream_keys(key, nonce, theirs[0], proof_names(hello))


def _is_ack(obj: list[Any]) -> bool:
    """``[seq]`` or ``[seq, dropped]``, unsigned integers."""
    return 1 <= len(obj) <= 2 and all(type(x) is int and x >= 0 for x in obj)
