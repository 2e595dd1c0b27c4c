"""The host side of the control channel (docs/protocol.md, section 1).

How it works: the agent's end of a Unix socket pair is inherited as `SDRPEER_CONTROL_FD`. Bytes
read from it go through `ControlDecoder`, a pure core: the shared framing
(`sdrpeer.control.stream`, the same code the agent uses) cuts the msgpack stream into maps and
enforces the limits (a map over 1 MiB, or a value that is not a map with a str `"t"`, is a
`ProtocolError`); the codec (`sdrpeer.control.codec`) makes a command dataclass of each map that
carries an integer `"id"`, delivered as a `Request`. A command the codec cannot read (unknown
`"t"`, a field missing or of the wrong type) becomes a `Refusal`: the host answers it `ok=false`
with the codec's words and keeps the channel. `Part`s (a big value cut up,
`sdrpeer.control.parts`) are collected, and the `restore` they belong to gets their bytes as
`Request.blob` (or is refused when they do not add up). `ControlChannel` is the asyncio shell:
it feeds the decoder, hands requests and refusals to a callback, writes reports (message
dataclasses) at once, sends a heartbeat every 0.5 s, and calls `on_closed` exactly once when
the channel ends: the agent closed it (the agent died), a protocol error closed it, or the
parent pid changed. A host must never outlive its agent, so `arm_parent_death_signal` also asks
Linux to send SIGTERM when the parent goes away (unless the agent armed a signal of its own, e.g.
SIGKILL in its pre-exec hook: that one is kept).
"""

from __future__ import annotations

import asyncio
import logging
import os
import signal
import socket
import sys
import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

from sdrpeer.control.codec import (
    decode_command,
    decode_part,
    encode,
    encode_all,
    id_of,
    type_of,
)
from sdrpeer.control.messages import Command, Heartbeat, Part, Report, Restore
from sdrpeer.control.parts import MAX_BLOB, PartAssembler
from sdrpeer.control.stream import MAX_MESSAGE, MessageStream
from sdrpeer.errors import PartError, ProtocolError

log = logging.getLogger("sdrpeer.host.control")

__all__ = [
    "HEARTBEAT_INTERVAL",
    "MAX_MESSAGE",
    "ControlChannel",
    "ControlDecoder",
    "ProtocolError",
    "Refusal",
    "Request",
    "arm_parent_death_signal",
]

HEARTBEAT_INTERVAL = 0.5
"""Seconds between two heartbeats."""


@dataclass(frozen=True, slots=True)
class Request:
    """One agent -> host command, read."""

    id: int
    """The id the reply carries back."""
    command: Command
    """The command."""
    blob: bytes | None = None
    """The bytes its `part`s carried (a `restore`'s state), else None."""


@dataclass(frozen=True, slots=True)
class Refusal:
    """A command the host cannot read: it answers `ok=false` with `error`."""

    id: int
    """The id the reply carries back."""
    t: str
    """Its `"t"`."""
    error: str
    """Why (the codec's or the parts' words)."""


class ControlDecoder:
    """Cuts the byte stream from the agent into requests and refusals (pure: no I/O, no clock)."""

    def __init__(self, max_message: int = MAX_MESSAGE, max_blob: int = MAX_BLOB) -> None:
        self._stream = MessageStream(max_message)
        self._parts = PartAssembler()
        self.max_blob = max_blob
        """The most bytes one command's parts may carry."""
        self.ignored = 0
        """Maps that were well-formed but not commands (no integer id): logged and skipped."""

    def feed(self, data: bytes) -> list[Request | Refusal]:
        """Consume `data`; return the complete commands in it; raise ProtocolError."""
        out: list[Request | Refusal] = []
        for raw in self._stream.feed(data):
            ident = id_of(raw)
            if ident is None and type_of(raw) == Part.T:
                part = decode_part(raw)
                self._parts.add(part.of, part.data, self.max_blob)
            elif ident is None:
                self.ignored += 1
                log.warning("control: %r without an integer id ignored", type_of(raw))
            else:
                out.append(self._request(raw, ident))
        return out

    def _request(self, raw: dict[str, Any], ident: int) -> Request | Refusal:
        try:
            command = decode_command(raw)
        except ProtocolError as exc:
            self._parts.drop(ident)
            return Refusal(ident, type_of(raw), str(exc))
        if not isinstance(command, Restore):
            return Request(ident, command)
        try:
            blob = self._parts.take(ident, command.size)
        except PartError as exc:
            return Refusal(ident, command.T, f"{command.T}: {exc}")
        return Request(ident, command, blob)


def arm_parent_death_signal(sig: int = signal.SIGTERM) -> bool:
    """Have Linux send `sig` when our parent dies, unless the agent already armed one (it wins)."""
    if not sys.platform.startswith("linux"):
        return False
    import ctypes  # noqa: PLC0415 - only on Linux, only here

    try:
        libc = ctypes.CDLL(None, use_errno=True)
        current = ctypes.c_int(0)
        if libc.prctl(2, ctypes.byref(current), 0, 0, 0) == 0 and current.value:  # GET
            return True
        return int(libc.prctl(1, sig, 0, 0, 0)) == 0  # 1 = PR_SET_PDEATHSIG
    except (OSError, AttributeError):
        return False


class ControlChannel(asyncio.Protocol):
    """The asyncio shell: socket in, commands out; reports and heartbeats written at once."""

    def __init__(
        self,
        on_command: Callable[[Request | Refusal], None],
        on_closed: Callable[[str], None],
        counters: Callable[[], dict[str, dict[str, int]]],
        *,
        data_counters: Callable[[], dict[str, int]] | None = None,
        endpoints: Callable[[], dict[str, list[str]]] | None = None,
        clock: Callable[[], float] = time.time,
        heartbeat_interval: float = HEARTBEAT_INTERVAL,
    ) -> None:
        self._on_command = on_command
        self._on_closed = on_closed
        self._counters = counters
        self._data_counters = data_counters
        self._endpoints = endpoints
        self._clock = clock
        self._interval = heartbeat_interval
        self._decoder = ControlDecoder()
        self._transport: asyncio.Transport | None = None
        self._lost: asyncio.Future[None] | None = None
        self._beat: asyncio.TimerHandle | None = None
        self._ppid = os.getppid()
        self._closed_reason: str | None = None
        self.protocol_errors = 0
        """Protocol errors seen (each one closes the channel)."""

    @classmethod
    async def open(
        cls, fd: int, *args: Any, **kwargs: Any
    ) -> ControlChannel:  # pragma: no cover - thin
        """Wrap the inherited socket `fd` in a running channel."""
        sock = socket.socket(fileno=fd)
        loop = asyncio.get_running_loop()
        channel = cls(*args, **kwargs)
        await loop.create_unix_connection(lambda: channel, sock=sock)
        return channel

    @property
    def closed(self) -> bool:
        """True once the channel has ended."""
        return self._closed_reason is not None

    def send(self, report: Report, *before: Part) -> None:
        """Write one report now, `before` first in one write (dropped once the channel ended)."""
        if self._transport is not None and self._closed_reason is None:
            self._transport.write(encode_all([*before, report]) if before else encode(report))

    def send_heartbeat(self) -> None:
        """Write a heartbeat with the current counters."""
        data = None if self._data_counters is None else self._data_counters() or None
        endpoints = None if self._endpoints is None else self._endpoints()
        self.send(Heartbeat(self._clock(), self._counters(), data, endpoints))

    def close(self) -> None:
        """End the channel from our side (after the reports already queued are written)."""
        if self._closed_reason is None:
            self._closed_reason = "closed by the host"
            if self._beat is not None:
                self._beat.cancel()
            if self._transport is not None:
                self._transport.close()

    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        """Start the heartbeat."""
        assert isinstance(transport, asyncio.Transport)
        self._transport = transport
        self._lost = asyncio.get_running_loop().create_future()
        self._schedule_beat()

    def data_received(self, data: bytes) -> None:
        """Decode and dispatch; a protocol error closes the channel."""
        try:
            requests = self._decoder.feed(data)
        except ProtocolError as exc:
            self.protocol_errors += 1
            log.error("control: protocol error: %s; closing the channel", exc)
            self._end(f"protocol error: {exc}")
            return
        for request in requests:
            self._on_command(request)

    def eof_received(self) -> bool:
        """The agent closed its end: we end too."""
        self._end("the agent closed the control channel")
        return False

    async def wait_closed(self) -> None:
        """Return once the socket is closed (the reports queued before are written)."""
        if self._lost is not None:
            await asyncio.shield(self._lost)

    def connection_lost(self, exc: Exception | None) -> None:
        """The socket is gone."""
        if self._lost is not None and not self._lost.done():
            self._lost.set_result(None)
        self._end(f"control channel lost: {exc}" if exc else "control channel closed")

    def _schedule_beat(self) -> None:
        """Arm the next heartbeat."""
        loop = asyncio.get_running_loop()
        self._beat = loop.call_later(self._interval, self._on_beat)

    def _on_beat(self) -> None:
        """Send a heartbeat, and check that our parent is still the agent that started us."""
        if self._closed_reason is not None:
            return
        if os.getppid() != self._ppid:
            self._end(f"parent {self._ppid} is gone")
            return
        try:
            self.send_heartbeat()
        finally:
            self._schedule_beat()

    def _end(self, reason: str) -> None:
        """Close once and tell the owner why."""
        if self._closed_reason is not None:
            return
        self._closed_reason = reason
        if self._beat is not None:
            self._beat.cancel()
        if self._transport is not None:
            self._transport.close()
        self._on_closed(reason)
