"""The runtime side of an InPort: per-connection sequence tracking and policy, one queue.

How it works: `deliver(value, seq, conn)` is called by the data plane for each received frame.
It counts sequence gaps per connection as `lost` (a connection's first frame sets the baseline; a
seq that goes back means the sender restarted), applies the connection's `ConnectorPolicy` (see
sdrpeer.sdk.policy) to one shared arrival-ordered queue, remembers the newest value for `read()`,
and wakes waiting readers and the OnInput execution context. It is synchronous, allocation-free
on the common path, and never raises for a well-typed call; `deliver_many` takes a read's
worth of frames at once (the data plane's path: one call, one wake-up, per read). The
component reads with `read()` (newest), `get_nowait()`/`get()`/`async for` (oldest first).

Acknowledged streams (sdrpeer.sdk.acks): a data-plane socket whose sender keeps frames until
they are acknowledged calls `attach_stream(conn, session, next_seq, send)` and delivers under
the key it returns (one per sender session). From then on every
queued value has a tag (the stream's `AckState` and the seq) in `_tags`, parallel to the queue,
so taking or evicting it moves the stream's acknowledged seq; acknowledgements are sent once per
event-loop iteration at most (`flush_acks`). Within one session a seq already received is a
replay of a frame this port has: it is dropped and counted in `duplicates`. A new session (the
sender restarted) starts the stream afresh at its `next_seq`.
"""

from __future__ import annotations

import asyncio
from collections import deque
from collections.abc import Callable
from typing import Any, Final

from sdrpeer.sdk.acks import AckState, SendAck
from sdrpeer.sdk.errors import NoData
from sdrpeer.sdk.policy import ConnectorPolicy
from sdrpeer.sdk.typed import PortTypeError, port_message

__all__ = ["InPortRuntime"]

_NOTHING: Final = object()
_SESSION_SEP: Final = "\x1f"
_SESSIONS_KEPT: Final = 4
_IN_ORDER: Final = ("all", "fifo")


class _Conn:
    """What an InPort tracks per incoming connection."""

    __slots__ = ("acks", "arrivals", "last_seq", "policy")

    def __init__(self, policy: ConnectorPolicy, last_seq: int) -> None:
        self.policy = policy
        self.last_seq = last_seq
        self.arrivals = 0
        self.acks: AckState | None = None


class InPortRuntime:
    """One component instance's input port: per-connection policy, one arrival-ordered queue."""

    __slots__ = (
        "_ack_soon",
        "_arity",
        "_conns",
        "_decode",
        "_decoded",
        "_dirty",
        "_listener",
        "_make",
        "_new",
        "_newest",
        "_queue",
        "_space_waiter",
        "_tags",
        "_waiter",
        "doc",
        "dropped",
        "duplicates",
        "frames_in",
        "lost",
        "name",
        "policy",
        "refused",
        "skipped",
        "type_id",
    )

    def __init__(
        self,
        name: str,
        policy: ConnectorPolicy | None = None,
        doc: str = "",
        port_type: type | None = None,
    ) -> None:
        self.name = name
        self.doc = doc
        info = port_message(port_type)
        self._decode = None if info is None else info.decode
        self._make = None if info is None else info.build
        self._arity = 0 if info is None else info.arity
        self._decoded: tuple[Any, Any] = (_NOTHING, _NOTHING)  # (newest as received, decoded)
        self.type_id = None if info is None else info.type_id
        """The message type's id (None: any value); senders of another type are refused."""
        self.policy = policy or ConnectorPolicy()
        """The default policy, for connections that were not registered with their own."""
        self.frames_in = self.dropped = self.lost = self.refused = 0
        self.skipped = 0
        self.duplicates = 0
        """Frames of an acknowledged stream received twice (a replay after a reconnect)."""
        self._queue: deque[Any] = deque()
        self._tags: deque[tuple[AckState, int] | None] | None = None  # see the module doc
        self._dirty: set[AckState] = set()
        self._ack_soon = False
        self._newest: Any = _NOTHING
        self._new = False
        self._conns: dict[str, _Conn] = {}
        self._waiter: asyncio.Future[None] | None = None
        self._space_waiter: asyncio.Future[None] | None = None
        self._listener: Callable[[int], None] | None = None
        """Told how many frames were queued, after each delivery (the OnInput context's)."""

    # -- the data plane's side -------------------------------------------------------------

    def connect(self, conn: str, policy: ConnectorPolicy | None = None) -> None:
        """Register connection `conn` with its policy (None: the port's default)."""
        old = self._conns.get(conn)
        self._conns[conn] = _Conn(policy or self.policy, old.last_seq if old else -1)

    def connection_policy(
        self, given: dict[str, Any] | None, *, acked: bool = True
    ) -> ConnectorPolicy:
        """The policy a connection whose own policy map is `given` gets at this port: the
        port's declared policy with the connection's `buffer` and `full` over it (its `push`
        and `skip` are the sender's: applied there, not twice). `full: block` holds only for
        an acknowledged stream (`acked`: the sender's window bounds what waits); otherwise the
        port's own `full` stays, so a hello cannot make the queue unbounded. ValueError when a
        value is bad."""
        self.policy.merged(given)  # every key checked, even those not applied here
        keys = {k: v for k, v in (given or {}).items() if k in ("buffer", "full")}
        if keys.get("full") == "block" and not acked:
            del keys["full"]
        return self.policy.merged(keys)

    def disconnect(self, conn: str) -> None:
        """Forget connection `conn` (frames already queued stay readable)."""
        self._conns.pop(conn, None)

    def deliver(self, value: Any, seq: int, conn: str) -> None:
        """Accept one received frame `[seq, value]` of connection `conn` (never blocks)."""
        c = self._conns.get(conn)
        if c is None:
            c = self._conns[conn] = _Conn(self.policy, -1)
        last = c.last_seq
        a = c.acks
        if a is not None and seq <= last:
            self.duplicates += 1  # a replay of a frame this port has had
            return
        if last >= 0 and seq > last + 1:
            self.lost += seq - last - 1
        c.last_seq = seq
        if self._decode is not None and (type(value) is not list or len(value) != self._arity):
            self.refused += 1  # not this port's type (an untyped sender): never queued
            if a is not None:
                self._refused(a, seq, overflow=False)
            return
        self.frames_in += 1
        p = c.policy
        q = self._queue
        tags = self._tags
        if p.push == "skip":
            c.arrivals += 1
            if (c.arrivals - 1) % (p.skip + 1):
                self.skipped += 1
                if a is not None:
                    self._refused(a, seq, overflow=False)
                return
        elif p.push == "new" and q:
            self.dropped += len(q)
            q.clear()
            if tags is not None:
                self._taken_all()  # replaced by design: not an overflow
        if len(q) >= p.buffer:
            if p.full == "drop":
                self.dropped += 1
                if a is not None:
                    self._refused(a, seq)
                return
            if p.full == "overwrite":
                q.popleft()
                self.dropped += 1
                if tags is not None:
                    self._evicted_one()
            # "block": never drop here; an acknowledged stream's sender stops at its window.
        q.append(value)
        if tags is not None:
            if a is not None:
                a.enq += 1
                tags.append((a, seq))
            else:
                tags.append(None)
        self._newest = value
        self._new = True
        w = self._waiter
        if w is not None:
            self._waiter = None
            if not w.done():
                w.set_result(None)
        if self._listener is not None:
            self._listener(1)

    def deliver_many(self, frames: list[list[Any]], conn: str) -> None:
        """`deliver` every ``[seq, value]`` of `frames`, oldest first: the data plane's batch,
        one call per read. Frames in order on an all/fifo connection with room for all of
        them (the common case) are queued in one tight loop, waking readers once; from the
        first other one on (a gap back, a wrong shape, a policy that thins or a buffer that
        could fill) each goes through `deliver`."""
        c = self._conns.get(conn)
        if c is None:
            c = self._conns[conn] = _Conn(self.policy, -1)
        q = self._queue
        n = 0
        if c.policy.push in _IN_ORDER and len(q) + len(frames) <= c.policy.buffer:
            a = c.acks
            last = c.last_seq
            arity = self._arity if self._decode is not None else -1
            append = q.append
            tags = self._tags
            tag_append = None if tags is None else tags.append
            lost = 0
            for seq, value in frames:
                if arity >= 0 and (type(value) is not list or len(value) != arity):
                    break  # not the port's type: `deliver` refuses it
                if seq != last + 1:
                    if seq <= last:
                        break  # a replay or a restarted sender: `deliver` sorts it out
                    if last >= 0:
                        lost += seq - last - 1
                last = seq
                append(value)
                if tag_append is not None:
                    tag_append(None if a is None else (a, seq))
                n += 1
            if n:
                c.last_seq = last
                self.lost += lost
                self.frames_in += n
                if a is not None:
                    a.enq += n
                self._newest = q[-1]
                self._new = True
                w = self._waiter
                if w is not None:
                    self._waiter = None
                    if not w.done():
                        w.set_result(None)
                if self._listener is not None:
                    self._listener(n)
        deliver = self.deliver
        for seq, value in frames[n:] if n else frames:
            deliver(value, seq, conn)

    # -- acknowledged streams (see the module doc) -------------------------------------------

    def attach_stream(self, conn: str, session: str, next_seq: int, send: SendAck) -> str:
        """A socket of an acknowledged stream opened: its acks go to `send` from now on.
        Returns the key its frames are delivered under (one per sender session, so two senders
        of one connection — an old copy still flushing, a new one — never mix)."""
        key = f"{conn}{_SESSION_SEP}{session}"
        c = self._conns.get(key)
        if c is None or c.acks is None:
            base = self._conns.get(conn)
            c = self._conns[key] = _Conn(base.policy if base else self.policy, next_seq - 1)
            c.acks = AckState(session, next_seq, send)
            if self._tags is None:
                self._tags = deque([None] * len(self._queue))
            self._forget_sessions(conn)
            return key
        c.acks.send = send  # the same sender again (a reconnect): tell it where we are
        c.acks.dirty = True
        self._schedule_acks(c.acks)
        return key

    def _forget_sessions(self, conn: str) -> None:
        """Keep the newest `_SESSIONS_KEPT` sessions of `conn` (older senders are gone)."""
        prefix = f"{conn}{_SESSION_SEP}"
        keys = [k for k in self._conns if k.startswith(prefix)]
        for key in keys[: max(0, len(keys) - _SESSIONS_KEPT)]:
            acks = self._conns[key].acks
            if acks is None or acks.send is None:
                del self._conns[key]

    def detach_stream(self, conn: str, send: SendAck) -> None:
        """The socket whose acks went to `send` closed."""
        c = self._conns.get(conn)
        if c is not None and c.acks is not None and c.acks.send is send:
            c.acks.send = None

    def acked(self, conn: str) -> int:
        """The seq up to which every frame of `conn`'s stream was handled (-1: not a stream)."""
        c = self._conns.get(conn)
        return c.acks.acked if c is not None and c.acks is not None else -1

    def flush_acks(self) -> None:
        """Send every acknowledgement due now."""
        self._ack_soon = False
        dirty, self._dirty = self._dirty, set()
        for a in dirty:
            a.flush()

    def _schedule_acks(self, a: AckState) -> None:
        self._dirty.add(a)
        if self._ack_soon:
            return
        try:
            loop = asyncio.get_running_loop()
        except RuntimeError:  # no loop (a unit test): at once
            self.flush_acks()
            return
        self._ack_soon = True
        loop.call_soon(self.flush_acks)

    def _refused(self, a: AckState, seq: int, *, overflow: bool = True) -> None:
        a.refused(seq, overflow=overflow)
        if a.dirty:
            self._schedule_acks(a)

    def _evicted_one(self) -> None:
        """The oldest queued value was evicted by a newer one (overwrite on a full buffer)."""
        assert self._tags is not None
        tag = self._tags.popleft()
        if tag is not None:
            tag[0].evicted(tag[1])
            self._schedule_acks(tag[0])

    def _taken_all(self) -> None:
        tags = self._tags
        assert tags is not None
        for tag in tags:
            if tag is not None:
                a = tag[0]
                a.taken(tag[1])
                if a.dirty:
                    self._schedule_acks(a)
        tags.clear()

    def refuse(self) -> None:
        """Count a refused frame (oversized or malformed; the data plane closes the stream)."""
        self.refused += 1

    def has_space(self, conn: str) -> bool:
        """Whether a frame of `conn` would fit in the buffer without evicting or dropping."""
        c = self._conns.get(conn)
        return len(self._queue) < (c.policy if c else self.policy).buffer

    async def wait_space(self, conn: str) -> None:
        """Wait until `has_space(conn)`: how the data plane applies `full="block"` backpressure."""
        while not self.has_space(conn):
            if self._space_waiter is None or self._space_waiter.done():
                self._space_waiter = asyncio.get_running_loop().create_future()
            await asyncio.shield(self._space_waiter)

    # -- the component's side --------------------------------------------------------------

    def read(self) -> Any:
        """The newest value received; consumes everything queued. NoData if nothing ever came."""
        if self._newest is _NOTHING:
            raise NoData(f"in-port {self.name!r}: no data received yet")
        self._new = False
        if self._queue:
            self._queue.clear()
            if self._tags is not None:
                self._taken_all()
            self._space_freed()
        if self._decode is not None:
            raw, typed = self._decoded
            if raw is not self._newest:  # decoded once, however often it is read
                typed = self._typed(self._newest)
                self._decoded = (self._newest, typed)
            return typed
        return self._newest

    def is_new(self) -> bool:
        """Whether a frame arrived that read()/get_nowait()/iteration has not returned yet."""
        return self._new

    def get_nowait(self) -> Any:
        """The oldest queued value; NoData if the queue is empty."""
        q = self._queue
        if not q:
            raise NoData(f"in-port {self.name!r}: queue is empty")
        value = q.popleft()
        tags = self._tags
        if tags is not None:  # the taken frame's stream moves on (a consumer's hot path: inline)
            tag = tags.popleft()
            if tag is not None:
                a, seq = tag
                if a.drops:
                    a.taken(seq)
                    if a.dirty:
                        self._schedule_acks(a)
                else:
                    a.deq += 1
                    if seq > a.acked:
                        a.acked = seq
                        if not a.dirty:  # already dirty: already waiting for the next flush
                            a.dirty = True
                            self._schedule_acks(a)
        if not q:
            self._new = False
        if self._space_waiter is not None:
            self._space_freed()
        if self._make is not None:  # its shape was checked on arrival
            try:
                return self._make(*value)
            except TypeError as e:
                raise PortTypeError(f"in-port {self.name!r}: not a {self.type_id}: {e}") from None
        if self._decode is not None:
            return self._typed(value)
        return value

    async def get(self) -> Any:
        """The oldest queued value, waiting for one if the queue is empty."""
        while not self._queue:
            if self._waiter is None or self._waiter.done():
                self._waiter = asyncio.get_running_loop().create_future()
            await asyncio.shield(self._waiter)
        return self.get_nowait()

    def _typed(self, value: Any) -> Any:
        """A received value as the port's message type (PortTypeError if it is not one)."""
        assert self._decode is not None
        try:
            return self._decode(value)
        except PortTypeError as e:
            raise PortTypeError(f"in-port {self.name!r}: {e}") from None

    def __aiter__(self) -> InPortRuntime:
        return self

    async def __anext__(self) -> Any:
        return await self.get()

    def qsize(self) -> int:
        """How many values are queued."""
        return len(self._queue)

    def counters(self) -> dict[str, int]:
        """The protocol's port counters, plus `skipped` (frames thinned by push="skip").
        `bytes_in` is the data plane's to count (what its server received for the port: a
        host reports that), 0 here."""
        return {
            "frames_in": self.frames_in,
            "bytes_in": 0,
            "frames_out": 0,
            "bytes_out": 0,
            "dropped": self.dropped,
            "lost": self.lost,
            "refused": self.refused,
            "skipped": self.skipped,
            "duplicates": self.duplicates,
        }

    def policy_for(self, conn: str) -> ConnectorPolicy:
        """The policy applied to frames of `conn`."""
        c = self._conns.get(conn)
        return c.policy if c else self.policy

    def _space_freed(self) -> None:
        w = self._space_waiter
        if w is not None:
            self._space_waiter = None
            if not w.done():
                w.set_result(None)
