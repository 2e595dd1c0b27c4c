"""The deployment core of one robot: plan sync, the allocator's duties, and applying the plan to
this robot (sans-IO).

How it works: the shell (`sdrpeer.deploy.coordinator`) calls `step(now, view)` whenever gossip
changes something and at `next_timer()`; `view` is what the rest of the agent knows this step
(the alive robots' records, the election's verdict, the robots the health judge degrades or
excludes). The core never reads a clock, never awaits and never spawns: everything it wants
done is queued as an effect (`sdrpeer.deploy.effects`) that the shell drains with `effects()`.
1. Fencing: every allocator claim in a record raises the plan store's fence, so a plan from an
   older epoch (or a lower allocator at the same epoch) is refused (`plan.refused`).
2. Plan sync: when an alive robot gossips a plan the store would take, `Fetch` it from that
   robot (one fetch in flight); the shell reports `fetched(robot, plan)` or
   `fetch_failed(now, robot)` (that robot is not asked again for `fetch_retry` seconds). Pushed
   and fetched plans go through `offer`; a plan taken becomes `Adopted` (store, apply, gossip).
3. Allocator duties, while the view says this robot holds the role: once it has caught up with the
   newest plan it can hear of (`adopt_after` seconds after winning, or at once when no robot
   gossips a newer one) it re-issues that plan under its own epoch — losing the allocator loses
   nothing; a predecessor's plan (an earlier epoch, or a rival it outranks at its own) newer than
   the one it holds is taken although its own claim raised the fence, and so is a predecessor's
   plan while it holds none, e.g. a deploy the old allocator took before it heard of the new one —
   and from then on re-allocates (smallest change) when a placement's robot is gone or degraded or
   a standby is missing; an attempt that issued nothing is not repeated with the same plan and
   robots for `retry_every` seconds. A component the disconnect policy holds
   (`disconnect.held_components`) keeps its placements until its `lost_after`; one moved off a lost
   robot with `reconcile: keep_original` is moved back once that robot is well.
4. Requests (`request`: `Deploy`, `Move`, `Recover`) run on the allocator only (`NotAllocator`
   elsewhere).
5. Apply (`apply(now, state, here)`, once the shell has heard whether the robot is in touch):
   the plan's placements on this robot become the instance manager's desired set (`Desired`:
   only the names the plan owns), built by `derive.specs_for_robot`, except the actives a robot
   cut off holds INACTIVE by their components' disconnect policy (`CutOff`), the actives a robot
   holding a newer plan already runs (`derive.superseded`: the old side of a heal stands down on
   the first gossip of the new side, `plan.superseded`), the actives waiting at most
   `handover_wait` for their component's old copy elsewhere to stand down, and what this
   robot's launch policy refuses (`launch.refused`, said once). Nothing is applied before the
   robot has been in touch with the fleet since it started.
Every plan, whatever asked for it, comes from the one allocation path (`plan_change.change`),
and is offered to our own store, then `Push`ed to every alive robot.
"""

from __future__ import annotations

import logging
import math
from collections.abc import Sequence
from dataclasses import dataclass, field, replace
from typing import Protocol

from sdrpeer.deploy.config import DeployConfig
from sdrpeer.deploy.derive import Remote, handover_waits, specs_for_robot, superseded
from sdrpeer.deploy.disconnect import CutOff, held_components
from sdrpeer.deploy.effects import Adopted, Desired, Effect, Fetch, Log, Push
from sdrpeer.deploy.placer import Infeasible
from sdrpeer.deploy.plan_change import (
    Comply,
    Context,
    Deploy,
    Move,
    Reason,
    Recover,
    Reissue,
    change,
    with_origins,
)
from sdrpeer.deploy.planstore import PlanStore
from sdrpeer.deploy.view import ClusterState, PlanKey
from sdrpeer.errors import NotAllocator
from sdrpeer.eventlog import EventKind
from sdrpeer.plan import Plan
from sdrpeer.runtime.spec import InstanceSpec
from sdrpeer.system.model import SystemDef
from sdrpeer.vocabulary import InstanceRole, LifecycleState

log = logging.getLogger(__name__)


Request = Deploy | Move | Recover | Comply
"""What an operator or a robot (or continuous compliance) may ask the allocator for."""


@dataclass(frozen=True, slots=True)
class DeployView:
    """What the rest of the agent knows at one step."""

    state: ClusterState
    """The alive robots and their records."""
    allocator: bool = False
    """Whether this robot holds the allocator role now (the election's verdict)."""
    epoch: int = 0
    """The epoch of the allocator this robot believes in (its own when `allocator`)."""
    leader: str | None = None
    """The allocator this robot believes in."""
    degraded: frozenset[str] = frozenset()
    """Robots a robot-wide recovery condition holds on: their components must move."""
    excluded: frozenset[str] = frozenset()
    """Robots that must not receive components (degraded, or within their minimum dwell)."""


class Refusals(Protocol):
    """What this robot lets its hosts run (`sdrpeer.launch.policy.LaunchPolicy`)."""

    def refusal(self, launcher: str, target: str | Sequence[str]) -> str | None:
        """None if a host of `launcher` running `target` may start here, else why not."""
        ...


@dataclass(frozen=True, slots=True)
class Here:
    """This robot's own side at one step, for applying the plan."""

    active: frozenset[str] = frozenset()
    """The instances running ACTIVE here (the instance manager's)."""
    joined: bool = True
    """In touch with the fleet (and caught up) at least once since the agent started."""
    cutoff: CutOff = field(default_factory=CutOff)
    """Whether this robot is cut off from the fleet, or back and not caught up yet."""
    policy: Refusals | None = None
    """Its launch policy (None: everything may run)."""


def _before(plan: Plan | None, epoch: int, me: str) -> bool:
    """Whether `plan` is a predecessor's of the allocator `me` at `epoch` (the fence's order)."""
    return plan is not None and (plan.epoch, plan.allocator) < (epoch, me)


def _same_system(plan: Plan | None, system: SystemDef | None, epoch: int, me: str) -> bool:
    """Whether `plan` is this allocator's own, at its epoch, for exactly `system`."""
    if plan is None or (plan.epoch, plan.allocator) != (epoch, me):
        return False
    if plan.system is None or system is None:
        return plan.system is system
    return plan.system.digest() == system.digest()


def _carried(plan: Plan) -> str:
    """The reason logged when an allocator re-issues a predecessor's plan after adopting."""
    return f"carried on {plan.allocator}'s plan (epoch {plan.epoch}, version {plan.version})"


class DeployCore:
    """One robot's plan sync, its share of the plan and, while it holds the role, the
    allocator's duties."""

    def __init__(self, name: str, store: PlanStore, config: DeployConfig | None = None) -> None:
        """`store`: the plan this robot holds and its fence (loaded by the shell)."""
        self.name = name
        self.store = store
        self.config = config or DeployConfig()
        self._effects: list[Effect] = []
        self._fetching: PlanKey | None = None
        """The key of the plan a fetch in flight was sent for."""
        self._fetch_failed: dict[str, float] = {}
        """Robot -> time before which a plan is not fetched from it again (a fetch failed)."""
        self._elected_at: float | None = None
        """When this robot took the role (None: it does not hold it)."""
        self._adopted_epoch = 0
        """The epoch under which it last adopted (or deployed) a plan."""
        self._adopt_by = math.inf
        """While a new allocator waits to catch up: when it re-issues anyway."""
        self._last_attempt: (
            tuple[PlanKey, frozenset[str], frozenset[str], frozenset[str]] | None
        ) = None
        self._retry_at = math.inf
        """When the last attempt may be repeated (inf: nothing to retry)."""
        self._lost_since: dict[str, float] = {}
        """Robot -> when this allocator first saw it gone while the plan placed something there."""
        self._held_due = math.inf
        """When the first held component may be replaced (`disconnect.held_components`)."""
        self._moving_back: tuple[str, PlanKey] | None = None
        """The keep_original move last made, with the key of the plan it was asked under
        (asked once per plan: a move that cannot be made waits for the next plan)."""
        self._owned: frozenset[str] = frozenset()
        """The instance names the plan had this robot run at the last apply."""
        self._handover_since: dict[str, float] = {}
        """Active placement here -> since when it waits for its component's old copy elsewhere."""
        self._yielded: set[str] = set()
        """Active placements here stood down for a newer plan's copy elsewhere (`superseded`)."""
        self._refused: dict[str, str] = {}
        """Placements here the launch policy refuses, with why (logged once)."""
        self._successor_of = 0
        """While this robot holds the role: its epoch (plans of lower epochs are its
        predecessors'); 0 otherwise."""
        self._basis: Plan | None = None
        """A predecessor's plan, newer than the one held, that the fence keeps out of the store:
        what the allocator re-issues (see `_wants_predecessor`)."""

    # ----------------------------------------------------------------- the shell's surface
    def effects(self) -> list[Effect]:
        """Everything queued since the last call, in order."""
        out, self._effects = self._effects, []
        return out

    def next_timer(self) -> float:
        """When the core wants a step even if nothing changes (inf: never)."""
        due = min(self._adopt_by, self._retry_at, self._held_due)
        return min(due, min(self._fetch_failed.values(), default=math.inf))

    def step(self, now: float, view: DeployView) -> None:
        """Fence, plan sync, and the allocator's duties (see the module docstring)."""
        state = view.state
        for epoch, leader in state.claims():
            self.store.see_claim(epoch, leader)
        for robot in [r for r, t in self._fetch_failed.items() if t <= now]:
            del self._fetch_failed[robot]
        self._successor_of = view.epoch if view.allocator else 0
        self._sync(now, state)
        if view.allocator:
            self._duties(now, view)
        else:
            self._off_duty()

    def offer(self, plan: Plan, source: str) -> bool:
        """A plan (pushed, fetched, or our own); True if it is now the one this robot holds."""
        held = self.store.plan
        if held is not None and held.key == plan.key:
            return True  # the same plan again (a push and a fetch crossed): nothing to do
        detail = {"epoch": plan.epoch, "version": plan.version, "allocator": plan.allocator}
        if not self.store.offer(plan):
            fence = self.store.highest_epoch
            self._effects.append(
                Log(EventKind.PLAN_REFUSED, {**detail, "fence": fence, "source": source})
            )
            return False
        self._effects.append(Log(EventKind.PLAN_ACCEPTED, {**detail, "source": source}))
        self._effects.append(Adopted(plan, source))
        return True

    def fetched(self, robot: str, plan: Plan) -> None:
        """The answer of the `Fetch` from `robot`: offered to the store; a predecessor's plan the
        allocator wants (`_wants_predecessor`) and the fence refuses becomes what it re-issues."""
        self._fetching = None
        if not self.offer(plan, source=robot) and self._wants_predecessor(plan.key):
            self._basis = plan

    def fetch_failed(self, now: float, robot: str) -> None:
        """The `Fetch` from `robot` failed: ask it again `fetch_retry` seconds from now."""
        self._fetching = None
        self._fetch_failed[robot] = now + self.config.fetch_retry

    def caught_up(self, state: ClusterState) -> bool:
        """No alive robot gossips a plan newer than ours, no fetch is in flight, and (on the
        allocator) no predecessor's plan waits to be re-issued."""
        return self._basis is None and self._synced(state)

    def _synced(self, state: ClusterState) -> bool:
        """No alive robot gossips a plan newer than ours or than the predecessor's plan the
        allocator will re-issue, and no fetch is in flight."""
        return self._fetching is None and self._newest_offer(state) is None

    def newer_holders(self, state: ClusterState) -> set[str]:
        """The other alive robots that gossip a plan this robot would take."""
        held = self.store.plan
        floor = None if held is None else held.key
        newer = set()
        last: tuple[PlanKey | None, bool] = (None, False)  # robots holding one plan: ask once
        for key, robot in state.plan_offers():
            if floor is not None and key <= floor:
                break  # newest first: the rest is older still
            if key != last[0]:
                last = (key, self.store.accepts(key))
            if last[1] and robot != self.name:
                newer.add(robot)
        return newer

    def request(self, now: float, view: DeployView, reason: Request) -> Plan | Infeasible:
        """Allocate for a request and publish the plan; allocator only (`NotAllocator`).
        `Deploy`: the system (None: undeploy). `Move`: a planned move of the component's active
        off its robot, onto `to` when given (`MoveError` when it cannot be asked for).
        `Recover`: a robot's recovery step that changes who is active (`LookupError` for a
        component the deployed system does not have)."""
        if not view.allocator:
            raise NotAllocator(view.leader)
        held = self._basis or self.store.plan
        if isinstance(reason, Deploy) and _same_system(held, reason.system, view.epoch, self.name):
            assert held is not None
            self._effects.append(
                Log(EventKind.ALLOCATION, {"reason": "deploy: the system held, unchanged"})
            )
            return held  # deploying again what runs moves nothing (a client's retry, an apply)
        result = self._allocate(now, view, reason)
        assert result is not None  # only a Reissue may come to nothing
        if isinstance(reason, Deploy) and isinstance(result, Plan):
            self._adopted_epoch = view.epoch  # a deploy under our epoch: nothing left to adopt
            self._adopt_by = math.inf
        return result

    # ----------------------------------------------------------------- apply
    def apply(self, now: float, state: ClusterState, here: Here) -> None:
        """This robot's share of the plan as a `Desired` effect (see the module docstring)."""
        plan = self.store.plan
        if plan is None or not here.joined:
            return
        remote = {
            inst.name: Remote(robot, inst.state, inst.data, inst.component, inst.role)
            for robot, inst in state.hosted()
            if robot != self.name
        }
        waits = handover_waits(plan, self.name, remote, here.active)
        for gone in self._handover_since.keys() - waits:
            del self._handover_since[gone]
        wait = self.config.handover_wait
        hold = {n for n in waits if now - self._handover_since.setdefault(n, now) < wait}
        newer = self.newer_holders(state)
        yielded = superseded(plan, self.name, remote, newer)
        for name in sorted(yielded - self._yielded):
            self._effects.append(
                Log(EventKind.PLAN_SUPERSEDED, {"instance": name, "newer": sorted(newer)})
            )
        self._yielded = yielded
        specs = specs_for_robot(plan, self.name, remote, here.active, hold | yielded)
        specs = self._allowed(self._held_down(now, plan, here.cutoff, specs), here.policy)
        names = frozenset(s.name for s in specs)
        self._effects.append(Desired(tuple(specs), tuple(sorted(self._owned - names))))
        self._owned = names

    @staticmethod
    def _held_down(
        now: float, plan: Plan, cutoff: CutOff, specs: list[InstanceSpec]
    ) -> list[InstanceSpec]:
        """`specs` with the actives a robot cut off (or not caught up yet) stands down INACTIVE."""
        system = plan.system
        if not (cutoff.cut or cutoff.rejoining) or system is None:
            return specs
        return [
            replace(s, desired=LifecycleState.INACTIVE)
            if s.role == InstanceRole.ACTIVE
            and cutoff.holds_down(now, system.component(s.component).disconnect)
            else s
            for s in specs
        ]

    def _allowed(self, specs: list[InstanceSpec], policy: Refusals | None) -> list[InstanceSpec]:
        """`specs` less those this robot's launch policy refuses (a plan from an allocator that
        did not know the policy yet): `launch.refused` says which and why, once."""
        out = []
        refused: dict[str, str] = {}
        for spec in specs:
            why = None if policy is None else policy.refusal(spec.launcher, spec.target)
            if why is None:
                out.append(spec)
            else:
                refused[spec.name] = why
        for name, why in sorted(refused.items()):
            if self._refused.get(name) != why:
                self._effects.append(
                    Log(EventKind.LAUNCH_REFUSED, {"instance": name, "reason": why})
                )
        self._refused = refused
        return out

    # ----------------------------------------------------------------- plan sync
    def _newest_offer(
        self, state: ClusterState, now: float | None = None
    ) -> tuple[str, PlanKey] | None:
        """The robot gossiping the newest plan we would take (with `now`: leaving out robots a
        fetch just failed from)."""
        floor = self._floor()
        failed = self._fetch_failed
        for key, robot in state.plan_offers():
            if floor is not None and key <= floor:
                return None  # newest first: the rest is older still
            if robot == self.name or state.alive[robot].api is None:
                continue
            if now is not None and failed.get(robot, -math.inf) > now:
                continue
            if self.store.accepts(key) or self._wants_predecessor(key):
                return (robot, key)
        return None

    def _floor(self) -> PlanKey | None:
        """The newest plan this robot holds or will re-issue (None: neither)."""
        keys = [p.key for p in (self.store.plan, self._basis) if p is not None]
        return max(keys, default=None)

    def _wants_predecessor(self, key: PlanKey) -> bool:
        """Whether the allocator takes a predecessor's plan (an earlier epoch, or a rival ranked
        below it at its own epoch: the fence's order) that the fence refuses, to re-issue it
        under its own: while it adopts (a robot it had not heard from yet may hold a plan newer
        than its own; the fence, raised by its own claim, would refuse it), and while it holds
        no plan at all (a predecessor that had not heard of it yet took a deploy: without this,
        nobody would own that system and the robots that heard of the new allocator would
        refuse it). Once it holds a plan of its own, a predecessor's later plan is refused like
        anywhere else (a cut-off old allocator's plans must not undo the fleet's)."""
        epoch = self._successor_of
        mine = (epoch, self.name)
        if not epoch or (key[0], key[1]) >= mine or not self.store.fence.accepts(*mine):
            return False  # not a predecessor's, or a higher claim fenced this allocator off
        held = self.store.plan
        if held is not None and (held.epoch, held.allocator) >= mine:
            return False
        floor = self._floor()
        return floor is None or key > floor

    def _sync(self, now: float, state: ClusterState) -> None:
        if self._fetching is not None:
            return
        offer = self._newest_offer(state, now)
        if offer is None:
            return
        robot, key = offer
        api = state.alive[robot].api
        assert api is not None
        self._fetching = key
        self._effects.append(Fetch(robot, api))

    # ----------------------------------------------------------------- the allocator
    def _off_duty(self) -> None:
        self._elected_at, self._last_attempt, self._basis = None, None, None
        self._adopt_by = self._retry_at = self._held_due = math.inf
        self._lost_since.clear()

    def _duties(self, now: float, view: DeployView) -> None:
        """One step while this robot holds the role (adopt, then move what must move)."""
        if self._elected_at is None:
            self._elected_at = now
        state, epoch = view.state, view.epoch
        adopting = self._adopted_epoch != epoch
        if adopting:
            adopt_by = self._elected_at + self.config.adopt_after  # the timer's own value
            if not self._synced(state) and now < adopt_by:
                self._adopt_by = adopt_by  # the only deadline while it waits
                self._held_due, self._last_attempt, self._retry_at = math.inf, None, math.inf
                return
            self._adopt_by = math.inf
            self._adopted_epoch = epoch
        basis, self._basis = self._basis, None  # taken now: a refused publish does not loop
        plan = basis or self.store.plan
        # a plan this allocator did not make (adopted, or a predecessor's it carries on) is
        # issued under its epoch now, whatever else this step does: the robots that heard of it
        # refuse the predecessor's
        foreign = (adopting or basis is not None) and _before(plan, epoch, self.name)
        reason = "new allocator" if adopting or plan is None else _carried(plan)
        if foreign and plan is not None and not self._must_move(plan, view):
            self._allocate(now, view, Reissue(reason), plan)
            return
        if plan is None or plan.system is None:
            self._held_due = self._retry_at = math.inf
            self._last_attempt = None
            return
        held = self._held(now, plan, view)
        if self._reconcile(now, view, plan):
            return
        lost = {p.robot for p in plan.placements if p.component not in held} - state.alive.keys()
        placed_on = {p.robot for p in plan.placements}
        sick = placed_on & view.degraded
        short = plan.standbys_short()
        if not (lost or sick or short):
            self._last_attempt, self._retry_at = None, math.inf
            if foreign:  # what must move is held by its disconnect policy: issue it, held
                self._allocate(now, view, Reissue(reason, recovery=True), plan)
            return
        attempt = (plan.key, frozenset(state.alive), view.degraded, held)
        if attempt == self._last_attempt and now < self._retry_at:
            return  # the same plan and robots failed to place already: wait or for a change
        self._last_attempt = attempt
        self._retry_at = now + self.config.retry_every
        why = [f"robots gone: {', '.join(sorted(lost))}"] if lost else []
        if sick:
            why.append(f"robots degraded: {', '.join(sorted(sick))}")
        if short:
            why.append(
                f"standbys missing: {', '.join(f'{c} {n}' for c, n in sorted(short.items()))}"
            )
        self._allocate(now, view, Reissue("; ".join(why), recovery=True), plan)

    def _must_move(self, plan: Plan, view: DeployView) -> bool:
        """Whether some placement sits on a robot that is gone or degraded."""
        placed_on = {p.robot for p in plan.placements}
        return bool(placed_on - view.state.alive.keys() or placed_on & view.degraded)

    def _held(self, now: float, plan: Plan | None, view: DeployView) -> frozenset[str]:
        """Components on lost robots the disconnect policy does not let us replace yet."""
        if plan is None:
            return frozenset()
        alive = view.state.alive
        placed_on = {p.robot for p in plan.placements}
        for robot in placed_on - alive.keys():
            self._lost_since.setdefault(robot, now)
        for robot in list(self._lost_since):
            if robot in alive or robot not in placed_on:
                del self._lost_since[robot]
        held, self._held_due = held_components(plan, alive, self._lost_since, now, view.degraded)
        return held

    def _reconcile(self, now: float, view: DeployView, plan: Plan) -> bool:
        """Move a `keep_original` component back to its robot (`plan.origins`) once that robot
        is alive again and not degraded: one move at a time, each asked once per plan. True
        when a new plan was issued."""
        for comp, robot in plan.origins:
            active = plan.active_of(comp)
            if robot not in view.state.alive or robot in view.degraded or active is None:
                continue
            if active.robot == robot or self._moving_back == (comp, plan.key):
                continue
            self._moving_back = (comp, plan.key)
            self._effects.append(
                Log(
                    EventKind.RECONCILE, {"component": comp, "to": robot, "policy": "keep_original"}
                )
            )
            try:
                result = self._allocate(now, view, Move(comp, robot), plan)
            except (LookupError, ValueError) as e:
                log.info("cannot move %s back to %s: %s", comp, robot, e)
                return False
            if isinstance(result, Infeasible):
                log.info("cannot move %s back to %s: %s", comp, robot, result)
            return isinstance(result, Plan)
        return False

    def _allocate(
        self, now: float, view: DeployView, reason: Reason, base: Plan | None = None
    ) -> Plan | Infeasible | None:
        """The one allocation path: `plan_change.change` from `base` (the plan held, or a
        predecessor's the allocator re-issues), its logs, and the plan published."""
        plan = base or self._basis or self.store.plan
        held = self._held(now, plan, view)
        ctx = Context(self.name, view.epoch, view.state, view.excluded, held)
        out = change(reason, plan, ctx)
        self._effects.extend(out.logs)
        if isinstance(out.result, Plan):
            self._publish(out.result, view.state, plan)
        return out.result

    def _publish(self, plan: Plan, state: ClusterState, base: Plan | None) -> None:
        plan = with_origins(plan, base, state)
        self._basis = None  # made from it (or refused: this robot is not the allocator after all)
        if not self.offer(plan, source=self.name):
            return
        for robot, rec in state.alive.items():
            if robot != self.name and rec.api is not None:
                self._effects.append(Push(robot, rec.api, plan))
