"""Whether this robot is in touch with the fleet, for the coordinator (`deploy.disconnect`'s
robot side, with its I/O).

How it works: on every step the coordinator asks `quorum(state, plan)` before the election runs
(a robot without the quorum is not eligible), and calls `after_sync(...)` once plan sync has run:
the pure `CutOff` learns whether the robot is cut off, back (rejoining) or in touch. A robot back
from a cut, or restarted with a plan that places other robots, asks one robot of the fleet for
its plan over the API (the allocator first, else the robot gossiping the newest plan; gossip
alone may still show it the records from before the cut) and counts as caught up only after the
answer; failed asks are retried every `DeployConfig.ask_retry` seconds. `joined` says whether
the robot has been in touch since it started (until then the coordinator applies no plan: it
would launch hosts for a plan the fleet has very likely replaced); the deployment core reads
`cutoff` to hold down the actives a robot cut off must stand down INACTIVE. Events
`fleet.cut_off`, `fleet.rejoined` and `fleet.in_touch` say when the state changed, with how
many robots it heard of how many.
"""

from __future__ import annotations

import asyncio
import logging
import time
from collections.abc import Awaitable, Callable, Coroutine
from typing import Any

from sdrpeer.deploy.disconnect import CutOff, fleet_of, has_quorum
from sdrpeer.deploy.view import ClusterState
from sdrpeer.errors import ApiError
from sdrpeer.eventlog import EventKind, EventLog
from sdrpeer.plan import Plan
from sdrpeer.vocabulary import InstanceRole

log = logging.getLogger(__name__)


class TouchShell:
    """One robot's contact with the fleet."""

    def __init__(
        self,
        name: str,
        events: EventLog,
        kept: Plan | None,
        *,
        ask: Callable[[str], Awaitable[Plan | None]],
        accept: Callable[[Plan, str], bool],
        spawn: Callable[[Coroutine[Any, Any, None]], None],
        wake: Callable[[], None],
        ask_retry: float = 0.5,
    ) -> None:
        """`kept`: the plan this agent started with; `ask(api)`: the plan of the robot there;
        `accept(plan, source)`: offer it to the plan store; `spawn`, `wake`: the coordinator's;
        `ask_retry`: `DeployConfig.ask_retry`."""
        self.name = name
        self.ask_retry = ask_retry
        self.events = events
        self.ask = ask
        self.accept = accept
        self.spawn = spawn
        self.wake = wake
        self.cutoff = CutOff()
        self.joined = False
        """In touch with the fleet (and caught up) at least once since this agent started."""
        self._confirmed = False
        self._asking = False
        self._ask_after = 0.0
        self._fleet = 1
        if kept is not None and any(p.robot != name for p in kept.placements):
            self.cutoff.restarted()  # like a robot back from a cut: the fleet's plan first

    @property
    def cut(self) -> bool:
        """Whether this robot is cut off from the fleet now."""
        return self.cutoff.cut

    def quorum(self, state: ClusterState, plan: Plan | None) -> bool:
        """Whether this robot hears a majority of the fleet (or the system waives it)."""
        fleet = fleet_of(self.name, state.members, plan, state.heard_of_others)
        self._fleet = len(fleet)
        if plan is not None and plan.system is not None and plan.system.allocation.quorum == "any":
            return True
        return has_quorum(self.name, state.heard | state.alive.keys(), fleet)

    def after_sync(
        self, now: float, state: ClusterState, quorum: bool, caught_up: bool, leader: str | None
    ) -> None:
        """Feed the cut-off core; ask the fleet for its plan when back from a cut."""
        if self.cutoff.update(now, quorum, caught_up and self._confirmed):
            self._log(len(state.heard | state.alive.keys()))
        self.joined = self.joined or not (self.cutoff.cut or self.cutoff.rejoining)
        if not quorum:
            self._confirmed = False
        elif self.cutoff.rejoining and not self._asking and now >= self._ask_after:
            self._ask(state, leader)

    def next_timer(self, plan: Plan | None) -> float:
        """When a `stop_after` of an active here runs out (inf: none pending)."""
        if plan is None or plan.system is None:
            return self.cutoff.next_timer(())
        system = plan.system
        policies = [
            system.component(p.component).disconnect
            for p in plan.on_robot(self.name)
            if p.role == InstanceRole.ACTIVE
        ]
        return self.cutoff.next_timer(policies)

    def _log(self, heard: int) -> None:
        c = self.cutoff
        kind = (
            EventKind.FLEET_CUT_OFF
            if c.cut
            else EventKind.FLEET_REJOINED
            if c.rejoining
            else EventKind.FLEET_IN_TOUCH
        )
        log.info("%s: hears %d of %d robots", kind, heard, self._fleet)
        self.events.add(time.time(), kind, self.name, heard=heard, fleet=self._fleet)

    def _ask(self, state: ClusterState, leader: str | None) -> None:
        asked = {n: r for n, r in state.alive.items() if n != self.name and r.api is not None}
        if not asked:
            if not (state.heard | state.alive.keys()) - {self.name}:
                self._confirmed = True  # nobody to ask: the quorum is this robot's half alone
            return  # else their records (with their API addresses) are on their way

        def newest(name: str) -> tuple[tuple[int, str, int], str]:
            p = asked[name].plan
            return (p.key if p is not None else (-1, "", -1), name)

        robot = leader if leader is not None and leader in asked else max(asked, key=newest)
        api = asked[robot].api
        assert api is not None
        self._asking = True
        self.spawn(self._ask_one(robot, api))

    async def _ask_one(self, robot: str, api: str) -> None:
        try:
            plan = await self.ask(api)
        except ApiError as e:
            log.info("cannot ask %s for its plan after a cut: %s", robot, e)
            self._ask_after = asyncio.get_running_loop().time() + self.ask_retry
        else:
            if plan is not None:
                self.accept(plan, robot)
            self._confirmed = True
        finally:
            self._asking = False
            self.wake()
