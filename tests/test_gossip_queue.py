"""The transmit-limited broadcast queue."""

from __future__ import annotations

from sdrpeer.gossip.messages import Alive, Suspect
from sdrpeer.gossip.queue import BroadcastQueue


def alive(name: str, inc: int) -> Alive:
    return Alive(name, ("h", 1), inc)


def test_newer_update_invalidates_older_with_same_key() -> None:
    q = BroadcastQueue()
    q.push(("m", "a"), alive("a", 1), 10)
    q.take(1000, limit=5)  # sent once
    q.push(("m", "a"), Suspect("a", 1, "b"), 10)
    assert len(q) == 1
    assert q.take(1000, limit=5) == [Suspect("a", 1, "b")]


def test_least_sent_first_then_newest() -> None:
    q = BroadcastQueue()
    q.push(("m", "a"), alive("a", 1), 10)
    q.push(("m", "b"), alive("b", 1), 10)
    assert q.take(10, limit=5) == [alive("b", 1)]  # newest among equals
    assert q.take(10, limit=5) == [alive("a", 1)]  # least sent
    q.push(("m", "c"), alive("c", 1), 10)
    taken = q.take(100, limit=5)
    assert taken[0] == alive("c", 1)  # never sent: first
    assert sorted(taken[1:], key=repr) == [alive("a", 1), alive("b", 1)]


def test_dropped_after_limit_transmissions() -> None:
    q = BroadcastQueue()
    q.push(("m", "a"), alive("a", 1), 10)
    for _ in range(3):
        assert q.take(100, limit=3) == [alive("a", 1)]
    assert q.take(100, limit=3) == []
    assert len(q) == 0


def test_budget_is_respected_and_skips_too_large() -> None:
    q = BroadcastQueue()
    q.push(("m", "big"), alive("big", 1), 500)
    q.push(("m", "small"), alive("small", 1), 50)
    assert q.take(100, limit=3) == [alive("small", 1)]
    assert q.take(600, limit=3) == [alive("big", 1), alive("small", 1)]


def test_bounded_size_drops_most_sent() -> None:
    q = BroadcastQueue(max_items=2)
    q.push(("m", "a"), alive("a", 1), 10)
    q.take(10, limit=9)  # a sent once
    q.push(("m", "b"), alive("b", 1), 10)
    q.push(("m", "c"), alive("c", 1), 10)
    assert len(q) == 2
    assert q.dropped == 1
    assert q.take(100, limit=9) == [alive("c", 1), alive("b", 1)]


def test_discard() -> None:
    q = BroadcastQueue()
    q.push(("m", "a"), alive("a", 1), 10)
    q.discard(("m", "a"))
    q.discard(("m", "zzz"))
    assert q.take(100, limit=3) == []
