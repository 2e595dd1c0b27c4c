"""ConditionTracker: sustain, hysteresis, staleness, timers (literal times)."""

from __future__ import annotations

import math

import pytest

from sdrpeer.recovery.conditions import CLEARED, FIRED, ConditionTracker
from sdrpeer.recovery.plugins import Condition
from sdrpeer.system.model import RecoveryRule
from sdrpeer.system.recovery_defaults import MOVE

RSSI = RecoveryRule("communication_failure", "rssi", "<=", -52.5, 6.0, -50.0, MOVE)


def rssi_tracker(stale: float = 3.0) -> ConditionTracker:
    return ConditionTracker(RSSI, Condition(("rssi",), robot_wide=True), stale)


def feed(t: ConditionTracker, samples: list[tuple[float, float]]) -> list[tuple[float, str]]:
    out = []
    for now, value in samples:
        change = t.observe(now, value)
        if change:
            out.append((now, change))
    return out


def test_fires_at_exactly_the_sustain_not_before() -> None:
    t = rssi_tracker()
    assert feed(t, [(100.0 + i, -55.0) for i in range(6)]) == []  # 100..105: 5 s held
    assert t.next_timer() == 106.0
    assert t.handle_timer(105.9) is None
    assert not t.fired
    assert t.handle_timer(106.0) == FIRED
    assert (t.since, t.fired_at, t.value) == (100.0, 106.0, -55.0)
    assert t.next_timer() == math.inf


def test_a_sample_exactly_at_the_threshold_holds() -> None:
    t = rssi_tracker()
    assert feed(t, [(0.0, -52.5), (3.0, -52.5), (6.0, -52.5)]) == [(6.0, FIRED)]


def test_a_sample_above_resets_the_run() -> None:
    t = rssi_tracker()
    feed(t, [(0.0, -55.0), (1.0, -55.0), (2.0, -55.0), (3.0, -52.4), (4.0, -55.0)])
    assert t.since == 4.0
    # the deadline 10.0 is armed only once a sample is recent enough to reach it (stale 3 s)
    assert t.next_timer() == math.inf
    assert feed(t, [(5.0, -55.0), (7.0, -55.0)]) == []
    assert t.next_timer() == 10.0
    assert t.handle_timer(9.9) is None
    assert t.handle_timer(10.0) == FIRED


def test_hysteresis_clears_only_past_the_clear_level() -> None:
    t = rssi_tracker()
    assert feed(t, [(0.0, -60.0), (3.0, -60.0), (6.0, -60.0)]) == [(6.0, FIRED)]
    # back above the threshold but not past -50: still fired
    assert feed(t, [(7.0, -51.0), (8.0, -50.0)]) == []
    assert t.fired
    assert feed(t, [(9.0, -49.9)]) == [(9.0, CLEARED)]
    assert (t.fired, t.since) == (False, None)


def test_clear_defaults_to_the_threshold() -> None:
    rule = RecoveryRule("low_battery", "battery", "<", 15.0, 0.0, None, MOVE)
    t = ConditionTracker(rule, Condition(("battery",), robot_wide=True), 3.0)
    assert feed(t, [(0.0, 15.0), (1.0, 14.9), (2.0, 14.0), (3.0, 15.0)]) == [
        (1.0, FIRED),
        (3.0, CLEARED),
    ]


def test_a_gap_longer_than_stale_after_restarts_the_run() -> None:
    t = rssi_tracker(stale=3.0)
    feed(t, [(0.0, -55.0), (2.0, -55.0)])
    assert t.next_timer() == math.inf  # 6.0 is past 2.0 + 3.0: the run cannot reach it
    assert t.handle_timer(6.0) is None
    feed(t, [(5.5, -55.0)])  # 3.5 s after the last sample: the run starts again
    assert t.since == 5.5
    assert feed(t, [(8.0, -55.0), (11.0, -55.0)]) == []
    assert t.next_timer() == 11.5
    assert t.handle_timer(11.5) == FIRED


def test_a_gap_of_exactly_stale_after_still_counts() -> None:
    t = rssi_tracker(stale=3.0)
    assert feed(t, [(0.0, -55.0), (3.0, -55.0), (6.0, -55.0)]) == [(6.0, FIRED)]


def test_fired_stays_fired_without_samples_and_none_changes_nothing() -> None:
    t = rssi_tracker()
    feed(t, [(0.0, -60.0), (3.0, -60.0), (6.0, -60.0)])
    assert t.observe(100.0, None) is None
    assert t.fired


def test_zero_sustain_fires_on_the_first_sample() -> None:
    rule = RecoveryRule("memory_shortage", "mem_free", "<=", 200e6, 0.0, 250e6, ())
    t = ConditionTracker(rule, Condition(("mem_free",), culprit="rss"), 3.0)
    assert feed(t, [(1.0, 300e6), (2.0, 200e6)]) == [(2.0, FIRED)]


def test_float_deadline_is_reached_by_the_timer() -> None:
    t = rssi_tracker()
    feed(t, [(0.1, -55.0), (3.1, -55.0)])
    deadline = t.next_timer()
    assert t.handle_timer(deadline) == FIRED


def test_rearm_ignores_samples_then_needs_the_whole_sustain_again() -> None:
    t = rssi_tracker()
    feed(t, [(0.0, -60.0), (3.0, -60.0), (6.0, -60.0)])
    t.rearm(6.0, 10.0)
    assert not t.fired
    assert feed(t, [(7.0, -60.0), (15.9, -60.0)]) == []
    assert t.since is None
    assert feed(t, [(16.0, -60.0), (19.0, -60.0), (22.0, -60.0)]) == [(22.0, FIRED)]


def test_an_event_rule_has_no_tracker() -> None:
    with pytest.raises(ValueError, match="event"):
        ConditionTracker(RecoveryRule("component_error", actions=MOVE), Condition(), 3.0)
