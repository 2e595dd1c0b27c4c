"""The agent's end of a host's control channel (docs/protocol.md, section 1).

How it works: `ControlDecoder` is the pure part: bytes in, report dataclasses out (msgpack maps
with a string "t", at most 1 MiB each, framed by `sdrpeer.control.stream` exactly as the host does,
read by the codec, which checks every field; anything else raises `ProtocolError`; a report of an
unknown type is ignored and counted). `ControlChannel` is its asyncio shell over the agent's end of
a `socket.socketpair()`: `command(cmd)` sends a command dataclass with a fresh integer id and
awaits the matching `Reply` (timeout -> `CommandError` "timeout", ok=false -> "refused", channel
gone -> "closed"); the other reports (`Hello`, `State`, `Heartbeat`, `Fault`) go to `on_report`.
A value too big for one message travels as `Part`s (`sdrpeer.control.parts`): `command(Restore(n),
blob=b)` writes b's parts and the command in one write; `fetch(cmd, limit)` collects up to `limit`
bytes of parts sent before the reply and returns them (parts that do not add up refuse the
command). A protocol error closes the channel, is counted in `counters["protocol_errors"]`, and
`on_close` hears why; the supervisor then treats the host as failed.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Callable, Collection

from sdrpeer.control.codec import decode_report, encode, encode_all
from sdrpeer.control.messages import Command, Part, Reply, Report, Restore
from sdrpeer.control.parts import PartAssembler, parts
from sdrpeer.control.stream import MAX_MESSAGE, MessageStream
from sdrpeer.errors import CommandError, PartError, ProtocolError

_READ = 64 * 1024
log = logging.getLogger(__name__)

__all__ = [
    "MAX_MESSAGE",
    "CommandError",
    "ControlChannel",
    "ControlDecoder",
    "ProtocolError",
    "ReportHandler",
]

ReportHandler = Callable[[Report], None]
"""Where the reports that answer no command go (hello, state, heartbeat, fault)."""


class ControlDecoder:
    """Turns the byte stream from a host into report dataclasses (pure)."""

    def __init__(self, max_message: int = MAX_MESSAGE) -> None:
        self._stream = MessageStream(max_message)
        self.ignored = 0
        """Maps of an unknown type: ignored (docs/protocol.md)."""

    def feed(self, data: bytes) -> list[Report | Part]:
        """Every complete report in the stream so far; ProtocolError on a bad one."""
        out: list[Report | Part] = []
        for raw in self._stream.feed(data):
            msg = decode_report(raw)
            if msg is None:
                self.ignored += 1
            else:
                out.append(msg)
        return out


class ControlChannel:
    """Commands to and reports from one host, over the agent's end of a socket pair."""

    def __init__(
        self,
        sock: socket.socket,
        on_report: ReportHandler,
        on_close: Callable[[str | None], None],
        *,
        name: str = "",
        command_timeout: float = 5.0,
    ) -> None:
        self.name = name
        self.command_timeout = command_timeout
        self.counters = {"messages_in": 0, "messages_out": 0, "protocol_errors": 0, "late": 0}
        self._sock = sock
        self._on_report = on_report
        self._on_close = on_close
        self._decoder = ControlDecoder()
        self._pending: dict[int, asyncio.Future[tuple[Reply, bytes | None]]] = {}
        self._sent: dict[int, tuple[str, float]] = {}  # command id -> (its type, loop time sent)
        self._accept: dict[int, int] = {}  # command id -> bytes of parts its reply may bring
        self._parts = PartAssembler()
        self._next_id = 1
        self._writer: asyncio.StreamWriter | None = None
        self._reader_task: asyncio.Task[None] | None = None
        self.closed = False

    def pending_since(self, kinds: Collection[str]) -> float | None:
        """Loop time the oldest command of one of `kinds` still awaiting its reply was sent
        (None: none is)."""
        times = [t for kind, t in self._sent.values() if kind in kinds]
        return min(times, default=None)

    async def open(self) -> None:
        """Start reading reports."""
        reader, self._writer = await asyncio.open_unix_connection(sock=self._sock)
        self._reader_task = asyncio.create_task(self._read(reader))

    async def command(
        self, cmd: Command, *, wait: float | None = None, blob: bytes | None = None
    ) -> Reply:
        """Send one command, await its reply for `wait` seconds; CommandError unless ok.

        `blob` goes along in parts, right before `cmd`, a `Restore` saying its size.
        """
        if blob is not None and not (isinstance(cmd, Restore) and cmd.size == len(blob)):
            raise ValueError(f"{cmd.T}: parts go only with a restore that says their size")
        reply, _ = await self._call(cmd, wait, blob, 0)
        return reply

    async def fetch(self, cmd: Command, limit: int, *, wait: float | None = None) -> bytes:
        """Send one command whose reply brings a value in parts (snapshot); up to `limit` bytes
        of them, else CommandError "refused"."""
        _, blob = await self._call(cmd, wait, None, limit)
        return blob if blob is not None else b""

    async def _call(
        self, cmd: Command, wait: float | None, blob: bytes | None, accept: int
    ) -> tuple[Reply, bytes | None]:
        t = cmd.T
        if self.closed or self._writer is None:
            raise CommandError(t, "closed")
        cid = self._next_id
        self._next_id += 1
        loop = asyncio.get_running_loop()
        future: asyncio.Future[tuple[Reply, bytes | None]] = loop.create_future()
        self._pending[cid] = future
        self._sent[cid] = (t, loop.time())
        if accept > 0:
            self._accept[cid] = accept
        data = encode(cmd, cid)
        if blob is not None:
            data = encode_all(parts(cid, blob)) + data
        try:
            self._writer.write(data)
            self.counters["messages_out"] += 1
            async with asyncio.timeout(self.command_timeout if wait is None else wait):
                await self._writer.drain()
                reply, got = await future
        except TimeoutError:
            raise CommandError(t, "timeout") from None
        except CommandError as e:
            raise CommandError(t, e.reason, e.detail) from None
        except (ConnectionError, OSError) as e:
            raise CommandError(t, "closed", str(e)) from None
        finally:
            self._pending.pop(cid, None)
            self._sent.pop(cid, None)
            self._accept.pop(cid, None)
        if not reply.ok:
            raise CommandError(t, "refused", reply.error or "")
        return reply, got

    async def _read(self, reader: asyncio.StreamReader) -> None:
        reason: str | None = None
        try:
            while data := await reader.read(_READ):
                for msg in self._decoder.feed(data):
                    self._dispatch(msg)
        except ProtocolError as e:
            self.counters["protocol_errors"] += 1
            reason = f"protocol error: {e}"
            log.warning("%s: control channel %s; closing it", self.name, reason)
        except (ConnectionError, OSError) as e:
            reason = f"read failed: {e}"
        self._shutdown(reason)

    def _dispatch(self, msg: Report | Part) -> None:
        self.counters["messages_in"] += 1
        if isinstance(msg, Part):
            if msg.of in self._accept:
                self._parts.add(msg.of, msg.data, self._accept[msg.of])
            else:
                self.counters["late"] += 1
        elif isinstance(msg, Reply):
            future = self._pending.get(msg.id)
            if future is None or future.done():
                self.counters["late"] += 1
            else:
                future.set_result(self._with_blob(msg))
        else:
            self._on_report(msg)

    def _with_blob(self, reply: Reply) -> tuple[Reply, bytes | None]:
        """A reply to a command that accepts parts comes with their bytes (or fails)."""
        cid = reply.id
        if cid not in self._accept or not reply.ok:
            return reply, None
        try:
            return reply, self._parts.take(cid, reply.size)
        except PartError as e:
            return Reply(cid, False, f"the state sent back: {e}"), None

    def _shutdown(self, reason: str | None) -> None:
        if self.closed:
            return
        self.closed = True
        for future in self._pending.values():
            if not future.done():
                future.set_exception(CommandError("command", "closed", reason or "EOF"))
        if self._writer is not None:
            self._writer.close()
        else:
            self._sock.close()
        self._on_close(reason)

    async def close(self) -> None:
        """Close the channel (the host sees EOF) and stop reading."""
        task = self._reader_task
        self._shutdown(None)
        if task is not None and task is not asyncio.current_task():
            task.cancel()
            with contextlib.suppress(asyncio.CancelledError):
                await task
