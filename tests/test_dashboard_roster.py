"""The dashboard's roster (pure): dead robots kept, with "dead since", after gossip reaps them."""

from __future__ import annotations

from typing import Any

from sdrpeer.dashboard.roster import Roster


def row(name: str, state: str = "alive", since: float | None = None) -> dict[str, Any]:
    return {"name": name, "state": state, "since": since, "instances": []}


def names(rows: list[dict[str, Any]]) -> list[tuple[Any, ...]]:
    return [(r["name"], r["state"], r.get("dead_since"), r.get("reaped", False)) for r in rows]


def test_a_dead_robot_stays_after_it_is_reaped_with_its_death_time() -> None:
    r = Roster(keep_s=100)
    assert names(r.observe(1.0, [row("a"), row("b")])) == [
        ("a", "alive", None, False),
        ("b", "alive", None, False),
    ]
    dead = r.observe(5.0, [row("a"), row("b", "dead", since=4.5)])
    assert names(dead) == [("a", "alive", None, False), ("b", "dead", 4.5, False)]
    # the view's `since` moves (another agent's view, a clock): the first death time holds
    r.observe(6.0, [row("a"), row("b", "dead", since=5.9)])
    assert names(r.observe(20.0, [row("a")])) == [
        ("a", "alive", None, False),
        ("b", "dead", 4.5, True),
    ]
    assert len(r) == 1
    assert names(r.observe(104.0, [row("a")]))[1:] == [("b", "dead", 4.5, True)]
    assert names(r.observe(104.6, [row("a")])) == [("a", "alive", None, False)]  # > keep_s
    assert len(r) == 0


def test_a_robot_that_comes_back_is_a_member_again() -> None:
    r = Roster()
    r.observe(1.0, [row("b", "left", since=1.0)])
    r.observe(2.0, [])
    assert names(r.observe(3.0, [row("b")])) == [("b", "alive", None, False)]
    assert names(r.observe(4.0, [])) == []  # vanished alive: nothing says it died


def test_a_death_without_a_time_is_dated_when_first_seen_and_the_kept_are_bounded() -> None:
    r = Roster(max_kept=2)
    assert names(r.observe(7.0, [row("x", "dead")])) == [("x", "dead", 7.0, False)]
    r.observe(8.0, [row("y", "dead", since=8.0)])
    r.observe(9.0, [row("z", "dead", since=9.0)])
    assert names(r.observe(10.0, [])) == [("y", "dead", 8.0, True), ("z", "dead", 9.0, True)]
