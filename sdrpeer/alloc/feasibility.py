"""Feasibility: does robot i take one more instance, given what the plan put there so far?

How it works: `Feasibility` holds the enabled constraints and the per-robot and per-pair results
that do not change during one allocation: static robot constraints (battery, plugins marked
`static`) are checked once per robot, link constraints once per pair of robots (memoised by
index pair, so a placement costs a dictionary lookup per placed peer, never a rescan). Only the
load constraints (CPU, memory) run per candidate, against `RobotLoad`, which the core updates as
instances land.

A robot whose launch policy (`sdrpeer.launch.policy`, gossiped in its record) refuses the
component's launcher or target never takes it, a cold standby included (it would be launched
there on a failover).

What an instance needs on a robot (`need`): nothing for a cold standby (placed, not running);
otherwise its `requires`, less what an instance of the same name and component already running
on that robot uses now (the robot's metrics count that already). Instances in `GONE_STATES` do
not count as running.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

from sdrpeer.alloc.constraints import Need, RobotLoad, active_constraints
from sdrpeer.alloc.strategies import Peer
from sdrpeer.alloc.view import RobotView
from sdrpeer.record.robot import InstanceInfo
from sdrpeer.system.model import AllocationDef, ComponentDef
from sdrpeer.vocabulary import LifecycleState, ProcessState

GONE_STATES: frozenset[str] = frozenset(
    {LifecycleState.FINALIZED, ProcessState.STOPPING, ProcessState.STOPPED, ProcessState.FAILED}
)
"""Instance states that do not count as running (they are going or gone)."""
_NOTHING = Need()


class Feasibility:
    """The constraint checks of one allocation, with what does not change memoised."""

    def __init__(
        self,
        robots: tuple[RobotView, ...],
        loads: tuple[RobotLoad, ...],
        allocation: AllocationDef,
        avoid: Mapping[str, Collection[str]] | None = None,
    ) -> None:
        self.robots = robots
        self.avoid = avoid or {}
        """component -> robots it must not be placed on (recovery moved it away from them)."""
        self.loads = loads
        self.t = allocation.thresholds
        robot_cs, self.link_cs = active_constraints(allocation.constraints, self.t)
        self.static_cs = [c for c in robot_cs if c.static]
        self.hot_cs = [c for c in robot_cs if not c.static]
        self.cold_cs = [c for c in self.hot_cs if c.cold]
        self._static: dict[int, tuple[str | None, str | None]] = {}
        self._pairs: dict[int, str | None] = {}
        self.running: dict[tuple[int, str], InstanceInfo] = {}
        """(robot index, instance name) -> the instance running there."""
        self.running_at: dict[str, list[int]] = {}
        """Instance name -> robots running an instance of that name."""
        for k, r in enumerate(robots):
            for inst in r.instances:
                if inst.state in GONE_STATES:
                    continue
                self.running[(k, inst.name)] = inst
                self.running_at.setdefault(inst.name, []).append(k)

    def need(self, comp: ComponentDef, name: str, cold: bool, i: int) -> Need:
        """What the instance adds to robot i: nothing if cold, less what already runs there."""
        if cold:
            return _NOTHING
        req = comp.requires
        inst = self.running.get((i, name))
        if inst is None or inst.component != comp.name:
            return Need(req.cpu_pct, req.mem_bytes)
        return Need(max(0.0, req.cpu_pct - inst.cpu_pct), max(0, req.mem_bytes - inst.rss))

    def _static_reason(self, i: int, comp: ComponentDef, cold: bool) -> str | None:
        """The first static constraint robot i fails (for hot, or for cold instances)."""
        cached = self._static.get(i)
        if cached is None:
            hot: str | None = None
            cold_r: str | None = None
            for c in self.static_cs:
                why = c.check(self.loads[i], _NOTHING, comp, self.t)
                if why is not None:
                    hot = hot or f"{c.name}: {why}"
                    if c.cold:
                        cold_r = cold_r or f"{c.name}: {why}"
            cached = self._static[i] = (hot, cold_r)
        return cached[1] if cold else cached[0]

    def _pair(self, i: int, q: int) -> str | None:
        """The first link constraint robots i and q fail together (memoised per pair)."""
        key = i * len(self.robots) + q if i < q else q * len(self.robots) + i
        if key in self._pairs:
            return self._pairs[key]
        a, b = self.robots[i], self.robots[q]
        link, dist = a.link_to(b), a.distance_to(b)
        why: str | None = None
        for c in self.link_cs:
            r = c.check(a, b, link, dist, self.t)
            if r is not None:
                why = f"{c.name}: {r}"
                break
        self._pairs[key] = why
        return why

    def reason(
        self, comp: ComponentDef, name: str, cold: bool, i: int, peers: Sequence[Peer]
    ) -> str | None:
        """None when robot i may take the instance, else the first constraint it fails."""
        if self.robots[i].name in self.avoid.get(comp.name, ()):
            return "avoid: recovery is moving this component away from it"
        refused = self.robots[i].launch.refusal(comp.launcher, comp.target)
        if refused is not None:
            return f"launch: {refused}"
        why = self._static_reason(i, comp, cold)
        if why is not None:
            return why
        load = self.loads[i]
        need = self.need(comp, name, cold, i)
        for c in self.cold_cs if cold else self.hot_cs:
            r = c.check(load, need, comp, self.t)
            if r is not None:
                return f"{c.name}: {r}"
        for p in peers:
            if p.robot != i:
                r = self._pair(i, p.robot)
                if r is not None:
                    return f"link to {p.component} on {self.robots[p.robot].name}: {r}"
        return None
