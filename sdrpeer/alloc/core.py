"""Dynamic module allocation: (system, cluster view[, previous plan]) -> a plan or a report.

How it works (pure: no I/O, no clock; `allocate` is the whole API):
1. Robots are indexed in first-fit order (`view.origin` first). Components are ordered so that
   connected ones follow each other (`order.py`). Each instance is a slot: the active one, then
   `standby.same_robot` standbys on the active's robot and `standby.other_robots` standbys each
   on a robot of its own (not the active's, not another standby's).
2. Actives are placed first, in three passes: (a) every active that the previous plan or a
   running instance of the same name already has on a robot stays there if that robot still
   passes every constraint (smallest change); (b) pinned components, on their pin or nowhere;
   (c) the rest: a robot already running a standby of the component, or given a hot one by the
   previous plan and not reporting it yet (the paper reuses started standbys: the active takes
   over that instance and its name, so a re-allocation after the active's robot died activates
   a warm standby instead of starting a new instance), then
   `prefer`, then the strategy's order. Standbys follow in two passes: (a) kept where the
   previous plan or a running instance has them, (b) the rest, named `<component>-s<k>` with the
   smallest free k (names held by the previous plan stay with their instance).
3. A robot takes an instance when every enabled robot constraint passes with what the plan put
   there so far, and every link constraint passes between it and the robot of each connected
   component already placed (`feasibility.py`: once per pair of robots, memoised). Standbys are
   checked against the actives of the connected components.
4. Memory and CPU: a robot's metrics already count what runs there now, so an instance running
   on the robot it is placed on adds only what it still lacks (its need minus its measured use).
5. Cold standbys are placements the robot launches only when needed: they use nothing, so only
   constraints with `cold = True` apply (battery, links, plugins), not CPU or memory.
6. Any instance without a robot makes the result `Infeasible` (never a partial plan), listing
   for every robot the constraint that ruled it out.
7. `held` components keep the previous plan's placements as they are, also on robots not in the
   view (the disconnect policy: the fleet does not replace them yet); what they hold on robots in
   the view still counts against those robots.
8. Every decision is explained as it is made (`explain.py`): the plan carries one `Why` per
   placement and per standby left out (the robots tried and what ruled each out, how the robot
   was chosen, the constraints it passed, the objective's scores).
"""

from __future__ import annotations

from collections.abc import Collection, Iterable, Mapping, Sequence

from sdrpeer.alloc.constraints import RobotLoad
from sdrpeer.alloc.explain import Explainer
from sdrpeer.alloc.feasibility import Feasibility
from sdrpeer.alloc.order import adjacency, component_order
from sdrpeer.alloc.result import AllocationResult, Infeasible, Unplaced
from sdrpeer.alloc.strategies import STRATEGIES, Context, Peer
from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.plan import Placement, Plan
from sdrpeer.record.robot import InstanceInfo
from sdrpeer.system.model import ComponentDef, SystemDef
from sdrpeer.vocabulary import InstanceRole

NOT_IN_VIEW = "not in view (dead, left or unknown)"


def allocate(
    system: SystemDef,
    view: ClusterView,
    *,
    epoch: int,
    version: int,
    allocator: str,
    previous: Plan | None = None,
    avoid: Mapping[str, Collection[str]] | None = None,
    standbys_optional: bool = False,
    held: Collection[str] = (),
) -> AllocationResult:
    """Place every instance of `system` on the robots in `view` (see the module docstring).

    `avoid`: component -> robots its instances must not be placed on (recovery moving a
    component off a robot where it failed, while its other components stay).
    `standbys_optional`: a standby that finds no robot is left out instead of making the result
    infeasible (recovery: the actives must run even when too few robots are left for standbys;
    `Plan.standbys_short` tells what is missing).
    `held`: components whose previous placements are kept as they are (point 7)."""
    allocation = _Allocation(system, view, previous, avoid)
    allocation.standbys_optional = standbys_optional
    allocation.held = frozenset(held)
    return allocation.run(epoch, version, allocator)


def _first_fit_order(view: ClusterView) -> tuple[RobotView, ...]:
    """The origin first, then the other robots in view order."""
    first = [r for r in view.robots if r.name == view.origin]
    return tuple(first + [r for r in view.robots if r.name != view.origin])


class _Allocation:
    """The state of one allocation (used once)."""

    def __init__(
        self,
        system: SystemDef,
        view: ClusterView,
        previous: Plan | None,
        avoid: Mapping[str, Collection[str]] | None = None,
    ) -> None:
        self.system = system
        self.t = system.allocation.thresholds
        self.robots = _first_fit_order(view)
        self.index = {r.name: i for i, r in enumerate(self.robots)}
        self.loads = tuple(RobotLoad(r) for r in self.robots)
        self.check = Feasibility(
            self.robots, self.loads, system.allocation, avoid, system.connections
        )
        self.standbys_optional = False
        """Leave out standbys that find no robot (see `allocate`)."""
        self.held: frozenset[str] = frozenset()
        """Components whose previous placements are kept as they are (see `allocate`)."""
        self.running_standbys: dict[str, list[tuple[int, InstanceInfo]]] = {}
        for i, inst in self.check.running.items():
            if inst.role == InstanceRole.STANDBY:
                self.running_standbys.setdefault(inst.component, []).append((i[0], inst))
        self.adj = adjacency(system)
        self.order = component_order(system, self.adj)
        strategy = STRATEGIES.get(system.allocation.strategy)
        self.ranker = strategy.ranker(Context(self.robots, self.loads, system.allocation))
        self.explain = Explainer(self.robots, self.check, self.ranker)
        self.previous: dict[str, list[Placement]] = {}
        for p in previous.placements if previous is not None else ():
            self.previous.setdefault(p.component, []).append(p)
        self.active_at: dict[str, int] = {}
        self.holders: dict[str, dict[int, str]] = {c.name: {} for c in system.components}
        self.names: dict[str, set[str]] = {c.name: set() for c in system.components}
        self.placements: list[Placement] = []
        self.unplaced: list[Unplaced] = []
        self.kept = 0

    def _peers(self, comp: ComponentDef) -> list[Peer]:
        """Connected components whose active is placed, with the traffic to each."""
        at = self.active_at
        return [Peer(at[p], rate, p) for p, rate in self.adj[comp.name].items() if p in at]

    # -- placing --------------------------------------------------------------------------

    def _place(
        self, comp: ComponentDef, name: str, role: InstanceRole, cold: bool, i: int, *, how: str
    ) -> None:
        if how == "held":
            self.explain.held(comp, name, role, self.robots[i].name)
        else:
            peers = self._peers(comp)
            self.explain.placed(comp, name, role, i, cold=cold, how=how, peers=peers)
        need = self.check.need(comp, name, cold, i)
        load = self.loads[i]
        load.cpu_pct += need.cpu_pct
        load.mem_bytes += need.mem_bytes
        self.ranker.placed(i)
        mode = "cold" if cold else "hot"
        self.placements.append(Placement(comp.name, name, self.robots[i].name, role, mode))
        self.holders[comp.name][i] = name
        self.names[comp.name].add(name)
        if role == InstanceRole.ACTIVE:
            self.active_at[comp.name] = i

    def _first(
        self,
        comp: ComponentDef,
        name: str,
        cold: bool,
        candidates: Iterable[int],
        peers: Sequence[Peer],
    ) -> int | None:
        """The first candidate robot (not holding this component yet) that takes the instance."""
        held = self.holders[comp.name]
        for i in candidates:
            if i in held:
                self.explain.tried(name, i, f"already holds {held[i]}")
                continue
            why = self.check.reason(comp, name, cold, i, peers)
            if why is None:
                return i
            self.explain.tried(name, i, why)
        return None

    def _sticky(self, comp: ComponentDef, name: str) -> list[int]:
        """Robots that already have this instance: the previous plan's, then running ones."""
        out = [
            self.index[p.robot]
            for p in self.previous.get(comp.name, ())
            if p.instance == name and p.robot in self.index
        ]
        out += [
            i
            for i in self.check.running_at.get(name, ())
            if self.check.running[(i, name)].component == comp.name
        ]
        return list(dict.fromkeys(out))

    def _candidates(self, comp: ComponentDef) -> Iterable[int]:
        """`prefer` robots in view, then the strategy's order (repeats are re-checked cheaply)."""
        prefer = [self.index[n] for n in comp.prefer if n in self.index]
        yield from prefer
        tried = set(prefer)
        for i in self.ranker.order(comp, self._peers(comp)):
            if i not in tried:
                yield i

    def _fail(
        self, comp: ComponentDef, name: str, role: InstanceRole, cold: bool, only: int | None
    ) -> None:
        """Record that the instance found no robot, with every robot's reason."""
        self.unplaced.append(
            Unplaced(comp.name, name, role, self._reasons(comp, name, role, cold, only))
        )

    def _reasons(
        self, comp: ComponentDef, name: str, role: InstanceRole, cold: bool, only: int | None
    ) -> tuple[tuple[str, str], ...]:
        """Why each robot (or only robot `only`) cannot take the instance."""
        peers = self._peers(comp)
        held = self.holders[comp.name]
        reasons: list[tuple[str, str]] = []
        for i, r in enumerate(self.robots):
            if only is not None and i != only:
                continue
            if i in held:
                why: str | None = f"already holds {held[i]}"
            else:
                why = self.check.reason(comp, name, cold, i, peers)
            reasons.append((r.name, why or "ok, but another instance needed it first"))
        missing = [p.robot for p in self.previous.get(comp.name, ()) if p.instance == name]
        if role == InstanceRole.ACTIVE and comp.pin is not None:
            missing.append(comp.pin)
        for robot in dict.fromkeys(missing):
            if robot not in self.index:
                reasons.append((robot, NOT_IN_VIEW))
        return tuple(reasons)

    def _fresh_name(self, comp: ComponentDef) -> str:
        """`<component>-s<k>` with the smallest k not used by this component."""
        k = 1
        while f"{comp.name}-s{k}" in self.names[comp.name]:
            k += 1
        return f"{comp.name}-s{k}"

    def _actives(self) -> None:
        """Place every active instance (module docstring, point 2)."""
        names: dict[str, str] = {}
        for comp in self.order:
            if comp.name in self.held:
                continue
            prev = [p for p in self.previous.get(comp.name, ()) if p.role == InstanceRole.ACTIVE]
            names[comp.name] = prev[0].instance if prev else comp.name
            peers = self._peers(comp)
            for i in self._sticky(comp, names[comp.name]):
                if comp.pin not in (None, self.robots[i].name):
                    continue
                why = self.check.reason(comp, names[comp.name], False, i, peers)
                if why is None:
                    self._place(comp, names[comp.name], InstanceRole.ACTIVE, False, i, how="kept")
                    self.kept += 1
                    break
                self.explain.tried(names[comp.name], i, f"was here; now {why}")
        rest = [c for c in self.order if c.name not in self.active_at and c.name not in self.held]
        for comp in sorted(rest, key=lambda c: c.pin is None):
            name = names[comp.name]
            if comp.pin is not None:
                pin = self.index.get(comp.pin)
                if pin is None or self._first(comp, name, False, [pin], self._peers(comp)) is None:
                    self._fail(
                        comp, name, InstanceRole.ACTIVE, False, pin if pin is not None else -1
                    )
                else:
                    self._place(comp, name, InstanceRole.ACTIVE, False, pin, how="pinned")
                continue
            if self._adopt(comp, name):
                continue
            got = self._first(comp, name, False, self._candidates(comp), self._peers(comp))
            if got is None:
                self._fail(comp, name, InstanceRole.ACTIVE, False, None)
            else:
                self._place(comp, name, InstanceRole.ACTIVE, False, got, how=self._how(comp, got))

    def _adopt(self, comp: ComponentDef, name: str) -> bool:
        """Make a running standby of `comp` its active, if one fits (it keeps its name; what
        ruled out the robots tried for the active `name` goes with it)."""
        peers = self._peers(comp)
        for i, standby in self._takeovers(comp):
            why = self.check.reason(comp, standby, False, i, peers)
            if why is None:
                self.explain.carry(name, standby)
                self._place(comp, standby, InstanceRole.ACTIVE, False, i, how="standby_promoted")
                self.kept += 1
                return True
            self.explain.tried(standby, i, f"runs a standby; {why}")
        return False

    def _takeovers(self, comp: ComponentDef) -> list[tuple[int, str]]:
        """(robot index, name) of the standbys of `comp` an active may take over: the running
        ones, then the previous plan's hot ones that robots in the view have not reported yet
        (a standby still starting when its active's robot died is the quickest way back)."""
        out = [(i, inst.name) for i, inst in self.running_standbys.get(comp.name, ())]
        seen = {name for _, name in out}
        for p in self.previous.get(comp.name, ()):
            i = self.index.get(p.robot)
            hot = p.role == InstanceRole.STANDBY and p.mode != "cold"
            if not hot or i is None or p.instance in seen or p.instance in self.names[comp.name]:
                continue
            if any(inst.name == p.instance for inst in self.robots[i].instances):
                continue  # reported, and not running: failed or going (not a standby to take)
            out.append((i, p.instance))
        return out

    def _how(self, comp: ComponentDef, i: int) -> str:
        """preferred when robot i is in the component's `prefer` list, else ranked."""
        return "preferred" if self.robots[i].name in comp.prefer else "ranked"

    def _standbys(self) -> None:
        """Place every standby (module docstring, point 2)."""
        todo: list[tuple[ComponentDef, int, int]] = []
        for comp in self.order:
            at = self.active_at.get(comp.name)
            spec = comp.standby
            if at is None or spec.same_robot + spec.other_robots == 0 or comp.name in self.held:
                continue
            cold = spec.mode == "cold"
            peers = self._peers(comp)
            same = other = 0
            for name, i in self._pool(comp):
                fits = self.check.reason(comp, name, cold, i, peers) is None
                if i == at and same < spec.same_robot and fits:
                    same += 1
                elif i not in self.holders[comp.name] and other < spec.other_robots and fits:
                    other += 1
                else:
                    continue
                self._place(comp, name, InstanceRole.STANDBY, cold, i, how="kept")
                self.kept += 1
            todo.append((comp, spec.same_robot - same, spec.other_robots - other))
        for comp, same, other in todo:
            at = self.active_at[comp.name]
            cold = comp.standby.mode == "cold"
            peers = self._peers(comp)
            for n in range(same + other):
                name = self._fresh_name(comp)
                only = at if n < same else None
                if only is not None:
                    got = self._first_same(comp, name, cold, only, peers)
                else:
                    got = self._first(comp, name, cold, self._candidates(comp), peers)
                if got is None and self.standbys_optional:
                    reasons = self._reasons(comp, name, InstanceRole.STANDBY, cold, only)
                    self.explain.left_out(comp, name, InstanceRole.STANDBY, list(reasons))
                    continue
                if got is None:
                    self._fail(comp, name, InstanceRole.STANDBY, cold, only)
                    self.names[comp.name].add(name)
                else:
                    how = "same_robot" if only is not None else self._how(comp, got)
                    self._place(comp, name, InstanceRole.STANDBY, cold, got, how=how)

    def _first_same(
        self, comp: ComponentDef, name: str, cold: bool, at: int, peers: Sequence[Peer]
    ) -> int | None:
        """The active's robot, if it also takes this same-robot standby."""
        why = self.check.reason(comp, name, cold, at, peers)
        if why is not None:
            self.explain.tried(name, at, why)
        return at if why is None else None

    def _pool(self, comp: ComponentDef) -> list[tuple[str, int]]:
        """Standbys that exist already: the previous plan's, then running ones, by name."""
        pool: dict[str, int] = {}
        for p in self.previous.get(comp.name, ()):
            if p.role == InstanceRole.STANDBY and p.robot in self.index:
                pool.setdefault(p.instance, self.index[p.robot])
        for i, inst in self.running_standbys.get(comp.name, ()):
            pool.setdefault(inst.name, i)
        used = self.names[comp.name]
        return [(name, i) for name, i in pool.items() if name not in used]

    def _hold(self) -> None:
        """Keep the previous placements of every held component (module docstring, point 7)."""
        for comp in self.order:
            if comp.name not in self.held:
                continue
            for p in self.previous.get(comp.name, ()):
                i = self.index.get(p.robot)
                if i is None:
                    self.placements.append(p)
                    self.names[comp.name].add(p.instance)
                    self.explain.held(comp, p.instance, p.role, p.robot)
                else:
                    self._place(comp, p.instance, p.role, p.mode == "cold", i, how="held")
                    self.kept += 1

    def run(self, epoch: int, version: int, allocator: str) -> AllocationResult:
        """Place everything; a Plan, or an Infeasible report."""
        self._hold()
        self._actives()
        self._standbys()
        if self.unplaced:
            return AllocationResult(
                infeasible=Infeasible(self.system.name, tuple(self.unplaced), len(self.robots))
            )
        declared = {c.name: k for k, c in enumerate(self.system.components)}
        placements = sorted(
            self.placements,
            key=lambda p: (
                declared[p.component],
                p.role != InstanceRole.ACTIVE,
                len(p.instance),
                p.instance,
            ),
        )
        order = {p.instance: k for k, p in enumerate(placements)}
        why = sorted(
            self.explain.whys,
            key=lambda w: (w.robot is None, order.get(w.instance, 0), declared[w.component]),
        )
        plan = Plan(epoch, version, self.system, tuple(placements), allocator, why=tuple(why))
        return AllocationResult(plan=plan, kept=self.kept)
