"""A plan: which robot runs which instance of which component, under which allocator epoch.

How it works: the allocator turns (system, cluster view) into `Placement`s; a `Plan` bundles them
with the system they came from, the allocator's `epoch` and a `version` that grows with every
plan that epoch issues. Robots order plans by `(epoch, allocator, version)` and ignore anything
older than what they hold (fencing): a stale allocator cannot undo a newer plan.
`to_json`/`plan_from_json` are the form plans travel in between agents.

A plan also carries why each instance is where it is (`Why`, one per placement and one per
standby no robot took): the allocator's explanation of its placement travels with the plan, so
every robot that holds the plan can answer `sdrpeer describe`, and a new allocator that re-issues
the plan keeps it. A placement kept from an earlier plan keeps the explanation of the plan that
decided it, with the plan that last re-checked it (`checked_in`).
"""

from __future__ import annotations

from dataclasses import dataclass, field
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


HOW = (
    "kept",
    "pinned",
    "standby_promoted",
    "preferred",
    "ranked",
    "same_robot",
    "held",
    "left_out",
)
"""How an instance came to its robot (`Why.how`):
kept: it stays where the previous plan or a running instance had it (still passing every
constraint); pinned: the component's `pin`; standby_promoted: a running standby of the component
became its active; preferred: the first robot of its `prefer` list that passed; ranked: the first
robot in the strategy's order that passed; same_robot: a standby on its active's robot; held: the
disconnect policy keeps it where it was (its robot is lost); left_out: no robot took it."""
MAX_RULED_OUT = 12
"""Robots listed in one `Why.ruled_out` (the rest are counted in `more_ruled_out`)."""


@dataclass(frozen=True, slots=True)
class Why:
    """Why one instance is on its robot, or on none (the allocator's explanation)."""

    component: str
    instance: str
    role: InstanceRole
    robot: str | None
    """Its robot; None when no robot took it (a standby left out)."""
    how: str
    """One of `HOW`."""
    checked: tuple[str, ...] = ()
    """The constraints its robot passed: Table I by name (memory, cpu, battery, launch, ...) and
    Table II as `link to PEER on ROBOT: delay, loss, ...` for each connected component placed on
    another robot."""
    ruled_out: tuple[tuple[str, str], ...] = ()
    """(robot, the first constraint it failed) for the robots tried before its robot, in the
    order tried; for an instance no robot took, every robot in view."""
    more_ruled_out: int = 0
    """Robots ruled out beyond the `MAX_RULED_OUT` listed."""
    scores: tuple[tuple[str, float], ...] = ()
    """(robot, weighted score) of the robots tried, under the objective strategy."""
    reason: str = ""
    """Why the allocator allocated when it decided this (deploy, robots gone: ..., a move)."""
    decided_in: tuple[int, int] = (0, 0)
    """(epoch, version) of the plan that decided it."""
    checked_in: tuple[int, int] = (0, 0)
    """(epoch, version) of the newest plan that checked it again and kept it."""

    def to_json(self) -> dict[str, Any]:
        """JSON form (`why_from_json` inverts it)."""
        return {
            "component": self.component,
            "instance": self.instance,
            "role": str(self.role),
            "robot": self.robot,
            "how": self.how,
            "checked": list(self.checked),
            "ruled_out": [list(r) for r in self.ruled_out],
            "more_ruled_out": self.more_ruled_out,
            "scores": [[r, s] for r, s in self.scores],
            "reason": self.reason,
            "decided_in": list(self.decided_in),
            "checked_in": list(self.checked_in),
        }


def why_from_json(doc: Any) -> Why:
    """Rebuild a Why; KeyError, TypeError or ValueError on anything malformed."""
    robot = doc["robot"]
    how = str(doc["how"])
    if how not in HOW:
        raise ValueError(f"unknown how {how!r}")
    epoch, version = doc["decided_in"]
    c_epoch, c_version = doc["checked_in"]
    return Why(
        component=str(doc["component"]),
        instance=str(doc["instance"]),
        role=_role(doc["role"]),
        robot=None if robot is None else str(robot),
        how=how,
        checked=tuple(str(c) for c in doc["checked"]),
        ruled_out=tuple((str(r), str(w)) for r, w in doc["ruled_out"]),
        more_ruled_out=int(doc["more_ruled_out"]),
        scores=tuple((str(r), float(s)) for r, s in doc["scores"]),
        reason=str(doc["reason"]),
        decided_in=(int(epoch), int(version)),
        checked_in=(int(c_epoch), int(c_version)),
    )


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
    why: tuple[Why, ...] = field(default=(), compare=False)
    """The allocator's explanation: one `Why` per placement, and one per standby no robot took
    (not part of the plan's identity: two plans that place alike are equal)."""

    def why_of(self, instance: str) -> Why | None:
        """The explanation of one instance, if the plan has one."""
        for w in self.why:
            if w.instance == instance:
                return w
        return None

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
            "why": [w.to_json() for w in self.why],
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
            why=tuple(why_from_json(w) for w in doc.get("why", ())),
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
