"""What `allocate` returns: a plan, or a report of what could not be placed and why.

How it works: an allocation either places every instance (a `Plan`) or none (no partial plans).
When it cannot, `Infeasible` lists each instance that found no robot with, for every robot it
could have gone to, the constraint that ruled that robot out (like Nomad's placement failures),
and `str()` renders it for a command line.
"""

from __future__ import annotations

from dataclasses import dataclass

from sdrpeer.plan import Plan
from sdrpeer.vocabulary import InstanceRole


@dataclass(frozen=True, slots=True)
class Unplaced:
    """One instance that found no robot."""

    component: str
    instance: str
    role: str
    """active or standby."""
    reasons: tuple[tuple[str, str], ...]
    """(robot, why it was ruled out) for every robot considered, in first-fit order."""

    def __str__(self) -> str:
        what = self.instance if self.role == InstanceRole.ACTIVE else f"{self.instance} (standby)"
        if not self.reasons:
            return f"{what}: no robot in view"
        lines = [f"{what}:"] + [f"  {robot}: {why}" for robot, why in self.reasons]
        return "\n".join(lines)


@dataclass(frozen=True, slots=True)
class Infeasible:
    """Why a system cannot be placed on the robots in view."""

    system: str
    unplaced: tuple[Unplaced, ...]
    robots: int
    """How many robots were in view."""

    def reason_for(self, instance: str, robot: str) -> str | None:
        """Why `robot` could not take `instance` (None if not reported)."""
        for u in self.unplaced:
            if u.instance == instance:
                return dict(u.reasons).get(robot)
        return None

    def __str__(self) -> str:
        head = (
            f"cannot place system {self.system!r} on {self.robots} robot(s): "
            f"{len(self.unplaced)} instance(s) found no robot"
        )
        return "\n".join([head, *(str(u) for u in self.unplaced)])


@dataclass(frozen=True, slots=True)
class AllocationResult:
    """Either `plan` or `infeasible` is set."""

    plan: Plan | None = None
    infeasible: Infeasible | None = None
    kept: int = 0
    """Placements that stayed where the previous plan or a running instance had them."""

    @property
    def ok(self) -> bool:
        """True when every instance was placed."""
        return self.plan is not None
