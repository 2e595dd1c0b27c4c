"""The receiving side of data streams: one listener per host, many connections, many InPorts.

How it works: `DataServer` listens on TCP (and optionally a Unix socket, faster on the same robot).
Each accepted connection is a `Receiver` (sdrpeer.dataplane.receiver) with its own `FrameReader`.
The first message must be a hello naming an InPort that `resolve` knows and protocol version 1; it
is answered ``{"ok": true}``, or ``{"ok": false, "error": ...}`` and the connection is closed. Then
every received chunk (read into the connection's `FrameReader`: a reused buffer, big binary values
taken out without msgpack) is decoded and each frame goes to ``port.deliver(value, seq, conn_id)``
at once: no queue or task per frame. A bad frame (oversized, malformed) calls ``port.refuse()``, is
counted by reason, logged (first time per reason, then at most every ten seconds) and closes that
connection only. Connections beyond `max_connections` are answered with an error and closed; a
hello must arrive within `hello_timeout` seconds. On TCP, while a big frame is arriving,
SO_RCVLOWAT asks the kernel to wake the receiver only once up to 512 KiB more of it are there, not
for every batch of segments (measured: a third more throughput with 1 MB frames; every wake-up
costs a trip through the event loop). A hello that offers a shared-memory ring
(sdrpeer.dataplane.shm) gets it mapped (and its name unlinked); then a ``[seq, pos, length]``
frame's value is copied out of the ring just before it is delivered, and after each read the
position consumed is written back as the sender's credit. A hello that asks for acknowledgements
(``"ack"``) to an InPort that can give them (`attach_stream`, sdrpeer.sdk.inport) is answered
``"ack": true``; the port then calls back with the seq up to which the component took every frame,
written as ``[seq]`` on the same reverse direction as the credits. Such a connection outlives the
sender's end of stream until everything it delivered is acknowledged (so a repointed sender hears
the last of it); `close` sends what is due and closes gracefully, so a stopping instance tells its
senders exactly what it never took. A hello with ``svc`` opens a service binding to a provided
service port (`resolve_service`; sdrpeer.dataplane.service): requests in, replies back.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import os
from collections import Counter
from collections.abc import Callable

from sdrpeer.dataplane.address import format_tcp
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.dataplane.frames import DEFAULT_MAX_FRAME
from sdrpeer.dataplane.port_api import InPortLike, ServicePortLike
from sdrpeer.dataplane.receiver import Receiver

log = logging.getLogger("sdrpeer.dataplane")
_LOG_EVERY = 10.0


class DataServer:
    """Accepts data connections and delivers their frames to InPorts."""

    def __init__(
        self,
        resolve: Callable[[str], InPortLike | None],
        *,
        tcp_host: str | None = "127.0.0.1",
        tcp_port: int = 0,
        unix_path: str | None = None,
        max_frame: int = DEFAULT_MAX_FRAME,
        max_connections: int = 256,
        hello_timeout: float = 10.0,
        shm: bool = True,
        auth: DataAuth | None = None,
        resolve_service: Callable[[str], ServicePortLike | None] | None = None,
    ) -> None:
        self.resolve = resolve
        self.resolve_service: Callable[[str], ServicePortLike | None] = (
            resolve_service or _no_service
        )
        """The provided service port a service binding's hello names (sdrpeer.dataplane.service)."""
        self.tcp_host = tcp_host
        self.tcp_port = tcp_port
        self.unix_path = unix_path
        self.max_frame = max_frame
        self.max_connections = max_connections
        self.hello_timeout = hello_timeout
        self.shm = shm
        """Take the shared-memory rings senders on this machine offer."""
        self.auth = auth
        """The host's data keys: with any, only senders that prove they hold one get in."""
        self.quiesced = False
        """True while the component takes no frames (not ACTIVE): a sender that ends its side
        gets the acks due and the close at once, nothing more will be taken (`set_taking`)."""
        self.counters: Counter[str] = Counter()
        """accepted, rejected (hello refused or over the limit), refused_<reason> (refused_auth:
        a hello or proof without a valid data key), deliver_error, shm (connections that took a
        shared-memory ring), acked (acknowledged streams)."""
        self.bytes_in: Counter[str] = Counter()
        """Bytes received after the hello, by in-port name (for the port's `bytes_in`)."""
        self._servers: list[asyncio.Server] = []
        self._receivers: set[Receiver] = set()
        self._addresses: dict[str, str] = {}
        self._last_log: dict[str, float] = {}

    async def start(self) -> None:
        """Listen on TCP (port 0: a free port; `tcp_host` None: not at all) and, if configured,
        on the Unix socket."""
        loop = asyncio.get_running_loop()
        if self.tcp_host is not None:
            tcp = await loop.create_server(
                lambda: Receiver(self), self.tcp_host, self.tcp_port, reuse_address=True
            )
            self._servers.append(tcp)
            port = tcp.sockets[0].getsockname()[1]
            self._addresses["tcp"] = format_tcp(self.tcp_host, port)
        if self.unix_path is not None:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.unix_path)
            unix = await loop.create_unix_server(lambda: Receiver(self), self.unix_path)
            self._servers.append(unix)
            self._addresses["unix"] = self.unix_path

    def set_taking(self, taking: bool) -> None:
        """The component takes frames (ACTIVE) or not; when not, every acknowledged stream is
        told what was taken, and one whose sender already left is closed."""
        self.quiesced = not taking
        if taking:
            return
        for receiver in list(self._receivers):
            receiver.quiesce()

    @property
    def addresses(self) -> dict[str, str]:
        """Where we listen: {"tcp": "HOST:PORT", "unix": "/path"} (unix only when configured)."""
        return dict(self._addresses)

    @property
    def connections(self) -> int:
        """Connections currently open."""
        return len(self._receivers)

    async def close(self) -> None:
        """Stop listening and close every connection."""
        for server in self._servers:
            server.close()
        for receiver in list(self._receivers):
            receiver.finish()
        for server in self._servers:
            await server.wait_closed()
        self._servers.clear()
        if self.unix_path is not None and "unix" in self._addresses:
            with contextlib.suppress(FileNotFoundError):
                os.unlink(self.unix_path)

    def admit(self, receiver: Receiver) -> bool:
        """Count `receiver` among the open connections; False when no more are allowed."""
        if len(self._receivers) >= self.max_connections:
            return False
        self._receivers.add(receiver)
        return True

    def forget(self, receiver: Receiver) -> None:
        """`receiver` closed."""
        self._receivers.discard(receiver)

    def report(self, reason: str, conn: str, detail: str) -> None:
        """Log a refused or failed connection (at most once per `_LOG_EVERY` s per reason)."""
        now = asyncio.get_running_loop().time()
        last = self._last_log.get(reason)
        if last is None or now - last >= _LOG_EVERY:
            self._last_log[reason] = now
            count = self.counters[reason]
            log.warning("data connection %s: %s (%s; %d so far)", conn, reason, detail, count)


def _no_service(name: str) -> ServicePortLike | None:
    """A server that provides no services."""
    return None
