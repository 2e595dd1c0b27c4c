"""State handoff in the agent: periodic syncs to hot standbys, the final state of a planned move.

How it works: the rules are `handoff_rules`' (which instance sends to which, which state a robot
takes). `tick()` runs with every coordinator step: it starts the syncs that fall due and retries
held states. `retire(instance)` is the instance manager's `before_stop` hook: before an ACTIVE
instance is stopped because the plan moved its component, its last snapshot goes to the new
active instance (bounded by the manager's timeout: an unreachable robot only costs that). A state
for an instance on this robot is handed over directly; for another robot it is POSTed as msgpack
to that robot's `/v1/state` with the peer token, whose route calls `receive`. A state the robot
takes waits (up to `hold_s`) until its instance runs (INACTIVE or ACTIVE) and its plan has caught
up, then goes to the instance's `on_restore`. Unchanged states are not synced again. Everything
is counted (`counters`); final handoffs, and states dropped or failed, are also events.
"""

from __future__ import annotations

import asyncio
import hashlib
import logging
import time
from collections import Counter
from collections.abc import Callable
from typing import Any

import msgpack

from sdrpeer.api import peer_client
from sdrpeer.deploy.handoff_rules import (
    APPLY,
    HOLD,
    Send,
    StateMsg,
    SyncSchedule,
    admit,
    final_target,
)
from sdrpeer.errors import ApiError, CommandError
from sdrpeer.eventlog import EventKind, EventLog
from sdrpeer.plan import Plan
from sdrpeer.runtime.manager import InstanceManager
from sdrpeer.vocabulary import LifecycleState

log = logging.getLogger(__name__)

READY = (LifecycleState.INACTIVE, LifecycleState.ACTIVE)
"""States in which an instance can take a state (sdrpeer.sdk.handoff's table)."""


class HandoffShell:
    """Carries component states between instances for one robot."""

    def __init__(
        self,
        robot: str,
        manager: InstanceManager,
        plan: Callable[[], Plan | None],
        api_of: Callable[[str], str | None],
        *,
        token: str,
        events: EventLog,
        hold_s: float = 10.0,
    ) -> None:
        self.robot = robot
        self.manager = manager
        self.plan = plan
        self.api_of = api_of
        """The API address of an alive robot (None if not known)."""
        self.token = token
        self.events = events
        self.hold_s = hold_s
        self.counters: Counter[str] = Counter()
        """sync_sent, sync_unchanged, final_sent, sync_restored, final_restored, held,
        dropped_<reason>, expired, snapshot_failed, send_failed, restore_failed."""
        self.schedule = SyncSchedule()
        self._pending: dict[str, tuple[StateMsg, float]] = {}
        self._sent: dict[tuple[str, str], bytes] = {}
        self._busy: set[str] = set()
        self._bg: set[asyncio.Task[Any]] = set()

    # -- the coordinator's side ----------------------------------------------------------------

    def tick(self) -> None:
        """Start due syncs, hand held states to instances that are ready."""
        now = asyncio.get_running_loop().time()
        states = self._states()
        active = {name for name, state in states.items() if state == LifecycleState.ACTIVE}
        for send in self.schedule.due(now, self.plan(), self.robot, active):
            if send.source not in self._busy:
                self._spawn(self._send(send))
        self._retry(now, states)

    async def retire(self, instance: str) -> None:
        """Before an ACTIVE instance stops: its last state to its component's new instance."""
        component = self.manager.status_of(instance).get("component", "")
        target = final_target(self.plan(), component, instance, self.robot)
        if target is not None:
            await self._send(Send("final", component, instance, (target,)))

    async def stop(self) -> None:
        """Cancel sends and restores in flight."""
        for task in list(self._bg):
            task.cancel()
        await asyncio.gather(*self._bg, return_exceptions=True)

    # -- sending -------------------------------------------------------------------------------

    async def _send(self, send: Send) -> None:
        self._busy.add(send.source)
        try:
            try:
                state = await self.manager.snapshot(send.source)
            except CommandError as exc:
                self._failed("snapshot_failed", send.source, str(exc), loud=send.kind == "final")
                return
            digest = hashlib.blake2b(msgpack.packb(state), digest_size=16).digest()
            plan = self.plan()
            key = (0, "", 0) if plan is None else plan.key
            for robot, target in send.targets:
                if send.kind == "sync" and self._sent.get((send.source, target)) == digest:
                    self.counters["sync_unchanged"] += 1
                    continue
                msg = StateMsg(
                    send.kind, send.component, send.source, target, key, state, self.robot
                )
                if await self._deliver(robot, msg):
                    self._sent[(send.source, target)] = digest
                    self.counters[f"{send.kind}_sent"] += 1
                    if send.kind == "final":
                        self._event(EventKind.STATE_HANDOFF, msg, to_robot=robot)
        finally:
            self._busy.discard(send.source)

    async def _deliver(self, robot: str, msg: StateMsg) -> bool:
        if robot == self.robot:
            return self.receive(msg) in (APPLY, HOLD)
        loud = msg.kind == "final"
        api = self.api_of(robot)
        if api is None:
            self._failed("send_failed", msg.source, f"{robot} has no known API address", loud=loud)
            return False
        try:
            status, doc = await peer_client.post_packed(api, "/v1/state", self.token, msg.encode())
        except ApiError as exc:
            self._failed("send_failed", msg.source, str(exc), loud=loud)
            return False
        if status != 200:
            self._failed("send_failed", msg.source, f"{robot} answered {status}: {doc}", loud=loud)
        return status == 200

    # -- receiving -----------------------------------------------------------------------------

    def receive(self, msg: StateMsg) -> str:
        """A state for an instance here: "apply" or "hold" when kept, else why it was dropped."""
        verdict = admit(self.plan(), self.robot, msg)
        if verdict not in (APPLY, HOLD):
            self._drop(msg, verdict)
            return verdict
        held = self._pending.get(msg.target)
        if held is not None and held[0].kind == "final" and msg.kind == "sync":
            self._drop(msg, "final_pending")  # the last state of the old instance wins
            return "final_pending"
        now = asyncio.get_running_loop().time()
        self._pending[msg.target] = (msg, now + self.hold_s)
        self.counters["held"] += 1
        states = self._states()
        self._retry(now, states)
        return verdict

    def _retry(self, now: float, states: dict[str, Any]) -> None:
        for target, (msg, deadline) in list(self._pending.items()):
            verdict = admit(self.plan(), self.robot, msg)
            if verdict == HOLD or (verdict == APPLY and states.get(target) not in READY):
                if now > deadline:
                    del self._pending[target]
                    self._drop(msg, "expired")
                continue
            del self._pending[target]
            if verdict == APPLY:
                self._spawn(self._restore(msg))
            else:
                self._drop(msg, verdict)

    async def _restore(self, msg: StateMsg) -> None:
        try:
            await self.manager.restore(msg.target, msg.state)
        except CommandError as exc:
            self._failed("restore_failed", msg.target, str(exc), loud=True)
            return
        self.counters[f"{msg.kind}_restored"] += 1
        if msg.kind == "final":
            self._event(EventKind.STATE_RESTORED, msg)

    # -- bookkeeping ---------------------------------------------------------------------------

    def _states(self) -> dict[str, Any]:
        """This robot's instances' lifecycle states, by name."""
        return {s["name"]: s.get("state") for s in self.manager.status()}

    def _drop(self, msg: StateMsg, reason: str) -> None:
        self.counters["expired" if reason == "expired" else f"dropped_{reason}"] += 1
        if msg.kind == "final" or reason == "expired":
            self._event(EventKind.STATE_DROPPED, msg, reason=reason)

    def _failed(self, counter: str, instance: str, detail: str, *, loud: bool) -> None:
        """Count a failure; a final handoff's or a restore's is also logged and an event (a sync
        that fails every second to an unreachable robot is only counted)."""
        self.counters[counter] += 1
        if loud:
            log.info("state handoff: %s: %s: %s", instance, counter, detail)
            self.events.add(
                time.time(), EventKind.STATE_FAILED, self.robot, instance=instance, error=detail
            )

    def _event(self, kind: str, msg: StateMsg, **extra: Any) -> None:
        fields = {"component": msg.component, "source": msg.source, "target": msg.target}
        self.events.add(time.time(), kind, self.robot, kind_of=msg.kind, **fields, **extra)

    def _spawn(self, coro: Any) -> None:
        task = asyncio.create_task(coro)
        self._bg.add(task)
        task.add_done_callback(self._bg.discard)
