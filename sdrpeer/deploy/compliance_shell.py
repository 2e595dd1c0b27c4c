"""Continuous compliance in the agent: the running placements re-checked at every step.

How it works: every coordinator step (`DeployConfig.tick`, and at the monitor's sustain
deadlines) hands `update(now, plan, state)` the plan this robot holds and the alive robots'
records; the shell builds the allocator's view of them (`plan_change.cluster_view`), measures
every Table I/II constraint of the plan's active placements (`sdrpeer.alloc.compliance`) and
feeds the pure `ComplianceMonitor` (`sdrpeer.recovery.compliance`). Every agent runs it, as it
runs the health shell: `sdrpeer status` and the dashboard of any robot show the table, and an
allocator that takes over already knows how long a violation has held. Only the allocator acts
on `due_moves` (the coordinator asks its core for a `Comply` move). The monitor is rebuilt when
the system's `compliance:` policy changes; nothing deployed, nothing is watched.
"""

from __future__ import annotations

import math
from typing import Any

from sdrpeer.alloc.compliance import Reading, readings
from sdrpeer.deploy.plan_change import cluster_view
from sdrpeer.deploy.view import ClusterState
from sdrpeer.plan import Plan
from sdrpeer.recovery.compliance import ComplianceEvent, ComplianceMonitor
from sdrpeer.recovery.config import RecoveryConfig


class ComplianceShell:
    """The running placements' constraints over time, as this agent judges them."""

    def __init__(self, config: RecoveryConfig | None = None) -> None:
        self.config = config or RecoveryConfig()
        self.monitor: ComplianceMonitor | None = None
        self._at = 0.0
        """The `now` of the last update (rows are given relative to it)."""

    def update(self, now: float, plan: Plan | None, state: ClusterState) -> None:
        """Measure the plan's placements against the current records (see the module doc)."""
        self._at = now
        system = None if plan is None else plan.system
        if plan is None or system is None:
            self.monitor = None
            return
        if self.monitor is None or self.monitor.policy != system.compliance:
            self.monitor = ComplianceMonitor(system.compliance, self.config.gossip_stale_after_s)
        self.monitor.observe(now, readings(system, plan.placements, cluster_view(state, None)))
        if self.monitor.next_timer() <= now:
            self.monitor.handle_timer(now)

    def next_timer(self) -> float:
        """The earliest sustain deadline (inf: none)."""
        return math.inf if self.monitor is None else self.monitor.next_timer()

    def drain(self) -> list[ComplianceEvent]:
        """Violations and clearings since the last call."""
        out: list[ComplianceEvent] = []
        while self.monitor is not None and (event := self.monitor.next_event()) is not None:
            out.append(event)
        return out

    def due_moves(self, now: float) -> list[tuple[str, Reading]]:
        """What the allocator should move now (`on_violation: replace`)."""
        return [] if self.monitor is None else self.monitor.due_moves(now)

    def moved(self, now: float, component: str) -> None:
        """A compliance move of `component` was asked for at `now`."""
        if self.monitor is not None:
            self.monitor.moved(now, component)

    def rows(self, now_wall: float) -> list[dict[str, Any]]:
        """The compliance table with `since` as wall-clock times (None: nothing deployed)."""
        if self.monitor is None:
            return []
        out = self.monitor.rows(self._at)
        for row in out:
            if row["since"] is not None:
                row["since"] = round(now_wall - (self._at - row["since"]), 3)
        return out


def describe(r: Reading) -> str:
    """One line for a person: `loss 0.3 not below 0.05 (Cam.image->Det.image, robot-1/robot-2)`."""
    value = "unmeasured" if r.value is None else f"{r.value:.4g}"
    side = "above" if r.above else "below"
    return f"{r.constraint} {value} not {side} {r.bound:.4g} ({r.subject}, {'/'.join(r.robots)})"
