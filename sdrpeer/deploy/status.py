"""`sdrpeer status`: each component with its robot, state, standbys and since when (pure).

How it works: the plan says where every instance should be; the gossip records say what each
robot actually runs. `SinceTracker.observe(now_wall, rows)` remembers when each (instance, robot)
pair was first seen in its current state, so status can say "ACTIVE since 12:03:04" without the
robots gossiping timestamps.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sdrpeer.plan import Plan
from sdrpeer.record.robot import InstanceInfo, RobotRecord, state_to_wire
from sdrpeer.vocabulary import InstanceRole, LifecycleState


class SinceTracker:
    """First time each (instance, robot) was seen in its current state."""

    def __init__(self) -> None:
        self._seen: dict[tuple[str, str], tuple[str, float]] = {}

    def since(self, instance: str, robot: str, state: str, now: float) -> float:
        """When the pair entered `state` (now, if this is news)."""
        key = (instance, robot)
        old = self._seen.get(key)
        if old is None or old[0] != state:
            self._seen[key] = (state, now)
            return now
        return old[1]


def instance_state(
    alive: Mapping[str, RobotRecord], robot: str, instance: str, plan: Plan | None = None
) -> str:
    """What gossip says of one instance: its state, 'pending' (not running yet, or its robot
    has not applied `plan` yet) or 'robot down'."""
    rec = alive.get(robot)
    if rec is None:
        return "robot down"
    if plan is not None and (rec.plan is None or rec.plan.key != plan.key):
        return "pending"
    for inst in rec.instances:
        if inst.name == instance:
            return state_to_wire(inst.state)
    return "pending"


def status_doc(
    plan: Plan | None,
    alive: Mapping[str, RobotRecord],
    allocator: Mapping[str, Any],
    since: SinceTracker,
    now_wall: float,
) -> dict[str, Any]:
    """The JSON of GET /v1/status."""
    if plan is None:
        return {"allocator": dict(allocator), "plan": None, "components": []}
    comps: dict[str, dict[str, Any]] = {}
    wanted: dict[str, int] = (
        {}
        if plan.system is None
        else {c.name: c.standby.same_robot + c.standby.other_robots for c in plan.system.components}
    )
    for name, count in wanted.items():
        comps[name] = {
            "component": name,
            "instance": None,
            "robot": None,
            "state": "unplaced",
            "since": None,
            "standbys": [],
            "standbys_wanted": count,
        }
    actives = _actives(plan, alive)
    for p in plan.placements:
        state = instance_state(alive, p.robot, p.instance, plan)
        if p.role == InstanceRole.STANDBY and p.mode == "cold" and state == "pending":
            state = "cold"
        row = {
            "instance": p.instance,
            "robot": p.robot,
            "state": state,
            "since": round(since.since(p.instance, p.robot, state, now_wall), 3),
        }
        entry = comps.setdefault(p.component, {"component": p.component, "standbys": []})
        if p.role == InstanceRole.ACTIVE:
            info = actives.get(p.component)
            row["sends_bytes_per_s"] = None if info is None else info.out_bps
            entry.update(row)
        else:
            entry["standbys"].append({**row, "mode": p.mode})
    return {
        "allocator": dict(allocator),
        "plan": {
            "epoch": plan.epoch,
            "version": plan.version,
            "allocator": plan.allocator,
            "system": None if plan.system is None else plan.system.name,
            "digest": None if plan.system is None else plan.system.digest(),
        },
        "components": list(comps.values()),
        "connections": _connections(plan, alive),
    }


def _actives(plan: Plan, alive: Mapping[str, RobotRecord]) -> dict[str, InstanceInfo]:
    """Component -> what its active instance's robot reports of it."""
    out: dict[str, InstanceInfo] = {}
    for robot, rec in alive.items():
        for inst in rec.instances:
            p = plan.active_of(inst.component)
            if p is not None and p.instance == inst.name and p.robot == robot:
                out[inst.component] = inst
    return out


def _connections(plan: Plan, alive: Mapping[str, RobotRecord]) -> list[dict[str, Any]]:
    """Each connection of the system with the bytes/s its sender's active instance sends now
    and the frames/s its outgoing connections lose to full buffers at either end (all its
    OutPorts, like the bytes; None when not known), how many of them their receivers refuse
    now (`refused`, likewise the instance's), and the traffic the system file expects."""
    if plan.system is None:
        return []
    sending = _actives(plan, alive)
    rows = []
    for c in plan.system.connections:
        sender = sending.get(c.from_component)
        rows.append(
            {
                "from": f"{c.from_component}.{c.from_port}",
                "to": f"{c.to_component}.{c.to_port}",
                "bytes_per_s": None if sender is None else sender.out_bps,
                "expected_bytes_per_s": c.traffic_bytes_per_s,
                "lost_per_s": None if sender is None else sender.out_lost,
                "refused": None if sender is None else sender.out_refused,
            }
        )
    return rows


def all_active(doc: Mapping[str, Any]) -> bool:
    """Whether every component's active instance is ACTIVE (what `deploy --wait` waits for)."""
    comps = doc.get("components") or []
    return bool(comps) and all(
        c.get("state") == state_to_wire(LifecycleState.ACTIVE) for c in comps
    )
