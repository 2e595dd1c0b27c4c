"""The API's connection table (sdrpeer.api.connections) with literal times: who is shed to make
room, who is refused, and the idle and request-head deadlines."""

from __future__ import annotations

import pytest

from sdrpeer.api.config import ApiLimits
from sdrpeer.api.connections import ConnectionTable

LIMITS = ApiLimits(max_connections=3, idle_timeout=30.0, header_timeout=10.0)


def table(limits: ApiLimits = LIMITS) -> ConnectionTable[str]:
    return ConnectionTable(limits)


def test_room_is_made_by_shedding_the_oldest_waiting_connection_not_by_refusing() -> None:
    t = table()
    assert t.open("a", "10.0.0.1", 0.0) == []
    assert t.open("b", "10.0.0.1", 1.0) == []
    assert t.open("c", "10.0.0.1", 2.0) == []
    assert t.open("new", "10.0.0.1", 3.0) == ["a"]  # full: the oldest goes, the newcomer stays
    assert (t.state("a"), t.state("new"), len(t)) == (None, "idle", 3)
    assert t.counters["shed"] == 1
    assert t.counters["refused"] == 0


def test_a_head_arriving_does_not_make_a_connection_younger() -> None:
    t = table()
    t.open("dribbler", "10.0.0.1", 0.0)
    t.open("b", "10.0.0.1", 1.0)
    t.open("c", "10.0.0.1", 2.0)
    t.received("dribbler", 2.5)  # a byte of a head: still the oldest quiet time
    assert t.state("dribbler") == "head"
    assert t.open("new", "10.0.0.1", 3.0) == ["dribbler"]


def test_a_busy_connection_is_never_shed_and_the_newcomer_is_refused_when_all_are_busy() -> None:
    t = table()
    for i, key in enumerate("abc"):
        t.open(key, "10.0.0.1", float(i))
    t.started("a")
    t.started("b")
    assert t.open("d", "10.0.0.1", 3.0) == ["c"]  # the only waiting one
    t.started("d")
    assert t.open("e", "10.0.0.1", 4.0) == ["e"]  # every kept connection is busy
    assert t.counters["refused"] == 1
    assert t.state("e") is None
    t.finished("a", 5.0)  # done with its request: waiting again, quiet since 5.0
    assert t.open("f", "10.0.0.1", 6.0) == ["a"]


def test_the_address_holding_the_most_connections_loses_its_oldest_first() -> None:
    t = table(ApiLimits(max_connections=5))
    t.open("peer", "10.0.0.9", 0.0)  # the oldest of all, but its address holds one
    t.open("cli", "127.0.0.1", 1.0)
    for i, key in enumerate(("x1", "x2", "x3")):
        t.open(key, "10.6.6.6", 2.0 + i)
    assert t.open("x4", "10.6.6.6", 9.0) == ["x1"]
    assert t.open("peer2", "10.0.0.9", 10.0) == ["x2"]  # 10.6.6.6 still holds the most (3)
    assert {t.state(k) for k in ("peer", "cli", "peer2")} == {"idle"}


def test_equal_addresses_lose_their_oldest_quiet_time_first() -> None:
    t = table(ApiLimits(max_connections=2))
    t.open("a", "10.0.0.1", 0.0)
    t.open("b", "10.0.0.2", 1.0)
    assert t.open("c", "10.0.0.3", 2.0) == ["a"]


@pytest.mark.parametrize(
    ("events", "now", "expired", "counter"),
    [
        # accepted at 0, nothing received: idle_timeout after its quiet time
        ([], 29.9, [], None),
        ([], 30.0, ["a"], "idle_closed"),
        # a head begun at 5 must end by 15, however many bytes dribble in
        ([("received", 5.0), ("received", 14.0)], 14.9, [], None),
        ([("received", 5.0), ("received", 14.0)], 15.0, ["a"], "header_closed"),
        # busy: no deadline, however long
        ([("received", 1.0), ("started", 1.0)], 1000.0, [], None),
        # answered at 40: idle again from 40, its old head forgotten
        ([("received", 1.0), ("started", 1.0), ("finished", 40.0)], 69.9, [], None),
        ([("received", 1.0), ("started", 1.0), ("finished", 40.0)], 70.0, ["a"], "idle_closed"),
    ],
)
def test_deadlines(
    events: list[tuple[str, float]], now: float, expired: list[str], counter: str | None
) -> None:
    t = table()
    t.open("a", "10.0.0.1", 0.0)
    for what, at in events:
        if what == "received":
            t.received("a", at)
        elif what == "started":
            t.started("a")
        else:
            t.finished("a", at)
    assert t.expired(now) == expired
    if counter is not None:
        assert t.counters[counter] == 1
        assert (t.state("a"), t.next_deadline()) == (None, None)


def test_next_deadline_is_the_earliest_of_both_queues_and_expired_takes_all_due() -> None:
    t = table(ApiLimits(max_connections=10, idle_timeout=30.0, header_timeout=10.0))
    assert t.next_deadline() is None
    t.open("idle", "10.0.0.1", 0.0)
    t.open("slow", "10.0.0.1", 1.0)
    assert t.next_deadline() == 30.0
    t.received("slow", 2.0)
    assert t.next_deadline() == 12.0
    t.open("late", "10.0.0.1", 3.0)
    assert t.expired(100.0) == ["idle", "late", "slow"]
    assert len(t) == 0
    assert t.counters == {"refused": 0, "shed": 0, "idle_closed": 2, "header_closed": 1}


def test_closed_connections_are_forgotten_and_unknown_ones_ignored() -> None:
    t = table()
    t.open("a", "10.0.0.1", 0.0)
    t.received("a", 1.0)
    t.closed("a")
    t.closed("a")
    t.received("ghost", 1.0)
    t.started("ghost")
    t.finished("ghost", 1.0)
    assert (len(t), t.next_deadline(), t.expired(1e9)) == (0, None, [])


@pytest.mark.parametrize(
    "bad",
    [
        {"max_connections": 0},
        {"backlog": 0},
        {"idle_timeout": 0.0},
        {"header_timeout": -1.0},
    ],
)
def test_limits_refuse_nonsense(bad: dict[str, float]) -> None:
    with pytest.raises(ValueError, match="must be"):
        ApiLimits(**bad)  # type: ignore[arg-type]
