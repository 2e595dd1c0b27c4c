"""Plans in the election simulator: issued by allocators, applied through each robot's fence,
and an independent check that no robot ever applies an older plan.

How it works: a plan is `(epoch, issuer, version)`; an allocator issues a new version every plan
round and publishes it in its record (as the agent's record carries the plan it holds). A robot
that sees a plan in any record asks its `Fence` first (an older epoch is refused and counted),
then applies it if it is newer than the one it holds. `applied` logs every plan applied, and
`violations` lists each one whose (epoch, issuer) is below one the same robot applied before: it
is checked against that log, not against the fence. Fences and logs survive restarts (an agent
keeps its fence on disk).
"""

from __future__ import annotations

from sdrpeer.election import Fence

PlanKey = tuple[int, str, int]
"""(epoch, issuer, version)."""


class PlanBook:
    """What every robot of a simulated cluster has applied, and the fences that decided it."""

    def __init__(self, names: list[str]) -> None:
        self.names = names
        self.fences = [Fence() for _ in names]
        """Per robot: its fence (it outlives restarts)."""
        self.held: list[PlanKey] = [(0, "", 0)] * len(names)
        """Per robot: the plan it holds."""
        self.issued: list[tuple[int, int] | None] = [None] * len(names)
        """Per robot: the last plan it issued, (epoch, version), published in its record."""
        self.applied: list[list[tuple[float, int, str, int]]] = [[] for _ in names]
        """Per robot: every plan it applied, as (time, epoch, issuer, version)."""
        self.violations: list[tuple[float, str, tuple[int, str], tuple[int, str]]] = []
        """(time, robot, applied (epoch, issuer), a higher one it applied before)."""
        self._top = [(0, "")] * len(names)

    def issue(self, i: int, epoch: int, now: float) -> tuple[int, int]:
        """Robot i issues its next plan at `epoch` and applies it; returns (epoch, version)."""
        last = self.issued[i]
        version = 1 if last is None else last[1] + 1
        self.issued[i] = (epoch, version)
        self.offer(i, epoch, self.names[i], version, now)
        return (epoch, version)

    def offer(self, i: int, epoch: int, issuer: str, version: int, now: float) -> bool:
        """Robot i sees a plan: the fence decides, then it applies it if newer than its own."""
        if not self.fences[i].admit(epoch, issuer):
            return False
        key = (epoch, issuer, version)
        if key <= self.held[i]:
            return False
        self.held[i] = key
        top = self._top[i]
        if (epoch, issuer) < top:
            self.violations.append((now, self.names[i], (epoch, issuer), top))
        self._top[i] = max(top, (epoch, issuer))
        self.applied[i].append((now, epoch, issuer, version))
        return True

    def refused(self) -> int:
        """Plans refused by the fences so far, over all robots."""
        return sum(f.refused for f in self.fences)

    def last(self, i: int) -> tuple[int, str] | None:
        """(epoch, issuer) of the last plan robot i applied."""
        return self.applied[i][-1][1:3] if self.applied[i] else None
