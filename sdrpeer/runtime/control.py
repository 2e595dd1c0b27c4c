"""The agent's end of a host's control channel (docs/protocol.md, section 1).

How it works: `ControlDecoder` is the pure part: bytes in, validated messages out (msgpack maps
with a string "t", at most 1 MiB each, framed by `sdrpeer.control.stream` exactly as the host does;
anything else raises `ProtocolError`). `ControlChannel` is
its asyncio shell over the agent's end of a `socket.socketpair()`: `command(t, **fields)` sends a
map with a fresh integer id and awaits the matching `reply` (timeout -> `CommandError` "timeout",
ok=false -> "refused", channel gone -> "closed"); reports (`hello`, `state`, `heartbeat`,
`fault`) go to the handler registered for their type. A value too big for one message travels as
`part` messages (`sdrpeer.control.parts`): `command(..., blob=b)` writes b's parts and the command
(with `"size"`) in one write; `command(..., accept=n)` collects up to n bytes of parts sent before
the reply and returns them as `reply["blob"]` (parts that do not add up refuse the command). A
protocol error closes the channel, is counted in `counters["protocol_errors"]`, and `on_close`
hears why; the supervisor then treats the host as failed.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import socket
from collections.abc import Callable, Collection, Mapping
from typing import Any

from sdrpeer.control.parts import PartAssembler, check_part, parts
from sdrpeer.control.stream import MAX_MESSAGE, PROTOCOL, MessageStream, encode
from sdrpeer.errors import CommandError, PartError, ProtocolError
from sdrpeer.vocabulary import LifecycleState

REPORTS = ("hello", "state", "heartbeat", "fault", "part")
LIFECYCLE = tuple(LifecycleState)
_READ = 64 * 1024
log = logging.getLogger(__name__)

__all__ = [
    "LIFECYCLE",
    "MAX_MESSAGE",
    "REPORTS",
    "CommandError",
    "ControlChannel",
    "ControlDecoder",
    "ProtocolError",
    "Report",
    "ReportHandler",
    "check_report",
    "encode",
]

Report = dict[str, Any]
ReportHandler = Callable[[Report], None]


def check_report(msg: Report) -> None:
    """Validate the fields of a report the agent acts on; raise ProtocolError if wrong."""
    t = msg["t"]
    if t == "hello":
        if msg.get("protocol") != PROTOCOL:
            raise ProtocolError(f"hello: protocol {msg.get('protocol')!r}, we speak {PROTOCOL}")
        if not isinstance(msg.get("pid"), int) or not isinstance(msg.get("data", {}), dict):
            raise ProtocolError("hello: pid must be an integer and data a map")
    elif t == "state" and msg.get("state") not in LIFECYCLE:
        raise ProtocolError(f"state: unknown state {msg.get('state')!r}")
    elif t == "reply" and (
        not isinstance(msg.get("id"), int) or not isinstance(msg.get("ok"), bool)
    ):
        raise ProtocolError("reply: id must be an integer and ok a boolean")
    elif t == "part":
        try:
            check_part(msg)
        except PartError as e:
            raise ProtocolError(str(e)) from None


class ControlDecoder:
    """Turns the byte stream from a host into validated reports (pure)."""

    def __init__(self, max_message: int = MAX_MESSAGE) -> None:
        self._stream = MessageStream(max_message)

    def feed(self, data: bytes) -> list[Report]:
        """Every complete report in the stream so far; ProtocolError on a bad one."""
        reports = self._stream.feed(data)
        for msg in reports:
            check_report(msg)
        return reports


class ControlChannel:
    """Commands to and reports from one host, over the agent's end of a socket pair."""

    def __init__(
        self,
        sock: socket.socket,
        handlers: Mapping[str, ReportHandler],
        on_close: Callable[[str | None], None],
        *,
        name: str = "",
        command_timeout: float = 5.0,
    ) -> None:
        self.name = name
        self.command_timeout = command_timeout
        self.counters = {"messages_in": 0, "messages_out": 0, "protocol_errors": 0, "late": 0}
        self._sock = sock
        self._handlers = dict(handlers)
        self._on_close = on_close
        self._decoder = ControlDecoder()
        self._pending: dict[int, asyncio.Future[Report]] = {}
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
        self,
        t: str,
        *,
        wait: float | None = None,
        blob: bytes | None = None,
        accept: int = 0,
        **fields: Any,
    ) -> Report:
        """Send one command, await its reply for `wait` seconds; CommandError unless ok.

        `blob` goes along in parts; `accept` > 0 takes up to that many bytes of parts back, as
        `reply["blob"]`.
        """
        if self.closed or self._writer is None:
            raise CommandError(t, "closed")
        cid = self._next_id
        self._next_id += 1
        future: asyncio.Future[Report] = asyncio.get_running_loop().create_future()
        self._pending[cid] = future
        self._sent[cid] = (t, asyncio.get_running_loop().time())
        if accept > 0:
            self._accept[cid] = accept
        msg = {"t": t, "id": cid, **fields}
        if blob is None:
            data = encode(msg)
        else:
            msg["size"] = len(blob)
            data = b"".join([*map(encode, parts(cid, blob)), encode(msg)])
        try:
            self._writer.write(data)
            self.counters["messages_out"] += 1
            async with asyncio.timeout(self.command_timeout if wait is None else wait):
                await self._writer.drain()
                reply = await future
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
        if not reply.get("ok"):
            raise CommandError(t, "refused", str(reply.get("error") or ""))
        return reply

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

    def _dispatch(self, msg: Report) -> None:
        self.counters["messages_in"] += 1
        t = msg["t"]
        if t == "part":
            of, data = check_part(msg)
            if of in self._accept:
                self._parts.add(of, data, self._accept[of])
            else:
                self.counters["late"] += 1
            return
        if t == "reply":
            future = self._pending.get(msg["id"])
            if future is None or future.done():
                self.counters["late"] += 1
            else:
                future.set_result(self._with_blob(msg))
            return
        handler = self._handlers.get(t)
        if handler is not None:
            handler(msg)

    def _with_blob(self, msg: Report) -> Report:
        """A reply to a command that accepts parts gets their bytes as "blob" (or fails)."""
        cid = msg["id"]
        if cid not in self._accept or not msg.get("ok"):
            return msg
        try:
            return {**msg, "blob": self._parts.take(cid, msg.get("size"))}
        except PartError as e:
            return {**msg, "ok": False, "error": f"the state sent back: {e}"}

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
