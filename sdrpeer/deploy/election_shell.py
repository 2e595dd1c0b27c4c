"""Feeds the pure election core (`sdrpeer.election`) from this robot's gossip view.

How it works: on every step the coordinator hands over the alive robots' records; each becomes a
`Candidate` — eligible and coarse health from its battery, RSSI and typical link loss (the
loss a strict majority of the links it measures reach, from its record's link summary) against the
deployed system's allocation thresholds (none deployed: every alive robot is eligible), priority and
published election state from its record. Robots not alive are left out of the view (the core treats
a missing robot as gone). The core's timers are run here too.

Another robot's claim is taken at its word: a robot that claims the role is eligible in every
view, because it judges its own eligibility (its battery, RSSI and links are its own
measurements, its quorum its own view) and abdicates the moment it is not. Judging it again here,
with recovery conditions whose `for:` clocks started at other moments, let one robot call the role
vacant (and show "allocator (none)") while the rest of the fleet followed the allocator.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping
from dataclasses import replace

from sdrpeer.election.config import ElectionConfig, lan
from sdrpeer.election.core import Election
from sdrpeer.election.events import ElectionEvent
from sdrpeer.election.health import eligible, health_bucket
from sdrpeer.election.state import Candidate, ElectionState
from sdrpeer.record.robot import ElectionInfo, RobotRecord
from sdrpeer.system.model import Thresholds


def candidate(rec: RobotRecord, thresholds: Thresholds, healthy: bool = True) -> Candidate:
    """What the election needs to know of one alive robot (`healthy`: no recovery condition)."""
    m = rec.metrics
    loss = None if rec.links.typical is None else rec.links.typical.loss
    e = rec.election
    return Candidate(
        alive=True,
        eligible=healthy
        and eligible(thresholds, battery_pct=m.battery_pct, rssi_dbm=m.rssi_dbm, link_loss=loss),
        priority=rec.priority,
        health=health_bucket(battery_pct=m.battery_pct, rssi_dbm=m.rssi_dbm, link_loss=loss),
        state=None if e is None else ElectionState(e.epoch, e.leader, e.claiming),
    )


class ElectionShell:
    """One robot's election, driven by the coordinator's steps."""

    def __init__(
        self, name: str, config: ElectionConfig | None = None, known_epoch: int = 0
    ) -> None:
        """`known_epoch`: the highest epoch this robot followed before a restart (its plan's)."""
        self.name = name
        self.config = config or lan()
        self.known_epoch = known_epoch
        self.core: Election | None = None
        self._events: list[ElectionEvent] = []
        self._candidates: dict[str, tuple[RobotRecord, Thresholds, bool, Candidate]] = {}
        """The candidate made of each robot's record (records are immutable: a step remakes
        only those whose record, thresholds or health changed)."""

    def update(
        self,
        now: float,
        alive: Mapping[str, RobotRecord],
        thresholds: Thresholds | None,
        degraded: Collection[str] = (),
        *,
        preempt: bool = False,
    ) -> None:
        """Feed the current view; runs a due timer too. `degraded` robots (a robot-wide recovery
        condition holds) are not eligible: an allocator on one abdicates before recovery runs.
        `preempt`: the deployed system's `allocation.preempt`."""
        if self.core is None:
            self.core = Election(self.name, self.config, now, known_epoch=self.known_epoch)
        t = thresholds or Thresholds()
        view = {
            name: self._candidate(name, rec, t, name not in degraded or self._claims(name, rec))
            for name, rec in alive.items()
        }
        for gone in self._candidates.keys() - alive.keys():
            del self._candidates[gone]
        self.core.update(now, view, preempt=preempt)
        if self.core.next_timer() <= now:
            self.core.handle_timer(now)
        while (event := self.core.next_event()) is not None:
            self._events.append(event)

    def drain(self) -> list[ElectionEvent]:
        """The core's events since the last call (claims won, roles given up, leaders changed)."""
        events, self._events = self._events, []
        return events

    def _claims(self, name: str, rec: RobotRecord) -> bool:
        """Whether `name` (another robot) publishes a claim to the role."""
        e = rec.election
        return name != self.name and e is not None and e.claiming and e.leader == name

    def _candidate(self, name: str, rec: RobotRecord, t: Thresholds, healthy: bool) -> Candidate:
        made = self._candidates.get(name)
        if made is not None and made[0] is rec and made[1] == t and made[2] == healthy:
            return made[3]
        c = candidate(rec, t, healthy)
        if self._claims(name, rec) and not c.eligible:
            c = replace(c, eligible=True)  # its claim, at its word (module docstring)
        self._candidates[name] = (rec, t, healthy, c)
        return c

    def next_timer(self) -> float:
        """When the core wants to be woken (inf: nothing pending)."""
        return math.inf if self.core is None else self.core.next_timer()

    def leave(self, now: float) -> None:
        """Abdicate for good (graceful leave)."""
        if self.core is not None:
            self.core.leave(now)

    def info(self) -> ElectionInfo:
        """What this robot publishes in its record."""
        if self.core is None:
            return ElectionInfo(0, None, False)
        s = self.core.state()
        return ElectionInfo(s.epoch, s.leader, s.claiming)

    def is_allocator(self) -> bool:
        """Whether this robot holds the allocator role now."""
        return self.core is not None and self.core.is_leader
