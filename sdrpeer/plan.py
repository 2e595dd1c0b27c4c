"""A plan: which robot runs which instance of which component, under which allocator epoch.

How it works: the allocator turns (system, cluster view) into `Placement`s; a `Plan` bundles them
with the system they came from, the allocator's `epoch` and a `version` that grows with every
plan that epoch issues. Robots order plans by `(epoch, allocator, version)` and ignore anything
older than what they hold (fencing): a stale allocator cannot undo a newer plan.
`to_json`/`plan_from_json` are the form plans travel in between agents.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from sdrpeer.system.model import SystemDef, system_from_json
from sdrpeer.vocabulary import InstanceRole

_ROLES = {r.value: r for r in InstanceRole}


@dataclass(frozen=True, slots=True)
class Placement:
    """One instance of a component on one robot."""

    component: str
    instance: str
    """Instance name, unique in the plan (CameraRTC, CameraRTC-s1, ...)."""
    robot: str
    role: InstanceRole = InstanceRole.ACTIVE
    """active or standby."""
    mode: str = "hot"
    """For standbys: hot (started, INACTIVE) or cold (placed, launched only when needed)."""


@dataclass(frozen=True, slots=True)
class Plan:
    """Everything robots need to converge on a system, fenced by the allocator's epoch."""

    epoch: int
    version: int
    system: SystemDef | None
    """None: the system was undeployed (robots stop everything the plan owned)."""
    placements: tuple[Placement, ...] = ()
    allocator: str = ""
    """The robot that issued the plan."""
    origins: tuple[tuple[str, str], ...] = ()
    """(component, robot) for each `reconcile: keep_original` component the fleet replaced off
    a robot it lost: whichever robot holds the allocator role moves it back when that robot
    returns (kept in the plan, so a change of allocator forgets nothing)."""

    @property
    def key(self) -> tuple[int, str, int]:
        """Order of plans: (epoch, allocator, version). A robot only applies a plan with a larger
        key than the one it holds; at one epoch the election keeps the higher name, so do plans."""
        return (self.epoch, self.allocator, self.version)

    def on_robot(self, robot: str) -> list[Placement]:
        """The placements a robot must host."""
        return [p for p in self.placements if p.robot == robot]

    def active_of(self, component: str) -> Placement | None:
        """Where the component's active instance is, if placed."""
        for p in self.placements:
            if p.component == component and p.role == InstanceRole.ACTIVE:
                return p
        return None

    def standbys_short(self) -> dict[str, int]:
        """Component -> how many of the standbys its system asks for the plan has not placed
        (a recovery on too few robots places the actives first)."""
        if self.system is None:
            return {}
        short = {}
        for c in self.system.components:
            want = c.standby.same_robot + c.standby.other_robots
            have = sum(
                1
                for p in self.placements
                if p.component == c.name and p.role == InstanceRole.STANDBY
            )
            if have < want:
                short[c.name] = want - have
        return short

    def to_json(self) -> dict[str, Any]:
        """JSON form (`plan_from_json` inverts it)."""
        return {
            "epoch": self.epoch,
            "version": self.version,
            "allocator": self.allocator,
            "system": None if self.system is None else self.system.to_json(),
            "placements": [
                [p.component, p.instance, p.robot, p.role, p.mode] for p in self.placements
            ],
            "origins": [list(o) for o in self.origins],
        }


def plan_from_json(doc: Any) -> Plan:
    """Rebuild a Plan; raises ValueError on anything malformed (peers may be buggy or hostile)."""
    try:
        system = None if doc["system"] is None else system_from_json(doc["system"])
        placements = tuple(
            Placement(str(c), str(i), str(r), _role(role), str(mode))
            for c, i, r, role, mode in doc["placements"]
        )
        plan = Plan(
            epoch=int(doc["epoch"]),
            version=int(doc["version"]),
            system=system,
            placements=placements,
            allocator=str(doc.get("allocator", "")),
            origins=tuple((str(c), str(r)) for c, r in doc.get("origins", ())),
        )
    except _UnknownRole:
        raise ValueError("malformed plan: unknown role") from None
    except (KeyError, TypeError, ValueError, AttributeError) as e:
        raise ValueError(f"malformed plan: {type(e).__name__}: {e}") from None
    return plan


class _UnknownRole(ValueError):
    """A placement names a role this version does not know."""


def _role(x: object) -> InstanceRole:
    """A placement's role as plans spell it."""
    role = _ROLES.get(str(x))
    if role is None:
        raise _UnknownRole
    return role
