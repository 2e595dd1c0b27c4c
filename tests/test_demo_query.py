"""Timeline helpers over a literal timeline: the demo's figures of merit."""

from __future__ import annotations

from typing import Any

from sdrpeer.demo.query import Timeline


def state(t: float, robot: str, instance: str, component: str, st: str, *, role: str = "active"):
    return {
        "t": t,
        "kind": "state",
        "robot": robot,
        "instance": instance,
        "component": component,
        "role": role,
        "state": st,
    }


def sample(t: float, robot: str, rssi: float | None) -> dict[str, Any]:
    return {"t": t, "kind": "sample", "robot": robot, "mem_free": 10**9, "rssi": rssi}


LINES: list[dict[str, Any]] = [
    {"t": 0.0, "kind": "start", "robots": ["robot-1", "robot-2", "robot-3"]},
    sample(1.0, "robot-1", -47.0),
    {"t": 2.0, "kind": "mark", "what": "allocation", "label": "deploy"},
    {"t": 2.1, "kind": "event", "robot": "robot-1", "event": "allocation", "detail": {}},
    state(3.0, "robot-1", "Omni-1", "Omni", "inactive"),
    state(3.0, "robot-2", "Cam-1", "Cam", "inactive"),
    state(3.0, "robot-3", "Omni-2", "Omni", "active", role="standby"),
    state(4.0, "robot-1", "Omni-1", "Omni", "active"),
    state(5.5, "robot-2", "Cam-1", "Cam", "active"),
    sample(10.0, "robot-1", -47.0),
    sample(11.0, "robot-2", -60.0),
    sample(12.0, "robot-1", -55.0),
    sample(13.0, "robot-1", None),
    sample(14.0, "robot-1", -52.5),
    {"t": 15.0, "kind": "event", "robot": "robot-3", "event": "recovery.started", "detail": {}},
    {"t": 16.0, "kind": "mark", "what": "recovery", "label": "robot-1 weak signal"},
    state(17.0, "robot-3", "Omni-2", "Omni", "active", role="active"),
    state(18.0, "robot-1", "Omni-1", "Omni", "gone"),
]


def test_first_with_values_predicates_and_after() -> None:
    tl = Timeline(reversed(LINES))  # any order in, time order kept
    assert tl.lines[0]["kind"] == "start"
    assert tl.first("mark", what="recovery") == LINES[15]
    assert tl.first("event", event=lambda k: k.startswith("recovery.")) == LINES[14]
    assert tl.first("event", event="recovery.started", robot="robot-1") is None
    assert tl.first("sample", after=11.5, robot="robot-1") == LINES[11]
    assert tl.first("nothing") is None
    assert tl.marks("allocation") == [2.0]
    assert tl.robots() == ["robot-1", "robot-2", "robot-3"]
    assert Timeline(LINES[1:]).robots() == ["robot-1", "robot-2"]


def test_when_all_active() -> None:
    tl = Timeline(LINES)
    assert tl.when_all_active(["Omni", "Cam"], after=2.0) == 5.5
    assert tl.when_all_active(["Omni"], after=2.0) == 4.0
    assert tl.when_all_active(["Omni"], after=10.0) == 10.0  # already so at `after`
    # without robot-1: the standby on robot-3 counts only once it takes the active role
    assert tl.when_all_active(["Omni", "Cam"], after=12.0, exclude={"robot-1"}) == 17.0
    assert tl.when_all_active(["Omni", "Cam", "Nothing"]) is None
    assert tl.when_all_active(["Cam"], after=100.0) == 100.0
    assert Timeline([]).when_all_active(["Cam"]) is None


def test_rssi_crossing() -> None:
    tl = Timeline(LINES)
    assert tl.rssi_crossing("robot-1", -52.5) == 12.0
    assert tl.rssi_crossing("robot-1", -52.5, after=12.5) == 14.0  # None values are skipped
    assert tl.rssi_crossing("robot-1", -56.0) is None
    assert tl.rssi_crossing("robot-2", -52.5) == 11.0
