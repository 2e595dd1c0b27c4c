"""ComplianceMonitor (pure, literal times): sustain, a noisy link at the bound, hysteresis, a
placement that moved, the replace policy's one move per `min_interval`, the table."""

from __future__ import annotations

import itertools
import math
from dataclasses import replace

import pytest

from sdrpeer.alloc.compliance import Reading
from sdrpeer.recovery.compliance import (
    ComplianceMonitor,
    Compliant,
    Violated,
    clear_level,
)
from sdrpeer.system.model import ComplianceDef

REPLACE = ComplianceDef(on_violation="replace", sustain_s=3.0, clear=0.1, min_interval_s=60.0)
CONN = "Ctrl.cmd->Motor.cmd"


def loss(value: float | None, robots: tuple[str, ...] = ("robot-1", "robot-2")) -> Reading:
    """The loss of the Ctrl -> Motor link, bound 20 %."""
    return Reading("Motor", "loss", CONN, robots, value, 0.2, False, ("Motor",))


def battery(value: float | None) -> Reading:
    """Ctrl's robot's battery, which must stay above 40 %."""
    return Reading("Ctrl", "battery", "robot-1", ("robot-1",), value, 40.0, True, ("Ctrl",))


def drain(m: ComplianceMonitor) -> list[Violated | Compliant]:
    out = []
    while (e := m.next_event()) is not None:
        out.append(e)
    return out


def feed(
    m: ComplianceMonitor, samples: list[tuple[float, list[Reading]]]
) -> list[tuple[float, str]]:
    """Observe each (now, readings), firing timers in between as a shell does; (time, kind) of
    every event."""
    out: list[tuple[float, str]] = []
    for now, rs in samples:
        if m.next_timer() <= now:
            m.handle_timer(m.next_timer())  # the timer fires on time, before the sample
        m.observe(now, rs)
        out += [(e.at, type(e).__name__) for e in drain(m)]
    return out


def test_a_violation_counts_after_the_sustain_and_the_timer_says_when() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    m.observe(10.0, [loss(0.3)])
    assert m.next_timer() == math.inf  # 13.0 is past what a sample at 10.0 vouches for (12.0)
    m.observe(11.0, [loss(0.35)])
    assert m.next_timer() == 13.0
    m.observe(12.0, [loss(0.3)])
    assert drain(m) == []
    assert m.violated() == []
    m.handle_timer(12.99)
    assert drain(m) == []
    m.handle_timer(13.0)  # at exactly the sustain, between samples
    (event,) = drain(m)
    assert isinstance(event, Violated)
    assert (event.since, event.at, event.reading.value) == (10.0, 13.0, 0.3)
    assert m.next_timer() == math.inf


def test_a_value_exactly_at_the_bound_violates() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    assert feed(m, [(t, [loss(0.2)]) for t in (0.0, 1.0, 2.0, 3.0)]) == [(3.0, "Violated")]


def test_a_noisy_link_around_the_bound_never_fires() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    # past the bound for 2 s, back inside for one sample, and again, for ten minutes
    samples = [(t * 1.0, [loss(0.25 if t % 3 else 0.15)]) for t in range(600)]
    assert feed(m, samples) == []
    assert m.due_moves(600.0) == []


def test_hysteresis_a_violation_clears_only_past_the_clear_level() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    assert clear_level(0.2, False, 0.1) == pytest.approx(0.18)
    assert clear_level(-60.0, True, 0.1) == pytest.approx(-54.0)
    events = feed(
        m,
        [
            (0.0, [loss(0.3)]),
            (1.0, [loss(0.3)]),
            (2.0, [loss(0.3)]),
            (3.0, [loss(0.3)]),  # fired
            (4.0, [loss(0.19)]),  # inside the bound, not past the clear level (0.18): still
            (5.0, [loss(0.185)]),
            (6.0, [loss(0.17)]),  # cleared
        ],
    )
    assert events == [(3.0, "Violated"), (6.0, "Compliant")]
    assert [r["state"] for r in m.rows(6.0)] == ["ok"]


def test_an_above_bound_clears_above_its_margin() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    events = feed(m, [(t, [battery(v)]) for t, v in enumerate([39, 38, 40, 35, 42, 43.9, 44.1])])
    assert events == [(3.0, "Violated"), (6.0, "Compliant")]


def test_silence_is_not_health_but_a_gap_breaks_a_run() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    feed(m, [(0.0, [loss(0.3)]), (0.5, [loss(0.3)])])
    assert m.next_timer() == math.inf  # the last sample is too old to reach the deadline
    # a gap longer than stale_after: the run starts again at 5.0
    assert feed(m, [(5.0, [loss(0.3)]), (7.0, [loss(0.3)])]) == []
    assert feed(m, [(8.0, [loss(0.3)])]) == [(8.0, "Violated")]
    # fired: an unmeasured sample changes nothing
    assert feed(m, [(9.0, [loss(None)])]) == []
    assert [r.subject for r in m.violated()] == [CONN]


def test_a_placement_that_moved_drops_its_violation() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    feed(m, [(t, [loss(0.3)]) for t in (0.0, 1.0, 2.0, 3.0)])
    moved = loss(0.0, robots=("robot-1", "robot-3"))
    m.observe(4.0, [moved])
    (event,) = drain(m)
    assert isinstance(event, Compliant)
    assert (event.why, event.reading.robots) == ("placement changed", ("robot-1", "robot-2"))
    assert m.violated() == []
    assert [(r["robots"], r["state"]) for r in m.rows(4.0)] == [(["robot-1", "robot-3"], "ok")]


def test_replace_moves_a_component_at_most_once_per_min_interval() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    feed(m, [(t, [loss(0.3), battery(30.0)]) for t in (0.0, 1.0, 2.0, 3.0)])
    due = m.due_moves(3.0)
    assert [(c, r.constraint) for c, r in due] == [("Ctrl", "battery"), ("Motor", "loss")]
    for comp, _ in due:
        m.moved(3.0, comp)
    assert m.due_moves(3.5) == []
    assert m.due_moves(62.9) == []  # still violated (nothing moved it), but within the interval
    assert [c for c, _ in m.due_moves(63.0)] == ["Ctrl", "Motor"]


def test_a_noisy_link_moves_at_most_once_a_minute() -> None:
    """A link at its bound that is past it for 4 s of every 5 (sustain 3 s): it fires, the
    component moves, the new placement is just as noisy; over ten minutes: at most ten moves."""
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    robots = ("robot-1", "robot-2")
    moves: list[float] = []
    for step in range(6000):  # 0.1 s steps
        now = step / 10
        value = 0.25 if (step // 10) % 5 else 0.15
        m.observe(now, [loss(value, robots)])
        if m.next_timer() <= now:
            m.handle_timer(now)
        for comp, _ in m.due_moves(now):
            m.moved(now, comp)
            moves.append(now)
            robots = ("robot-1", "robot-3" if robots[1] == "robot-2" else "robot-2")
    assert 1 <= len(moves) <= 10
    assert all(b - a >= 60.0 for a, b in itertools.pairwise(moves))


def test_a_link_moves_its_receiver_never_its_sender_instead() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    both = replace(loss(0.3), movable=("Motor", "Ctrl"))
    feed(m, [(t, [both]) for t in (0.0, 1.0, 2.0, 3.0)])
    assert [c for c, _ in m.due_moves(3.0)] == ["Motor"]
    m.moved(3.0, "Motor")
    assert m.due_moves(10.0) == []  # Motor within its interval: Ctrl does not move instead


def test_every_agent_learns_a_move_from_the_placement_changing() -> None:
    """Not the allocator (no `moved()` call): the violated placement changes in the plan it
    follows; if it becomes the allocator, it waits out the interval like the one that moved."""
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    feed(m, [(t, [loss(0.3)]) for t in (0.0, 1.0, 2.0, 3.0)])
    there = ("robot-1", "robot-3")
    feed(m, [(t, [loss(0.3, there)]) for t in (4.0, 5.0, 6.0, 7.0)])
    assert [r.robots for r in m.violated()] == [there]
    assert m.due_moves(8.0) == []
    assert [c for c, _ in m.due_moves(64.0)] == ["Motor"]


def test_report_never_moves() -> None:
    m = ComplianceMonitor(replace(REPLACE, on_violation="report"), stale_after_s=2.0)
    feed(m, [(t, [loss(0.3)]) for t in (0.0, 1.0, 2.0, 3.0)])
    assert [r.subject for r in m.violated()] == [CONN]
    assert m.due_moves(100.0) == []


def test_a_reading_nothing_can_move_is_reported_not_moved() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    pinned = replace(loss(0.3), movable=())
    feed(m, [(t, [pinned]) for t in (0.0, 1.0, 2.0, 3.0)])
    assert len(m.violated()) == 1
    assert m.due_moves(3.0) == []


def test_the_table_says_each_state_and_since_when() -> None:
    m = ComplianceMonitor(REPLACE, stale_after_s=2.0)
    m.observe(0.0, [loss(0.1), battery(None)])
    m.observe(1.0, [loss(0.3), battery(None)])
    rows = {r["constraint"]: r for r in m.rows(1.0)}
    assert (rows["loss"]["state"], rows["loss"]["since"]) == ("holding", 1.0)
    assert (rows["battery"]["state"], rows["battery"]["since"]) == ("unknown", None)
    assert (rows["loss"]["must_be"], rows["battery"]["must_be"]) == ("below", "above")
    m.observe(2.0, [loss(0.1), battery(50.0)])  # the run broke before the sustain: ok again
    rows = {r["constraint"]: r for r in m.rows(2.0)}
    assert (rows["loss"]["state"], rows["loss"]["since"]) == ("ok", 2.0)
    assert rows["battery"]["state"] == "ok"
    for t in (3.0, 4.0, 5.0, 6.0):
        m.observe(t, [loss(0.4), battery(50.0)])
    rows = {r["constraint"]: r for r in m.rows(6.0)}
    assert (rows["loss"]["state"], rows["loss"]["since"], rows["loss"]["value"]) == (
        "violated",
        6.0,
        0.4,
    )
