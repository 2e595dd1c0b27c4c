"""The system a user deploys, as validated, frozen dataclasses (the loader's output).

How it works: `sdrpeer.system.loader` turns a YAML system file into a `SystemDef`; the
allocator reads only these types, never YAML. Every quantity is in base units: bytes,
bytes per second, percent (0-100), dBm, seconds, milliseconds for jitter and delay, metres.
A threshold left out of the file is `None` and its constraint is not checked.
Everything is hashable so plans and systems can be compared and digested cheaply.
"""

from __future__ import annotations

import hashlib
import json
from collections.abc import Callable
from dataclasses import asdict, dataclass, field
from typing import Any

STANDBY_MODES = ("hot", "cold")
"""hot: started and initialised (INACTIVE, ready); cold: launched only when needed."""


@dataclass(frozen=True, slots=True)
class Requirements:
    """What one instance of a component needs (measured in advance, or written inline)."""

    cpu_pct: float = 0.0
    """Mean CPU of one instance, percent of one core."""
    mem_bytes: int = 0
    """Peak memory (RSS, including any reserve) of one instance."""
    out_bytes_per_s: tuple[tuple[str, float], ...] = ()
    """Measured traffic leaving each OutPort, as sorted (port, bytes/s) pairs."""
    profile: str | None = None
    """The profile file these figures came from, if any (for messages)."""

    def port_rate(self, port: str) -> float | None:
        """Measured bytes/s of an OutPort, or None when not measured."""
        for name, rate in self.out_bytes_per_s:
            if name == port:
                return rate
        return None


@dataclass(frozen=True, slots=True)
class StandbySpec:
    """How many standbys a component keeps, and where."""

    same_robot: int = 0
    """Standbys on the robot of the active instance (for restarts that do not need a move)."""
    other_robots: int = 0
    """Standbys on other robots, each on a different robot."""
    mode: str = "hot"
    """hot or cold (see STANDBY_MODES)."""
    sync_s: float = 0.0
    """Seconds between state snapshots of the active instance handed to its hot standbys (its
    `on_snapshot` -> their `on_restore`); 0: none (a planned move still carries the last state)."""


QUORUMS = ("majority", "any")

RECONCILE = ("keep_replacement", "keep_original")
"""Which copy survives a heal: the fleet's replacement (its plan is the newer), or the robot that
ran the component before it was cut off gets it back by a planned move (state handed over)."""


@dataclass(frozen=True, slots=True)
class DisconnectSpec:
    """What becomes of a component's active copy when its robot is cut off from the fleet
    (in the spirit of Nomad's `disconnect` block; `sdrpeer.deploy.disconnect` carries it out)."""

    stop_after_s: float | None = 0.0
    """How long a robot cut off from the fleet keeps this active copy running (None: for ever)."""
    replace: bool = True
    """Whether the fleet replaces the active copy of a robot it has lost."""
    lost_after_s: float = 0.0
    """How long the fleet waits, once it lost the robot, before it replaces the copy."""
    reconcile: str = "keep_replacement"
    """Which copy survives a heal (see RECONCILE)."""


@dataclass(frozen=True, slots=True)
class Thresholds:
    """Tables I and II of the paper; None means the constraint is not checked."""

    cpu_below_pct: float | None = None
    """Table I: a robot's CPU after adding the component must stay below this."""
    mem_free_above_bytes: int | None = None
    """Table I: a robot's free memory after adding the component must stay above this."""
    battery_above_pct: float | None = None
    """Table I: a robot's battery must be above this."""
    rssi_above_dbm: float | None = None
    """Table II: both ends of a cross-robot connection need RSSI above this."""
    jitter_below_ms: float | None = None
    """Table II: measured jitter between the two robots must be below this."""
    distance_below_m: float | None = None
    """Table II: the two robots must be closer than this."""
    loss_below: float | None = None
    """Beyond the paper: measured packet loss (0..1) between the two robots below this."""
    delay_below_ms: float | None = None
    """Beyond the paper: measured round-trip time between the two robots below this (the
    smoothed RTT of the gossip probes, not half of it: docs/system-file.md, "Constraints")."""

    def stricter(self, other: Thresholds) -> Thresholds:
        """Each threshold of `self` and `other` taken at its stricter value (None: the other's):
        a component's or a connection's own bound narrows the fleet's, never widens it."""
        out: dict[str, Any] = {}
        for name in THRESHOLD_FIELDS:
            a, b = getattr(self, name), getattr(other, name)
            if a is None or b is None:
                out[name] = a if b is None else b
            elif name in ABOVE_FIELDS:
                out[name] = max(a, b)
            else:
                out[name] = min(a, b)
        return Thresholds(**out)

    def has_any(self) -> bool:
        """Whether any threshold is set."""
        return any(getattr(self, name) is not None for name in THRESHOLD_FIELDS)


THRESHOLD_FIELDS = (
    "cpu_below_pct",
    "mem_free_above_bytes",
    "battery_above_pct",
    "rssi_above_dbm",
    "jitter_below_ms",
    "distance_below_m",
    "loss_below",
    "delay_below_ms",
)
"""Every field of `Thresholds`, Table I's first."""
ABOVE_FIELDS = frozenset({"mem_free_above_bytes", "battery_above_pct", "rssi_above_dbm"})
"""The thresholds a value must stay above (the others: below)."""


@dataclass(frozen=True, slots=True)
class ComponentDef:
    """One component of the system: what to run, what it needs, and where it may go."""

    name: str
    """Logical name, unique in the system (e.g. CameraRTC)."""
    launcher: str
    """python (module:Class), script (file.py[:Class]), exec (argv), or a plugin's name."""
    target: str | tuple[str, ...]
    """What the launcher runs (an argv tuple for exec)."""
    params: tuple[tuple[str, Any], ...] = ()
    """Initial parameters as sorted (name, value) pairs."""
    requires: Requirements = field(default_factory=Requirements)
    standby: StandbySpec = field(default_factory=StandbySpec)
    pin: str | None = None
    """Robot this component must run on (its active instance)."""
    prefer: tuple[str, ...] = ()
    """Robots tried first, in this order, when they satisfy the constraints."""
    watchdog_s: float | None = None
    """Seconds its host may go without a heartbeat before it is killed as hung (None: the
    agent's default, 0: no watchdog)."""
    disconnect: DisconnectSpec = field(default_factory=DisconnectSpec)
    thresholds: Thresholds = field(default_factory=Thresholds)
    """Its own Table I thresholds (`constraints:`), on top of the fleet's: the robot of each of
    its instances must meet the stricter of the two (only the Table I fields are set)."""

    def params_map(self) -> dict[str, Any]:
        """The parameters as a dict."""
        return dict(self.params)


@dataclass(frozen=True, slots=True)
class ConnectionDef:
    """A data stream from `from_component.from_port` to `to_component.to_port`."""

    from_component: str
    from_port: str
    to_component: str
    to_port: str
    policy: tuple[tuple[str, Any], ...] = ()
    """Connector policy (push, buffer, full, ...; docs/protocol.md) as sorted pairs."""
    traffic_bytes_per_s: float | None = None
    """Expected traffic: written in the file, else the sender's profile for that port, else None."""
    bounds: Thresholds = field(default_factory=Thresholds)
    """Its own Table II bounds (`constraints:`), on top of the fleet's: when its two ends run on
    different robots, the link between them must meet the stricter of the two (only the Table II
    fields are set)."""

    @property
    def id(self) -> str:
        """The connection id used on the data plane (`Cam.image->View.image`)."""
        return f"{self.from_component}.{self.from_port}->{self.to_component}.{self.to_port}"


@dataclass(frozen=True, slots=True)
class AllocationDef:
    """How the allocator places components."""

    strategy: str = "first_fit"
    """first_fit, objective, or a plugin's name (entry point group sdrpeer.strategies)."""
    thresholds: Thresholds = field(default_factory=Thresholds)
    weights: tuple[tuple[str, float], ...] = ()
    """Objective weights as sorted (term, weight) pairs: mem_free, battery, rssi, distance,
    traffic_local, load (and any term a plugin adds)."""
    constraints: tuple[str, ...] = ()
    """Extra constraint plugins by name (entry point group sdrpeer.constraints)."""
    preempt: bool = False
    """Whether a returning higher-priority robot takes the allocator role from a healthy one."""
    quorum: str = "majority"
    """majority: only robots that hear a majority of the fleet act as it (`deploy.disconnect`);
    any: every robot does, also alone (a fleet of two that must survive either robot's death;
    a partition then runs a copy on each side until the heal). See QUORUMS."""


@dataclass(frozen=True, slots=True)
class RecoveryRule:
    """One Table III row: a cause, when it holds, when it clears, and what to do."""

    cause: str
    """memory_shortage, cpu_high, component_error, hardware_failure, abnormal_behaviour,
    emergency_stop, low_battery, communication_failure, or a plugin's name."""
    metric: str | None = None
    """What is compared (mem_free, cpu, battery, rssi, delay, jitter, loss); None for events."""
    op: str | None = None
    """'<=' '<' '>=' '>' between the metric and `threshold`."""
    threshold: float | None = None
    """In base units (bytes, percent, dBm, ms, fraction)."""
    sustain_s: float = 0.0
    """How long the condition must hold before the rule fires."""
    clear: float | None = None
    """The threshold at which the condition clears (hysteresis); None: same as `threshold`."""
    actions: tuple[str, ...] = ()
    """The escalation ladder, in order (e.g. standby_same_robot, restart, standby_other_robot,
    launch_other_robot)."""


@dataclass(frozen=True, slots=True)
class RecoveryDef:
    """The `recovery:` section (used by the recovery engine)."""

    rules: tuple[RecoveryRule, ...] = ()
    max_attempts: int = 3
    """Local attempts (restart, same-robot standby) within `window_s` before escalating."""
    window_s: float = 60.0
    min_dwell_s: float = 30.0
    """A moved component stays at least this long before it may move back."""


ON_VIOLATION = ("report", "replace")
"""What the allocator does when a placement stops meeting its constraints: report it (event,
status, dashboard), or also move the component (`sdrpeer.recovery.compliance`)."""


@dataclass(frozen=True, slots=True)
class ComplianceDef:
    """The `compliance:` section: placements re-checked against fresh metrics while they run."""

    on_violation: str = "report"
    """report or replace (see ON_VIOLATION)."""
    sustain_s: float = 5.0
    """How long a constraint must be violated without a break before it counts (`for:`)."""
    clear: float = 0.1
    """Hysteresis: a violation clears only once the value is this share of the bound inside
    it (delay bound 20ms, clear 10%: below 18ms; rssi above -60dBm: above -54dBm); at most 20%:
    a record lists a link's exact values down to 80% of its bound (`monitor.links.STAY_LISTED`)."""
    min_interval_s: float = 60.0
    """At most one compliance move of a component per this many seconds (`min_interval:`)."""


@dataclass(frozen=True, slots=True)
class StreamsDef:
    """The system's data streams as a whole (the `streams:` section)."""

    encrypt: bool = True
    """Port streams between robots are encrypted (a connection's policy may still say
    `encrypt: false`, or `true` where this is false): docs/security.md gives the cost."""


@dataclass(frozen=True, slots=True)
class SystemDef:
    """A whole system file."""

    name: str
    components: tuple[ComponentDef, ...]
    connections: tuple[ConnectionDef, ...] = ()
    allocation: AllocationDef = field(default_factory=AllocationDef)
    recovery: RecoveryDef = field(default_factory=RecoveryDef)
    streams: StreamsDef = field(default_factory=StreamsDef)
    compliance: ComplianceDef = field(default_factory=ComplianceDef)
    source: str | None = field(default=None, compare=False)
    """The file it was read from (messages only; not part of equality or the digest)."""

    def component(self, name: str) -> ComponentDef:
        """The component called `name` (KeyError if unknown)."""
        for c in self.components:
            if c.name == name:
                return c
        raise KeyError(name)

    def tightest_thresholds(self) -> Thresholds:
        """The fleet's thresholds narrowed by every component's and every connection's own:
        where a robot starts to matter to some placement (what records list and publish at)."""
        t = self.allocation.thresholds
        for c in self.components:
            t = t.stricter(c.thresholds)
        for conn in self.connections:
            t = t.stricter(conn.bounds)
        return t

    def to_json(self) -> dict[str, Any]:
        """A JSON-able form (tuples become lists); `system_from_json` is its inverse."""
        doc = asdict(self)
        doc.pop("source", None)
        return doc

    def digest(self) -> str:
        """A short stable hash of the system's content (sha256 of its canonical JSON); computed
        once per object (`status` and the dashboard ask for it several times a second, and
        `asdict` of a 20-component system took a tenth of a busy agent's samples)."""
        return _DIGESTS.get(self, lambda: json_digest(self.to_json()))


def json_digest(doc: Any) -> str:
    """A short stable hash of a JSON-able document (sha256 of its canonical JSON)."""
    text = json.dumps(doc, sort_keys=True, separators=(",", ":"), default=str)
    return hashlib.sha256(text.encode()).hexdigest()[:16]


class DigestMemo:
    """Digests computed once per object, for the last `kept` objects asked about (each object
    is kept while it is here, so its id cannot be reused meanwhile)."""

    def __init__(self, kept: int = 8) -> None:
        self.kept = kept
        self._known: dict[int, tuple[object, str]] = {}

    def get(self, obj: object, compute: Callable[[], str]) -> str:
        """`obj`'s digest: remembered, or `compute()`d now."""
        known = self._known.get(id(obj))
        if known is not None and known[0] is obj:
            return known[1]
        digest = compute()
        if len(self._known) >= self.kept:
            del self._known[next(iter(self._known))]
        self._known[id(obj)] = (obj, digest)
        return digest


_DIGESTS = DigestMemo()


def _pairs(x: Any) -> tuple[tuple[str, Any], ...]:
    """JSON [[k, v], ...] back into sorted tuple pairs (values that are lists become tuples)."""
    return tuple(sorted((str(k), _freeze(v)) for k, v in x))


def _freeze(v: Any) -> Any:
    """Lists to tuples, recursively, so parameter values stay hashable."""
    if isinstance(v, list):
        return tuple(_freeze(i) for i in v)
    return v


def system_from_json(doc: dict[str, Any]) -> SystemDef:
    """Rebuild a SystemDef from `SystemDef.to_json()` output (trusted input: our own peers).

    Raises KeyError/TypeError/ValueError on a malformed document; callers that take it from the
    network wrap those into their own error.
    """
    comps = []
    for c in doc["components"]:
        req = c["requires"]
        comps.append(
            ComponentDef(
                name=c["name"],
                launcher=c["launcher"],
                target=c["target"] if isinstance(c["target"], str) else tuple(c["target"]),
                params=_pairs(c["params"]),
                requires=Requirements(
                    cpu_pct=float(req["cpu_pct"]),
                    mem_bytes=int(req["mem_bytes"]),
                    out_bytes_per_s=tuple((str(p), float(r)) for p, r in req["out_bytes_per_s"]),
                    profile=req.get("profile"),
                ),
                standby=StandbySpec(**c["standby"]),
                pin=c.get("pin"),
                prefer=tuple(c.get("prefer", ())),
                watchdog_s=c.get("watchdog_s"),
                disconnect=DisconnectSpec(**c.get("disconnect", {})),
                thresholds=Thresholds(**c.get("thresholds", {})),
            )
        )
    conns = tuple(
        ConnectionDef(
            from_component=c["from_component"],
            from_port=c["from_port"],
            to_component=c["to_component"],
            to_port=c["to_port"],
            policy=_pairs(c["policy"]),
            traffic_bytes_per_s=c.get("traffic_bytes_per_s"),
            bounds=Thresholds(**c.get("bounds", {})),
        )
        for c in doc["connections"]
    )
    a = doc["allocation"]
    allocation = AllocationDef(
        strategy=a["strategy"],
        thresholds=Thresholds(**a["thresholds"]),
        weights=tuple((str(k), float(v)) for k, v in a["weights"]),
        constraints=tuple(a["constraints"]),
        preempt=bool(a["preempt"]),
        quorum=str(a.get("quorum", "majority")),
    )
    r = doc["recovery"]
    recovery = RecoveryDef(
        rules=tuple(RecoveryRule(**{**x, "actions": tuple(x["actions"])}) for x in r["rules"]),
        max_attempts=int(r["max_attempts"]),
        window_s=float(r["window_s"]),
        min_dwell_s=float(r["min_dwell_s"]),
    )
    return SystemDef(
        name=doc["name"],
        components=tuple(comps),
        connections=conns,
        allocation=allocation,
        recovery=recovery,
        streams=StreamsDef(encrypt=bool(doc.get("streams", {}).get("encrypt", True))),
        compliance=ComplianceDef(**doc.get("compliance", {})),
    )
