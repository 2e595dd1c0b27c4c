"""Robot-wide recovery conditions judged on every agent from its gossip view.

How it works: every coordinator step feeds `sdrpeer.recovery.RobotMonitor` with each alive
robot's latest record — its own battery and RSSI, and its typical link delay, jitter and loss
(the values a strict majority of the links it measures reach: its record's link summary) — at
the step's `now`: the last gossiped value is what the cluster believes until the next one
arrives (a value crossing a threshold of a rule is published at once, see
`sdrpeer.monitor.publish`). Every agent runs it (it is cheap), so that when an
allocator hands over, its successor already knows how long a condition has held. The outputs:
`degraded(now)` (robots whose components must move and which may not hold the allocator role:
the allocator moves first), `excluded(now)` (degraded plus those within the minimum dwell after
clearing), and `drain()`: the conditions fired or cleared since the last call, for the event
log. The monitor is rebuilt when the deployed system's `recovery:` section changes.
"""

from __future__ import annotations

from collections.abc import Mapping

from sdrpeer.record.robot import RobotRecord
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import RobotEvent
from sdrpeer.recovery.robot_conditions import RobotMonitor
from sdrpeer.system.model import RecoveryDef


class HealthShell:
    """The robot-wide conditions of every robot, as this agent judges them."""

    def __init__(self, config: RecoveryConfig | None = None) -> None:
        self.config = config or RecoveryConfig()
        self.monitor: RobotMonitor | None = None
        self._known: set[str] = set()

    def update(
        self, now: float, recovery: RecoveryDef | None, alive: Mapping[str, RobotRecord]
    ) -> None:
        """Feed the current view (no system deployed: nothing is judged)."""
        if recovery is None:
            self.monitor = None
            return
        if self.monitor is None or self.monitor.recovery != recovery:
            self.monitor = RobotMonitor(recovery, self.config)
            self._known = set()
        monitor = self.monitor
        for gone in self._known - set(alive):
            monitor.robot_gone(now, gone)
        self._known = set(alive)
        for robot, rec in alive.items():
            m, t = rec.metrics, rec.links.typical
            monitor.observe_robot(
                now,
                robot,
                {
                    "battery": m.battery_pct,
                    "rssi": m.rssi_dbm,
                    "mem_free": float(m.mem_free),
                    "cpu": m.cpu_pct,
                    "delay": None if t is None else t.rtt_ms,
                    "jitter": None if t is None else t.jitter_ms,
                    "loss": None if t is None else t.loss,
                },
            )
        if monitor.next_timer() <= now:
            monitor.handle_timer(now)

    def next_timer(self) -> float:
        """When a sustain period ends (inf: none pending)."""
        return float("inf") if self.monitor is None else self.monitor.next_timer()

    def degraded(self, now: float) -> set[str]:
        """Robots that must give up their components (and the allocator role)."""
        return set() if self.monitor is None else self.monitor.degraded(now)

    def excluded(self, now: float) -> set[str]:
        """Robots that must not receive components now."""
        return set() if self.monitor is None else self.monitor.excluded(now)

    def drain(self) -> list[RobotEvent]:
        """Conditions fired or cleared since the last call."""
        out: list[RobotEvent] = []
        while self.monitor is not None and (event := self.monitor.next_event()) is not None:
            out.append(event)
        return out
