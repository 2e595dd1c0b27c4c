"""When a robot publishes a new record, a revision of its vitals, or nothing.

How it works: a record version is spread to every robot (each robot re-sends it a few times:
the epidemic), so the fleet pays for every version in proportion to its size. Its vitals — the
metrics, link summary and instance loads — are also sent as revisions of the current record,
directly to each peer on the next probe that peer has not acknowledged (`sdrpeer.gossip`), which
costs the same at any fleet size. `Publisher.decide(now, record)` picks:

- RECORD when something the fleet decides with changed: identity (API address, priority, capacity,
  position-less <-> positioned), an instance's name, component, state, role or data address, the
  election belief, the plan held, the link bounds, the launch policy, or a measured value moved
  across a `Boundaries` cut (a threshold some decision compares it with: the deployed system's
  robot-wide recovery rules and their clear levels, the allocation thresholds that decide who may be
  allocator, the broadcast default traps). So every robot sees each robot on the correct side of
  every threshold it judges by, at the same moment, whatever the fleet's size. A crossing less than
  `min_gap` after the last record goes out as vitals and makes a record at the next sample after the
  gap (a value flapping across a cut costs at most one record per gap);
- VITALS when a measured value moved past its deadband since the last record or vitals sent
  (cpu 5 points, free memory 1 % of capacity or 16 MiB, battery 1 point, RSSI 2 dB, position
  10 cm, typical link RTT 1 ms or 25 %, jitter 1 ms or 50 %, loss 5 points, a listed link
  added, gone or moved as much, an instance's cpu or memory as much as the robot's);
- NONE otherwise: noise inside the deadbands is never sent, and nothing is re-sent on a timer.

A robot's CPU is published as an average over the last `CPU_AVERAGE_S` seconds (`Average`,
exponential, like a load average): one-second samples swing by tens of points on a busy
computer, which would make a revision every few seconds and tell the allocator nothing about
the load a component would meet. The robot's own agent still judges its raw samples (Table III's
CPU rule, its traps).

Time is passed in; nothing here reads a clock.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Iterable, Mapping
from dataclasses import dataclass, field
from typing import Protocol

from sdrpeer.record.robot import (
    LinkBounds,
    LinkStats,
    LinkSummary,
    Metrics,
    RobotRecord,
    encode_record,
    encode_vitals,
    vitals_of,
)
from sdrpeer.system.model import RecoveryDef, Thresholds

RECORD = "record"
VITALS = "vitals"
NONE = "none"

CPU_AVERAGE_S = 10.0
"""Time constant of the published CPU average (seconds)."""

NO_LINK_BOUNDS = LinkBounds()
"""No system bounds its links: no link is listed (the typical link says how a robot's links
are; listing more would cost every peer bytes on every revision for no decision)."""

_GETTERS: dict[str, Callable[[Metrics, LinkSummary], float | None]] = {
    "cpu": lambda m, _: m.cpu_pct,
    "mem_free": lambda m, _: float(m.mem_free),
    "battery": lambda m, _: m.battery_pct,
    "rssi": lambda m, _: m.rssi_dbm,
    "delay": lambda _, s: None if s.typical is None else s.typical.rtt_ms,
    "jitter": lambda _, s: None if s.typical is None else s.typical.jitter_ms,
    "loss": lambda _, s: None if s.typical is None else s.typical.loss,
}
"""The record values a boundary may cut, by the recovery rules' metric names."""


@dataclass(frozen=True, slots=True)
class Boundaries:
    """Values of each metric at which some decision changes (metric name -> cuts)."""

    cuts: Mapping[str, tuple[float, ...]] = field(default_factory=dict)

    def crossed(self, old: RobotRecord, new: RobotRecord) -> str | None:
        """The first metric whose value moved across, onto or off a cut (None: none did)."""
        for metric, cuts in self.cuts.items():
            getter = _GETTERS.get(metric)
            if getter is None:
                continue
            a = getter(old.metrics, old.links)
            b = getter(new.metrics, new.links)
            if a is None or b is None:
                if (a is None) != (b is None):
                    return metric
                continue
            if a != b and any(_side(a, c) != _side(b, c) for c in cuts):
                return metric
        return None


def _side(value: float, cut: float) -> int:
    return (value > cut) - (value < cut)


def boundaries(
    recovery: RecoveryDef | None = None, thresholds: Thresholds | None = None
) -> Boundaries:
    """The cuts for a deployed system (both None: nothing deployed): the broadcast default
    traps (battery, RSSI) always; the allocation thresholds that decide who may be allocator;
    every robot-wide rule's threshold and clear level. Rules the robot's own agent judges
    (memory shortage, CPU: Table III's local steps) cut nothing: no other robot decides on
    them, and the allocator reads CPU and memory from the vitals. Nor do the election's coarse
    health steps: they only order who claims first on a vacancy, the election orders claims by
    what they carry whatever each robot's view of health, and a step reaches every peer as vitals
    within one probe round; as cuts they made a record per robot per step crossed, a cost that
    grows with the fleet (a draining battery crosses three)."""
    cuts: dict[str, set[float]] = {
        "battery": {20.0, 25.0},
        "rssi": {-52.5, -50.0},
    }
    t = thresholds
    if t is not None:
        _add(cuts, "battery", [t.battery_above_pct])
        _add(cuts, "rssi", [t.rssi_above_dbm])
        _add(cuts, "loss", [t.loss_below])
    if recovery is not None:
        # Loaded with a deployed system only: an agent starts without the recovery package.
        from sdrpeer.recovery.plugins import CONDITIONS  # noqa: PLC0415

        for rule in recovery.rules:
            if rule.metric is not None and CONDITIONS.get(rule.cause).robot_wide:
                _add(cuts, rule.metric, [rule.threshold, rule.clear])
    return Boundaries({m: tuple(sorted(v)) for m, v in sorted(cuts.items())})


def _add(cuts: dict[str, set[float]], metric: str, values: Iterable[float | None]) -> None:
    for v in values:
        if v is not None:
            cuts.setdefault(metric, set()).add(float(v))


def link_bounds(thresholds: Thresholds | None) -> LinkBounds:
    """The bounds past which a record lists a link: the deployed system's allocation bounds
    (`delay_below`, `jitter_below`, `loss_below`), so a link the allocator must refuse is
    listed by both its ends (unless more than `MAX_LISTED` are); none deployed or none set:
    nothing is listed."""
    if thresholds is None:
        return NO_LINK_BOUNDS
    t = thresholds
    return LinkBounds(rtt_ms=t.delay_below_ms, jitter_ms=t.jitter_below_ms, loss=t.loss_below)


class Average:
    """An exponential average with time constant `tau` over samples at any spacing."""

    def __init__(self, tau: float = CPU_AVERAGE_S) -> None:
        self.tau = tau
        self.value: float | None = None
        self._at = 0.0

    def add(self, now: float, sample: float) -> float:
        """Take `sample` at `now`; the average (the first sample as it is)."""
        if self.value is None:
            self.value = sample
        else:
            weight = 1.0 - math.exp(-max(0.0, now - self._at) / self.tau)
            self.value += (sample - self.value) * weight
        self._at = now
        return self.value


class Publisher:
    """This robot's publishing decisions (see the module docstring)."""

    def __init__(self, bounds: Boundaries | None = None, *, min_gap: float = 1.0) -> None:
        self.boundaries = bounds or boundaries()
        self.min_gap = min_gap
        self.record: RobotRecord | None = None
        """The last record published."""
        self.sent: RobotRecord | None = None
        """The last values sent, as a record or as vitals."""
        self._record_at = -1e18
        self.urgent = False
        """Whether the last RECORD decided carries a placement others wait for: an instance's
        state or role changed, the plan it holds, its claim of the allocator role
        (`_placement_changed`)."""

    def decide(self, now: float, new: RobotRecord, *, force: bool = False) -> str:
        """RECORD, VITALS or NONE for this sample; the caller publishes what it says."""
        last = self.record
        self.urgent = last is not None and _placement_changed(last, new)
        if force or last is None or _identity_changed(last, new):
            return self._published(now, new)
        sent = self.sent
        assert sent is not None
        if self.boundaries.crossed(last, new) is not None:
            if now - self._record_at >= self.min_gap:
                return self._published(now, new)
            if self.boundaries.crossed(sent, new) is None and not _vitals_moved(sent, new):
                return NONE  # the crossing went out as vitals already
            self.sent = new
            return VITALS
        if self.boundaries.crossed(sent, new) is not None or _vitals_moved(sent, new):
            self.sent = new
            return VITALS
        return NONE

    def _published(self, now: float, new: RobotRecord) -> str:
        self.record = self.sent = new
        self._record_at = now
        return RECORD


class RecordSink(Protocol):
    """Where a robot's record goes: its gossip shell (the agent) or a simulated core's adapter."""

    def set_record(self, payload: bytes, *, urgent: bool = False) -> int:
        """Publish a new record version (spread to every robot; `urgent`: at once, in a gossip
        round of its own); returns the version."""
        ...

    def set_vitals(self, payload: bytes) -> int:
        """A new vitals revision of the current record (on our pings); returns the revision."""
        ...


def publish(
    sink: RecordSink, publisher: Publisher, now: float, record: RobotRecord, *, force: bool = False
) -> tuple[str, int]:
    """One sample through the publisher into the sink: (decision, record version or vitals
    revision, 0 for NONE). The agent and the simulator's agents both publish through this."""
    decision = publisher.decide(now, record, force=force)
    if decision == RECORD:
        return decision, sink.set_record(encode_record(record), urgent=publisher.urgent)
    if decision == VITALS:
        return decision, sink.set_vitals(encode_vitals(vitals_of(record)))
    return decision, 0


def _identity_changed(a: RobotRecord, b: RobotRecord) -> bool:
    if (a.api, a.priority, a.metrics.mem_total) != (b.api, b.priority, b.metrics.mem_total):
        return True
    if (a.metrics.pos is None) != (b.metrics.pos is None):
        return True
    if (a.election, a.plan, a.links.bounds, a.launch) != (
        b.election,
        b.plan,
        b.links.bounds,
        b.launch,
    ):
        return True
    return [(i.name, i.component, i.state, i.role, i.data, i.out_refused) for i in a.instances] != [
        (i.name, i.component, i.state, i.role, i.data, i.out_refused) for i in b.instances
    ]


def _placement_changed(a: RobotRecord, b: RobotRecord) -> bool:
    """Whether `b` says something about placements that `a` did not: an instance added,
    removed, or changed in state or role, another plan held, or a claim of the allocator role
    made or dropped (what a robot taking over a component, or the fleet, waits for)."""
    if a.plan != b.plan:
        return True
    if (a.election is not None and a.election.claiming) != (
        b.election is not None and b.election.claiming
    ):  # a claim of the allocator role (one robot's record, not every follower's belief)
        return True
    return [(i.name, i.state, i.role) for i in a.instances] != [
        (i.name, i.state, i.role) for i in b.instances
    ]


def _vitals_moved(a: RobotRecord, b: RobotRecord) -> bool:
    """Whether the measured values of `b` moved past a deadband from those of `a` (same
    identity and instances)."""
    ma, mb = a.metrics, b.metrics
    band = max(16 << 20, mb.mem_total // 100)
    if abs(ma.cpu_pct - mb.cpu_pct) >= 5.0 or abs(ma.mem_free - mb.mem_free) >= band:
        return True
    if _moved(ma.battery_pct, mb.battery_pct, 1.0) or _moved(ma.rssi_dbm, mb.rssi_dbm, 2.0):
        return True
    if ma.pos != mb.pos and (
        ma.pos is None
        or mb.pos is None
        or max(abs(p - q) for p, q in zip(ma.pos, mb.pos, strict=True)) >= 0.1
    ):
        return True
    if _links_moved(a.links, b.links):
        return True
    return any(
        abs(x.cpu_pct - y.cpu_pct) >= 5.0 or abs(x.rss - y.rss) >= band
        for x, y in zip(a.instances, b.instances, strict=True)
    )


def _links_moved(a: LinkSummary, b: LinkSummary) -> bool:
    if (a.typical is None) != (b.typical is None) or a.listed.keys() != b.listed.keys():
        return True
    if a.typical is not None and b.typical is not None and _link_moved(a.typical, b.typical):
        return True
    return any(_link_moved(a.listed[p], b.listed[p]) for p in b.listed)


def _link_moved(old: LinkStats, new: LinkStats) -> bool:
    return (
        abs(new.rtt_ms - old.rtt_ms) >= max(1.0, 0.25 * old.rtt_ms)
        or abs(new.loss - old.loss) >= 0.05
        or abs(new.jitter_ms - old.jitter_ms) >= max(1.0, 0.5 * old.jitter_ms)
    )


def _moved(old: float | None, new: float | None, band: float) -> bool:
    if old is None or new is None:
        return old is not new
    return abs(new - old) >= band
