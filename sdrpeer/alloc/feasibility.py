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

Per-component and per-connection constraints: a component's own Table I thresholds
(`ComponentDef.thresholds`) and a connection's own Table II bounds (`ConnectionDef.bounds`) narrow
the fleet's (`Thresholds.stricter`); the robot checks of a component run under its narrowed
thresholds, and the link check between two robots under the bounds of every connection between
the two components (memoised per pair of robots and bounds). A constraint the fleet leaves off
is checked for the component or connection that sets it.

What an instance needs on a robot (`need`): nothing for a cold standby (placed, not running);
otherwise its `requires`, less what an instance of the same name and component already running
on that robot uses now (the robot's metrics count that already). Instances in `GONE_STATES` do
not count as running.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence

from sdrpeer.alloc.constraints import (
    LinkConstraint,
    Need,
    RobotConstraint,
    RobotLoad,
    active_constraints,
)
from sdrpeer.alloc.strategies import Peer
from sdrpeer.alloc.view import RobotView
from sdrpeer.record.robot import InstanceInfo
from sdrpeer.system.model import AllocationDef, ComponentDef, ConnectionDef, Thresholds
from sdrpeer.vocabulary import LifecycleState, ProcessState

GONE_STATES: frozenset[str] = frozenset(
    {LifecycleState.FINALIZED, ProcessState.STOPPING, ProcessState.STOPPED, ProcessState.FAILED}
)
"""Instance states that do not count as running (they are going or gone)."""
_NOTHING = Need()


def connection_bounds(
    fleet: Thresholds, connections: Sequence[ConnectionDef]
) -> dict[tuple[str, str], Thresholds]:
    """(component, component) -> the fleet's thresholds narrowed by the bounds of every
    connection between the two (both orders; only pairs with bounds of their own)."""
    out: dict[tuple[str, str], Thresholds] = {}
    for c in connections:
        if not c.bounds.has_any():
            continue
        for key in ((c.from_component, c.to_component), (c.to_component, c.from_component)):
            out[key] = out.get(key, fleet).stricter(c.bounds)
    return out


class Feasibility:
    """The constraint checks of one allocation, with what does not change memoised."""

    def __init__(
        self,
        robots: tuple[RobotView, ...],
        loads: tuple[RobotLoad, ...],
        allocation: AllocationDef,
        avoid: Mapping[str, Collection[str]] | None = None,
        connections: Sequence[ConnectionDef] = (),
    ) -> None:
        self.robots = robots
        self.avoid = avoid or {}
        """component -> robots it must not be placed on (recovery moved it away from them)."""
        self.loads = loads
        self.t = allocation.thresholds
        self.extra = allocation.constraints
        self._ids: dict[Thresholds, int] = {}
        self._sets: list[_Set] = []
        """Each distinct set of thresholds in use gets a small id (keys of the memos below)."""
        self._fleet = self._intern(self.t)
        self.edges = {k: self._intern(t) for k, t in connection_bounds(self.t, connections).items()}
        """(component, component) -> the thresholds id their link must meet (own bounds only)."""
        self._comp_t: dict[str, int] = {}
        self._static: dict[int, tuple[str | None, str | None]] = {}
        """robot index + thresholds id * robots -> (hot, cold) reason."""
        self._pairs: dict[int, str | None] = {}
        """pair index + thresholds id * robots^2 -> the first link constraint failed."""
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

    @property
    def static_cs(self) -> list[RobotConstraint]:
        """The fleet's static robot constraints (what an explanation names as checked)."""
        return self._sets[self._fleet].static

    @property
    def hot_cs(self) -> list[RobotConstraint]:
        """The fleet's load constraints for a running instance."""
        return self._sets[self._fleet].hot

    @property
    def cold_cs(self) -> list[RobotConstraint]:
        """The fleet's load constraints that also hold for a cold standby."""
        return self._sets[self._fleet].cold

    @property
    def link_cs(self) -> list[LinkConstraint]:
        """The fleet's link constraints."""
        return self._sets[self._fleet].link

    def need(self, comp: ComponentDef, name: str, cold: bool, i: int) -> Need:
        """What the instance adds to robot i: nothing if cold, less what already runs there."""
        if cold:
            return _NOTHING
        req = comp.requires
        inst = self.running.get((i, name))
        if inst is None or inst.component != comp.name:
            return Need(req.cpu_pct, req.mem_bytes)
        return Need(max(0.0, req.cpu_pct - inst.cpu_pct), max(0, req.mem_bytes - inst.rss))

    def _intern(self, t: Thresholds) -> int:
        """The id of thresholds `t`, with its enabled constraints computed once."""
        got = self._ids.get(t)
        if got is None:
            robot_cs, link_cs = active_constraints(self.extra, t)
            got = self._ids[t] = len(self._sets)
            self._sets.append(_Set(t, robot_cs, link_cs))
        return got

    def _comp(self, comp: ComponentDef) -> int:
        """The id of the Table I thresholds `comp` is held to: the fleet's narrowed by its own."""
        got = self._comp_t.get(comp.name)
        if got is None:
            own = comp.thresholds
            got = self._fleet if not own.has_any() else self._intern(self.t.stricter(own))
            self._comp_t[comp.name] = got
        return got

    def _static_reason(self, i: int, comp: ComponentDef, cold: bool, tid: int) -> str | None:
        """The first static constraint robot i fails (for hot, or for cold instances)."""
        key = i + tid * len(self.robots)
        cached = self._static.get(key)
        if cached is None:
            hot: str | None = None
            cold_r: str | None = None
            cs = self._sets[tid]
            for c in cs.static:
                why = c.check(self.loads[i], _NOTHING, comp, cs.t)
                if why is not None:
                    hot = hot or f"{c.name}: {why}"
                    if c.cold:
                        cold_r = cold_r or f"{c.name}: {why}"
            cached = self._static[key] = (hot, cold_r)
        return cached[1] if cold else cached[0]

    def _pair(self, i: int, q: int, tid: int) -> str | None:
        """The first link constraint robots i and q fail together under thresholds `tid`."""
        n = len(self.robots)
        key = (i * n + q if i < q else q * n + i) + tid * n * n
        if key in self._pairs:
            return self._pairs[key]
        a, b = self.robots[i], self.robots[q]
        link, dist = a.link_to(b), a.distance_to(b)
        why: str | None = None
        cs = self._sets[tid]
        for c in cs.link:
            r = c.check(a, b, link, dist, cs.t)
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
        tid = self._comp_t.get(comp.name)
        if tid is None:
            tid = self._comp(comp)
        why = self._static_reason(i, comp, cold, tid)
        if why is not None:
            return why
        load = self.loads[i]
        need = self.need(comp, name, cold, i)
        cs = self._sets[tid]
        for c in cs.cold if cold else cs.hot:
            r = c.check(load, need, comp, cs.t)
            if r is not None:
                return f"{c.name}: {r}"
        edges, fleet = self.edges, self._fleet
        for p in peers:
            if p.robot != i:
                link_t = edges.get((comp.name, p.component), fleet) if edges else fleet
                r = self._pair(i, p.robot, link_t)
                if r is not None:
                    return f"link to {p.component} on {self.robots[p.robot].name}: {r}"
        return None


class _Set:
    """The enabled constraints under one set of thresholds, split as `reason` uses them."""

    __slots__ = ("cold", "hot", "link", "static", "t")

    def __init__(
        self, t: Thresholds, robot: list[RobotConstraint], link: list[LinkConstraint]
    ) -> None:
        self.t = t
        self.static = [c for c in robot if c.static]
        self.hot = [c for c in robot if not c.static]
        self.cold = [c for c in self.hot if c.cold]
        self.link = link
