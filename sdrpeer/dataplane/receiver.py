"""One accepted data connection: hello (and proof), frames to the port, credits and acks back.

How it works: see sdrpeer.dataplane.server, whose `DataServer` makes one `Receiver` per
accepted connection; this module is that connection's protocol. It reads into its own
`FrameReader`, answers the hello (and, when the host authenticates, checks the sender's proof
before any frame: sdrpeer.dataplane.auth), maps an offered shared-memory ring (Unix sockets
only), delivers every frame at once, writes back ring credits and acknowledgements, and keeps
the socket open after the sender's end of stream until what it delivered is acknowledged. On an
authenticated TCP connection everything after the proof is encrypted (sdrpeer.dataplane.seal):
a hello that does not ask for it (``enc``) is refused (`refused_clear`) unless the connection's
own policy says ``encrypt: false``, and both proofs cover the choice, so a flipped flag fails
them. The socket then reads into the `Opener`'s buffer, and each record is decrypted straight
into the `FrameReader`'s buffer, as if its bytes had been read there. A hello
with ``svc`` opens a service binding instead (sdrpeer.dataplane.service): its frames are requests
for the provided service port it names, and the replies go back on the same socket.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Callable
from typing import TYPE_CHECKING, Any, Final, Protocol, cast

import msgpack

from sdrpeer.dataplane.auth import proof_names, proof_parts
from sdrpeer.dataplane.frames import PROTOCOL_VERSION, Hello, encode_reply, parse_hello
from sdrpeer.dataplane.port_api import AckingPort, InPortLike, PolicyPort, ServicePortLike
from sdrpeer.dataplane.reader import FrameReader
from sdrpeer.dataplane.seal import TAG, Opener, sealed_writer
from sdrpeer.dataplane.service import ServiceStream, request_frame
from sdrpeer.dataplane.shm import ReceiverRing
from sdrpeer.errors import FrameError
from sdrpeer.keys.derive import stream_keys

if TYPE_CHECKING:
    from collections import Counter

    from sdrpeer.dataplane.auth import DataAuth

log = logging.getLogger("sdrpeer.dataplane")
_RCVBUF = 4 * 1024 * 1024
_packb: Final = msgpack.packb
_LOWAT_MAX: Final = 512 * 1024
RECORD_SLACK: Final = 1024 * 1024
"""A record may carry a whole write of the sender: a frame of the maximum size and more."""


class Intake(Protocol):
    """What a `Receiver` needs of the server that accepted it (`DataServer` is one)."""

    max_frame: int
    max_connections: int
    hello_timeout: float
    shm: bool
    """Take the shared-memory rings senders on this machine offer."""
    auth: DataAuth | None
    quiesced: bool
    """The component takes no frames (not ACTIVE)."""
    counters: Counter[str]
    bytes_in: Counter[str]
    resolve: Callable[[str], InPortLike | None]
    """The in-port a hello names, None when there is no such port."""
    resolve_service: Callable[[str], ServicePortLike | None]
    """The provided service port a service hello names, None when there is no such port."""

    def admit(self, receiver: Receiver) -> bool:
        """Count `receiver` among the open connections; False when no more are allowed."""

    def forget(self, receiver: Receiver) -> None:
        """`receiver` closed."""

    def report(self, reason: str, conn: str, detail: str) -> None:
        """Log a refused or failed connection (rate-limited per reason)."""


class Receiver(asyncio.BufferedProtocol):
    """One accepted data connection."""

    def __init__(self, server: Intake) -> None:
        self.server = server
        self.reader = FrameReader(server.max_frame)
        self.transport: asyncio.Transport | None = None
        self.port: InPortLike | None = None
        self.conn = "?"
        self.key = "?"
        """What frames are delivered under: the connection id, or its stream's session key."""
        self.in_port = ""
        self.ring: ReceiverRing | None = None
        self.acking: AckingPort | None = None
        """The port, when this stream is acknowledged."""
        self._proving: tuple[Hello, InPortLike, bool, bytes] | None = None  # hello answered
        self._sealed = False  # the stream is encrypted after the sender's proof
        self._policy: Any = None  # the connection's policy at a PolicyPort (from the hello)
        self._drops = False  # the sender reads [seq, dropped] acks (its hello's ack map said)
        self._last_seq = 0  # the highest seq delivered on this socket
        self._eof = False  # the sender ended its side; we close once all is acknowledged
        self._credited = 0
        self._sock: Any = None
        self._lowat = 1
        self._timer: asyncio.TimerHandle | None = None
        self._opener: Opener | None = None
        """Opens the sender's records, on an encrypted connection."""
        self._send: Callable[[bytes], None] | None = None
        """Writes to the sender (sealed on an encrypted connection), once the transport is up."""

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        assert isinstance(transport, asyncio.Transport)
        self.transport = transport
        self._send = transport.write
        server = self.server
        if not server.admit(self):
            server.counters["rejected"] += 1
            server.report("rejected", "?", f"over {server.max_connections} connections")
            transport.write(encode_reply(f"too many connections (max {server.max_connections})"))
            transport.close()
            return
        server.counters["accepted"] += 1
        sock = transport.get_extra_info("socket")
        if sock is not None and sock.family != socket.AF_UNIX:
            self._sock = sock  # TCP: big frames wake us in big pieces (see _wake_later)
        if sock is not None and sock.family == socket.AF_UNIX:
            with contextlib.suppress(OSError):
                sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, _RCVBUF)
        loop = asyncio.get_running_loop()
        self._timer = loop.call_later(server.hello_timeout, self._hello_timeout)

    def get_buffer(self, sizehint: int) -> memoryview:
        opener = self._opener
        return self.reader.buffer() if opener is None or self.port is None else opener.buffer()

    def buffer_updated(self, nbytes: int) -> None:
        if self._opener is not None and self.port is not None:
            self._opener.received(nbytes)
            self._records(nbytes)
            return
        reader = self.reader
        reader.received(nbytes)
        try:
            if self.port is not None:
                self.server.bytes_in[self.in_port] += nbytes
            elif self._hello():  # what came behind the handshake in this read counts too
                if self._opener is not None:  # encrypted from the proof on: what followed it
                    rest = reader.decoder.take_rest()
                    self.server.bytes_in[self.in_port] += len(rest)
                    self._opener.buffer()[: len(rest)] = rest  # (a hello is far below a read)
                    self._opener.received(len(rest))
                    self._records(0)
                    return
                self.server.bytes_in[self.in_port] += reader.decoder.partial
            else:
                return
            frames = reader.frames()
        except FrameError as exc:
            self._bad(exc)
            return
        self._after(frames)

    def _records(self, nbytes: int) -> None:
        """Open the records complete after `nbytes` more were read, each straight into the
        frame reader's buffer when it fits there (else through a copy), and read their frames."""
        opener = self._opener
        assert opener is not None
        if self.port is not None:
            self.server.bytes_in[self.in_port] += nbytes
        reader = self.reader
        frames: list[list[Any]] = []
        try:
            while (record := opener.next_record()) is not None:
                size = len(record) - TAG
                space = reader.buffer()
                if size <= len(space):
                    opener.open_into(record, space[:size])
                    reader.received(size)
                    frames += reader.frames()
                    continue
                view, done = memoryview(opener.open_record(record)), 0
                while done < size:
                    space = reader.buffer()
                    n = min(len(space), size - done)
                    space[:n] = view[done : done + n]
                    reader.received(n)
                    done += n
                    frames += reader.frames()
        except FrameError as exc:
            self._bad(exc)
            return
        self._after(frames)

    def _after(self, frames: list[list[Any]]) -> None:
        """Deliver what was read, then ring credits and a stream's pending error."""
        reader = self.reader
        self._deliver(frames)
        if self._sock is not None and (reader.big_frame or self._lowat != 1):
            self._wake_later(reader.awaiting)
        ring = self.ring
        if ring is not None and ring.consumed != self._credited and self.port is not None:
            self._credited = ring.consumed
            assert self._send is not None
            self._send(_packb(ring.consumed))  # room for the sender
        if reader.failed:
            try:
                reader.frames()
            except FrameError as exc:
                self._bad(exc)

    def _wake_later(self, awaiting: int) -> None:
        """While a big frame arrives, have the kernel wake us only once a good part of the
        rest is there (SO_RCVLOWAT), not for every segment; at once again between frames."""
        lowat = min(awaiting, _LOWAT_MAX) or 1
        if lowat != self._lowat:
            self._lowat = lowat
            try:
                self._sock.setsockopt(socket.SOL_SOCKET, socket.SO_RCVLOWAT, lowat)
            except OSError:
                self._sock = None

    def _deliver(self, frames: list[list[Any]]) -> None:
        if self.port is None:
            return
        if self.ring is not None:
            self._deliver_from_ring(frames)
            return
        conn = self.key
        many = getattr(self.port, "deliver_many", None)
        if many is not None:  # the whole read at once (sdrpeer.sdk.inport)
            try:
                many(frames, conn)
            except Exception as exc:
                self.server.counters["deliver_error"] += 1
                self.server.report("deliver_error", self.conn, f"{type(exc).__name__}: {exc}")
        else:
            deliver = self.port.deliver
            for seq, value in frames:
                try:
                    deliver(value, seq, conn)
                except Exception as exc:
                    self.server.counters["deliver_error"] += 1
                    self.server.report("deliver_error", self.conn, f"{type(exc).__name__}: {exc}")
        if frames and self.acking is not None:
            self._last_seq = max(self._last_seq, frames[-1][0])

    def _deliver_from_ring(self, frames: list[list[Any]]) -> None:
        """Deliver frames, taking each ``[seq, pos, length]`` value out of the ring just before
        (counted in bytes_in like the socket's bytes)."""
        ring, port, conn = self.ring, self.port, self.key
        assert ring is not None
        assert port is not None
        bytes_in = self.server.bytes_in
        for frame in frames:
            if len(frame) == 3:
                try:
                    value = ring.take(frame)
                except FrameError as exc:
                    self._bad(exc)
                    return
                bytes_in[self.in_port] += frame[2]
            else:
                value = frame[1]
            try:
                port.deliver(value, frame[0], conn)
            except Exception as exc:
                self.server.counters["deliver_error"] += 1
                self.server.report("deliver_error", self.conn, f"{type(exc).__name__}: {exc}")
            del value  # the next value may reuse its memory
        if frames and self.acking is not None:
            self._last_seq = max(self._last_seq, frames[-1][0])

    def _hello(self) -> bool:
        """Handle the hello (and, when we authenticate, the sender's proof behind it) once it
        has arrived; True when frames may follow."""
        if self._proving is not None:
            return self._proof()
        obj = self.reader.first_map()
        if obj is None:
            return False
        hello = parse_hello(obj)
        self.conn = self.key = hello.conn
        error = None
        port = None
        auth = self.server.auth
        authenticating = auth is not None and auth.enabled
        tcp = not self._local()
        if hello.version != PROTOCOL_VERSION:
            error = f"protocol version {hello.version} not supported (this is {PROTOCOL_VERSION})"
        elif authenticating and hello.auth is None:
            error = "this receiver only takes authenticated connections (a data key's nonce)"
            self.server.counters["refused_auth"] += 1
        elif authenticating and tcp and not hello.enc and hello.policy.get("encrypt") is not False:
            error = (
                'this receiver only takes encrypted streams over TCP ("enc": true in the hello;'
                " a connection whose policy says encrypt: false may stream in clear)"
            )
            self.server.counters["refused_clear"] += 1
        elif hello.svc is not None:
            port, error = self._service(hello)
        else:
            port = self.server.resolve(hello.in_port)
            if port is None:
                error = f"unknown in-port {hello.in_port!r}"
        assert self.transport is not None
        can_ack = hello.ack is not None and hasattr(port, "attach_stream")
        taken = getattr(port, "type_id", None)
        if error is None and taken is not None and hello.type is not None and taken != hello.type:
            error = (
                f"type mismatch: {hello.from_} sends {hello.type}, {hello.in_port} takes {taken}"
            )
            self.server.counters["refused_type"] += 1
        if error is None and hasattr(port, "connection_policy"):
            try:
                policy_port = cast(PolicyPort, port)
                self._policy = policy_port.connection_policy(hello.policy, acked=can_ack)
            except (ValueError, TypeError) as exc:
                error = f"bad hello: policy: {exc}"
        if (
            error is None
            and hello.shm is not None
            and self.server.shm
            and self._local()
            and (hello.svc is None)
        ):
            self._attach(hello.shm)  # only for a hello that is accepted
        acks = error is None and can_ack
        proof = None
        self._sealed = authenticating and hello.auth is not None and hello.enc and tcp
        if error is None and authenticating and auth is not None and hello.auth is not None:
            nonce = auth.nonce()
            parts = proof_parts(hello, self._sealed)
            proof = (nonce, auth.receiver_proof(hello.auth, nonce, parts))
        enc = proof is not None and self._sealed
        reply = encode_reply(error, shm=self.ring is not None, ack=acks, auth=proof, enc=enc)
        self.transport.write(reply)
        if error is not None or port is None:
            self.server.counters["rejected"] += 1
            self.server.report("rejected", hello.conn, error or "")
            self.transport.close()
            return False
        self._proving = (hello, port, acks, proof[0] if proof is not None else b"")
        return self._proof() if proof is not None else self._open()

    def _service(self, hello: Hello) -> tuple[InPortLike | None, str | None]:
        """(the binding's stream, None) for a hello naming a provided service port of the
        consumer's interface, else (None, the error)."""
        service = self.server.resolve_service(hello.in_port)
        if service is None:
            return None, f"unknown service port {hello.in_port!r}"
        if service.interface_id != hello.svc:
            self.server.counters["refused_interface"] += 1
            return None, (
                f"interface mismatch: {hello.from_} requires {hello.svc}, "
                f"{hello.in_port} provides {service.interface_id}"
            )
        self.reader.decoder.refs = request_frame  # requests are [call_id, method, arg]
        counters = self.server.counters
        return ServiceStream(service, self.send_back, counters, self.server.max_frame), None

    def send_back(self, data: bytes) -> None:
        """Write to the sender (a service reply), unless the socket is closing."""
        transport = self.transport
        if transport is not None and not transport.is_closing() and self._send is not None:
            self._send(data)

    def _proof(self) -> bool:
        """The sender's proof, the first map after our reply; True once it holds."""
        assert self._proving is not None
        obj = self.reader.first_map()
        if obj is None:
            return False
        hello, _, _, nonce = self._proving
        auth = self.server.auth
        assert auth is not None
        proof = obj.get("auth") if isinstance(obj, dict) else None
        key = None
        if type(proof) is bytes and hello.auth is not None:
            key = auth.check_sender(nonce, hello.auth, proof_parts(hello, self._sealed), proof)
        if key is None or hello.auth is None:
            self._proving = None
            self.server.counters["refused_auth"] += 1
            self.server.counters["rejected"] += 1
            self.server.report("refused_auth", hello.conn, "the sender's proof does not hold")
            self.abort()
            return False
        if self._sealed:
            self._encrypt(*stream_keys(key, hello.auth, nonce, proof_names(hello)))
        return self._open()

    def _encrypt(self, receive_key: bytes, send_key: bytes) -> None:
        """Everything after the proof is sealed both ways (sdrpeer.dataplane.seal)."""
        assert self.transport is not None
        self._opener = Opener(receive_key, self.server.max_frame + RECORD_SLACK)
        self._send = sealed_writer(send_key, self.transport.write)
        self._sock = None  # records do not line up with frames: no SO_RCVLOWAT tuning

    def _open(self) -> bool:
        """The connection is accepted: frames go to the port from now on."""
        assert self._proving is not None
        hello, port, acks, _ = self._proving
        self._proving = None
        if self._timer is not None:
            self._timer.cancel()
        self.port = port
        self.in_port = hello.in_port
        if self._policy is not None:  # this connection's frames queue per its own policy
            cast(PolicyPort, port).connect(hello.conn, self._policy)
        if acks and hello.ack is not None:
            self.acking = cast(AckingPort, port)
            ack = hello.ack
            self._drops = ack.drops
            self.key = self.acking.attach_stream(hello.conn, ack.session, ack.next, self._ack)
            self.server.counters["acked"] += 1
        return True

    def _ack(self, seq: int, dropped: int) -> None:
        """The port acknowledges every frame up to `seq`; its policy discarded `dropped` more of
        this stream's frames since the previous acknowledgement."""
        transport = self.transport
        if transport is None or transport.is_closing() or self._send is None:
            return
        told = dropped and self._drops  # only to a sender that said it reads them
        self._send(_packb([seq, dropped] if told else [seq]))
        if self._eof and seq >= self._last_seq:
            transport.close()  # the sender left and has heard everything

    def eof_received(self) -> bool | None:
        """The sender ended its side: close now, or once what we delivered is acknowledged."""
        if self.acking is None:
            return None
        self.acking.flush_acks()  # what the component took so far goes out before any close
        if not self.server.quiesced and self.acking.acked(self.key) < self._last_seq:
            self._eof = True
            return True  # keep the socket open for the acks
        return None

    def quiesce(self) -> None:
        """Our component stopped taking frames: send the acks due; close if the sender left."""
        if self.acking is None:
            return
        self.acking.flush_acks()
        if self._eof and self.transport is not None:
            self.transport.close()

    def finish(self) -> None:
        """Close for the server's end: send the acknowledgements due, then close gracefully."""
        acking, self.acking = self.acking, None
        if acking is not None:
            acking.flush_acks()
            acking.detach_stream(self.key, self._ack)
        self.port = None
        if self.transport is not None:
            self.transport.close()

    def _local(self) -> bool:
        """True on a Unix socket (a ring is only for a sender on this machine)."""
        assert self.transport is not None
        sock = self.transport.get_extra_info("socket")
        return sock is not None and sock.family == socket.AF_UNIX

    def _attach(self, offer: object) -> None:
        """Map the ring the sender offered; without it the stream carries every value."""
        try:
            self.ring = ReceiverRing.attach(offer, self.server.max_frame)
        except (OSError, ValueError) as exc:
            log.info("data connection %s: no shared memory (%s)", self.conn, exc)
            return
        self.server.counters["shm"] += 1
        self.reader.decoder.refs = self.ring.check

    def _bad(self, exc: FrameError) -> None:
        server = self.server
        reason = f"refused_{exc.reason}"
        server.counters[reason] += 1
        if self.port is not None:
            self.port.refuse()
        else:  # a bad hello: tell the sender why before closing
            assert self.transport is not None
            self.transport.write(encode_reply(f"bad hello: {exc}"))
        server.report(reason, self.conn, str(exc))
        self.abort(graceful=self.port is None)

    def _hello_timeout(self) -> None:
        self.server.counters["rejected"] += 1
        self.server.report("rejected", self.conn, "no hello in time")
        self.abort()

    def abort(self, *, graceful: bool = False) -> None:
        """Close this connection now (graceful: after the reply written, if any)."""
        self.port = None
        if self.transport is not None:
            if graceful:
                self.transport.close()
            else:
                self.transport.abort()

    def connection_lost(self, exc: Exception | None) -> None:
        if self._timer is not None:
            self._timer.cancel()
        if self._proving is not None and self._proving[3]:  # left without proving itself
            self._proving = None
            self.server.counters["refused_auth"] += 1
        if self.acking is not None:
            self.acking.detach_stream(self.key, self._ack)
            self.acking = None
        self.port = None
        self.server.forget(self)
        if self.ring is not None:
            self.ring.close()
            self.ring = None
