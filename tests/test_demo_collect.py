"""The timeline's pure core: answers -> lines, de-duplication, states only on change."""

from __future__ import annotations

from typing import Any

from sdrpeer.demo.collect import Answer, Collector, wanted

START = 1000.0


def member(
    name: str,
    *,
    state: str = "alive",
    mem_free: int = 1_500_000_000,
    rssi: float = -47.0,
    instances: tuple[tuple[str, str, str, str], ...] = (),
) -> dict[str, Any]:
    return {
        "name": name,
        "state": state,
        "metrics": {
            "cpu_pct": 5.0,
            "mem_total": 2_000_000_000,
            "mem_free": mem_free,
            "battery_pct": 90.0,
            "rssi_dbm": rssi,
            "pos": None,
        },
        "instances": [
            {
                "name": n,
                "component": c,
                "state": s,
                "role": r,
                "cpu_pct": 1.0,
                "rss": 1,
                "data": None,
            }
            for n, c, s, r in instances
        ],
    }


def ev(eid: int, ts: float, kind: str, robot: str, **detail: Any) -> dict[str, Any]:
    return {"id": eid, "ts": ts, "kind": kind, "robot": robot, "detail": detail}


CAM = ("Cam-1", "Camera", "active", "active")
CAM_OFF = ("Cam-1", "Camera", "inactive", "active")


def of(lines: list[dict[str, Any]], kind: str) -> list[dict[str, Any]]:
    return [line for line in lines if line["kind"] == kind]


def test_wanted_kinds() -> None:
    assert wanted("allocation")
    assert wanted("recovery.done")
    assert wanted("member.dead")
    assert not wanted("member.join")
    assert not wanted("instance.state")
    assert not wanted("plan.refused")


def test_samples_come_from_each_robots_own_agent() -> None:
    c = Collector(["robot-1", "robot-2"], START)
    lines = c.round(
        [
            Answer("robot-1", START + 1, [member("robot-1", mem_free=111), member("robot-2")]),
            Answer("robot-2", START + 1.5, [member("robot-1", mem_free=999), member("robot-2")]),
        ]
    )
    samples = of(lines, "sample")
    assert samples == [
        {
            "t": 1.0,
            "kind": "sample",
            "robot": "robot-1",
            "mem_free": 111,
            "mem_total": 2_000_000_000,
            "cpu": 5.0,
            "battery": 90.0,
            "rssi": -47.0,
        },
        {
            "t": 1.5,
            "kind": "sample",
            "robot": "robot-2",
            "mem_free": 1_500_000_000,
            "mem_total": 2_000_000_000,
            "cpu": 5.0,
            "battery": 90.0,
            "rssi": -47.0,
        },
    ]
    assert [(x["robot"], x["status"]) for x in of(lines, "agent")] == [
        ("robot-1", "up"),
        ("robot-2", "up"),
    ]


def test_states_only_on_change_own_view_first_then_others_then_gone() -> None:
    c = Collector(["robot-1", "robot-2"], START)
    stale = member("robot-1", instances=(CAM,))
    own = member("robot-1", instances=(CAM_OFF,))
    first = c.round(
        [
            Answer("robot-1", START + 1, [own, member("robot-2")]),
            Answer("robot-2", START + 1, [stale, member("robot-2")]),
        ]
    )
    assert of(first, "state") == [
        {
            "t": 1.0,
            "kind": "state",
            "robot": "robot-1",
            "instance": "Cam-1",
            "component": "Camera",
            "role": "active",
            "state": "inactive",
            "via": "robot-1",
        }
    ]
    same = c.round(
        [
            Answer("robot-1", START + 2, [own, member("robot-2")]),
            Answer("robot-2", START + 2, [stale, member("robot-2")]),
        ]
    )
    assert of(same, "state") == []
    # robot-1's agent is gone: robot-2's view of robot-1 is used (still listed alive, active)
    down = c.round(
        [
            Answer("robot-1", START + 3, error="connection refused"),
            Answer("robot-2", START + 3, [stale, member("robot-2")]),
        ]
    )
    assert [(x["state"], x["via"]) for x in of(down, "state")] == [("active", "robot-2")]
    assert of(down, "agent") == [
        {
            "t": 3.0,
            "kind": "agent",
            "robot": "robot-1",
            "status": "down",
            "error": "connection refused",
        }
    ]
    assert [x["robot"] for x in of(down, "sample")] == ["robot-2"]
    dead = member("robot-1", state="dead", instances=(CAM,))
    gone = c.round(
        [
            Answer("robot-1", START + 4, error="connection refused"),
            Answer("robot-2", START + 4, [dead, member("robot-2")]),
        ]
    )
    assert [(x["instance"], x["state"], x["via"]) for x in of(gone, "state")] == [
        ("Cam-1", "gone", "robot-2")
    ]
    assert of(gone, "agent") == []  # still down: no new line


def test_no_answer_at_all_changes_no_state() -> None:
    c = Collector(["robot-1"], START)
    c.round([Answer("robot-1", START + 1, [member("robot-1", instances=(CAM,))])])
    lines = c.round([Answer("robot-1", START + 2, error="timed out")])
    assert of(lines, "state") == []


def test_events_own_only_member_events_from_one_agent_and_dedup() -> None:
    c = Collector(["robot-1", "robot-2"], START)
    log1 = [
        ev(1, START + 0.5, "election", "robot-1", epoch=1, leader="robot-1"),
        ev(2, START + 0.6, "trap", "robot-1", metric="rssi"),
        ev(3, START + 0.7, "instance.state", "robot-1", instance="Cam-1"),
        ev(4, START + 0.8, "member.alive", "robot-2"),
    ]
    log2 = [
        ev(1, START + 0.55, "election", "robot-2", epoch=1, leader="robot-1"),
        ev(2, START + 0.65, "trap", "robot-1", metric="rssi"),  # robot-1's trap, heard
        ev(3, START + 0.85, "member.alive", "robot-1"),  # robot-1 is the member source
    ]
    ms = [member("robot-1"), member("robot-2")]
    lines = c.round(
        [Answer("robot-1", START + 1, ms, log1), Answer("robot-2", START + 1, ms, log2)]
    )
    events = [(x["t"], x["robot"], x["event"], x["via"]) for x in of(lines, "event")]
    assert events == [
        (0.5, "robot-1", "election", "robot-1"),
        (0.6, "robot-1", "trap", "robot-1"),
        (0.8, "robot-2", "member.alive", "robot-1"),
        (0.55, "robot-2", "election", "robot-2"),
    ]
    assert of(lines, "event")[0]["detail"] == {"epoch": 1, "leader": "robot-1"}
    assert (c.cursor("robot-1"), c.cursor("robot-2")) == (4, 3)

    # robot-2 failed once: re-read from 0, and nothing it already gave comes back
    c.round([Answer("robot-1", START + 2, ms, []), Answer("robot-2", START + 2, error="timed out")])
    assert c.cursor("robot-2") == 0
    again = c.round([Answer("robot-1", START + 3, ms, []), Answer("robot-2", START + 3, ms, log2)])
    assert of(again, "event") == []

    # robot-1 is killed: robot-2 becomes the member source; only newer member events are kept
    later = [
        *log2,
        ev(4, START + 5, "member.suspect", "robot-1"),
        ev(5, START + 6, "member.dead", "robot-1"),
        ev(6, START + 6.5, "recovery.started", "robot-2", cause="rssi"),
    ]
    dead = c.round(
        [
            Answer("robot-1", START + 7, error="connection refused"),
            Answer("robot-2", START + 7, ms, later[3:]),
        ]
    )
    assert [(x["robot"], x["event"], x["via"]) for x in of(dead, "event")] == [
        ("robot-1", "member.suspect", "robot-2"),
        ("robot-1", "member.dead", "robot-2"),
        ("robot-2", "recovery.started", "robot-2"),
    ]


def test_malformed_answers_are_skipped() -> None:
    c = Collector(["robot-1"], START)
    ms: list[dict[str, Any]] = [{"name": "robot-1", "metrics": None}, {"no": "name"}]
    log: list[dict[str, Any]] = [{"id": 1, "kind": "trap"}, {"ts": "x", "kind": 3}]
    lines = c.round([Answer("robot-1", START + 1, ms, log)])
    assert [x["kind"] for x in lines] == ["agent"]
    assert c.cursor("robot-1") == 1
