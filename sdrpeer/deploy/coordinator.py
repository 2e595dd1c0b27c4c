"""The deployment side of one agent: the asyncio shell around the deployment core.

How it works: `step()` runs whenever gossip changes something, at the deadlines of the cores it
drives (`next_timer()` of the deployment core, the election, health, local recovery and touch
shells), and every `tick` seconds while a plan is held or this robot is the allocator (state
handoff polls); with nothing deployed an idle fleet steps at most every `idle_tick` seconds.
Each step reads `loop.time()` once and passes it inward:
1. the health shell judges every robot's robot-wide conditions; the election shell is fed this
   robot's view and says who the allocator is, with its epoch. A robot that does not hear a
   majority of the fleet (`deploy.disconnect`, `touch_shell`) is not eligible: the side of a cut
   that is cut off elects no allocator and issues no plan;
2. the deployment core (`sdrpeer.deploy.core`, sans-IO) gets the view and decides: fencing, which
   robot to fetch a newer plan from and, on the allocator, adopting and re-issuing the newest
   plan, re-allocating when robots die or degrade, moving `keep_original` components back;
3. the touch shell learns whether the robot is caught up; then the core applies the plan to
   this robot (`DeployCore.apply`, given the instances ACTIVE here, the cut-off state and the
   launch policy);
4. the compliance shell re-checks the plan's running placements against their Table I/II
   constraints (`deploy.compliance_shell`); on the allocator, a violation held for the policy's
   sustain under `on_violation: replace` becomes a `Comply` move.
The core's effects are carried out here, in order: plan fetches and pushes over HTTP
(`deploy.peers`, one task each), a plan taken is saved (`PlanStore.save`), applied and
published in the record (`on_change`), the desired instances go to the instance manager, events
to the event log. `deploy()` / `undeploy()`, `move_component()` and `recover_component()` are
the core's requests (on the allocator; other agents forward them to it), run at once with the
current view.
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

from sdrpeer.api import peer_client
from sdrpeer.deploy import peers
from sdrpeer.deploy.compliance_shell import ComplianceShell, describe
from sdrpeer.deploy.config import DeployConfig
from sdrpeer.deploy.core import DeployCore, DeployView, Here, Request
from sdrpeer.deploy.effects import Adopted, Desired, Effect, Fetch, Log, Push
from sdrpeer.deploy.election_shell import ElectionShell
from sdrpeer.deploy.handoff_shell import HandoffShell
from sdrpeer.deploy.health_shell import HealthShell
from sdrpeer.deploy.local_shell import LocalShell
from sdrpeer.deploy.placer import Infeasible
from sdrpeer.deploy.plan_change import Comply, Deploy, Move, Recover
from sdrpeer.deploy.planstore import PlanStore
from sdrpeer.deploy.status import SinceTracker, status_doc
from sdrpeer.deploy.touch_shell import TouchShell
from sdrpeer.deploy.view import ClusterState
from sdrpeer.election.config import ElectionConfig
from sdrpeer.election.events import Elected, SteppedDown
from sdrpeer.errors import ApiError, MoveError
from sdrpeer.eventlog import EventKind, EventLog
from sdrpeer.plan import Plan
from sdrpeer.recovery.compliance import Violated
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Decision, RobotCondition
from sdrpeer.runtime.manager import InstanceManager
from sdrpeer.system.model import SystemDef, Thresholds
from sdrpeer.vocabulary import LifecycleState

log = logging.getLogger(__name__)


class Coordinator:
    """Plans in, instance specs out; allocates when this robot holds the role."""

    def __init__(
        self,
        name: str,
        data_dir: Path,
        manager: InstanceManager,
        cluster: Callable[[], ClusterState],
        *,
        token: str,
        events: EventLog,
        on_change: Callable[[], None],
        config: DeployConfig | None = None,
        election: ElectionConfig | None = None,
        recovery: RecoveryConfig | None = None,
    ) -> None:
        self.name = name
        self.manager = manager
        self.cluster = cluster
        self.token = token
        self.events = events
        self.on_change = on_change
        self.config = config = config or DeployConfig()
        self.tick = config.tick
        self.idle_tick = config.idle_tick
        self.local = LocalShell(
            name, manager, lambda: self.store.plan, self.request_recovery, events, config=recovery
        )
        """Component faults on this robot (restart here; plan changes through the allocator)."""
        self.health = HealthShell(recovery)
        """Robot-wide recovery conditions (low battery, bad link) of every robot."""
        self.compliance = ComplianceShell(recovery)
        """The running placements re-checked against their Table I/II constraints."""
        self.core = DeployCore(name, PlanStore(data_dir / "plan.json"), config)
        """Plan sync and the allocator's duties (sans-IO); this shell carries out its effects."""
        self.handoff = HandoffShell(
            name, manager, lambda: self.store.plan, self._api_of, token=token, events=events
        )
        """Component states to hot standbys (sync) and to a moved component's new instance."""
        manager.before_stop = self.handoff.retire
        self.election = ElectionShell(name, election, self.store.highest_epoch)
        self._wake = asyncio.Event()
        self._task: asyncio.Task[None] | None = None
        self._bg: set[asyncio.Task[Any]] = set()
        self._since = SinceTracker()
        self.touch = TouchShell(
            name,
            events,
            self.store.plan,
            ask=lambda api: peers.peer_plan(api, self.token),
            accept=lambda plan, source: self.accept(plan, source=source),
            spawn=self._spawn,
            wake=self.wake,
            ask_retry=config.ask_retry,
        )
        """Whether this robot is in touch with the fleet (quorum, cut off, rejoining)."""

    @property
    def store(self) -> PlanStore:
        """The plan this robot holds and its fence."""
        return self.core.store

    # ----------------------------------------------------------------- loop
    def start(self) -> None:
        """Start the step loop; its first step runs at once (the election's clock starts there:
        in a quiet fleet the next wake may be an idle tick away)."""
        self._wake.set()
        self._task = asyncio.create_task(self._loop())

    def leave(self) -> None:
        """Abdicate the allocator role for good (before a graceful leave) and publish that."""
        self.election.leave(asyncio.get_running_loop().time())
        self.on_change()

    async def stop(self) -> None:
        """Stop the loop and any call in flight."""
        for t in [self._task, *self._bg]:
            if t is not None:
                t.cancel()
                with contextlib.suppress(asyncio.CancelledError):
                    await t
        await self.local.stop()
        await self.handoff.stop()
        await peer_client.close()

    def set_token(self, token: str) -> None:
        """Present `token` to other agents from now on (the keys rotated)."""
        self.token = self.handoff.token = token

    def wake(self) -> None:
        """Something changed (gossip, a member, an instance): step soon."""
        self._wake.set()

    async def _loop(self) -> None:
        loop = asyncio.get_running_loop()
        while True:
            due = min(
                self.election.next_timer(),
                self.health.next_timer(),
                self.compliance.next_timer(),
                self.local.next_timer(),
                self.core.next_timer(),
                self.touch.next_timer(self.store.plan),
            )
            busy = self.store.plan is not None or self.election.is_allocator()
            wait = min(self.tick if busy else self.idle_tick, max(0.0, due - loop.time()))
            with contextlib.suppress(TimeoutError):
                async with asyncio.timeout(wait):  # not wait_for: on 3.11 it can swallow a
                    await self._wake.wait()  # cancel, and then stop() waited for ever
            self._wake.clear()
            try:
                self.step()
            except Exception:
                log.exception("deployment step failed")

    def _spawn(self, coro: Any) -> None:
        task = asyncio.create_task(coro)
        self._bg.add(task)
        task.add_done_callback(self._bg.discard)

    # ----------------------------------------------------------------- one step
    def step(self) -> None:
        """Health, election, the deployment core, apply (see the module docstring)."""
        now = asyncio.get_running_loop().time()
        state = self.cluster()
        plan = self.store.plan
        recovery = None if plan is None or plan.system is None else plan.system.recovery
        self.health.update(now, recovery, state.alive)
        self.local.tick()
        self._log_health()
        quorum = self.touch.quorum(state, plan)
        degraded = set(self.health.degraded(now))
        if not quorum:  # a robot cut off from the fleet neither claims nor keeps the role
            degraded.add(self.name)
        before = self.election.info()
        preempt = plan is not None and plan.system is not None and plan.system.allocation.preempt
        self.election.update(now, state.alive, self._thresholds(), degraded, preempt=preempt)
        self._log_election()
        info = self.election.info()
        if info != before:
            self.on_change()  # our record carries the election belief
        self.core.step(now, self._view(now, state))
        self._carry_out()
        self.touch.after_sync(now, state, quorum, self.caught_up(state), info.leader)
        self._apply(now, state)
        self.compliance.update(now, self.store.plan, state)
        self._log_compliance()
        if self.election.is_allocator():
            self._comply(now)
        self.handoff.tick()

    def _view(self, now: float, state: ClusterState | None = None) -> DeployView:
        """What the deployment core is told this step."""
        info = self.election.info()
        return DeployView(
            self.cluster() if state is None else state,
            allocator=self.election.is_allocator(),
            epoch=info.epoch,
            leader=info.leader,
            degraded=frozenset(self.health.degraded(now)),
            excluded=frozenset(self.health.excluded(now)),
        )

    def _carry_out(self) -> None:
        """Do what the core asked for, in order."""
        for effect in self.core.effects():
            self._do(effect)

    def _do(self, effect: Effect) -> None:
        if isinstance(effect, Log):
            self.events.add(time.time(), effect.kind, self.name, **effect.detail)
        elif isinstance(effect, Adopted):
            self.store.save()
            # applied before it is published: the record never shows the new plan's key next
            # to instance states from the old one
            self._apply(asyncio.get_running_loop().time(), self.cluster())
            self.on_change()
            self.wake()
        elif isinstance(effect, Desired):
            current = self.manager.desired()
            for gone in effect.removed:
                self.manager.remove(gone)
            changed = [s for s in effect.specs if current.get(s.name) != s]
            if changed:
                self.manager.set_desired(changed)
        elif isinstance(effect, Fetch):
            self._spawn(self._fetch(effect.robot, effect.api))
        elif isinstance(effect, Push):
            self._spawn(self._push(effect))

    def _log_election(self) -> None:
        """The election core's events, as they happened (claims won, roles given up, leaders
        changed), into the event log."""
        wall = time.time()
        for event in self.election.drain():
            detail: dict[str, Any]
            if isinstance(event, Elected):
                kind, detail = EventKind.ELECTION_ELECTED, {"previous": event.previous}
            elif isinstance(event, SteppedDown):
                kind, detail = EventKind.ELECTION_STEPPED_DOWN, {"reason": event.reason}
            else:
                kind = EventKind.ELECTION
                detail = {"leader": event.leader, "previous": event.previous}
            self.events.add(wall, kind, self.name, epoch=event.epoch, **detail)

    def _log_health(self) -> None:
        for event in self.health.drain():
            kind = (
                EventKind.RECOVERY_CONDITION
                if isinstance(event, RobotCondition)
                else EventKind.RECOVERY_CLEARED
            )
            self.events.add(  # logged as this robot's judgement of `subject`
                time.time(),
                kind,
                self.name,
                subject=event.robot,
                cause=event.cause,
                metric=event.metric,
                value=event.value,
            )

    def _log_compliance(self) -> None:
        """Violations and clearings, as this robot judges them, into the event log."""
        for event in self.compliance.drain():
            r = event.reading
            detail: dict[str, Any] = {
                "component": r.component,
                "constraint": r.constraint,
                "subject": r.subject,
                "robots": list(r.robots),
                "value": r.value,
                "bound": r.bound,
                "must_be": "above" if r.above else "below",
            }
            if isinstance(event, Violated):
                kind = EventKind.COMPLIANCE_VIOLATED
                detail["held_s"] = round(event.at - event.since, 3)
            else:
                kind, detail["why"] = EventKind.COMPLIANCE_CLEARED, event.why
            self.events.add(time.time(), kind, self.name, **detail)

    def _comply(self, now: float) -> None:
        """On the allocator: move what `on_violation: replace` says must move (one at a time
        per component, at most once per `min_interval`)."""
        for component, reading in self.compliance.due_moves(now):
            self.compliance.moved(now, component)
            try:
                result = self.core.request(
                    now, self._view(now), Comply(component, describe(reading))
                )
            except (MoveError, LookupError) as e:
                log.info("compliance: cannot move %s: %s", component, e)
                continue
            finally:
                self._carry_out()
            if isinstance(result, Infeasible):
                log.info("compliance: no robot for %s: %s", component, result)

    def _api_of(self, robot: str) -> str | None:
        rec = self.cluster().alive.get(robot)
        return None if rec is None else rec.api

    def _thresholds(self) -> Thresholds | None:
        plan = self.store.plan
        return None if plan is None or plan.system is None else plan.system.allocation.thresholds

    def caught_up(self, state: ClusterState) -> bool:
        """No alive robot gossips a plan newer than ours, and no fetch is in flight."""
        return self.core.caught_up(state)

    async def _fetch(self, robot: str, api: str) -> None:
        plan: Plan | None = None
        try:
            plan = await peers.fetch_plan(api, self.token)
        except ApiError as e:
            log.info("cannot fetch the plan from %s: %s", robot, e)
        finally:  # whatever happened, the core hears the end of its fetch
            if plan is None:
                self.core.fetch_failed(asyncio.get_running_loop().time(), robot)
            else:
                self.core.fetched(robot, plan)
            self._carry_out()
            self.wake()

    async def _push(self, push: Push) -> None:
        try:
            await peers.push_plan(push.api, self.token, push.plan)
        except ApiError as e:
            log.info("cannot push the plan to %s (it will fetch it): %s", push.robot, e)

    def accept(self, plan: Plan, source: str) -> bool:
        """Offer a plan (fetched, pushed, or our own); True if it is now the one we hold."""
        ok = self.core.offer(plan, source)
        self._carry_out()
        return ok

    def _apply(self, now: float, state: ClusterState) -> None:
        """Hand the core this robot's own side; it answers with the desired instances."""
        active = frozenset(
            s["name"] for s in self.manager.status() if s.get("state") == LifecycleState.ACTIVE
        )
        here = Here(active, self.touch.joined, self.touch.cutoff, self.manager.policy)
        self.core.apply(now, state, here)
        self._carry_out()

    def status(self, now_wall: float) -> dict[str, Any]:
        """GET /v1/status: the plan's components with their robots and states."""
        info = self.election.info()
        allocator = {"name": info.leader, "epoch": info.epoch}
        alive = self.cluster().alive
        doc = status_doc(self.store.plan, alive, allocator, self._since, now_wall)
        doc["cut_off"] = self.touch.cut
        doc["compliance"] = rows = self.compliance.rows(now_wall)
        for comp in doc["components"]:
            mine = [r for r in rows if r["component"] == comp["component"]]
            comp["compliance"] = (
                None
                if not mine
                else "violated"
                if any(r["state"] == "violated" for r in mine)
                else "ok"
            )
        return doc

    # ----------------------------------------------------------------- the allocator
    async def request_recovery(self, d: Decision) -> bool:
        """Send a plan-changing recovery step of this robot to the allocator; True if taken."""
        body = {
            "robot": self.name,
            "component": d.component,
            "instance": d.instance,
            "action": d.action,
        }
        if self.election.is_allocator():
            try:
                result = await self.recover_component(self.name, d.component, d.instance, d.action)
            except LookupError:  # a plan changed under the decision: nothing to recover
                return False
            return not isinstance(result, Infeasible)
        leader = self.election.info().leader
        rec = self.cluster().alive.get(leader or "")
        if rec is None or rec.api is None:
            return False
        status, _ = await peer_client.call(rec.api, "POST", "/v1/recovery", self.token, body=body)
        return status == 200

    async def request(self, reason: Request) -> Plan | Infeasible:
        """Hand a request to the core at once, with the current view (allocator only:
        NotAllocator elsewhere), and carry out what it asks for."""
        now = asyncio.get_running_loop().time()
        try:
            return self.core.request(now, self._view(now), reason)
        finally:
            self._carry_out()

    async def deploy(self, system: SystemDef | None, origin: str) -> Plan | Infeasible:
        """Allocate `system` (None: undeploy) and publish the plan (allocator only)."""
        return await self.request(Deploy(system, origin))

    async def move_component(self, component: str, to: str | None) -> Plan | Infeasible:
        """A planned move of one component's active (allocator only; see deploy.move)."""
        return await self.request(Move(component, to))

    async def recover_component(
        self, robot: str, component: str, instance: str, action: str
    ) -> Plan | Infeasible:
        """A robot's recovery step that changes who is active (allocator only)."""
        return await self.request(Recover(robot, component, instance, action))
