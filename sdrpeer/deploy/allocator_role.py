"""The allocator's duties, on the robot that holds the role: deploy, adopt, re-place, recover.

How it works: the coordinator calls `on_duty(now, state)` on every step while its robot is the
allocator (and `off_duty()` otherwise). On taking the role it first catches up with the newest
plan any robot gossips (at most `adopt_after` seconds), then re-issues it under its own epoch —
losing the allocator loses nothing — or, when some placement sits on a robot that is gone or
degraded, re-places at once (smallest change; the sick robot left out of the view; recovery
moves only need to stay out of a memory shortage, and place the actives even where too few robots
are left for every standby: the missing standbys are placed later, when robots allow).
`deploy` and `recover_component` (a robot's recovery step that changes who is active) run here
too; every new plan is accepted locally, gossiped, and pushed to every alive robot.
The disconnect policy (`deploy.disconnect`) says when a lost robot's actives are replaced: a
component whose policy waits keeps its placements until then (`held`). One replaced off a lost
robot with `reconcile: keep_original` is noted in the plan (`Plan.origins`, so any later
allocator knows) and moved back (a planned move, state handed over) once that robot is alive
again and not degraded.
"""

from __future__ import annotations

import asyncio
import logging
import math
import time
from dataclasses import replace
from typing import TYPE_CHECKING

from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.deploy import peers
from sdrpeer.deploy.disconnect import held_components
from sdrpeer.deploy.move import move_inputs, swap_to_standby
from sdrpeer.deploy.placer import Infeasible, place
from sdrpeer.errors import ApiError, NotAllocator
from sdrpeer.plan import Plan
from sdrpeer.system.model import SystemDef

if TYPE_CHECKING:
    from sdrpeer.deploy.coordinator import Coordinator
    from sdrpeer.deploy.view import ClusterState

log = logging.getLogger(__name__)


class AllocatorRole:
    """What the allocator does, for one coordinator."""

    def __init__(self, coordinator: Coordinator, adopt_after: float, retry_every: float) -> None:
        self.c = coordinator
        self.adopt_after = adopt_after
        self.retry_every = retry_every
        self._elected_at: float | None = None
        self._adopted_epoch = 0
        self._last_attempt: (
            tuple[tuple[int, str, int], frozenset[str], frozenset[str], frozenset[str]] | None
        ) = None
        self._last_attempt_at = 0.0
        self._lock = asyncio.Lock()
        self._lost_since: dict[str, float] = {}
        """Robot -> when this allocator first saw it gone while the plan placed something there."""
        self._due = math.inf
        self._moving_back: tuple[str, tuple[int, str, int]] | None = None
        """The keep_original move last asked for, with the key of the plan it was asked under
        (asked once per plan: a move that cannot be made waits for the next plan)."""

    def next_timer(self) -> float:
        """When a held component may be replaced (inf: none waits)."""
        return self._due

    def off_duty(self) -> None:
        """This robot does not hold the role (any more)."""
        self._elected_at = None
        self._lost_since.clear()
        self._due = math.inf

    def held(self, now: float, plan: Plan | None, state: ClusterState) -> frozenset[str]:
        """Components on lost robots the disconnect policy does not let us replace yet."""
        if plan is None:
            return frozenset()
        placed_on = {p.robot for p in plan.placements}
        for robot in placed_on - set(state.alive):
            self._lost_since.setdefault(robot, now)
        for robot in list(self._lost_since):
            if robot in state.alive or robot not in placed_on:
                del self._lost_since[robot]
        sick = self.c.health.degraded(now)
        held, self._due = held_components(plan, state.alive, self._lost_since, now, sick)
        return held

    def view(
        self, state: ClusterState, origin: str | None, exclude: frozenset[str] = frozenset()
    ) -> ClusterView:
        """The allocator's view: every alive robot with a record, in first-fit order, except
        `exclude` (robots that must not receive components: degraded, or being left)."""
        names = [n for n in state.order if n in state.alive] or sorted(state.alive)
        names = [n for n in names if n not in exclude]
        robots = tuple(
            RobotView(
                n,
                state.alive[n].metrics,
                state.alive[n].links,
                state.alive[n].instances,
                state.alive[n].launch,
            )
            for n in names
        )
        return ClusterView(robots, origin)

    def on_duty(self, now: float, state: ClusterState) -> None:
        """One step while this robot holds the role (adopt, then move what must move)."""
        if self._elected_at is None:
            self._elected_at = now
        epoch = self.c.election.info().epoch
        plan = self.c.store.plan
        if self._adopted_epoch != epoch:
            if not self.c.caught_up(state) and now - self._elected_at < self.adopt_after:
                return
            self._adopted_epoch = epoch
            if plan is not None and plan.epoch < epoch and not self._must_move(now, plan, state):
                self._reissue(plan, epoch, state, reason="new allocator")
                return
        if plan is None or plan.system is None:
            return
        held = self.held(now, plan, state)
        sick = frozenset(self.c.health.degraded(now))
        self._reconcile(plan, state, sick)
        lost = {p.robot for p in plan.placements if p.component not in held} - set(state.alive)
        placed_on = {p.robot for p in plan.placements}
        short = plan.standbys_short()
        if not (lost or placed_on & sick or short) or self._lock.locked():
            return
        attempt = (plan.key, frozenset(state.alive), sick, held)
        if attempt == self._last_attempt and now - self._last_attempt_at < self.retry_every:
            return  # the same plan and robots failed to place already: wait or for a change
        self._last_attempt, self._last_attempt_at = attempt, now
        why = [f"robots gone: {', '.join(sorted(lost))}"] if lost else []
        if placed_on & sick:
            why.append(f"robots degraded: {', '.join(sorted(placed_on & sick))}")
        if short:
            why.append(
                f"standbys missing: {', '.join(f'{c} {n}' for c, n in sorted(short.items()))}"
            )
        exclude = frozenset(self.c.health.excluded(now))
        self._reissue(plan, epoch, state, "; ".join(why), exclude=exclude, recovery=True, held=held)

    def _must_move(self, now: float, plan: Plan, state: ClusterState) -> bool:
        """Whether some placement sits on a robot that is gone or degraded."""
        placed_on = {p.robot for p in plan.placements}
        return bool(placed_on - set(state.alive) or placed_on & self.c.health.degraded(now))

    def _reissue(
        self,
        plan: Plan,
        epoch: int,
        state: ClusterState,
        reason: str,
        *,
        exclude: frozenset[str] = frozenset(),
        recovery: bool = False,
        held: frozenset[str] = frozenset(),
    ) -> None:
        """Re-allocate `plan` (smallest change) under our epoch; when that is infeasible keep the
        placements as they are (re-issued only when the epoch is new: adopting a plan).

        `recovery`: components are moving because of a failure; the robots receiving them only
        need to stay out of the recovery rules' memory shortage, not above the allocation's
        free-memory threshold (as in the paper, where robot-3 ends below Table V's 500MB)."""
        version = plan.version + 1 if plan.epoch == epoch else 1
        if plan.system is None:
            new = Plan(epoch, version, None, (), self.c.name)
        else:
            result = place(
                plan.system,
                self.view(state, None, exclude),
                epoch=epoch,
                version=version,
                allocator=self.c.name,
                previous=plan,
                recovery=recovery,
                held=held,
            )
            if isinstance(result, Infeasible):
                self.c.events.add(
                    time.time(), "allocation.infeasible", self.c.name, report=str(result)
                )
                if plan.epoch == epoch and plan.allocator == self.c.name:
                    return  # nothing better to issue: keep the plan we hold
                new = Plan(epoch, version, plan.system, plan.placements, self.c.name)
            elif result.placements == plan.placements and plan.epoch == epoch:
                return  # e.g. still no robot for a missing standby: nothing to publish
            else:
                new = result
        self.c.events.add(time.time(), "allocation", self.c.name, reason=reason, epoch=epoch)
        if recovery:
            moved = moved_components(plan, new)
            if moved:
                self.c.events.add(
                    time.time(), "recovery.move", self.c.name, reason=reason, moved=moved
                )
        self._publish_plan(new, state)

    def _reconcile(self, plan: Plan, state: ClusterState, sick: frozenset[str]) -> None:
        """Move a `keep_original` component back to its robot (`plan.origins`) once that robot
        is alive again and not degraded: one move at a time, each asked once per plan."""
        if self._lock.locked():
            return
        for comp, robot in plan.origins:
            active = plan.active_of(comp)
            if robot not in state.alive or robot in sick or active is None:
                continue
            if active.robot == robot or self._moving_back == (comp, plan.key):
                continue
            self._moving_back = (comp, plan.key)
            self.c.events.add(time.time(), "reconcile", self.c.name, component=comp, to=robot,
                              policy="keep_original")  # fmt: skip
            self.c._spawn(self._move_back(comp, robot))
            return

    async def _move_back(self, component: str, robot: str) -> None:
        try:
            result = await self.move_component(component, robot)
        except (NotAllocator, LookupError, ValueError) as e:
            log.info("cannot move %s back to %s: %s", component, robot, e)
            return
        if isinstance(result, Infeasible):
            log.info("cannot move %s back to %s: %s", component, robot, result)

    def _publish_plan(self, plan: Plan, state: ClusterState) -> None:
        plan = with_origins(plan, self.c.store.plan, state)
        if not self.c.accept(plan, source=self.c.name):
            return
        for robot, rec in state.alive.items():
            if robot != self.c.name and rec.api is not None:
                self.c._spawn(self._push(robot, rec.api, plan))

    async def _push(self, robot: str, api: str, plan: Plan) -> None:
        try:
            await peers.push_plan(api, self.c.token, plan)
        except ApiError as e:
            log.info("cannot push the plan to %s (it will fetch it): %s", robot, e)

    async def recover_component(
        self, robot: str, component: str, instance: str, action: str
    ) -> Plan | Infeasible:
        """A robot's recovery step that changes who is active (allocator only):
        `standby_same_robot` activates the component's standby on that robot in place of the
        faulty instance; `standby_other_robot` / `launch_other_robot` move the component off
        that robot (to a running standby first). Missing standbys are re-created. LookupError
        for a component the deployed system does not have."""
        if not self.c.election.is_allocator():
            raise NotAllocator(self.c.election.info().leader)
        async with self._lock:
            plan = self.c.store.plan
            if plan is None or plan.system is None:
                return Infeasible(component, (), 0)
            if all(c.name != component for c in plan.system.components):
                raise LookupError(f"no component {component!r} in the deployed system")
            state = self.c.cluster()
            epoch = self.c.election.info().epoch
            version = plan.version + 1 if plan.epoch == epoch else 1
            avoid: dict[str, set[str]] = {}
            previous = plan
            if action == "standby_same_robot":
                previous = swap_to_standby(plan, component, robot)
            else:
                avoid = {component: {robot}}
            now = asyncio.get_running_loop().time()
            result = place(
                plan.system,
                self.view(state, None, frozenset(self.c.health.excluded(now))),
                epoch=epoch,
                version=version,
                allocator=self.c.name,
                previous=previous,
                avoid=avoid,
                recovery=True,
                held=self.held(now, plan, state) - {component},
            )
            if isinstance(result, Infeasible):
                self.c.events.add(
                    time.time(), "allocation.infeasible", self.c.name, report=str(result)
                )
                return result
            new = result
            self.c.events.add(
                time.time(),
                "recovery.move",
                self.c.name,
                reason=f"{action} for {instance} on {robot}",
                moved=moved_components(plan, new),
            )
            self._publish_plan(new, state)
            return new

    async def move_component(self, component: str, to: str | None) -> Plan | Infeasible:
        """A planned move (`sdrpeer move`): the component's active leaves its robot, for `to`
        when given; MoveError when it cannot be asked for. Allocator only."""
        if not self.c.election.is_allocator():
            raise NotAllocator(self.c.election.info().leader)
        async with self._lock:
            plan = self.c.store.plan
            state = self.c.cluster()
            inputs = move_inputs(plan, component, to, state.alive)
            assert plan is not None
            assert plan.system is not None
            epoch = self.c.election.info().epoch
            now = asyncio.get_running_loop().time()
            result = place(
                inputs.system,
                self.view(state, None, frozenset(self.c.health.excluded(now))),
                epoch=epoch,
                version=plan.version + 1 if plan.epoch == epoch else 1,
                allocator=self.c.name,
                previous=inputs.previous,
                avoid=inputs.avoid,
                held=self.held(now, plan, state) - {component},
            )
            if isinstance(result, Infeasible):
                self.c.events.add(
                    time.time(), "allocation.infeasible", self.c.name, report=str(result)
                )
                return result
            new = replace(result, system=plan.system)
            moved = moved_components(plan, new)
            reason = f"move {component} from {inputs.origin}" + (f" to {to}" if to else "")
            self.c.events.add(time.time(), "allocation", self.c.name, reason=reason, epoch=epoch)
            self.c.events.add(time.time(), "move", self.c.name, reason=reason, moved=moved)
            self._publish_plan(new, state)
            return new

    async def deploy(self, system: SystemDef | None, origin: str) -> Plan | Infeasible:
        """Allocate `system` (None: undeploy) and publish the plan. Allocator only."""
        if not self.c.election.is_allocator():
            raise NotAllocator(self.c.election.info().leader)
        async with self._lock:
            state = self.c.cluster()
            epoch = self.c.election.info().epoch
            current = self.c.store.plan
            version = current.version + 1 if current is not None and current.epoch == epoch else 1
            if system is None:
                plan: Plan | Infeasible = Plan(epoch, version, None, (), self.c.name)
            else:
                previous = current if current is not None and current.system is not None else None
                plan = place(
                    system,
                    self.view(state, origin),
                    epoch=epoch,
                    version=version,
                    allocator=self.c.name,
                    previous=previous,
                )
            if isinstance(plan, Infeasible):
                self.c.events.add(
                    time.time(), "allocation.infeasible", self.c.name, report=str(plan)
                )
                return plan
            self._adopted_epoch = epoch
            self.c.events.add(
                time.time(),
                "allocation",
                self.c.name,
                reason="deploy",
                epoch=epoch,
                system=None if system is None else system.name,
            )
            self._publish_plan(plan, state)
            return plan


def with_origins(new: Plan, old: Plan | None, state: ClusterState) -> Plan:
    """`new` with the origins of `old` it still needs (the component is not back on its robot),
    and one for each `keep_original` active it moves off a robot that is gone."""
    if new.system is None or old is None or old.system is None:
        return replace(new, origins=())
    names = {c.name for c in new.system.components}
    same = old.system.digest() == new.system.digest()  # a new system starts afresh
    origins = dict(old.origins) if same else {}
    for comp, (src, _) in moved_components(old, new).items():
        if src not in state.alive and new.system.component(comp).disconnect.reconcile == (
            "keep_original"
        ):
            origins.setdefault(comp, src)
    kept = {}
    for comp, robot in origins.items():
        active = new.active_of(comp)
        if comp in names and (active is None or active.robot != robot):
            kept[comp] = robot
    return replace(new, origins=tuple(sorted(kept.items())))


def moved_components(old: Plan, new: Plan) -> dict[str, list[str]]:
    """component -> [from robot, to robot] for every active instance that changed robot."""
    out = {}
    for p in new.placements:
        if p.role != "active":
            continue
        before = old.active_of(p.component)
        if before is not None and before.robot != p.robot:
            out[p.component] = [before.robot, p.robot]
    return out
