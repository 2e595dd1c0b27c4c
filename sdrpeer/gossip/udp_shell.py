"""The asyncio shell around the membership core: one UDP socket, one timer.

How it works (after aioquic's asyncio/protocol.py): every datagram is authenticated and decoded
by the wire codec, then handed to the core with `loop.time()`; whatever the core queued is
encoded and sent, its events are passed to `on_event`, and a single `call_at` timer is re-armed
at the core's next deadline. A datagram that fails authentication or parsing is dropped and
counted by reason, with at most one log line per reason every ten seconds: a hostile peer can
cost us a few microseconds per datagram, never a crash or a stall. An authenticated datagram
refused as stale and newer than anything its sender sent us before comes from a robot whose
clock is behind the cluster time (sdrpeer.gossip.wire): it gets an empty gossip back, addressed
to it, at most every 5 s per sender, so it catches up even when nobody else talks to it (a robot
joining with a wrong clock). A replay of recorded traffic is never newer than what followed it
and is not answered; the per-sender limit bounds what one replayed sender costs, whatever
source addresses the replays are sent from.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections import Counter
from collections.abc import Callable, Sequence
from typing import cast

from sdrpeer.errors import WireError
from sdrpeer.gossip.core import Membership
from sdrpeer.gossip.events import CoreEvent
from sdrpeer.gossip.messages import Addr, Gossip, Packet
from sdrpeer.gossip.wire import Codec

log = logging.getLogger("sdrpeer.gossip")
_LOG_EVERY = 10.0
_NUDGE_EVERY = 5.0
_NUDGE_MAX = 1024


class GossipShell(asyncio.DatagramProtocol):
    """Drives a `Membership` core from a UDP socket and the event loop's clock."""

    def __init__(
        self,
        codec: Codec,
        on_event: Callable[[CoreEvent], None],
        wall: Callable[[], float] = time.time,
        on_reject: Callable[[str, str, int], None] | None = None,
    ) -> None:
        self.codec = codec
        self.core: Membership | None = None
        self._on_event = on_event
        self._on_reject = on_reject
        """Called (reason, detail, count since the last call) at most once per reason per 10 s."""
        self._since_logged: Counter[str] = Counter()
        self._wall = wall
        self._loop = asyncio.get_running_loop()
        self._transport: asyncio.DatagramTransport | None = None
        self._timer: asyncio.TimerHandle | None = None
        self._deadline = float("inf")
        self.counters: Counter[str] = Counter()
        self.sent_by_kind: Counter[str] = Counter()
        """Bytes sent per packet kind ("ping", "ack", "sync", ...), what pings carried as vitals
        ("vitals"), and piggybacked updates sent per kind ("updates.record", ...): where the
        traffic goes (`GET /v1/agent`)."""
        self._logged: dict[str, float] = {}
        self._nudged: dict[str, float] = {}
        """Sender name -> when we last nudged it."""

    # asyncio.DatagramProtocol
    def connection_made(self, transport: asyncio.BaseTransport) -> None:
        """Keep the transport."""
        self._transport = cast(asyncio.DatagramTransport, transport)

    def datagram_received(self, data: bytes, addr: tuple[str | int, ...]) -> None:
        """Authenticate, decode and feed one datagram to the core."""
        self.counters["messages_in"] += 1
        self.counters["bytes_in"] += len(data)
        if self.core is None:
            return
        try:
            packet = self.codec.decode(data, self._wall())
        except WireError as e:
            if e.sender_behind:
                self._nudge(addr, e.sender)
            self._rejected(e, addr)
            return
        src: Addr = (str(addr[0]), int(addr[1]))
        self.core.receive(self._loop.time(), src, packet)
        self.flush()

    def error_received(self, exc: Exception) -> None:
        """ICMP errors (a peer's port closed) are normal in a failing fleet: count them."""
        self.counters["socket_errors"] += 1

    # driving the core
    def attach(self, core: Membership) -> None:
        """Start driving `core` (the socket is bound first so the core knows its address)."""
        self.core = core
        self.flush()

    def join(self, seeds: Sequence[Addr]) -> None:
        """Contact seed robots."""
        assert self.core is not None
        self.core.join(self._loop.time(), seeds)
        self.flush()

    def leave(self) -> None:
        """Announce a graceful leave."""
        assert self.core is not None
        self.core.leave(self._loop.time())
        self.flush()

    def set_record(self, payload: bytes, *, urgent: bool = False) -> int:
        """Publish a new version of our record (`urgent`: see `Membership.set_record`)."""
        assert self.core is not None
        version = self.core.set_record(self._loop.time(), payload, urgent=urgent)
        self.flush()
        return version

    def set_vitals(self, payload: bytes) -> int:
        """A new revision of our record's measured part (carried on our pings)."""
        assert self.core is not None
        return self.core.set_vitals(self._loop.time(), payload)

    def broadcast_event(self, kind: str, payload: bytes) -> None:
        """Broadcast a one-off event (a trap) at once."""
        assert self.core is not None
        self.core.broadcast_event(self._loop.time(), kind, payload)
        self.flush()

    def flush(self) -> None:
        """Send what the core queued, deliver its events, re-arm the timer."""
        core = self.core
        if core is None:
            return
        transport = self._transport
        wall = self._wall()
        for dest, packet in core.datagrams_to_send():
            try:
                data = self.codec.encode(packet, wall)
            except Exception as e:  # one bad packet must not stop the shell
                self.counters["encode_errors"] += 1
                reason = e.reason if isinstance(e, WireError) else type(e).__name__
                self._log_once("encode:" + reason, "cannot encode %s: %s", type(packet).__name__, e)
                continue
            if transport is not None and not transport.is_closing():
                transport.sendto(data, dest)
                self.counters["messages_out"] += 1
                self.counters["bytes_out"] += len(data)
                self._tally(packet, len(data))
        while (event := core.next_event()) is not None:
            self._on_event(event)
        deadline = core.next_timer()
        if deadline != self._deadline:
            if self._timer is not None:
                self._timer.cancel()
            self._deadline = deadline
            self._timer = (
                None if deadline == float("inf") else self._loop.call_at(deadline, self._fire)
            )

    def _tally(self, packet: Packet, size: int) -> None:
        kinds = self.sent_by_kind
        kinds[type(packet).__name__.lower()] += size
        vitals = getattr(packet, "vitals", None)
        if vitals is not None:
            kinds["vitals"] += len(vitals.payload)
        for u in packet.updates:
            kinds["updates." + type(u).__name__.lower()] += 1

    def close(self) -> None:
        """Stop the timer and close the socket."""
        if self._timer is not None:
            self._timer.cancel()
            self._timer = None
        if self._transport is not None:
            self._transport.close()

    def _fire(self) -> None:
        self._timer = None
        self._deadline = float("inf")
        if self.core is not None:
            self.core.handle_timer(self._loop.time())
            self.flush()

    def _nudge(self, addr: tuple[str | int, ...], sender: str) -> None:
        """`sender`, authenticated, has a clock behind the cluster's: send it an empty gossip at
        `addr` (it adopts our time from its timestamp), at most once per `_NUDGE_EVERY` per
        sender name, wherever it claims to be."""
        now = self._loop.time()
        dest: Addr = (str(addr[0]), int(addr[1]))
        if now - self._nudged.get(sender, float("-inf")) < _NUDGE_EVERY:
            return
        if len(self._nudged) >= _NUDGE_MAX:
            self._nudged.clear()
        self._nudged[sender] = now
        transport = self._transport
        if transport is None or transport.is_closing():
            return
        try:
            data = self.codec.encode(Gossip(self.codec.sender, (), sender), self._wall())
        except Exception:  # a nudge is a courtesy: it never stops the shell
            self.counters["encode_errors"] += 1
            return
        transport.sendto(data, dest)
        self.counters["clock_nudges"] += 1

    def _rejected(self, e: WireError, addr: tuple[str | int, ...]) -> None:
        self._since_logged[e.reason] += 1
        if not self._log_once(
            "reject:" + e.reason,
            "dropped datagram from %s:%s (%s); counted in rejected[%s]",
            addr[0],
            addr[1],
            e,
            e.reason,
        ):
            return
        count, self._since_logged[e.reason] = self._since_logged[e.reason], 0
        if self._on_reject is not None:
            self._on_reject(e.reason, f"from {addr[0]}:{addr[1]}: {e.detail}", count)

    def _log_once(self, key: str, msg: str, *args: object) -> bool:
        now = self._loop.time()
        last = self._logged.get(key)
        if last is None or now - last >= _LOG_EVERY:
            self._logged[key] = now
            log.warning(msg, *args)
            return True
        return False


async def open_gossip(
    host: str,
    port: int,
    codec: Codec,
    on_event: Callable[[CoreEvent], None],
    on_reject: Callable[[str, str, int], None] | None = None,
    *,
    wall: Callable[[], float] = time.time,
) -> tuple[GossipShell, Addr]:
    """Bind a UDP socket and return the shell and the address actually bound."""
    loop = asyncio.get_running_loop()
    transport, shell = await loop.create_datagram_endpoint(
        lambda: GossipShell(codec, on_event, wall, on_reject=on_reject), local_addr=(host, port)
    )
    sockname = transport.get_extra_info("sockname")
    return shell, (str(sockname[0]), int(sockname[1]))
