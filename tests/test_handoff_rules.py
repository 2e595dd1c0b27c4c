"""State handoff rules (pure): who syncs to whom and when, where a final state goes, what a robot
takes, and the message codec."""

from __future__ import annotations

from dataclasses import replace
from typing import Any

import msgpack
import pytest

from sdrpeer.deploy.handoff_rules import (
    Send,
    StateMsg,
    SyncSchedule,
    admit,
    final_target,
    sync_targets,
)
from sdrpeer.plan import Placement, Plan
from sdrpeer.system.model import ComponentDef, StandbySpec, SystemDef
from sdrpeer.vocabulary import InstanceRole

EST = ComponentDef(
    "Est", "python", "m:Est", standby=StandbySpec(other_robots=2, mode="hot", sync_s=1.0)
)
CAM = ComponentDef("Cam", "python", "m:Cam", standby=StandbySpec(other_robots=1))  # no sync
SYSTEM = SystemDef("s", (EST, CAM))
PLAN = Plan(
    epoch=3,
    version=7,
    system=SYSTEM,
    allocator="r2",
    placements=(
        Placement("Est", "Est", "r1"),
        Placement("Est", "Est-s1", "r2", InstanceRole.STANDBY, "hot"),
        Placement("Est", "Est-s2", "r3", InstanceRole.STANDBY, "cold"),
        Placement("Cam", "Cam", "r1"),
        Placement("Cam", "Cam-s1", "r2", InstanceRole.STANDBY, "hot"),
    ),
)
KEY = PLAN.key
MOVED = replace(  # Est-s1 took over on r2 (recovery); a new standby on r3
    PLAN,
    version=8,
    placements=(
        Placement("Est", "Est-s1", "r2"),
        Placement("Est", "Est-s3", "r3", InstanceRole.STANDBY, "hot"),
        Placement("Cam", "Cam", "r1"),
        Placement("Cam", "Cam-s1", "r2", InstanceRole.STANDBY, "hot"),
    ),
)


def msg(kind: str, source: str, target: str, key: tuple[int, str, int] = KEY) -> StateMsg:
    return StateMsg(kind, "Est", source, target, key, {"pose": [1.0, 2.0]})


def test_sync_targets_are_the_hot_standbys_of_active_instances_with_sync() -> None:
    targets = sync_targets(PLAN, "r1")
    assert list(targets) == ["Est"]  # Cam has no sync; cold standbys run nothing
    component, every, standbys = targets["Est"]
    assert (component, every, [s.instance for s in standbys]) == ("Est", 1.0, ["Est-s1"])
    assert sync_targets(PLAN, "r2") == {}  # r2 runs no active instance
    assert sync_targets(None, "r1") == {}
    assert sync_targets(replace(PLAN, system=None), "r1") == {}


def test_sync_falls_due_every_interval_while_the_instance_is_active() -> None:
    schedule = SyncSchedule()
    send = Send("sync", "Est", "Est", (("r2", "Est-s1"),))
    assert schedule.due(10.0, PLAN, "r1", {"Est", "Cam"}) == [send]
    assert schedule.next_due(PLAN, "r1") == 11.0
    assert schedule.due(10.9, PLAN, "r1", {"Est"}) == []
    assert schedule.due(11.0, PLAN, "r1", {"Est"}) == [send]
    assert schedule.due(13.0, PLAN, "r1", set()) == []  # not ACTIVE (yet): nothing to take
    assert schedule.due(13.0, PLAN, "r1", {"Est"}) == [send]
    assert schedule.due(20.0, MOVED, "r1", {"Est"}) == []  # moved away: r1 syncs nothing
    assert schedule.last == {}
    assert schedule.next_due(MOVED, "r1") is None


@pytest.mark.parametrize(
    ("plan", "component", "instance", "expected"),
    [
        (MOVED, "Est", "Est", ("r2", "Est-s1")),  # moved: the new active takes the last state
        (PLAN, "Est", "Est", None),  # still the active one (a restart, an update): nobody
        (replace(PLAN, placements=PLAN.placements[3:]), "Est", "Est", None),  # gone
        (replace(PLAN, system=None), "Est", "Est", None),  # undeployed
        (None, "Est", "Est", None),
    ],
)
def test_final_target(
    plan: Plan | None, component: str, instance: str, expected: tuple[str, str] | None
) -> None:
    assert final_target(plan, component, instance) == expected


def test_final_target_follows_a_name_that_moved_to_another_robot() -> None:
    est = next(p for p in PLAN.placements if p.instance == "Est")
    moved = replace(
        PLAN,
        placements=tuple(replace(p, robot="r3") if p is est else p for p in PLAN.placements),
    )
    assert final_target(moved, "Est", "Est", est.robot) == ("r3", "Est")
    assert final_target(PLAN, "Est", "Est", est.robot) is None  # it stays
    same_name = StateMsg("final", "Est", "Est", "Est", moved.key, {}, est.robot)
    assert admit(moved, "r3", same_name) == "apply"
    assert admit(moved, "r3", replace(same_name, origin="r3")) == "not_the_active"
    assert admit(moved, "r3", replace(same_name, origin="")) == "not_the_active"
    assert StateMsg.decode(same_name.encode()) == same_name


@pytest.mark.parametrize(
    ("plan", "robot", "message", "verdict"),
    [
        (PLAN, "r2", msg("sync", "Est", "Est-s1"), "apply"),
        (PLAN, "r2", msg("sync", "Est-s9", "Est-s1"), "not_from_the_active"),  # a stale active
        (MOVED, "r2", msg("sync", "Est", "Est-s1"), "not_a_standby"),  # cannot roll it back
        (PLAN, "r1", msg("sync", "Est", "Est"), "not_a_standby"),
        (PLAN, "r3", msg("sync", "Est", "Est-s1"), "not_here"),
        (PLAN, "r2", msg("sync", "Est", "Cam-s1"), "wrong_component"),
        (PLAN, "r2", msg("sync", "Est", "Est-s1", (9, "r2", 1)), "apply"),  # roles decide
        (MOVED, "r2", msg("final", "Est", "Est-s1", MOVED.key), "apply"),
        (PLAN, "r2", msg("final", "Est", "Est-s1", MOVED.key), "hold"),  # our plan is behind
        (PLAN, "r2", msg("final", "Est", "Est-s1", KEY), "not_the_active"),
        (MOVED, "r2", msg("final", "Est-s1", "Est-s1", MOVED.key), "not_the_active"),
        (None, "r2", msg("final", "Est", "Est-s1"), "hold"),  # no plan yet: it is coming
        (None, "r2", msg("sync", "Est", "Est-s1"), "no_plan"),
        (replace(MOVED, system=None), "r2", msg("final", "Est", "Est-s1"), "no_plan"),
    ],
)
def test_admit(plan: Plan | None, robot: str, message: StateMsg, verdict: str) -> None:
    assert admit(plan, robot, message) == verdict


def test_message_round_trip_keeps_bytes_and_nesting() -> None:
    m = StateMsg("final", "Est", "Est", "Est-s1", (3, "r2", 8), {"b": b"\x00\xff", "l": [1, None]})
    assert StateMsg.decode(m.encode()) == m


@pytest.mark.parametrize(
    ("blob", "error"),
    [
        (b"\xc1", "not one msgpack value"),
        (msgpack.packb({"kind": "sync"}), "expected [kind, component"),
        (msgpack.packb(["push", "E", "a", "b", [1, "r", 1], None]), "kind 'push' is not one of"),
        (msgpack.packb(["sync", "", "a", "b", [1, "r", 1], None]), "non-empty strings"),
        (msgpack.packb(["sync", "E", "a", 3, [1, "r", 1], None]), "non-empty strings"),
        (msgpack.packb(["sync", "E", "a", "b", [1, 1], None]), "plan must be"),
        (msgpack.packb(["sync", "E", "a", "b", ["1", "r", 1], None]), "plan must be"),
        (msgpack.packb(["sync", "E", "a", "b", [1, "r", 1], None]) + b"x", "not one msgpack"),
    ],
)
def test_malformed_messages_say_what_is_wrong(blob: Any, error: str) -> None:
    with pytest.raises(ValueError, match=error.replace("[", r"\[")):
        StateMsg.decode(blob)
