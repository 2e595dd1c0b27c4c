"""Which connections the agent's API keeps: a bounded table that sheds, and two deadlines.

How it works (no I/O: the shell, `sdrpeer.api.server`, passes `now` in and closes the
connections it is told to close):
- A connection is *waiting* (no request being served: nothing received yet, a request head
  arriving, or between two requests) or *busy* (a request is being served, from its complete
  head to its answer). A connection's *quiet time* is when it last became waiting (accepted, or
  done with its last request); bytes of a head that is not complete do not renew it.
- At most `max_connections` are kept. A connection accepted while that many are open makes room
  (`shed`): of the addresses holding a waiting connection, the one holding the most connections
  loses its waiting connection with the oldest quiet time (ties: the oldest quiet time). Only
  when every connection is busy is the newcomer itself closed (`refused`). So a flood from one
  address sheds its own connections first, and a flood from the caller's own address (loopback)
  sheds its oldest: a caller that connects and sends its request at once is served.
- Deadlines: a waiting connection that has received nothing of its next request is closed
  `idle_timeout` after its quiet time (`idle_closed`); one whose request head has begun must
  complete it within `header_timeout` of its first byte (`header_closed`: a slowloris sender
  dribbling a header). A busy connection has no deadline here (an event stream lasts).
- A connection the table says to close is forgotten at once; `closed` for it is a no-op.
"""

from __future__ import annotations

from collections.abc import Hashable, Iterator
from typing import Generic, TypeVar

from sdrpeer.api.config import ApiLimits

K = TypeVar("K", bound=Hashable)

COUNTERS = ("refused", "shed", "idle_closed", "header_closed")
"""The table's counters: connections closed at accept, to make room, idle, and mid-head."""


class _Entry:
    __slots__ = ("addr", "busy", "head_since", "quiet_since")

    def __init__(self, addr: str, now: float) -> None:
        self.addr = addr
        self.busy = False
        self.quiet_since = now
        self.head_since: float | None = None


class ConnectionTable(Generic[K]):
    """The API's open connections, keyed by the shell's handle for each (its transport)."""

    def __init__(self, limits: ApiLimits) -> None:
        self.limits = limits
        self.counters = dict.fromkeys(COUNTERS, 0)
        """How many connections were closed, by reason (`COUNTERS`)."""
        self._entries: dict[K, _Entry] = {}
        self._open_by_addr: dict[str, int] = {}
        self._waiting_by_addr: dict[str, dict[K, None]] = {}
        """Per address, its waiting connections in order of quiet time (oldest first)."""
        self._idle: dict[K, None] = {}
        """Waiting connections with nothing of a request received, oldest quiet time first."""
        self._heads: dict[K, None] = {}
        """Waiting connections whose request head has begun, oldest first byte first."""

    def __len__(self) -> int:
        return len(self._entries)

    def __iter__(self) -> Iterator[K]:
        return iter(list(self._entries))

    def open(self, key: K, addr: str, now: float) -> list[K]:
        """A connection was accepted from `addr`: the connections to close now (one shed to make
        room, or `key` itself when every connection is busy); `key` is kept unless listed."""
        if len(self._entries) >= self.limits.max_connections:
            victim = self._victim()
            if victim is None:
                self.counters["refused"] += 1
                return [key]
            self._forget(victim)
            self.counters["shed"] += 1
            closing = [victim]
        else:
            closing = []
        self._entries[key] = _Entry(addr, now)
        self._open_by_addr[addr] = self._open_by_addr.get(addr, 0) + 1
        self._wait(key, addr)
        return closing

    def received(self, key: K, now: float) -> None:
        """Bytes arrived on `key`: the first of a request head starts its header deadline."""
        entry = self._entries.get(key)
        if entry is None or entry.busy or entry.head_since is not None:
            return
        entry.head_since = now
        del self._idle[key]
        self._heads[key] = None

    def started(self, key: K) -> None:
        """A complete request is being served on `key`: no deadline, never shed."""
        entry = self._entries.get(key)
        if entry is None or entry.busy:
            return
        self._unwait(key, entry)
        entry.busy = True

    def finished(self, key: K, now: float) -> None:
        """`key` answered its request: waiting again, quiet since `now`."""
        entry = self._entries.get(key)
        if entry is None or not entry.busy:
            return
        entry.busy, entry.quiet_since, entry.head_since = False, now, None
        self._wait(key, entry.addr)

    def closed(self, key: K) -> None:
        """`key` is closed (by either side); forget it."""
        if key in self._entries:
            self._forget(key)

    def expired(self, now: float) -> list[K]:
        """The connections past their deadline at `now`, forgotten and counted: to close."""
        out: list[K] = []
        for queue, timeout, counter in (
            (self._idle, self.limits.idle_timeout, "idle_closed"),
            (self._heads, self.limits.header_timeout, "header_closed"),
        ):
            while queue:
                key = next(iter(queue))
                if self._since(key, queue) + timeout > now:
                    break
                self._forget(key)
                self.counters[counter] += 1
                out.append(key)
        return out

    def next_deadline(self) -> float | None:
        """When `expired` next has something to return (None: no connection is waiting)."""
        times = [
            self._since(next(iter(queue)), queue) + timeout
            for queue, timeout in (
                (self._idle, self.limits.idle_timeout),
                (self._heads, self.limits.header_timeout),
            )
            if queue
        ]
        return min(times, default=None)

    def state(self, key: K) -> str | None:
        """`busy`, `head` (a request head arriving), `idle`, or None when not in the table."""
        entry = self._entries.get(key)
        if entry is None:
            return None
        if entry.busy:
            return "busy"
        return "idle" if entry.head_since is None else "head"

    # ------------------------------------------------------------------------------ inside
    def _since(self, key: K, queue: dict[K, None]) -> float:
        entry = self._entries[key]
        if queue is self._idle:
            return entry.quiet_since
        assert entry.head_since is not None
        return entry.head_since

    def _victim(self) -> K | None:
        best: tuple[int, float] | None = None
        victim: K | None = None
        for addr, waiting in self._waiting_by_addr.items():
            oldest = next(iter(waiting))
            rank = (-self._open_by_addr[addr], self._entries[oldest].quiet_since)
            if best is None or rank < best:
                best, victim = rank, oldest
        return victim

    def _wait(self, key: K, addr: str) -> None:
        self._waiting_by_addr.setdefault(addr, {})[key] = None
        self._idle[key] = None

    def _unwait(self, key: K, entry: _Entry) -> None:
        waiting = self._waiting_by_addr[entry.addr]
        del waiting[key]
        if not waiting:
            del self._waiting_by_addr[entry.addr]
        self._idle.pop(key, None)
        self._heads.pop(key, None)

    def _forget(self, key: K) -> None:
        entry = self._entries.pop(key)
        if not entry.busy:
            self._unwait(key, entry)
        left = self._open_by_addr[entry.addr] - 1
        if left:
            self._open_by_addr[entry.addr] = left
        else:
            del self._open_by_addr[entry.addr]
