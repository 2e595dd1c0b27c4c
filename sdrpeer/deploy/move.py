"""A planned move of one component (`sdrpeer move`), as inputs to the allocation (pure).

How it works: the allocator asks `move_inputs(plan, component, to, alive)` what to allocate
with, then runs the ordinary allocation with it (every constraint of Tables I/II still holds):
- with a destination, the component is pinned there for this allocation (its running standby
  on that robot, if it has one, is made the active first, so it keeps its warm instance);
- without one, its current robot is avoided, so the allocation takes a running standby
  elsewhere, else the strategy's best robot.
The plan that comes out keeps the system as deployed (the pin is not remembered), so a later
re-allocation may move it again. Whatever cannot be moved raises `MoveError` saying why.
"""

from __future__ import annotations

from collections.abc import Collection
from dataclasses import dataclass, replace

from sdrpeer.errors import MoveError
from sdrpeer.plan import Plan
from sdrpeer.system.model import SystemDef
from sdrpeer.vocabulary import InstanceRole

__all__ = ["MoveError", "MoveInputs", "move_inputs", "swap_to_standby"]


@dataclass(frozen=True, slots=True)
class MoveInputs:
    """What to allocate with."""

    system: SystemDef
    previous: Plan
    avoid: dict[str, set[str]]
    origin: str
    """The robot the component's active leaves."""


def move_inputs(
    plan: Plan | None, component: str, to: str | None, alive: Collection[str]
) -> MoveInputs:
    """The allocation inputs that move `component`'s active off its robot (onto `to`)."""
    if plan is None or plan.system is None:
        raise MoveError("no system is deployed")
    system = plan.system
    comp = next((c for c in system.components if c.name == component), None)
    if comp is None:
        names = ", ".join(c.name for c in system.components)
        raise MoveError(f"no component {component!r} in system {system.name!r} ({names})")
    active = plan.active_of(component)
    if active is None:
        raise MoveError(f"{component} has no active instance placed (a recovery is under way)")
    if to is None:
        return MoveInputs(system, plan, {component: {active.robot}}, active.robot)
    if to == active.robot:
        raise MoveError(f"{component} already runs on {to}")
    if to not in alive:
        raise MoveError(f"robot {to!r} is not alive ({', '.join(sorted(alive))})")
    if comp.pin is not None:
        raise MoveError(f"{component} is pinned to {comp.pin} by the system file")
    pinned = tuple(replace(c, pin=to) if c is comp else c for c in system.components)
    return MoveInputs(
        replace(system, components=pinned),
        swap_to_standby(plan, component, to),
        {},
        active.robot,
    )


def swap_to_standby(plan: Plan, component: str, robot: str) -> Plan:
    """`plan` with the component's standby on `robot` made active and its active dropped."""
    standby = next(
        (
            p
            for p in plan.placements
            if p.component == component and p.robot == robot and p.role == InstanceRole.STANDBY
        ),
        None,
    )
    if standby is None:
        return plan
    kept = tuple(
        replace(p, role=InstanceRole.ACTIVE, mode="hot") if p is standby else p
        for p in plan.placements
        if not (p.component == component and p.role == InstanceRole.ACTIVE)
    )
    return replace(plan, placements=kept)
