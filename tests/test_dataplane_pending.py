"""The sender's policy queue, a pure core: which offered values wait for the socket."""

from __future__ import annotations

import pytest

from sdrpeer.dataplane.connection import next_backoff
from sdrpeer.dataplane.pending import PendingQueue, PolicyLike
from sdrpeer.dataplane.testing import make_policy as ConnectorPolicy


def run(policy: PolicyLike, n: int) -> tuple[list[bool], list[bytes], int]:
    queue: PendingQueue[bytes] = PendingQueue(policy)
    accepted = [queue.offer(str(i).encode()) for i in range(1, n + 1)]
    return accepted, queue.take(), queue.dropped


# (policy, offered 1..6 with no write in between) -> (offer results, pending, dropped)
TABLE = [
    (ConnectorPolicy("all", 8), [True] * 6, "123456", 0),
    (ConnectorPolicy("fifo", 4, "overwrite"), [True] * 6, "3456", 2),
    (ConnectorPolicy("fifo", 4, "drop"), [True] * 4 + [False] * 2, "1234", 2),
    (ConnectorPolicy("fifo", 4, "block"), [True] * 4 + [False] * 2, "1234", 0),
    (ConnectorPolicy("new", 8), [True] * 6, "6", 5),
    (ConnectorPolicy("new", 8, "block"), [True] * 6, "6", 5),
    (ConnectorPolicy("skip", 8, skip=1), [True, False] * 3, "135", 3),
    (ConnectorPolicy("skip", 8, skip=2), [True, False, False] * 2, "14", 4),
    (ConnectorPolicy("skip", 1, "drop", skip=1), [True, False, False, False, False, False], "1", 5),
]


@pytest.mark.parametrize(("policy", "accepted", "pending", "dropped"), TABLE)
def test_policy_table(policy: PolicyLike, accepted: list[bool], pending: str, dropped: int) -> None:
    got_accepted, got_pending, got_dropped = run(policy, 6)
    assert got_accepted == accepted
    assert b"".join(got_pending).decode() == pending
    assert got_dropped == dropped


def test_take_empties_and_makes_room() -> None:
    queue: PendingQueue[bytes] = PendingQueue(ConnectorPolicy("fifo", 2, "block"))
    assert queue.offer(b"a")
    assert queue.offer(b"b")
    full = queue.has_room
    assert queue.take() == [b"a", b"b"]
    assert (full, queue.has_room) == (False, True)
    assert len(queue) == 0


@pytest.mark.parametrize(
    ("delay", "expected"), [(0.0, 0.05), (0.05, 0.1), (0.4, 0.8), (1.5, 2.0), (2.0, 2.0)]
)
def test_backoff(delay: float, expected: float) -> None:
    assert next_backoff(delay, 0.05, 2.0) == pytest.approx(expected)
