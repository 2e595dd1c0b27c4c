"""`describe` documents (pure): a component's instances with the allocator's explanation, its
standby situation, links checked against Table II, the events that name it and its warnings; a
robot's metrics against Table I, what it hosts, its events; and their text."""

from __future__ import annotations

from typing import Any

from sdrpeer.cli.describe import format_describe
from sdrpeer.deploy.describe import (
    concerned_robots,
    describe_component,
    describe_robot,
    subject_kind,
    subject_names,
)
from sdrpeer.eventlog import naming
from sdrpeer.plan import Placement, Plan, Why
from sdrpeer.system.model import (
    AllocationDef,
    ComponentDef,
    ConnectionDef,
    StandbySpec,
    SystemDef,
    Thresholds,
)
from sdrpeer.vocabulary import InstanceRole

T = Thresholds(battery_above_pct=20.0, delay_below_ms=50.0, loss_below=0.2)
SYSTEM = SystemDef(
    "s",
    (
        ComponentDef("Cam", "python", "m:Cam"),
        ComponentDef("Det", "python", "m:Det", standby=StandbySpec(other_robots=2)),
    ),
    (ConnectionDef("Cam", "image", "Det", "image"),),
    AllocationDef(thresholds=T),
)
ACTIVE, STANDBY = InstanceRole.ACTIVE, InstanceRole.STANDBY
WHY = (
    Why("Cam", "Cam", ACTIVE, "robot-1", "ranked", ("launch", "battery"), reason="deploy"),
    Why(
        "Det",
        "Det",
        ACTIVE,
        "robot-2",
        "standby_promoted",
        ("launch", "battery", "link to Cam on robot-1: delay, loss"),
        reason="robots gone: robot-3",
        decided_in=(2, 1),
        checked_in=(2, 1),
    ),
    Why(
        "Det",
        "Det-s2",
        STANDBY,
        None,
        "left_out",
        ruled_out=(
            ("robot-1", "battery: battery 10% not above 20%"),
            ("robot-2", "already holds Det"),
        ),
        reason="robots gone: robot-3",
        decided_in=(2, 1),
        checked_in=(2, 1),
    ),
)
PLAN = Plan(
    2,
    1,
    SYSTEM,
    (
        Placement("Cam", "Cam", "robot-1"),
        Placement("Det", "Det", "robot-2"),
        Placement("Det", "Det-s1", "robot-1", STANDBY),
    ),
    "robot-2",
    why=WHY,
)
STATUS = {
    "allocator": {"name": "robot-2", "epoch": 2},
    "components": [
        {"component": "Cam", "instance": "Cam", "robot": "robot-1", "state": "active", "since": 5.0,
         "standbys": []},
        {"component": "Det", "instance": "Det", "robot": "robot-2", "state": "active", "since": 9.0,
         "standbys": [{"instance": "Det-s1", "robot": "robot-1", "state": "pending"}]},
    ],
    "connections": [{"from": "Cam.image", "to": "Det.image", "bytes_per_s": 1000, "lost_per_s": 7}],
}  # fmt: skip


def member(
    name: str, state: str = "alive", battery: float = 80.0, links: dict[str, Any] | None = None
) -> dict[str, Any]:
    return {
        "name": name,
        "state": state,
        "since": 1.0,
        "metrics": {"cpu_pct": 5.0, "mem_free": 10**9, "battery_pct": battery, "rssi_dbm": -45},
        "links": links or {},
        "link_summary": {"typical": {"rtt_ms": 2.0, "jitter_ms": 0.1, "loss": 0.0}, "listed": {}},
        "instances": [],
    }


MEMBERS = [
    member("robot-1", battery=10.0, links={"robot-2": {"rtt_ms": 80.0, "jitter_ms": 1, "loss": 0}}),
    member("robot-2"),
    member("robot-3", state="dead"),
]
EVENTS = [
    {"id": 1, "ts": 3.0, "kind": "member.dead", "robot": "robot-2",
     "detail": {"member": "robot-3"}},
    {"id": 2, "ts": 4.0, "kind": "recovery.move", "robot": "robot-2",
     "detail": {"moved": {"Det": ["robot-3", "robot-2"]}}},
    {"id": 3, "ts": 5.0, "kind": "port.overflow", "robot": "robot-1",
     "detail": {"instance": "Cam", "port": "image"}},
    {"id": 4, "ts": 6.0, "kind": "instance.state", "robot": "robot-1",
     "detail": {"instance": "Det-s12", "state": "active"}},
    {"id": 5, "ts": 7.0, "kind": "instance.state", "robot": "robot-1",
     "detail": {"instance": "Det-s1", "state": "inactive"}},
]  # fmt: skip


def test_subjects_and_the_names_their_events_carry() -> None:
    assert subject_kind("Det", PLAN, MEMBERS) == "component"
    assert subject_kind("Det-s1", PLAN, MEMBERS) == "component"
    assert subject_kind("Det-s2", PLAN, MEMBERS) == "component"  # left out: only in `why`
    assert subject_kind("robot-3", PLAN, MEMBERS) == "robot"
    assert subject_kind("nobody", PLAN, MEMBERS) is None
    assert subject_names("Det-s1", "component", PLAN) == ["Det", "Det-s1", "Det-s2"]
    assert subject_names("robot-3", "robot", PLAN) == ["robot-3"]
    assert concerned_robots("Det", "component", PLAN) == {"robot-2", "robot-1"}
    assert concerned_robots("robot-3", "robot", PLAN) == {"robot-3", "robot-2"}
    names_it = naming(["Det"])
    assert names_it(EVENTS[1])
    assert not names_it(EVENTS[3])  # Det-s12 is not Det
    assert not naming(["Det-s1"])(EVENTS[3])


def test_a_component_with_its_explanations_standbys_links_events_and_warnings() -> None:
    doc = describe_component("Det", PLAN, STATUS, MEMBERS, EVENTS)
    assert doc["component"] == "Det"
    assert [(i["instance"], i["robot"], i["state"]) for i in doc["instances"]] == [
        ("Det", "robot-2", "active"),
        ("Det-s1", "robot-1", "pending"),
    ]
    assert doc["instances"][0]["why"]["how"] == "standby_promoted"
    assert doc["instances"][1]["why"] is None  # the plan has no explanation of it
    sb = doc["standbys"]
    assert (sb["wanted"], sb["placed"]) == (2, 1)
    assert [w["instance"] for w in sb["left_out"]] == ["Det-s2"]
    (link,) = doc["links"]
    assert (link["peer"], link["robots"], link["source"]) == (
        "Cam",
        ["robot-2", "robot-1"],
        "measured",
    )
    assert {c["constraint"]: c["ok"] for c in link["checks"]} == {"delay": False, "loss": True}
    assert [e["id"] for e in doc["events"]] == [2, 5]
    warnings = doc["warnings"]
    assert any(w.startswith("no standby: the system asks for 2, the plan has 1") for w in warnings)
    assert any("robot-1 (battery: battery 10% not above 20%)" in w for w in warnings)
    assert "standby Det-s1 on robot-1 is not running yet" in warnings
    assert "Det-s1: robot-1 fails battery now: 10.0% not > 20.0%" in warnings
    assert "link to Cam (robot-2 - robot-1) fails delay now: 80 not < 50ms" in warnings
    assert "Cam.image -> Det.image drops 7 frames/s (full buffers)" in warnings
    text = format_describe(doc)
    assert "Det-s2  left out" in text
    assert "robot-1: battery: battery 10% not above 20%" in text
    assert "standby_promoted" in text
    assert "decided in: plan 2.1 (robots gone: robot-3)" in text


def test_a_healthy_component_has_no_warnings() -> None:
    members = [member("robot-1"), member("robot-2")]
    plan = Plan(1, 1, SYSTEM, (Placement("Cam", "Cam", "robot-1"),), "robot-1", why=WHY[:1])
    status = {"components": [{"component": "Cam", "instance": "Cam", "state": "active"}]}
    doc = describe_component("Cam", plan, status, members, [])
    assert doc["warnings"] == []
    assert doc["events"] == []


def test_a_robot_against_the_thresholds_with_what_it_hosts() -> None:
    doc = describe_robot("robot-1", PLAN, STATUS, MEMBERS, EVENTS)
    assert {c["constraint"]: c["ok"] for c in doc["checks"]} == {"battery": False}
    assert [p["instance"] for p in doc["placed"]] == ["Cam", "Det-s1"]
    assert [e["id"] for e in doc["events"]] == [3, 4, 5]
    assert doc["warnings"] == ["battery 10.0% not > 20.0%: the allocator places nothing more here"]
    dead = describe_robot("robot-3", PLAN, STATUS, MEMBERS, EVENTS)
    assert dead["state"] == "dead"
    assert dead["warnings"][0].startswith("robot-3 is dead")
    assert [e["id"] for e in dead["events"]] == [1, 2]
    assert "Robot:        robot-3" in format_describe(dead)


def test_a_connection_its_receiver_refuses_is_a_warning_until_it_gets_through() -> None:
    """conn.refused events (the sender's robot) say why a connection carries nothing; the
    warning stays while the connection's latest such event is a refusal."""
    members = [member("robot-1"), member("robot-2")]
    plan = Plan(1, 1, SYSTEM, (Placement("Cam", "Cam", "robot-1"),), "robot-1", why=WHY[:1])
    status = {"components": [{"component": "Cam", "instance": "Cam", "state": "active"}]}
    said: dict[str, Any] = {
        "instance": "Cam", "component": "Cam", "conn": "c1", "sender": "Cam.image",
        "to": "tcp://10.0.0.2:4000", "port": "image", "count": 1,
    }  # fmt: skip
    error = "this receiver only takes encrypted streams over TCP"
    refused = {"id": 7, "ts": 8.0, "kind": "conn.refused", "robot": "robot-1",
               "detail": {**said, "error": error}}  # fmt: skip
    accepted = {"id": 8, "ts": 9.0, "kind": "conn.accepted", "robot": "robot-1",
                "detail": said}  # fmt: skip
    doc = describe_component("Cam", plan, status, members, [refused])
    assert doc["warnings"] == [
        "Cam.image -> tcp://10.0.0.2:4000 image (connection c1 on robot-1) is refused by its "
        "receiver: this receiver only takes encrypted streams over TCP"
    ]
    assert [e["id"] for e in doc["events"]] == [7]
    assert describe_component("Cam", plan, status, members, [refused, accepted])["warnings"] == []
