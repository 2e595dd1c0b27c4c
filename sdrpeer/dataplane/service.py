"""Service bindings on the data plane: calls from a consumer to a provider, replies back.

How it works (docs/protocol.md section 2, "Service calls"): a binding reuses the data stream's
listener, hello and authenticated, encrypted handshake. The consumer's host (`ServiceClient`)
dials the provider host's `DataServer` with a hello whose ``in`` names the provider's service
port and whose ``svc`` is the consumer's interface id; the provider's host refuses an unknown
port or another interface like any bad hello. Then both directions carry msgpack arrays on the
same socket: requests ``[call_id, method, arg]`` (call_id an unsigned integer, new per call on
the socket), replies ``[call_id, ok, value]`` (value the result, or ``[kind, message]`` when ok
is false), in any order (an async handler may answer later calls first).

At the provider, the connection's `Receiver` reads requests with the frame decoder (its limits,
its error counting) through `request_frame`, and hands each one to a `ServiceStream`, which
passes it to the service port and writes the reply back. A request that is not
``[uint, str, value]`` breaks the connection like any malformed frame; a ``[uint, value]`` frame
on a service binding is answered with a ``ProtocolError`` reply. A reply that cannot be encoded
or is larger than the maximum frame is replaced by an error reply.

At the consumer, `ServiceClient` dials on the first call (and again after the socket is lost),
keeps the calls in flight by id and completes each with its reply. A call fails with
`ConnectionError` (the SDK's `ServiceUnavailable`) when the provider cannot be reached or
refuses the hello, when the socket is lost before the reply, and when the binding is re-pointed
(`repoint`: the provider moved) or closed while the call is in flight: such calls are not
retried, since the provider may have run them; the next call goes to the new address.
"""

from __future__ import annotations

import asyncio
import logging
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Final

import msgpack

from sdrpeer.dataplane.address import parse_address
from sdrpeer.dataplane.auth import DataAuth
from sdrpeer.dataplane.frames import DEFAULT_MAX_FRAME, Hello
from sdrpeer.dataplane.link import Link, dial
from sdrpeer.dataplane.port_api import ServicePortLike
from sdrpeer.dataplane.refusals import DialRefusals
from sdrpeer.errors import FrameError

__all__ = ["Call", "ServiceClient", "ServiceStream", "request_frame"]

log = logging.getLogger("sdrpeer.dataplane")
_packb: Final = msgpack.packb
METHOD_MAX: Final = 100
"""The longest method name a request may carry."""
RECORD_SLACK: Final = 1024 * 1024
"""An encrypted record may carry a reply of the maximum size and more."""


@dataclass(frozen=True, slots=True)
class Call:
    """One decoded request (what `request_frame` turns ``[call_id, method, arg]`` into)."""

    method: str
    arg: Any


def request_frame(obj: list[Any]) -> list[Any]:
    """``[call_id, method, arg]`` -> ``[call_id, Call]`` (the frame decoder's three-element hook
    on a service binding); FrameError("malformed") when it is not one."""
    call_id, method, arg = obj
    if type(call_id) is not int or call_id < 0:
        raise FrameError("malformed", f"request: call id is not a uint: {call_id!r:.40}")
    if type(method) is not str or not 0 < len(method) <= METHOD_MAX:
        raise FrameError("malformed", f"request: method must be a string of 1-{METHOD_MAX} chars")
    return [call_id, Call(method, arg)]


def encode_result(call_id: int, ok: bool, value: Any, max_frame: int) -> bytes:
    """A reply's bytes; an error reply instead when `value` cannot be encoded or is too large."""
    try:
        data: bytes = _packb([call_id, ok, value])
    except (TypeError, ValueError, OverflowError) as exc:
        data = _packb([call_id, False, ["UnencodableReply", f"{type(value).__name__}: {exc}"]])
    if len(data) > max_frame:
        text = f"reply of {len(data)} bytes, the maximum is {max_frame}"
        data = _packb([call_id, False, ["OversizedReply", text]])
    return data


class ServiceStream:
    """The provider's end of one binding: takes the decoded requests, writes the replies."""

    def __init__(
        self,
        port: ServicePortLike,
        send: Callable[[bytes], None],
        counters: Counter[str],
        max_frame: int = DEFAULT_MAX_FRAME,
    ) -> None:
        self.port = port
        self.send = send
        """Writes to the consumer (the receiver's writer: sealed on an encrypted socket); does
        nothing once the socket is closed."""
        self.counters = counters
        self.max_frame = max_frame

    def deliver(self, value: Any, seq: int, conn: str) -> None:
        """One request (`value` a `Call`; anything else is answered with an error)."""
        self.counters["calls"] += 1
        if type(value) is not Call:
            self.counters["refused_call"] += 1
            self.reply(seq, False, ["ProtocolError", "expected [call_id, method, arg]"])
            return
        self.port.serve(seq, value.method, value.arg, self.reply)

    def refuse(self) -> None:
        """A malformed request (the server counted it; the connection closes)."""

    def reply(self, call_id: int, ok: bool, value: Any) -> None:
        """Write one reply."""
        self.send(encode_result(call_id, ok, value, self.max_frame))


class ServiceClient:
    """The consumer's end of a binding: its calls, over one socket to the provider's host."""

    def __init__(
        self,
        conn_id: str,
        to: str,
        port: str,
        from_: str,
        interface_id: str,
        *,
        auth: DataAuth | None = None,
        encrypt: bool = True,
        max_frame: int = DEFAULT_MAX_FRAME,
        max_pending: int = 1024,
        dial_timeout: float = 5.0,
    ) -> None:
        parse_address(to)  # ValueError now, not at the first call
        self.conn_id = conn_id
        self.to = to
        """The provider host's data address."""
        self.hello = Hello(conn_id, port, from_, {}, svc=interface_id)
        self.auth = auth
        self.encrypt = encrypt
        self.max_frame = max_frame
        self.max_pending = max_pending
        """Calls in flight beyond this fail at once."""
        self.dial_timeout = dial_timeout
        self.counters: Counter[str] = Counter()
        """calls, replies, late (a reply after its caller gave up), lost (calls failed by a
        lost, re-pointed or closed socket), dials, refused (dials that failed)."""
        self.refusals = DialRefusals(conn_id)
        """Dials the provider's host refused (its error reply, a proof that does not hold),
        told to its `on_refused` (sdrpeer.dataplane.refusals)."""
        self._link: Link | None = None
        self._dialing: asyncio.Future[Link] | None = None
        self._pending: dict[int, tuple[asyncio.Future[tuple[bool, Any]], Link]] = {}
        self._next = 1
        self._closed = False

    @property
    def connected(self) -> bool:
        """True while a socket to the provider is open."""
        return self._link is not None

    @property
    def in_flight(self) -> int:
        """Calls waiting for their reply."""
        return len(self._pending)

    async def request(self, method: str, arg: Any) -> tuple[bool, Any]:
        """(ok, value or ``[kind, message]``) of one call; ConnectionError when the provider is
        unreachable or the socket ends before the reply (see the module doc); FrameError when
        `arg` cannot be encoded or is over the maximum frame."""
        if self._closed:
            raise ConnectionError("the binding is closed")
        if len(self._pending) >= self.max_pending:
            raise ConnectionError(f"{self.max_pending} calls already in flight")
        link = self._link or await self._connect()
        call_id = self._next
        self._next += 1
        try:
            data: bytes = _packb([call_id, method, arg])
        except (TypeError, ValueError, OverflowError) as exc:
            raise FrameError("unencodable", f"{type(arg).__name__}: {exc}") from None
        if len(data) > self.max_frame:
            raise FrameError("oversized", f"request of {len(data)} bytes, max {self.max_frame}")
        future: asyncio.Future[tuple[bool, Any]] = asyncio.get_running_loop().create_future()
        self._pending[call_id] = (future, link)
        self.counters["calls"] += 1
        try:
            link.write(data)
            return await future
        finally:
            self._pending.pop(call_id, None)

    def repoint(self, to: str) -> None:
        """Send the next calls to `to` (the provider moved); calls in flight fail."""
        parse_address(to)
        self.to = to
        self._dialing = None  # a dial still under way to the old address fails its callers
        self._drop_link(f"re-pointed to {to}")

    async def close(self) -> None:
        """Fail the calls in flight and close the socket."""
        self._closed = True
        self._drop_link("the binding was closed")
        if self._dialing is not None:
            self._dialing.cancel()

    def _drop_link(self, why: str) -> None:
        link, self._link = self._link, None
        if link is None:
            return
        self._fail(link, why)
        link.transport.close()

    def _fail(self, link: Link, why: str) -> None:
        for future, on in list(self._pending.values()):
            if on is link and not future.done():
                self.counters["lost"] += 1
                future.set_exception(ConnectionError(why))

    async def _connect(self) -> Link:
        if self._dialing is None:
            self._dialing = asyncio.ensure_future(self._dial(self.to))
            self._dialing.add_done_callback(_retrieve)
        dialing = self._dialing
        try:
            return await asyncio.shield(dialing)
        except asyncio.CancelledError:
            task = asyncio.current_task()
            if not dialing.cancelled() or (task is not None and task.cancelling()):
                raise  # the caller itself is being cancelled
            # the dial was (`close`): a ConnectionError for the caller, not a cancel that would
            # end its component's execution context
            raise ConnectionError("the binding was closed while connecting") from None

    async def _dial(self, to: str) -> Link:
        self.counters["dials"] += 1
        try:
            async with asyncio.timeout(self.dial_timeout):
                link = await dial(
                    to,
                    self.hello,
                    _ignore,
                    self._lost,
                    shm_size=0,
                    auth=self.auth,
                    encrypt=self.encrypt,
                    max_record=self.max_frame + RECORD_SLACK,
                    on_reply=self._reply,
                    max_reply=self.max_frame,
                )
        except (OSError, TimeoutError, FrameError) as exc:
            self.counters["refused"] += 1
            if isinstance(exc, FrameError) and exc.reason == "refused":
                self.refusals.refused(exc.detail)
            text = str(exc) or type(exc).__name__
            raise ConnectionError(f"provider at {to}: {text}") from None
        finally:
            if self._dialing is asyncio.current_task():  # not a newer dial (after a repoint)
                self._dialing = None
        if self._closed or to != self.to:
            link.transport.close()
            raise ConnectionError(f"re-pointed from {to} while connecting")
        self._link = link
        self.refusals.through()
        log.info("service binding %s: connected to %s", self.conn_id, to)
        return link

    def _lost(self, link: Link) -> None:
        if link is self._link:
            self._link = None
        self._fail(link, "the connection to the provider was lost")

    def _reply(self, obj: list[Any]) -> None:
        call_id, ok, value = obj
        if type(call_id) is not int or type(ok) is not bool:
            raise ValueError(f"malformed reply {obj!r:.40}")  # breaks the link
        entry = self._pending.get(call_id)
        if entry is None or entry[0].done():
            self.counters["late"] += 1
            return
        self.counters["replies"] += 1
        entry[0].set_result((ok, value))


def _ignore(link: Link) -> None:
    """Writes are not flow-controlled here: calls are bounded by `max_pending`."""


def _retrieve(future: asyncio.Future[Link]) -> None:
    """A dial nobody waits for any more must not log 'exception never retrieved'."""
    if not future.cancelled():
        future.exception()
