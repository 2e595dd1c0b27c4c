"""Escalation: the Table III ladders step by step, the attempts window, skipped steps."""

from __future__ import annotations

import pytest

from sdrpeer.recovery.ladder import Escalation
from sdrpeer.system.recovery_defaults import LOCAL_FIRST, MOVE

LOCAL = ("standby_same_robot", "restart")
EVERYTHING = set(LOCAL_FIRST)


def test_memory_shortage_ladder_with_two_local_attempts() -> None:
    e = Escalation(LOCAL_FIRST, LOCAL, max_attempts=2, window_s=60.0)
    assert e.next_action(0.0, EVERYTHING) == (0, "standby_same_robot")
    # the standby was used up: the same fault 10 s later restarts
    assert e.next_action(10.0, EVERYTHING - {"standby_same_robot"}) == (1, "restart")
    assert e.next_action(20.0, EVERYTHING) == (2, "standby_other_robot")  # budget spent
    assert e.next_action(30.0, EVERYTHING) == (3, "launch_other_robot")
    assert e.next_action(40.0, EVERYTHING) is None  # exhausted within the window


def test_restart_is_repeated_while_the_local_budget_lasts() -> None:
    e = Escalation(LOCAL_FIRST, LOCAL, max_attempts=3, window_s=60.0)
    no_standby = EVERYTHING - {"standby_same_robot"}
    steps = [e.next_action(t, no_standby) for t in (0.0, 5.0, 10.0, 15.0)]
    assert steps == [(1, "restart"), (1, "restart"), (1, "restart"), (2, "standby_other_robot")]


def test_a_fault_after_the_window_starts_the_ladder_again() -> None:
    e = Escalation(LOCAL_FIRST, LOCAL, max_attempts=1, window_s=60.0)
    assert e.next_action(0.0, EVERYTHING) == (0, "standby_same_robot")
    assert e.next_action(60.0, EVERYTHING) == (2, "standby_other_robot")  # 60 s: still inside
    assert e.next_action(121.0, EVERYTHING) == (0, "standby_same_robot")  # 61 s later: fresh
    assert e.idle(181.5)


def test_old_attempts_leave_the_budget() -> None:
    e = Escalation(LOCAL_FIRST, LOCAL, max_attempts=2, window_s=60.0)
    no_standby = EVERYTHING - {"standby_same_robot"}
    assert e.next_action(0.0, no_standby) == (1, "restart")
    assert e.next_action(50.0, no_standby) == (1, "restart")
    # at 100 s the restart at 0 s is forgotten, the one at 50 s is unresolved: budget 1 of 2
    assert e.next_action(100.0, no_standby) == (1, "restart")
    assert e.local_attempts() == 2


def test_error_ladder_standby_then_launch() -> None:
    e = Escalation(MOVE, LOCAL, max_attempts=3, window_s=60.0)
    assert e.next_action(0.0, set(MOVE)) == (0, "standby_other_robot")
    assert e.next_action(5.0, set(MOVE)) == (1, "launch_other_robot")
    assert e.next_action(6.0, set(MOVE)) is None


def test_no_standby_elsewhere_launches() -> None:
    e = Escalation(MOVE, LOCAL, max_attempts=3, window_s=60.0)
    assert e.next_action(0.0, {"launch_other_robot"}) == (1, "launch_other_robot")


def test_a_failed_step_is_not_repeated() -> None:
    e = Escalation(LOCAL_FIRST, LOCAL, max_attempts=3, window_s=60.0)
    assert e.next_action(0.0, EVERYTHING) == (0, "standby_same_robot")
    e.outcome(0.5, ok=False)  # the switch was refused
    assert e.next_action(0.5, EVERYTHING) == (1, "restart")
    e.outcome(1.0, ok=True)
    assert e.next_action(2.0, EVERYTHING) == (1, "restart")  # executed but unresolved: again


def test_an_empty_ladder_is_refused() -> None:
    with pytest.raises(ValueError, match="at least one step"):
        Escalation((), LOCAL, 3, 60.0)
