"""Election cores driven by the simulated membership cores: one `Election` per robot, plans fenced.

How it works:
- `ElectionSim` wraps a `Cluster` before it starts and replaces its `Trace` with one that also
  forwards every core event here: `MemberChanged` sets a robot's `alive` in the observer's view
  (ALIVE or SUSPECT count as alive), `RecordChanged` decodes the sim record
  `[priority, health, eligible, [epoch, leader, claiming], [plan_epoch, plan_version] | nil]`;
- an observer whose view changed is marked dirty; dirty robots are stepped from a scheduled
  action `batch` virtual seconds later (never from inside a core call): each gets its own
  candidate (the sim's `Facts` and its current state), `update(now, view)`, its events logged, its
  record republished when it changed, and its election timer scheduled on the cluster;
- every `plan_interval` each robot that claims the role issues the next plan version and
  publishes it in its record (and keeps showing its last one after it steps down: a stale plan);
  every robot that sees a plan in a record offers it to its `PlanBook` entry (fence first). A
  robot that adopts an allocator raises its fence to that claim;
- like the agent, each robot republishes its record every `heartbeat` seconds: a restarted
  robot's record can reuse the version number of its old one, and gossip (which compares only
  versions) keeps the old bytes everywhere until the next version;
- a robot that knows no other alive robot has not joined (it restarted while its seed was on the
  far side of a partition): `parts()` leaves it out until it joins.
"""

from __future__ import annotations

import functools
import math
from dataclasses import dataclass
from typing import Any

import msgpack

from sdrpeer.election import (
    Candidate,
    Election,
    ElectionConfig,
    ElectionEvent,
    LeaderChanged,
    state_from_wire,
    state_to_wire,
)
from sdrpeer.gossip.events import REAPED, CoreEvent, MemberChanged, RecordChanged
from sdrpeer.gossip.messages import ALIVE, SUSPECT
from sdrpeer.sim.cluster import Cluster
from sdrpeer.sim.plans import PlanBook
from sdrpeer.sim.trace import Trace


@dataclass(slots=True)
class Facts:
    """What a simulated robot says of itself in its record (the sim's stand-in for metrics)."""

    priority: int = 0
    health: int = 3
    eligible: bool = True
    leaving: bool = False


class _ForwardingTrace(Trace):
    """A Trace that also hands every event, boot and kill to the ElectionSim."""

    def __init__(self, old: Trace, sim: ElectionSim) -> None:
        super().__init__(old.names, keep_all=old.keep_all)
        self._sim = sim

    def record(self, i: int, event: CoreEvent, now: float) -> None:
        super().record(i, event, now)
        self._sim.on_core_event(i, event)

    def up(self, i: int, now: float) -> None:
        super().up(i, now)
        self._sim.on_boot(i, now)

    def down(self, i: int, now: float) -> None:
        super().down(i, now)
        self._sim.on_kill(i)


class ElectionSim:
    """Election and fenced plans on top of a simulated cluster; build it before `start()`."""

    def __init__(
        self,
        cluster: Cluster,
        config: ElectionConfig,
        *,
        priorities: dict[str, int] | None = None,
        plan_interval: float | None = 0.5,
        heartbeat: float | None = 5.0,
        batch: float = 0.0,
    ) -> None:
        if any(cluster.trace.boots):
            raise ValueError("build the ElectionSim before starting the cluster")
        self.cluster = cluster
        self.config = config
        self.names = names = cluster.names
        self.batch = batch
        """Virtual seconds between an observer's view change and its election step."""
        self.heartbeat = heartbeat
        """Each robot republishes its record this often, as the agent does (None: on change)."""
        self.facts = [Facts(priority=(priorities or {}).get(name, 0)) for name in names]
        self.elections: list[Election | None] = [None] * len(names)
        self.views: list[dict[str, Candidate]] = [{} for _ in names]
        self.plans = PlanBook(names)
        """Fences, plans held and applied, and fencing violations."""
        self.log: list[tuple[float, str, ElectionEvent]] = []
        """Every election event, as (time, robot, event)."""
        self.belief_since = [0.0] * len(names)
        """Per robot: when its current belief (epoch, leader) began."""
        self._published: list[bytes | None] = [None] * len(names)
        self._timer_at = [math.inf] * len(names)
        self._generation = [0] * len(names)
        self._dirty: set[int] = set()
        self._flush_pending = False
        cluster.trace = _ForwardingTrace(cluster.trace, self)
        self._plan_interval = plan_interval
        if plan_interval is not None:
            cluster.schedule(plan_interval, self._plan_round)

    # -- faults and facts ---------------------------------------------------------------------

    def set_facts(self, name: str, **changes: Any) -> None:
        """Change what `name` reports (priority, health, eligible); it republishes at once."""
        i = self.cluster.index[name]
        for key, value in changes.items():
            setattr(self.facts[i], key, value)
        self._mark(i)

    def leave(self, name: str) -> None:
        """Graceful leave: `name` abdicates and announces its leave (kill it afterwards)."""
        i = self.cluster.index[name]
        self.facts[i].leaving = True
        election = self.elections[i]
        if election is not None and self.cluster.is_up(name):
            election.leave(self.cluster.now)
            self._after(i)
        self.cluster.leave(name)

    def issue_plan(self, name: str, epoch: int | None = None) -> None:
        """Let `name` issue its next plan at its current epoch (or at `epoch`: a stale allocator)
        and publish it in its record."""
        i = self.cluster.index[name]
        self.plans.issue(i, self.election(name).epoch if epoch is None else epoch, self.cluster.now)
        self._publish(i)

    # -- questions ----------------------------------------------------------------------------

    def election(self, name: str) -> Election:
        """The election core of `name` (its last one, if it is down)."""
        election = self.elections[self.cluster.index[name]]
        if election is None:
            raise ValueError(f"{name} has not booted yet")
        return election

    def belief(self, name: str) -> tuple[int, str | None]:
        """(epoch, allocator) that `name` believes in."""
        election = self.election(name)
        return (election.epoch, election.leader)

    def joined(self, name: str) -> bool:
        """Whether `name` runs, has not left, and knows at least one other alive robot."""
        i = self.cluster.index[name]
        if not self.cluster.is_up(name) or self.facts[i].leaving:
            return False
        return any(c.alive for other, c in self.views[i].items() if other != name)

    def parts(self) -> list[list[str]]:
        """The joined robots, grouped by the current network partition."""
        groups: list[list[int]] = []
        partitioned = self.cluster.network.partitioned
        for i, name in enumerate(self.names):
            if not self.joined(name):
                continue
            for group in groups:
                if not partitioned(group[0], i):
                    group.append(i)
                    break
            else:
                groups.append([i])
        return [[self.names[i] for i in group] for group in groups]

    def part_allocator(self, part: list[str]) -> str | None:
        """The one allocator of a part if it is settled: exactly one robot claims and every robot
        of the part believes in it ("" when no robot of the part may lead); else None."""
        claimers = [name for name in part if self.election(name).is_leader]
        if not claimers:
            return "" if not any(self._can_lead(name) for name in part) else None
        if len(claimers) != 1:
            return None
        key = self.belief(claimers[0])
        return claimers[0] if all(self.belief(name) == key for name in part) else None

    def settled(self) -> bool:
        """Whether every connected part has exactly one allocator that all its robots know."""
        return all(self.part_allocator(part) is not None for part in self.parts())

    def describe(self) -> str:
        """A short account of each part's beliefs (for assertion messages)."""
        lines = []
        for part in self.parts():
            beliefs: dict[tuple[int, str | None], int] = {}
            for name in part:
                beliefs[self.belief(name)] = beliefs.get(self.belief(name), 0) + 1
            claimers = [n for n in part if self.election(n).is_leader]
            lines.append(f"part of {len(part)}: claimers {claimers}, beliefs {beliefs}")
        return "; ".join(lines)

    # -- the trace's callbacks ----------------------------------------------------------------

    def on_core_event(self, i: int, event: CoreEvent) -> None:
        """File a membership core's event into robot i's view (and offer any plan it carries)."""
        kind, own = type(event), self.names[i]
        if kind is MemberChanged:
            assert isinstance(event, MemberChanged)
            if event.name == own:
                return
            view = self.views[i]
            c = view.get(event.name)
            if event.state == REAPED:
                view.pop(event.name, None)
            else:
                alive = event.state in (ALIVE, SUSPECT)
                if c is not None and c.alive == alive:
                    return
                old = c or Candidate(alive, False, 0, 0, None)
                view[event.name] = Candidate(
                    alive, old.eligible, old.priority, old.health, old.state
                )
            self._mark(i)
        elif kind is RecordChanged:
            assert isinstance(event, RecordChanged)
            if event.name == own:
                return
            priority, health, eligible, wire, plan = msgpack.unpackb(event.payload)
            c = self.views[i].get(event.name)
            new = Candidate(
                c is not None and c.alive, eligible, priority, health, state_from_wire(wire)
            )
            if new != c:  # a heartbeat or a new plan changes nothing here
                self.views[i][event.name] = new
                self._mark(i)
            if plan is not None and self.elections[i] is not None:
                self.plans.offer(i, plan[0], event.name, plan[1], self.cluster.now)

    def on_boot(self, i: int, now: float) -> None:
        """Robot i (re)started: a fresh core seeded with the epoch its fence kept."""
        epoch = self.plans.fences[i].epoch
        self.elections[i] = Election(self.names[i], self.config, now, known_epoch=epoch)
        self.views[i] = {}
        self._published[i] = None
        self._timer_at[i] = math.inf
        self.facts[i].leaving = False
        self._generation[i] += 1
        self._mark(i)
        if self.heartbeat is not None:
            first = now + self.heartbeat * (1.0 + i / len(self.names))
            self.cluster.schedule(first, functools.partial(self._beat, i, self._generation[i]))

    def on_kill(self, i: int) -> None:
        """Robot i crashed: its election stops."""
        self._timer_at[i] = math.inf
        self._dirty.discard(i)

    # -- stepping -----------------------------------------------------------------------------

    def _mark(self, i: int) -> None:
        self._dirty.add(i)
        if not self._flush_pending:
            self._flush_pending = True
            self.cluster.schedule(self.cluster.now + self.batch, self._flush)

    def _flush(self) -> None:
        self._flush_pending = False
        dirty, self._dirty = sorted(self._dirty), set()
        for i in dirty:
            election = self.elections[i]
            if election is None or not self.cluster.is_up(self.names[i]):
                continue
            f = self.facts[i]
            self.views[i][self.names[i]] = Candidate(
                True, f.eligible and not f.leaving, f.priority, f.health, election.state()
            )
            election.update(self.cluster.now, self.views[i])
            self._after(i)

    def _on_timer(self, i: int, at: float) -> None:
        election = self.elections[i]
        if self._timer_at[i] != at or election is None or not self.cluster.is_up(self.names[i]):
            return
        self._timer_at[i] = math.inf
        election.handle_timer(self.cluster.now)
        self._after(i)

    def _after(self, i: int) -> None:
        """Log robot i's events, republish its record if it changed, schedule its timer."""
        election = self.elections[i]
        assert election is not None
        name, now = self.names[i], self.cluster.now
        while (event := election.next_event()) is not None:
            self.log.append((now, name, event))
            if isinstance(event, LeaderChanged):
                self.belief_since[i] = now
                if event.leader is not None:
                    self.plans.fences[i].raise_to(event.epoch, event.leader)
        self._publish(i)
        at = election.next_timer()
        if at != math.inf and at != self._timer_at[i]:
            self._timer_at[i] = at
            self.cluster.schedule(at, functools.partial(self._on_timer, i, at))

    def _publish(self, i: int) -> None:
        election = self.elections[i]
        assert election is not None
        f = self.facts[i]
        wire = state_to_wire(election.state())
        plan = self.plans.issued[i]  # an allocator that stepped down still shows its last one
        record: bytes = msgpack.packb(
            [f.priority, f.health, f.eligible and not f.leaving, wire, plan]
        )
        if record != self._published[i]:
            self._published[i] = record
            self.cluster.set_record(self.names[i], record)

    def _beat(self, i: int, generation: int) -> None:
        """Republish robot i's record (same bytes, next version), then again a heartbeat later."""
        if generation != self._generation[i] or not self.cluster.is_up(self.names[i]):
            return
        record = self._published[i]
        if record is not None:
            self.cluster.set_record(self.names[i], record)
        assert self.heartbeat is not None
        later = functools.partial(self._beat, i, generation)
        self.cluster.schedule(self.cluster.now + self.heartbeat, later)

    def _can_lead(self, name: str) -> bool:
        f = self.facts[self.cluster.index[name]]
        return f.eligible and not f.leaving

    def _plan_round(self) -> None:
        for i, name in enumerate(self.names):
            election = self.elections[i]
            if election is not None and election.is_leader and self.cluster.is_up(name):
                self.issue_plan(name)
        assert self._plan_interval is not None
        self.cluster.schedule(self.cluster.now + self._plan_interval, self._plan_round)


def run_until_settled(sim: ElectionSim, timeout: float, step: float = 0.1) -> float | None:
    """Run until `sim.settled()`; the virtual seconds it took, or None after `timeout`. What is
    due now (a change of facts, say) runs before the first check."""
    began = sim.cluster.now
    sim.cluster.run_until(began)
    return sim.cluster.now - began if sim.cluster.wait_for(sim.settled, timeout, step) else None
