"""Component faults on this robot: the agent side of Table III (`sdrpeer.recovery.LocalRecovery`).

How it works: the instance manager reports every fault a component raises (hardware failure,
abnormal behaviour, emergency stop), every instance that enters ERROR and every host that dies
unasked; the metrics loop reports free memory and CPU with each active instance's load. The
pure engine picks the step of the deployed system's ladder:
- `restart`: done here at once (the instance's host is restarted);
- `standby_same_robot`, `standby_other_robot`, `launch_other_robot`: the plan must change (who
  is active), so the request goes to the allocator (`POST /v1/recovery`, or directly when this
  robot holds the role), which issues the new plan at once; every robot repoints from it.
Whether a step could be carried out goes back to the engine, which escalates when it could not
or when the fault comes back. Every decision is in the event log as `recovery.decision`.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable
from typing import Any

from sdrpeer.eventlog import EventKind, EventLog
from sdrpeer.plan import Plan
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Decision, Exhausted, InstanceLoad
from sdrpeer.recovery.local import LocalRecovery
from sdrpeer.runtime.manager import InstanceManager
from sdrpeer.system.model import RecoveryDef
from sdrpeer.vocabulary import InstanceRole, LifecycleState

log = logging.getLogger(__name__)

Request = Callable[[Decision], Awaitable[bool]]
"""Sends a plan-changing decision to the allocator; True when it took it."""


class LocalShell:
    """Feeds `LocalRecovery` and carries out its decisions for this robot's instances."""

    def __init__(
        self,
        robot: str,
        manager: InstanceManager,
        plan: Callable[[], Plan | None],
        request: Request,
        events: EventLog,
        *,
        config: RecoveryConfig | None = None,
    ) -> None:
        self.robot = robot
        self.manager = manager
        self.plan = plan
        self.request = request
        self.events = events
        self.config = config or RecoveryConfig()
        """The engine's staleness and settle time (the agent's preset)."""
        self.engine: LocalRecovery | None = None
        self._bg: set[asyncio.Task[Any]] = set()

    def _engine(self) -> LocalRecovery | None:
        plan = self.plan()
        recovery: RecoveryDef | None = (
            None if plan is None or plan.system is None else (plan.system.recovery)
        )
        if recovery is None:
            self.engine = None
        elif self.engine is None or self.engine.recovery != recovery:
            self.engine = LocalRecovery(self.robot, recovery, self.config)
        if self.engine is not None and plan is not None:
            ready = {
                s["component"]
                for s in self.manager.status()
                if s.get("role") == InstanceRole.STANDBY
                and s.get("state") == LifecycleState.INACTIVE
            }
            self.engine.set_standbys(ready)
        return self.engine

    def _active_component(self, instance: str) -> str | None:
        plan = self.plan()
        if plan is None:
            return None
        for p in plan.on_robot(self.robot):
            if p.instance == instance and p.role == InstanceRole.ACTIVE:
                return p.component
        return None

    # -- inputs (from the instance manager and the metrics loop) -------------------------------

    def fault(self, instance: str, kind: str, detail: str = "") -> None:
        """A component reported a fault, entered ERROR, or its host died (`crashed`)."""
        component = self._active_component(instance)
        engine = self._engine()
        if component is None or engine is None:
            return  # a standby, or nothing deployed: the supervisor's restarts are enough
        now = asyncio.get_running_loop().time()
        engine.instance_fault(now, instance, component, kind, detail)
        self._drain(now)

    def sample(self, mem_free: int, cpu_pct: float) -> None:
        """One metrics sample of this robot (memory shortage and high CPU blame an instance)."""
        engine = self._engine()
        if engine is None:
            return
        now = asyncio.get_running_loop().time()
        loads = {
            s["name"]: InstanceLoad(s["component"], float(s.get("rss") or 0), s.get("cpu_pct") or 0)
            for s in self.manager.status()
            if s.get("state") == LifecycleState.ACTIVE and s.get("role") == InstanceRole.ACTIVE
        }
        engine.robot_metrics(now, {"mem_free": float(mem_free), "cpu": cpu_pct}, loads)
        self._drain(now)

    def tick(self) -> None:
        """Run the engine's due timers (sustain periods, settle times)."""
        if self.engine is None:
            return
        now = asyncio.get_running_loop().time()
        if self.engine.next_timer() <= now:
            self.engine.handle_timer(now)
            self._drain(now)

    def next_timer(self) -> float:
        """When the engine wants to run next (inf: nothing pending)."""
        return float("inf") if self.engine is None else self.engine.next_timer()

    # -- outputs -----------------------------------------------------------------------------

    def _drain(self, now: float) -> None:
        assert self.engine is not None
        while (out := self.engine.next_decision()) is not None:
            if isinstance(out, Exhausted):
                self.events.add(
                    time.time(), EventKind.RECOVERY_EXHAUSTED, self.robot, **_fields(out)
                )
                continue
            self.events.add(time.time(), EventKind.RECOVERY_DECISION, self.robot, **_fields(out))
            task = asyncio.create_task(self._carry_out(out))
            self._bg.add(task)
            task.add_done_callback(self._bg.discard)

    async def _carry_out(self, d: Decision) -> None:
        ok = False
        try:
            if d.action == "restart":
                await self.manager.act(d.instance, "restart")
                ok = True
            else:
                ok = await self.request(d)
        except Exception as e:  # any failure is the step failing: the engine escalates
            log.info("recovery step %s for %s failed: %s", d.action, d.instance, e)
        if self.engine is not None:
            self.engine.action_result(asyncio.get_running_loop().time(), d, ok)
            self._drain(asyncio.get_running_loop().time())

    async def stop(self) -> None:
        """Cancel steps in flight."""
        for task in list(self._bg):
            task.cancel()


def _fields(out: Decision | Exhausted) -> dict[str, Any]:
    keep = ("action", "instance", "component", "cause", "escalate", "detail", "metric")
    return {k: getattr(out, k) for k in keep if getattr(out, k, None) is not None}
