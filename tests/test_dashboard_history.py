"""The dashboard's bounded history (pure) and its fleet moments (pure)."""

from __future__ import annotations

import math
from typing import Any

import pytest

from sdrpeer.dashboard.history import METRICS, History, frame_values
from sdrpeer.dashboard.moments import Moments, diff_status, was_standby


def member(
    name: str, free: float = 1e9, state: str = "alive", typical: dict[str, float] | None = None
) -> dict[str, Any]:
    return {
        "name": name,
        "state": state,
        "metrics": {"mem_free": free, "cpu_pct": 5.0, "battery_pct": 90.0, "rssi_dbm": -47.5},
        "links": {},
        "link_summary": {"peers": 2, "typical": typical} if typical else None,
    }


def test_frame_values_take_the_typical_link_and_mark_unknowns() -> None:
    m = member("r1", typical={"rtt_ms": 2.0, "jitter_ms": 1.0, "loss": 0.3})
    assert frame_values(m) == [1e9, 5.0, 90.0, -47.5, 2.0, 1.0, 0.3]
    silent = frame_values({"name": "r9", "metrics": None, "links": {}})
    assert all(math.isnan(x) for x in silent)  # NaN everywhere: nothing reported


def test_series_follow_robots_that_join_and_leave() -> None:
    h = History(window_s=100)
    h.add(1.0, [member("r1", 100.0)])
    h.add(2.0, [member("r1", 200.0), member("r2", 50.0)])
    h.add(3.0, [member("r2", 60.0), member("r1", 0, state="dead")])  # dead: not plotted
    s = h.series()
    assert s["t"] == [1.0, 2.0, 3.0]
    assert s["robots"]["r1"]["mem_free"] == [100.0, 200.0, None]
    assert s["robots"]["r2"]["mem_free"] == [None, 50.0, 60.0]
    assert s["robots"]["r1"]["rtt_ms"] == [None, None, None]  # no links measured
    assert set(s["robots"]["r2"]) == set(METRICS)
    assert h.series(since=2.0)["t"] == [3.0]
    assert h.series(since=2.0)["robots"]["r2"]["mem_free"] == [60.0]


def test_frames_older_than_the_window_fall_off() -> None:
    h = History(window_s=10, max_frames=1000)
    for t in range(100):
        h.add(float(t), [member("r1", float(t))])
    assert h.series()["t"][0] == 89.0
    assert len(h) == 11


def test_max_frames_bounds_the_history_whatever_the_window() -> None:
    h = History(window_s=1e9, max_frames=50)
    for t in range(500):
        h.add(float(t), [member("r1")])
    assert len(h) == 50
    assert h.series()["t"][0] == 450.0


def test_fifty_robots_for_fifteen_minutes_stay_small() -> None:
    h = History(window_s=900)
    fleet = [
        member(f"robot-{i}", typical={"rtt_ms": 1.0, "jitter_ms": 0.1, "loss": 0.0})
        for i in range(50)
    ]
    for t in range(1000):
        h.add(float(t), fleet)
    assert len(h) == 901
    assert h.bytes_used() <= 50 * len(METRICS) * 4 * 901  # float32 values, nothing per robot name


STATUS = {
    "allocator": {"name": "r2", "epoch": 1},
    "plan": {"epoch": 1, "version": 1, "system": "s"},
    "components": [
        {
            "component": "Cam",
            "instance": "Cam",
            "robot": "r1",
            "state": "active",
            "standbys": [{"instance": "Cam-s1", "robot": "r2", "state": "inactive", "mode": "hot"}],
        }
    ],
}
MOVED = {
    "allocator": {"name": "r3", "epoch": 2},
    "plan": {"epoch": 2, "version": 1, "system": "s"},
    "components": [
        {"component": "Cam", "instance": "Cam-s1", "robot": "r2", "state": "active", "standbys": []}
    ],
}


def kinds(moments: list[dict[str, Any]]) -> list[tuple[Any, ...]]:
    return [
        (m["kind"], m.get("instance") or m.get("leader") or m.get("component"), m.get("state"))
        for m in moments
    ]


def test_first_look_reports_every_state_and_the_plan() -> None:
    assert kinds(diff_status(None, STATUS, 5.0)) == [
        ("allocation", None, None),
        ("state", "Cam", "active"),
        ("state", "Cam-s1", "inactive"),
        ("component", "Cam", "active"),
    ]
    assert diff_status(None, None, 5.0) == []
    assert diff_status(STATUS, STATUS, 6.0) == []  # nothing changed, nothing said


def test_a_move_reports_election_plan_states_and_the_move() -> None:
    moments = diff_status(STATUS, MOVED, 9.0)
    assert kinds(moments) == [
        ("election", "r3", None),
        ("allocation", None, None),
        ("state", "Cam-s1", "active"),  # the standby's role and state changed
        ("state", "Cam", "gone"),
        ("component", "Cam-s1", "active"),  # what Cam's timeline shows: its new active
        ("move", "Cam", None),
    ]
    move = moments[-1]
    assert (move["from"], move["to"], move["ts"]) == ("r1", "r2", 9.0)


def test_moments_are_kept_for_the_window() -> None:
    m = Moments(window_s=10)
    m.observe(0.0, STATUS)
    assert len(m) == 4
    m.observe(5.0, MOVED)
    assert len(m) == 10
    m.observe(12.0, MOVED)  # the first look's moments are older than 10 s now
    assert [x["ts"] for x in m.all()] == [5.0] * 6
    assert m.observe(13.0, None) == []  # no status (an agent that deploys nothing): no moments


@pytest.mark.parametrize(
    ("field", "lost", "found"),
    [
        # an allocator that vanishes is an election of nobody; one that appears, of its leader
        ("allocator", [("election", None, None)], [("election", "r2", None)]),
        # a plan that vanishes says nothing (no allocation happened); one that appears is one
        ("plan", [], [("allocation", None, None)]),
        # components that vanish are gone; that appear, are news in their states
        (
            "components",
            [("state", "Cam", "gone"), ("state", "Cam-s1", "gone"), ("component", "Cam", "gone")],
            [
                ("state", "Cam", "active"),
                ("state", "Cam-s1", "inactive"),
                ("component", "Cam", "active"),
            ],
        ),
    ],
)
def test_a_missing_field_reads_as_absent_not_as_a_crash(
    field: str, lost: list[tuple[Any, ...]], found: list[tuple[Any, ...]]
) -> None:
    partial = {k: v for k, v in STATUS.items() if k != field}
    assert kinds(diff_status(STATUS, partial, 1.0)) == lost
    assert kinds(diff_status(partial, STATUS, 1.0)) == found
    assert diff_status(partial, partial, 2.0) == []  # still missing: nothing new


def timeline(moments: list[dict[str, Any]]) -> list[tuple[Any, ...]]:
    """What the page's state row of a component draws: its `component` moments in order."""
    return [
        (m["ts"], m["instance"], m["state"], m["was_standby"])
        for m in moments
        if m["kind"] == "component"
    ]


def test_a_failover_is_a_change_of_colour_on_the_timeline_never_a_gap() -> None:
    # issue 18: after a death the new active's state and the old active's "gone" came in one
    # diff, "gone" last, and the page drew the component blank from then on
    (cam,) = STATUS["components"]
    assert isinstance(cam, dict)
    down = {**STATUS, "components": [{**cam, "state": "robot down"}]}
    m = Moments(window_s=100)
    for ts, doc in ((0.0, STATUS), (3.0, down), (4.0, MOVED), (5.0, MOVED)):
        m.observe(ts, doc)
    assert timeline(m.all()) == [
        (0.0, "Cam", "active", False),
        (3.0, "Cam", "robot down", False),
        (4.0, "Cam-s1", "active", True),  # the promoted standby, under its own name
    ]
    states = [x for x in m.all() if x["kind"] == "state"]
    assert (states[-1]["instance"], states[-1]["state"]) == ("Cam", "gone")  # still in the log


def test_a_state_older_than_the_window_is_still_drawn() -> None:
    m = Moments(window_s=10)
    m.observe(0.0, STATUS)
    m.observe(30.0, STATUS)  # nothing changed for 30 s: every moment is older than the window
    assert len(m) == 0
    assert timeline(m.all()) == [(0.0, "Cam", "active", False)]
    m.observe(31.0, MOVED)
    assert timeline(m.all()) == [(31.0, "Cam-s1", "active", True)]
    m.observe(32.0, {**MOVED, "components": []})  # undeployed: nothing is held any more
    m.observe(50.0, {**MOVED, "components": []})
    assert timeline(m.all()) == []


@pytest.mark.parametrize(
    ("component", "instance", "promoted"),
    [("Cam", "Cam", False), ("Cam", "Cam-s1", True), ("Cam", None, False), ("Cam", "", False)],
)
def test_was_standby_reads_the_allocators_names(
    component: str, instance: str | None, promoted: bool
) -> None:
    assert was_standby(component, instance) is promoted
