"""Simulated agents: what the real agent does with its gossip core, on the simulator's clock.

How it works: `AgentFleet` builds a `Cluster` whose cores are the real `Membership`, each starting
its record versions past a per-boot floor as an agent does from its data dir; a forwarding
`Trace` hands every `ProbeOutcome` to the robot's real `LinkTable`. Every
`interval` virtual seconds (staggered per robot, as agents start at different moments) each
running robot's `SimAgent` does what `Agent._publish` does: samples its metrics (a `Churn`
model, since a simulated robot has no hardware), averages its CPU (`Average`), summarises its
links against the link bounds (`LinkTable.summary`), builds a `RobotRecord` with the fields an
agent fills (API address, priority, election belief; no instances: an idle fleet), and
publishes it through the real `Publisher` (`sdrpeer.monitor.publish.publish`): a new record,
spread by the core, or a vitals revision, carried on its pings. Every byte the cluster counts is
the real codec's.

`Churn` is the metrics model: the CPU jumps by `cpu_step` points at a Poisson rate
(`cpu_jumps_per_s`), free memory moves by `mem_step_mib` at its own rate, and the battery, when
there is one, drains at `drain_pct_per_min` from a random level and is swapped for a full one at
5 %. The rates are calibrated against real agents (tests/test_sim_calibration.py compares the
bytes per agent of both at N = 10 and 25).

Big fleets: summarising a robot's links costs O(N) (one estimator per peer); `summary_every`
lets a run at thousands of robots summarise every few samples instead of at each (the real agent
summarises at each sample; the link values change slowly, the CPU and battery still at each).
"""

from __future__ import annotations

import functools
import random
from collections.abc import Sequence
from dataclasses import dataclass, field

from sdrpeer.agent.files import RECORD_RESERVE
from sdrpeer.gossip.config import GossipConfig
from sdrpeer.gossip.core import Membership
from sdrpeer.gossip.events import CoreEvent, ProbeOutcome
from sdrpeer.gossip.messages import Addr
from sdrpeer.monitor.links import LinkTable
from sdrpeer.monitor.publish import (
    Average,
    Publisher,
    link_bounds,
    publish,
)
from sdrpeer.record.robot import ElectionInfo, LinkSummary, Metrics, RobotRecord, encode_record
from sdrpeer.sim.cluster import Cluster
from sdrpeer.sim.trace import Trace

MIB = 1 << 20


@dataclass(frozen=True, slots=True)
class Churn:
    """How a simulated robot's metrics change (see the module docstring)."""

    cpu_mean: float = 30.0
    cpu_step: float = 15.0
    cpu_jumps_per_s: float = 0.1
    mem_total: int = 4096 * MIB
    mem_free: int = 2048 * MIB
    mem_step_mib: float = 64.0
    mem_moves_per_s: float = 0.01
    battery: bool = False
    drain_pct_per_min: float = 1.0


@dataclass(slots=True)
class _Robot:
    """One simulated robot's hardware state."""

    cpu: float
    mem_free: int
    battery: float | None


@dataclass(slots=True)
class SimAgent:
    """What one agent keeps between two samples."""

    name: str
    api: str
    robot: _Robot
    links: LinkTable = field(default_factory=LinkTable)
    publisher: Publisher = field(default_factory=Publisher)
    cpu: Average = field(default_factory=Average)
    summary: LinkSummary = field(default_factory=LinkSummary)
    generation: int = 0
    """Which boot of its robot this agent belongs to."""
    samples: int = 0
    published: dict[str, int] = field(default_factory=lambda: {"record": 0, "vitals": 0})


class _Sink:
    """One simulated robot as a `RecordSink` (the cluster drives its core after each call)."""

    def __init__(self, cluster: Cluster, name: str) -> None:
        self.cluster = cluster
        self.name = name

    def set_record(self, payload: bytes, *, urgent: bool = False) -> int:
        return self.cluster.set_record(self.name, payload, urgent=urgent)

    def set_vitals(self, payload: bytes) -> int:
        return self.cluster.set_vitals(self.name, payload)


class _LinkTrace(Trace):
    """A Trace that also hands each robot's probe outcomes to its agent's LinkTable."""

    def __init__(self, old: Trace, fleet: AgentFleet) -> None:
        super().__init__(old.names, keep_all=old.keep_all)
        self._fleet = fleet

    def record(self, i: int, event: CoreEvent, now: float) -> None:
        super().record(i, event, now)
        if type(event) is ProbeOutcome:
            agent = self._fleet.agents[i]
            if agent is not None:
                agent.links.observe(event.name, event.rtt, event.at)

    def up(self, i: int, now: float) -> None:
        super().up(i, now)
        self._fleet.on_boot(i, now)


class AgentFleet:
    """A simulated cluster with an agent on every robot (`cluster`; start it with `start`)."""

    def __init__(
        self,
        n: int,
        config: GossipConfig,
        churn: Churn | None = None,
        *,
        interval: float = 1.0,
        summary_every: int = 1,
        seed: int = 0,
        names: Sequence[str] | None = None,
        base_delay: float = 0.001,
        jitter: float = 0.004,
    ) -> None:
        self.churn = churn or Churn()
        self.interval = interval
        self.summary_every = max(1, summary_every)
        self._rng = random.Random(f"{seed}/agents")
        self.agents: list[SimAgent | None] = [None] * n
        self._boots = [0] * n
        self._bounds = link_bounds(None)
        self.cluster = Cluster(
            n,
            config,
            seed=seed,
            names=names,
            base_delay=base_delay,
            jitter=jitter,
            core_factory=self._factory,
        )
        self._index = self.cluster.index
        self.cluster.trace = _LinkTrace(self.cluster.trace, self)

    def start(self, spread: float = 0.0, *, converged: bool = False) -> None:
        """Boot every robot: joining through the seed (`Cluster.start`), or, with `converged`,
        as a fleet that has already converged, every agent's first record held by all
        (`Cluster.start_converged`: past the join storm, for thousands of robots)."""
        if not converged:
            self.cluster.start(spread)
            return
        now = self.cluster.now
        names = self.cluster.names
        rtt = 2 * self.cluster.network.base_delay
        records: dict[str, bytes] = {}
        for i, name in enumerate(names):
            agent = self.agents[i] = self._new_agent(i, generation=1)
            for k in range(1, min(4, len(names))):  # converged: it has measured some links
                agent.links.observe(names[(i + k) % len(names)], rtt, now)
            record = self._record(agent, now)
            agent.publisher.decide(now, record)  # published: everyone holds it from the start
            records[name] = encode_record(record)
        self.cluster.start_converged(records)

    def _factory(
        self, name: str, addr: Addr, config: GossipConfig, now: float, rng: random.Random
    ) -> Membership:
        """A real core whose record versions start past a floor that moves on at every boot,
        as an agent's do (its data dir's record.floor)."""
        i = self._index[name]
        first = 1 + self._boots[i] * RECORD_RESERVE
        self._boots[i] += 1
        return Membership(name, addr, config, now=now, rng=rng, first_version=first)

    def on_boot(self, i: int, now: float) -> None:
        """Robot i (re)started: a fresh agent (unless `start` made it for this boot), sampling
        from a random phase of its interval."""
        generation = self._boots[i]
        agent = self.agents[i]
        if agent is None or agent.generation != generation:
            agent = self.agents[i] = self._new_agent(i, generation)
        first = now + self._rng.uniform(0.0, self.interval)
        self.cluster.schedule(first, functools.partial(self._sample, i, generation))

    def _new_agent(self, i: int, generation: int) -> SimAgent:
        c = self.churn
        battery = self._rng.uniform(30.0, 100.0) if c.battery else None
        robot = _Robot(c.cpu_mean, c.mem_free, battery)
        api = f"http://10.0.{i // 200}.{i % 200}:8080"
        return SimAgent(self.cluster.names[i], api, robot, generation=generation)

    def _record(self, agent: SimAgent, now: float) -> RobotRecord:
        """What `Agent._publish` builds (no instances: an idle fleet)."""
        m = self._metrics(agent.robot)
        if agent.samples % self.summary_every == 0:
            agent.summary = agent.links.summary(now, self._bounds)
        agent.samples += 1
        leader = self.cluster.names[0]
        return RobotRecord(
            Metrics(
                round(agent.cpu.add(now, m.cpu_pct), 1),
                m.mem_total,
                m.mem_free,
                m.battery_pct,
                m.rssi_dbm,
                m.pos,
            ),
            agent.summary,
            agent.api,
            0,
            (),
            election=ElectionInfo(1, leader, agent.name == leader),
        )

    def _sample(self, i: int, generation: int) -> None:
        cluster = self.cluster
        agent = self.agents[i]
        if agent is None or generation != self._boots[i] or not cluster.is_up(agent.name):
            return
        now = cluster.now
        self._churn(agent.robot)
        record = self._record(agent, now)
        decision, _ = publish(_Sink(cluster, agent.name), agent.publisher, now, record)
        if decision in agent.published:
            agent.published[decision] += 1
        cluster.schedule(now + self.interval, functools.partial(self._sample, i, generation))

    def _churn(self, robot: _Robot) -> None:
        c, rng, dt = self.churn, self._rng, self.interval
        if rng.random() < c.cpu_jumps_per_s * dt:
            step = c.cpu_step if rng.random() < 0.5 else -c.cpu_step
            robot.cpu = min(95.0, max(5.0, robot.cpu + step))
            robot.cpu += (c.cpu_mean - robot.cpu) * 0.2  # drawn back towards its usual load
        if rng.random() < c.mem_moves_per_s * dt:
            step = int(c.mem_step_mib * MIB) * (1 if rng.random() < 0.5 else -1)
            robot.mem_free = min(c.mem_total, max(0, robot.mem_free + step))
        if robot.battery is not None:
            robot.battery -= c.drain_pct_per_min * dt / 60.0
            if robot.battery < 5.0:
                robot.battery = 100.0

    def _metrics(self, robot: _Robot) -> Metrics:
        return Metrics(robot.cpu, self.churn.mem_total, robot.mem_free, robot.battery, None, None)

    def published(self) -> dict[str, int]:
        """Records and vitals revisions published by the current agents, in total."""
        total = {"record": 0, "vitals": 0}
        for agent in self.agents:
            if agent is not None:
                for k in total:
                    total[k] += agent.published[k]
        return total
