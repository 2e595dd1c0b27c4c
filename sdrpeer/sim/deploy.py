"""Deployment cores driven by the simulator: one `DeployCore` per robot, plans fetched and pushed
over the simulated network, on the virtual clock.

How it works:
- the `Cluster` lends its clock, its event heap (`schedule`, `run_until`, `wait_for`) and its
  seeded `Network` (delay, loss, partitions); no membership core runs (a thousand SWIM cores
  would cost the run its speed; `sim/agents.py` measures gossip itself). Gossip is modelled by
  what it delivers: every robot's record (the plan it holds as a `PlanInfo`, the instances it
  runs, the allocator's claim) goes into one *truth*; a change of the truth is taken as a
  snapshot at most every `batch` seconds, and each robot sees a snapshot `lag` seconds after it
  was taken (robots are spread over `buckets` lags between `lags[0]` and `lags[1]`: an epidemic
  reaches robots at different moments, in order);
- a killed robot stops at once (its core is no longer stepped, nothing reaches it) and leaves the
  truth `detect_after` seconds later (failure detection); the election is an oracle: the first
  robot by name of the truth holds the role, at an epoch one higher at every change, and claims
  it in its record (which raises every robot's fence as the snapshot reaches it);
- each robot's core is stepped (then applies the plan) when a snapshot reaches it, at its
  `next_timer()`, and after the answer of a fetch; its effects are carried out as the agent's
  shell does: `Fetch` is a request and an answer over the network (a lost one, a dead robot or
  a robot without a plan fails after `fetch_timeout`), `Push` is one message offered to the
  receiver's core, `Adopted` rewrites the robot's record in the truth and applies the plan,
  `Log` lines are kept (`logs`; `plan.accepted` only counted);
- each robot's instance manager is modelled by what its core asks for (`Desired`), done at once:
  a spec that wants to run ACTIVE is ACTIVE, any other INACTIVE; its record carries them, so
  the handover of a moved component (the new copy waits until the old one's robot shows it
  stood down) runs over the same lagged gossip;
- requests (deploy, move, recovery) go to the robot whose view says it holds the role.
`converged()` says whether every running robot holds the allocator's plan and no placement of it
sits on a robot that is down; `running_as_planned()` also whether every running robot runs
exactly its share of it; `actives()` which robots run each component ACTIVE.
"""

from __future__ import annotations

import functools
import math
import random
from dataclasses import dataclass
from typing import Any

from sdrpeer.deploy.config import DeployConfig
from sdrpeer.deploy.core import DeployCore, DeployView, Here, Request
from sdrpeer.deploy.effects import Adopted, Desired, Fetch, Log, Push
from sdrpeer.deploy.placer import Infeasible
from sdrpeer.deploy.planstore import PlanStore
from sdrpeer.deploy.view import ClusterState, PlanKey
from sdrpeer.errors import NotAllocator
from sdrpeer.eventlog import EventKind
from sdrpeer.plan import Plan
from sdrpeer.record.robot import (
    ElectionInfo,
    InstanceInfo,
    LinkSummary,
    Metrics,
    PlanInfo,
    RobotRecord,
)
from sdrpeer.sim.cluster import Cluster
from sdrpeer.vocabulary import InstanceRole, LifecycleState

MB = 1000**2
METRICS = Metrics(10.0, 4000 * MB, 1600 * MB, 80.0, -45.0, (0.0, 0.0))
"""What every simulated robot reports (the allocation sees a fleet of equal robots)."""


class _Frozen(ClusterState):
    """A state nobody changes once built: its questions are answered once for every robot."""

    def plan_offers(self) -> list[tuple[PlanKey, str]]:
        offers: list[tuple[PlanKey, str]] | None = self.__dict__.get("_offers")
        if offers is None:
            offers = self.__dict__["_offers"] = super().plan_offers()
        return offers

    def claims(self) -> list[tuple[int, str]]:
        claims: list[tuple[int, str]] | None = self.__dict__.get("_claims")
        if claims is None:
            claims = self.__dict__["_claims"] = super().claims()
        return claims

    def hosted(self) -> list[tuple[str, InstanceInfo]]:
        hosted: list[tuple[str, InstanceInfo]] | None = self.__dict__.get("_hosted")
        if hosted is None:
            hosted = self.__dict__["_hosted"] = super().hosted()
        return hosted


@dataclass(frozen=True, slots=True)
class Snapshot:
    """The fleet as gossip shows it at one moment, with the election's verdict."""

    state: ClusterState
    epoch: int
    leader: str | None


class DeploySim:
    """A fleet of deployment cores on a `Cluster`'s clock and network (never started)."""

    def __init__(
        self,
        cluster: Cluster,
        config: DeployConfig | None = None,
        *,
        detect_after: float = 1.0,
        lags: tuple[float, float] = (0.02, 0.3),
        buckets: int = 8,
        batch: float = 0.05,
        fetch_timeout: float = 1.0,
    ) -> None:
        self.cluster = cluster
        self.names = names = cluster.names
        self.config = config or DeployConfig()
        self.detect_after = detect_after
        self.batch = batch
        self.fetch_timeout = fetch_timeout
        self.cores = [DeployCore(name, PlanStore(), self.config) for name in names]
        self.up = [True] * len(names)
        rng = random.Random(f"{cluster.seed}/deploy")
        lo, hi = lags
        self._lags = [lo + (hi - lo) * (k + 0.5) / buckets for k in range(buckets)]
        self._bucket = [rng.randrange(buckets) for _ in names]
        self._members: list[list[int]] = [[] for _ in range(buckets)]
        for i, k in enumerate(self._bucket):
            self._members[k].append(i)
        self.epoch = 0
        self.leader: str | None = None
        self._plans: dict[str, Plan | None] = dict.fromkeys(names)
        self.instances: list[dict[str, InstanceInfo]] = [{} for _ in names]
        """Per robot: the instances it runs (what its core last asked for, at once)."""
        self.truth: dict[str, RobotRecord] = {name: self._record(name) for name in names}
        """Every robot not yet detected dead, with its current record."""
        empty = Snapshot(ClusterState({}, names), 0, None)
        self._seen = [empty] * buckets
        self._timer_at = [math.inf] * len(names)
        self._pending = False
        self.logs: list[tuple[float, str, str, dict[str, Any]]] = []
        """(time, robot, kind, detail) of every event but `plan.accepted`."""
        self.accepted = 0
        """How many times a robot took a plan."""
        self.violations: list[tuple[float, str, PlanKey, PlanKey]] = []
        """(time, robot, plan taken, a newer one it held before): checked here, not by the
        plan store, so a fencing bug shows."""
        self._elect()

    # -- faults and requests ------------------------------------------------------------------

    def kill(self, name: str) -> None:
        """Crash `name` now; the fleet sees it gone `detect_after` seconds later."""
        i = self.cluster.index[name]
        self.up[i] = False
        self._timer_at[i] = math.inf
        self.cluster.schedule(
            self.cluster.now + self.detect_after, functools.partial(self._gone, name)
        )

    def allocator(self) -> str | None:
        """The allocator, once its own view says it holds the role (None in a handover)."""
        name = self.leader
        if name is None:
            return None
        i = self.cluster.index[name]
        return name if self.up[i] and self._view(i).allocator else None

    def request(self, reason: Request) -> Plan | Infeasible:
        """Hand a request to the allocator now (`NotAllocator` during a handover)."""
        name = self.allocator()
        if name is None:
            raise NotAllocator(self.leader)
        i = self.cluster.index[name]
        try:
            return self.cores[i].request(self.cluster.now, self._view(i), reason)
        finally:
            self._drain(i)
            self._arm(i)

    def push_from(self, name: str, plan: Plan) -> None:
        """Robot `name` offers `plan` to every running robot over the network (a deposed
        allocator's push still in flight, say), whether `name` runs or not."""
        i = self.cluster.index[name]
        for j, up in enumerate(self.up):
            if up and j != i:
                self._push(i, j, plan)

    # -- questions ----------------------------------------------------------------------------

    def plan(self, name: str) -> Plan | None:
        """The plan `name` holds."""
        return self.cores[self.cluster.index[name]].store.plan

    def converged(self) -> bool:
        """Whether every running robot holds the allocator's plan, and that plan places nothing
        on a robot that is down."""
        leader = self.allocator()
        if leader is None:
            return False
        plan = self.plan(leader)
        if plan is None or plan.epoch != self.epoch:
            return False
        index, up = self.cluster.index, self.up
        if any(not up[index[p.robot]] for p in plan.placements):
            return False
        key = plan.key
        return all(
            (held := core.store.plan) is not None and held.key == key
            for core, alive in zip(self.cores, up, strict=True)
            if alive
        )

    def running_as_planned(self) -> bool:
        """Whether `converged()` and every running robot runs exactly its share of that plan:
        the instances placed on it, each active one ACTIVE and each standby INACTIVE."""
        leader = self.allocator()
        if not self.converged() or leader is None:
            return False
        plan = self.plan(leader)
        assert plan is not None
        for i, up in enumerate(self.up):
            if not up:
                continue
            want = {p.instance: p.role for p in plan.on_robot(self.names[i])}
            have = self.instances[i]
            if {n: inst.role for n, inst in have.items()} != want:
                return False
            if any(
                (inst.state == LifecycleState.ACTIVE) != (inst.role == InstanceRole.ACTIVE)
                for inst in have.values()
            ):
                return False
        return True

    def actives(self) -> dict[str, list[str]]:
        """component -> the running robots that run it ACTIVE now."""
        out: dict[str, list[str]] = {}
        for i, up in enumerate(self.up):
            if up:
                for inst in self.instances[i].values():
                    if inst.state == LifecycleState.ACTIVE:
                        out.setdefault(inst.component, []).append(self.names[i])
        return out

    def kinds(self, kind: str) -> list[tuple[float, str, dict[str, Any]]]:
        """The logged events of one kind, as (time, robot, detail)."""
        return [(t, robot, detail) for t, robot, k, detail in self.logs if k == kind]

    # -- gossip and the election --------------------------------------------------------------

    def _record(self, name: str) -> RobotRecord:
        plan = self._plans[name]
        info = None if plan is None else PlanInfo(plan.epoch, plan.version, "", plan.allocator)
        instances = tuple(self.instances[self.cluster.index[name]].values())
        claim = ElectionInfo(self.epoch, name, True) if name == self.leader else None
        return RobotRecord(METRICS, LinkSummary(), f"sim://{name}", 0, instances, claim, info)

    def _gone(self, name: str) -> None:
        if self.truth.pop(name, None) is not None:
            self._elect()
            self._changed()

    def _elect(self) -> None:
        leader = min(self.truth, default=None)
        if leader != self.leader:
            self.epoch += 1
            self.leader = leader
            if leader is not None:
                self.truth[leader] = self._record(leader)
            self._changed()

    def _changed(self) -> None:
        if not self._pending:
            self._pending = True
            self.cluster.schedule(self.cluster.now + self.batch, self._snapshot)

    def _snapshot(self) -> None:
        self._pending = False
        snap = Snapshot(_Frozen(dict(self.truth), self.names), self.epoch, self.leader)
        now = self.cluster.now
        for k, lag in enumerate(self._lags):
            self.cluster.schedule(now + lag, functools.partial(self._deliver, k, snap))

    def _deliver(self, k: int, snap: Snapshot) -> None:
        self._seen[k] = snap
        for i in self._members[k]:
            if self.up[i]:
                self._step(i)

    # -- driving one core ---------------------------------------------------------------------

    def _view(self, i: int) -> DeployView:
        snap = self._seen[self._bucket[i]]
        mine = snap.leader == self.names[i]
        return DeployView(snap.state, allocator=mine, epoch=snap.epoch, leader=snap.leader)

    def _step(self, i: int) -> None:
        self.cores[i].step(self.cluster.now, self._view(i))
        self._drain(i)
        self._apply(i)
        self._arm(i)

    def _apply(self, i: int) -> None:
        active = frozenset(
            n for n, inst in self.instances[i].items() if inst.state == LifecycleState.ACTIVE
        )
        state = self._seen[self._bucket[i]].state
        self.cores[i].apply(self.cluster.now, state, Here(active))
        self._drain(i)

    def _arm(self, i: int) -> None:
        at = self.cores[i].next_timer()
        if at != math.inf and at != self._timer_at[i]:
            self._timer_at[i] = at
            self.cluster.schedule(at, functools.partial(self._on_timer, i, at))

    def _on_timer(self, i: int, at: float) -> None:
        if self.up[i] and self._timer_at[i] == at:
            self._timer_at[i] = math.inf
            self._step(i)

    def _drain(self, i: int) -> None:
        name, now = self.names[i], self.cluster.now
        for effect in self.cores[i].effects():  # an Adopted plan's own effects are drained by
            # `_apply` (called for it) before the rest of this list
            if isinstance(effect, Log):
                if effect.kind == EventKind.PLAN_ACCEPTED:
                    self.accepted += 1
                else:
                    self.logs.append((now, name, effect.kind, effect.detail))
            elif isinstance(effect, Adopted):
                before = self._plans[name]
                if before is not None and effect.plan.key <= before.key:
                    self.violations.append((now, name, effect.plan.key, before.key))
                self._plans[name] = effect.plan
                self._publish(name)
                self._apply(i)
            elif isinstance(effect, Desired):
                self._run(i, effect)
            elif isinstance(effect, Fetch):
                self._fetch(i, self.cluster.index[effect.robot])
            elif isinstance(effect, Push):
                self._push(i, self.cluster.index[effect.robot], effect.plan)

    def _run(self, i: int, want: Desired) -> None:
        """Robot i's instance manager does what its core asks, at once: a spec that wants to be
        active runs ACTIVE, any other INACTIVE; removed instances stop."""
        running = {
            spec.name: InstanceInfo(
                spec.name,
                spec.component,
                LifecycleState.ACTIVE if spec.wants_active() else LifecycleState.INACTIVE,
                spec.role,
                0.0,
                0,
                f"tcp://{self.names[i]}:7000",
            )
            for spec in want.specs
        }
        if running != self.instances[i]:
            self.instances[i] = running
            self._publish(self.names[i])

    def _publish(self, name: str) -> None:
        """`name`'s record changed: the next snapshot carries it (if the fleet still sees it)."""
        if name in self.truth:
            self.truth[name] = self._record(name)
            self._changed()

    def _fetch(self, i: int, j: int) -> None:
        """Robot i asks robot j for its plan (a lost request fails after `fetch_timeout`)."""
        delay = self.cluster.network.verdict(i, j)
        if delay < 0.0:
            self._fail_later(i, self.names[j])
        else:
            self.cluster.schedule(
                self.cluster.now + delay, functools.partial(self._serve_fetch, i, j)
            )

    def _push(self, i: int, j: int, plan: Plan) -> None:
        """Robot i offers `plan` to robot j (a lost push is lost: j fetches the plan)."""
        delay = self.cluster.network.verdict(i, j)
        if delay >= 0.0:
            receive = functools.partial(self._receive_push, j, plan, self.names[i])
            self.cluster.schedule(self.cluster.now + delay, receive)

    def _fail_later(self, i: int, robot: str) -> None:
        self.cluster.schedule(
            self.cluster.now + self.fetch_timeout, functools.partial(self._fetch_failed, i, robot)
        )

    def _serve_fetch(self, i: int, j: int) -> None:
        """Robot j answers robot i's fetch with the plan it holds."""
        plan = self.cores[j].store.plan
        if not self.up[j] or plan is None:
            self._fail_later(i, self.names[j])
            return
        delay = self.cluster.network.verdict(j, i)
        if delay < 0.0:
            self._fail_later(i, self.names[j])
            return
        answer = functools.partial(self._fetched, i, self.names[j], plan)
        self.cluster.schedule(self.cluster.now + delay, answer)

    def _fetched(self, i: int, robot: str, plan: Plan) -> None:
        if self.up[i]:
            self.cores[i].fetched(robot, plan)
            self._step(i)

    def _fetch_failed(self, i: int, robot: str) -> None:
        if self.up[i]:
            self.cores[i].fetch_failed(self.cluster.now, robot)
            self._step(i)

    def _receive_push(self, j: int, plan: Plan, source: str) -> None:
        if self.up[j]:
            self.cores[j].offer(plan, source)
            self._drain(j)
