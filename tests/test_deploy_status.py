"""`sdrpeer status`: the status document from a plan and records, and its table."""

from __future__ import annotations

from dataclasses import replace

from sdrpeer.cli.status import format_status
from sdrpeer.deploy.status import SinceTracker, all_active, status_doc
from sdrpeer.plan import Placement, Plan
from sdrpeer.record.robot import InstanceInfo, LinkSummary, Metrics, PlanInfo, RobotRecord
from sdrpeer.system.model import ComponentDef, ConnectionDef, StandbySpec, SystemDef
from sdrpeer.vocabulary import InstanceRole

SYSTEM = SystemDef(
    name="s",
    components=(
        ComponentDef("A", "python", "m:A", standby=StandbySpec(same_robot=1, other_robots=2)),
        ComponentDef("B", "python", "m:B"),
    ),
)
PLAN = Plan(
    3,
    2,
    SYSTEM,
    (
        Placement("A", "A", "r1"),
        Placement("A", "A-s1", "r2", InstanceRole.STANDBY, "hot"),
        Placement("A", "A-s2", "r2", InstanceRole.STANDBY, "cold"),
        Placement("B", "B", "r2"),
    ),
    "r1",
)


def record(instances: list[tuple[str, str]], key: tuple[int, int] | None = (3, 2)) -> RobotRecord:
    infos = tuple(InstanceInfo(n, n[0], st, "active", 0.0, 0) for n, st in instances)
    plan = None if key is None else PlanInfo(key[0], key[1], "d", "r1")
    return RobotRecord(Metrics(0, 1, 1, None, None, None), LinkSummary(), None, 0, infos, plan=plan)


def test_states_from_records_standbys_and_since() -> None:
    since = SinceTracker()
    alive = {
        "r1": record([("A", "active")]),
        "r2": record([("A-s1", "inactive"), ("B", "active")]),
    }
    doc = status_doc(PLAN, alive, {"name": "r1", "epoch": 3}, since, 100.0)
    a, b = doc["components"]
    assert (a["robot"], a["state"], a["since"]) == ("r1", "active", 100.0)
    assert [(s["instance"], s["state"], s["mode"]) for s in a["standbys"]] == [
        ("A-s1", "inactive", "hot"),
        ("A-s2", "cold", "cold"),
    ]
    assert (b["robot"], b["state"]) == ("r2", "active")
    assert (a["standbys_wanted"], b["standbys_wanted"]) == (3, 0)  # what the system asks for
    assert all_active(doc)
    again = status_doc(PLAN, alive, {"name": "r1", "epoch": 3}, since, 130.0)
    assert again["components"][0]["since"] == 100.0  # still ACTIVE since 100
    table = format_status(again)
    assert "allocator: r1 (epoch 3)" in table
    assert "plan 3.2 by r1" in table
    assert "r2:inactive, r2:cold" in table
    assert "cold/cold" not in table  # a cold standby says so once


def test_robot_behind_the_plan_or_down_is_not_active() -> None:
    alive = {"r1": record([("A", "active")], key=(3, 1))}
    doc = status_doc(PLAN, alive, {"name": "r1", "epoch": 3}, SinceTracker(), 0.0)
    a, b = doc["components"]
    assert a["state"] == "pending"  # r1 has not applied plan 3.2 yet
    assert b["state"] == "robot down"
    assert not all_active(doc)


def test_no_plan() -> None:
    doc = status_doc(None, {}, {"name": None, "epoch": 0}, SinceTracker(), 0.0)
    assert doc["plan"] is None
    assert not all_active(doc)
    assert "no system deployed" in format_status(doc)


def test_a_connection_row_says_how_many_of_its_senders_connections_are_refused() -> None:
    """The gossip record carries, per instance, its outgoing connections refused now
    (`out_refused`): each connection row of the status shows its sending instance's."""
    system = replace(SYSTEM, connections=(ConnectionDef("A", "out", "B", "inp"),))
    plan = replace(PLAN, system=system)
    sender = record([("A", "active")])
    refused = replace(sender, instances=(replace(sender.instances[0], out_refused=1),))
    alive = {"r1": refused, "r2": record([("B", "active")])}
    doc = status_doc(plan, alive, {"name": "r1", "epoch": 3}, SinceTracker(), 0.0)
    (row,) = doc["connections"]
    assert (row["from"], row["to"], row["refused"]) == ("A.out", "B.inp", 1)
    assert "A: 1 connection(s) refused by the receiver" in format_status(doc)
    alive["r1"] = sender
    doc = status_doc(plan, alive, {"name": "r1", "epoch": 3}, SinceTracker(), 0.0)
    assert doc["connections"][0]["refused"] == 0
    assert "refused" not in format_status(doc)
