"""Transmit-limited broadcast queue (after memberlist's queue.go).

How it works: every queued update has a key (the member or record it is about). Queueing a newer
update with the same key replaces the older one, so stale facts are never sent. `take(budget)`
returns the least-sent updates that fit in `budget` bytes (among equals, the one that entered its
bucket last) and counts one transmission for each; an update is dropped after `limit`
transmissions. Updates are kept in buckets by transmit count, so `take` touches only what it
sends.
"""

from __future__ import annotations

from collections.abc import Hashable

from sdrpeer.gossip.messages import Update

_MAX_MISSES = 16
"""Stop looking for an update small enough for the rest of a packet after this many misses
(without it, a nearly full packet scans every queued update: 40 % of a 1,000-robot bootstrap)."""


class _Item:
    __slots__ = ("key", "sent", "size", "update")

    def __init__(self, key: Hashable, update: Update, size: int) -> None:
        self.key = key
        self.update = update
        self.size = size
        self.sent = 0


class BroadcastQueue:
    """Updates waiting to be piggybacked, each sent at most `limit` times."""

    def __init__(self, max_items: int = 4096) -> None:
        self._by_key: dict[Hashable, _Item] = {}
        # buckets[sent] maps key -> item in insertion order (oldest first).
        self._buckets: list[dict[Hashable, _Item]] = [{}]
        self.max_items = max_items
        self.dropped = 0

    def __len__(self) -> int:
        return len(self._by_key)

    def push(self, key: Hashable, update: Update, size: int) -> None:
        """Queue `update` under `key`, replacing (invalidating) any older update with that key."""
        old = self._by_key.pop(key, None)
        if old is not None:
            del self._buckets[old.sent][key]
        item = _Item(key, update, size)
        self._by_key[key] = item
        self._buckets[0][key] = item
        if len(self._by_key) > self.max_items:
            self._drop_most_sent()

    def discard(self, key: Hashable) -> None:
        """Forget the update queued under `key`, if any."""
        old = self._by_key.pop(key, None)
        if old is not None:
            del self._buckets[old.sent][key]

    def take(self, budget: int, limit: int) -> list[Update]:
        """Updates fitting in `budget` bytes, least-sent first; each counts one transmission."""
        out: list[Update] = []
        if not self._by_key:
            return out
        buckets = self._buckets
        moved: list[_Item] = []
        for bucket in buckets:
            if not bucket:
                continue
            skipped: list[tuple[Hashable, _Item]] = []
            while bucket:
                key, item = bucket.popitem()  # newest first
                if item.size <= budget:
                    budget -= item.size
                    out.append(item.update)
                    moved.append(item)
                    if budget < 8:
                        break
                else:
                    skipped.append((key, item))
                    if len(skipped) > _MAX_MISSES:  # as full as it will usefully get
                        budget = 0
                        break
            for key, item in reversed(skipped):
                bucket[key] = item
            if budget < 8:
                break
        by_key = self._by_key
        for item in moved:
            item.sent += 1
            if item.sent >= limit:
                del by_key[item.key]
                continue
            if item.sent == len(buckets):
                buckets.append({})
            buckets[item.sent][item.key] = item
        return out

    def _drop_most_sent(self) -> None:
        for bucket in reversed(self._buckets):
            if bucket:
                key = next(iter(bucket))
                del bucket[key]
                del self._by_key[key]
                self.dropped += 1
                return
