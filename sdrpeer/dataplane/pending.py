"""The sender's queue of frames waiting for the socket, ruled by the connector policy.

How it works: a pure core (no I/O, no clock). `offer(item)` applies the policy to one encoded
value and says whether it was queued; `take()` hands everything pending to the writer at once
(which is what lets the writer coalesce many frames into one socket write).

- push ``all`` / ``fifo``: every value, in order; ``skip``: one value of every ``skip + 1``
  (the others are counted as dropped); ``new``: only the newest pending value is kept.
- At most ``buffer`` values wait. When full: ``overwrite`` evicts the oldest, ``drop`` refuses
  the newest (both counted in `dropped`), ``block`` refuses the newest without counting it as a
  drop (`offer` returns False and the caller waits for `has_room` before offering it again).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Sized
from typing import Generic, Protocol, TypeVar


class PolicyLike(Protocol):
    """The connector policy fields the data plane reads (sdrpeer.sdk's ConnectorPolicy fits)."""

    @property
    def push(self) -> str:
        """all, fifo, skip or new."""

    @property
    def buffer(self) -> int:
        """How many values may wait (>= 1)."""

    @property
    def full(self) -> str:
        """overwrite, drop or block."""

    @property
    def skip(self) -> int:
        """With push=skip: values skipped after each one sent."""

    def to_map(self) -> dict[str, object]:
        """The protocol policy map."""


T = TypeVar("T", bound=Sized)


class PendingQueue(Generic[T]):
    """Values waiting for the socket, queued by a connector policy."""

    __slots__ = (
        "_block",
        "_counter",
        "_items",
        "_new",
        "_overwrite",
        "_skip",
        "dropped",
        "evicted",
        "items",
        "limit",
        "overflowed",
        "simple",
    )

    def __init__(self, policy: PolicyLike) -> None:
        self._items: deque[T] = deque()
        self._new = policy.push == "new"
        self._skip = policy.skip + 1 if policy.push == "skip" else 1
        self.limit = 1 if self._new else policy.buffer
        """How many values may wait."""
        self.simple = policy.push in ("all", "fifo")
        """True when a value is queued as-is while there is room (a caller's fast path may
        ``items.append`` itself then)."""
        self.items = self._items
        """The values waiting, oldest first (read, or append under `simple` with room)."""
        self._overwrite = policy.full == "overwrite"
        self._block = policy.full == "block"
        self._counter = 0
        self.dropped = 0
        """Values discarded by the policy (skipped, evicted, refused when full, replaced)."""
        self.evicted = 0
        """Of those, values that had been queued (`offer` returned True for them: overwrite
        and new evict the oldest to queue the newest)."""
        self.overflowed = 0
        """Of `dropped`, values lost because the buffer was full (overwrite, drop); what `new`
        replaces and `skip` thins out is the policy's purpose, not an overflow."""

    def offer(self, item: T) -> bool:
        """Queue one encoded value per the policy; False when it was not queued."""
        items = self._items
        if self._skip > 1:
            self._counter += 1
            if (self._counter - 1) % self._skip:
                self.dropped += 1
                return False
        if len(items) < self.limit:
            items.append(item)
            return True
        if self._new or self._overwrite:
            items.popleft()
            items.append(item)
            self.dropped += 1
            self.evicted += 1
            if not self._new:
                self.overflowed += 1
            return True
        if not self._block:
            self.dropped += 1
            self.overflowed += 1
        return False

    def take(self) -> list[T]:
        """Everything pending, oldest first; the queue is empty afterwards."""
        items = list(self._items)
        self._items.clear()
        return items

    @property
    def has_room(self) -> bool:
        """True when `offer` would queue a value without evicting or refusing one."""
        return len(self._items) < self.limit

    def __len__(self) -> int:
        return len(self._items)
