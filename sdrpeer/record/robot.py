"""A robot's gossip record and its vitals: what the fleet needs to know of one robot.

How it works: the owning robot builds a `RobotRecord`, `encode_record` turns it into compact
msgpack, and gossip spreads those bytes epidemically without looking inside, as one versioned
record per robot. Every receiver calls `decode_record`, which checks each field and raises
`RecordError("malformed", ...)` on anything unexpected (never another exception), so a bad peer
cannot crash an agent.

What a record carries is bounded by what the fleet decides with, not by the fleet's size: the
robot's metrics; a *summary* of the links it measures (how many peers, the typical round-trip
time, jitter and loss — the values a strict majority of its links reach or pass, the same rule
the recovery judge applies — and, exactly, the few links past the bounds the deployed system
cares about: `LinkSummary`); its API address and election priority; the instances it hosts;
its election belief, the plan it holds, and what it lets hosts run (its launch policy, nil for the
default). A record is O(1) in the number of robots.

The *vitals* of a robot (its metrics, link summary and the measured load of each instance) also
travel as a revision of the current record: `encode_vitals` bytes that the gossip core carries
directly to each peer on its probes (not epidemically), ordered by (record version, revision).
`apply_vitals` lays the newest vitals over the record they revise. See
`sdrpeer.monitor.publish` for which changes make a new record and which only a new revision.

Wire layout (msgpack arrays, not maps; fixed-point integers, not floats):

    record    = [FORMAT, metrics, links, api, priority, components, instances, election, plan,
                 launch]
    vitals    = [FORMAT, [cpu, mem_free, battery, rssi, pos], [peers, rtt, jitter, loss, bad,
                 listed], loads]   (metrics and links without what only a record changes:
                 the capacity and the link bounds)
    metrics   = [cpu_dpct, mem_total_kib, mem_free_kib, battery_dpct|nil, rssi_ddbm|nil,
                 [x_cm, y_cm]|nil]
    links     = [peers, rtt_10us|nil, jitter_10us|nil, loss_permille|nil, bad,
                 [rtt_bound, jitter_bound, loss_bound] (each |nil),
                 [peer, rtt_10us, jitter_10us, loss_permille, ...]]   (at most MAX_LISTED)
    components= [component name, ...]                 (each distinct component once)
    instances = [[component_index, shared_prefix_len, name_rest, state, role, cpu_dpct,
                  rss_kib, data_addr|nil, out_bytes_per_s, out_lost_per_s, out_refused], ...]
    loads     = [cpu_dpct, rss_kib, out_bytes_per_s, out_lost_per_s, ...]   (4 per instance,
                 in record order)
    election  = [epoch, leader|nil, claiming] | nil   (who this robot believes is the allocator)
    plan      = [epoch, version, digest, allocator] | nil   (the newest plan this robot holds)
    launch    = [[launcher, ...], [python target pattern, ...]] | nil   (nil: python, any target)

`dpct` is 0.1 %, `ddbm` 0.1 dB, `10us` 0.01 ms, `permille` 0.1 % loss. An instance name usually
starts with its component's name (`CameraRTC2` of `CameraRTC`), so only the differing tail is
sent. Well-known states and roles are sent as a small index, any other as its string.
Decoding returns the rounded values: `decode_record(encode_record(r))` equals `r` only once `r`
is already on that grid. Format 5 (this one) added each instance's `out_refused` (how many of
its outgoing connections their receivers refuse now) to format 4, which had added each
instance's `out_lost_per_s` (frames its outgoing connections lose to full buffers) to format
3, which had added `launch` to format 2, which had replaced format 1 (whose record listed every
link and a timestamp); a record of another format is refused, so a fleet is upgraded all at
once.
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from typing import Any

import msgpack

from sdrpeer.errors import RecordError
from sdrpeer.launch.policy import DEFAULT_POLICY, LaunchPolicy
from sdrpeer.record.limits import LIMITS, MAX_COORD_M
from sdrpeer.vocabulary import InstanceRole, InstanceState, LifecycleState, ProcessState

FORMAT = 5
"""Version of the wire layout above; a decoder refuses any other."""

STATES: tuple[InstanceState, ...] = (
    LifecycleState.CREATED,
    LifecycleState.INACTIVE,
    LifecycleState.ACTIVE,
    LifecycleState.ERROR,
    LifecycleState.FINALIZED,
    ProcessState.STARTING,
    ProcessState.STOPPING,
)
"""Instance states sent as an index (in this order); others go as their wire spelling."""
ROLES: tuple[InstanceRole, ...] = (InstanceRole.ACTIVE, InstanceRole.STANDBY)
"""Instance roles sent as an index; others go as strings."""
_STATE_WIRE: dict[str, str] = {s: s.value.lower() for s in (*LifecycleState, *ProcessState)}
"""Instance state -> how records and their JSON spell it (lower case)."""
_STATE_OF_WIRE: dict[str, str] = {text: s for s, text in _STATE_WIRE.items()}
_STATES_WIRE = tuple(_STATE_WIRE[s] for s in STATES)
_ROLE_OF_WIRE: dict[str, str] = {r.value: r for r in InstanceRole}
MAX_LISTED = 8
"""Links past the bounds a summary lists exactly (the worst first); the rest are only counted."""

_MAX_NAME = 255
_MAX_ITEMS = 1024


@dataclass(frozen=True, slots=True)
class Metrics:
    """What a robot reports about itself (sizes in bytes, position in metres)."""

    cpu_pct: float
    mem_total: int
    mem_free: int
    battery_pct: float | None
    rssi_dbm: float | None
    pos: tuple[float, float] | None


@dataclass(frozen=True, slots=True)
class LinkStats:
    """Quality of the link from the measuring robot to one peer (loss is a fraction 0..1)."""

    rtt_ms: float
    jitter_ms: float
    loss: float


@dataclass(frozen=True, slots=True)
class LinkBounds:
    """Where a link starts to matter to the deployed system: a link with a value at or past
    any bound is listed in a `LinkSummary`; None means no bound on that metric."""

    rtt_ms: float | None = None
    jitter_ms: float | None = None
    loss: float | None = None

    def past(self, s: LinkStats, scale: float = 1.0) -> bool:
        """Whether `s` is at or past any bound (each bound times `scale`)."""
        return (
            (self.rtt_ms is not None and s.rtt_ms >= self.rtt_ms * scale)
            or (self.jitter_ms is not None and s.jitter_ms >= self.jitter_ms * scale)
            or (self.loss is not None and s.loss >= self.loss * scale)
        )

    def badness(self, s: LinkStats) -> float:
        """How far past its bounds `s` is (the largest value / bound ratio); orders the list."""
        ratios = [
            value / bound
            for value, bound in (
                (s.rtt_ms, self.rtt_ms),
                (s.jitter_ms, self.jitter_ms),
                (s.loss, self.loss),
            )
            if bound is not None and bound > 0
        ]
        return max(ratios, default=0.0)


@dataclass(frozen=True, slots=True)
class LinkSummary:
    """How a robot's links look, in O(1): the typical link and the few that matter.

    `typical` holds, metric by metric, the value a strict majority of the `peers` measured
    links reach or pass (the (n//2 + 1)-th worst): one bad peer cannot move it, a bad radio
    moves it at once. `bad` links are at or past `bounds`; the worst `MAX_LISTED` of them are in
    `listed` with their exact values.
    """

    peers: int = 0
    typical: LinkStats | None = None
    bad: int = 0
    bounds: LinkBounds = field(default_factory=LinkBounds)
    listed: dict[str, LinkStats] = field(default_factory=dict)

    @property
    def complete(self) -> bool:
        """Whether every link past the bounds is listed (an unlisted one is then inside)."""
        return self.bad <= len(self.listed)

    def towards(self, peer: str) -> LinkStats | None:
        """The best estimate of the link to `peer`: exact when listed; else the typical link,
        kept just inside each bound when the list is complete (it is known to be inside)."""
        exact = self.listed.get(peer)
        if exact is not None:
            return exact
        t = self.typical
        if t is None:
            return None
        if not self.complete:
            return t
        b = self.bounds
        return LinkStats(
            rtt_ms=_inside(t.rtt_ms, b.rtt_ms, 0.01),
            jitter_ms=_inside(t.jitter_ms, b.jitter_ms, 0.01),
            loss=_inside(t.loss, b.loss, 0.001),
        )


def _inside(value: float, bound: float | None, quantum: float) -> float:
    """`value`, or the largest value on the wire's grid below `bound` when it is not below."""
    if bound is None or value < bound:
        return value
    return max(0.0, round(bound - quantum, 6))


@dataclass(frozen=True, slots=True)
class InstanceInfo:
    """One component instance hosted by the robot, with its measured cpu % and RSS bytes."""

    name: str
    component: str
    state: str
    """An InstanceState, or a name this version does not know (from a peer's record)."""
    role: str
    """An InstanceRole, or a name this version does not know."""
    cpu_pct: float
    rss: int
    data: str | None = None
    """Where other robots' senders reach its InPorts (tcp://host:port), while it runs."""
    out_bps: int = 0
    """Bytes per second its OutPorts sent, over the last metrics interval."""
    out_lost: int = 0
    """Frames per second its outgoing connections lost to a full buffer at either end (a
    sender's queue or the receiving InPort; rounded up), over the last metrics interval."""
    out_refused: int = 0
    """How many of its outgoing connections (and service bindings) their receivers refuse now
    (its host's `refused` reports): they carry nothing."""


@dataclass(frozen=True, slots=True)
class ElectionInfo:
    """What a robot believes about the allocator role."""

    epoch: int
    leader: str | None
    claiming: bool
    """True when this robot claims the role itself."""


@dataclass(frozen=True, slots=True)
class PlanInfo:
    """Which plan a robot holds: others fetch it from the robot's API when theirs is older."""

    epoch: int
    version: int
    digest: str
    allocator: str = ""

    @property
    def key(self) -> tuple[int, str, int]:
        """The plan's order key (see `sdrpeer.plan.Plan.key`)."""
        return (self.epoch, self.allocator, self.version)


@dataclass(frozen=True, slots=True)
class RobotRecord:
    """Everything a robot gossips about itself."""

    metrics: Metrics
    links: LinkSummary
    api: str | None
    priority: int
    instances: tuple[InstanceInfo, ...]
    election: ElectionInfo | None = None
    plan: PlanInfo | None = None
    launch: LaunchPolicy = DEFAULT_POLICY
    """What this robot lets its hosts run (`sdrpeer.launch.policy`)."""


@dataclass(frozen=True, slots=True)
class Vitals:
    """A revision of a record's measured values: metrics, link summary, and each instance's
    (cpu %, RSS bytes, out bytes/s) in the record's instance order. The memory capacity and
    the link bounds change only with a new record, so vitals do not carry them: decoded vitals
    hold 0 and empty bounds there, and `apply_vitals` keeps the record's."""

    metrics: Metrics
    links: LinkSummary
    loads: tuple[tuple[float, int, int, int], ...] = ()


def vitals_of(r: RobotRecord) -> Vitals:
    """The measured values of a record."""
    return Vitals(
        r.metrics, r.links, tuple((i.cpu_pct, i.rss, i.out_bps, i.out_lost) for i in r.instances)
    )


def apply_vitals(r: RobotRecord, v: Vitals, *, same_version: bool = True) -> RobotRecord:
    """`r` with newer vitals laid over it. Instance loads apply only to the record version the
    vitals revise (`same_version`), where the instances are the same and in the same order."""
    instances = r.instances
    metrics = replace(v.metrics, mem_total=r.metrics.mem_total)
    links = replace(v.links, bounds=r.links.bounds)
    if same_version and len(v.loads) == len(instances):
        instances = tuple(
            replace(i, cpu_pct=cpu, rss=rss, out_bps=out, out_lost=lost)
            for i, (cpu, rss, out, lost) in zip(instances, v.loads, strict=True)
        )
    return replace(r, metrics=metrics, links=links, instances=instances)


def _fix(x: float, scale: float) -> int:
    """A float on a fixed-point grid (0.1 % -> scale 10)."""
    return round(x * scale)


def _kib(n: int) -> int:
    """Bytes rounded to whole KiB."""
    return (n + 512) // 1024


def state_to_wire(state: str) -> str:
    """An instance state as records, their JSON and the event log spell it (lower case);
    a name this version does not know, as it is."""
    return _STATE_WIRE.get(state, state)


def state_from_wire(text: str) -> str:
    """The InstanceState a record's spelling names; a name this version does not know, as it
    is."""
    return _STATE_OF_WIRE.get(text, text)


def _code(value: str, table: tuple[str, ...]) -> int | str:
    """Index of a well-known string, or the string itself."""
    return table.index(value) if value in table else value


def _common_prefix(a: str, b: str) -> int:
    """Length of the common prefix of two strings."""
    n = 0
    for x, y in zip(a, b, strict=False):
        if x != y:
            break
        n += 1
    return n


def _clamped(name: str, x: float, scale: float) -> int:
    """`x` inside `sdrpeer.record.limits.LIMITS[name]`, on its grid: whatever a robot file, the API
    or a measurement said, the record encodes (and decodes on every peer)."""
    return _fix(LIMITS[name].clamp(x), scale)


def _wire_metrics(m: Metrics) -> list[Any]:
    return [
        _clamped("cpu_pct", m.cpu_pct, 10),
        min(_kib(max(0, m.mem_total)), _MAX_KIB),
        min(_kib(max(0, m.mem_free)), _MAX_KIB),
        None if m.battery_pct is None else _clamped("battery", m.battery_pct, 10),
        None if m.rssi_dbm is None else _clamped("rssi", m.rssi_dbm, 10),
        None
        if m.pos is None
        else [_clamped("coord", m.pos[0], 100), _clamped("coord", m.pos[1], 100)],
    ]


def _opt(x: float | None, scale: float) -> int | None:
    return None if x is None else _fix(x, scale)


def _wire_links(s: LinkSummary) -> list[Any]:
    t = s.typical
    listed: list[Any] = []
    for peer, link in s.listed.items():
        listed += [peer, _fix(link.rtt_ms, 100), _fix(link.jitter_ms, 100), _fix(link.loss, 1000)]
    b = s.bounds
    return [
        s.peers,
        None if t is None else _fix(t.rtt_ms, 100),
        None if t is None else _fix(t.jitter_ms, 100),
        None if t is None else _fix(t.loss, 1000),
        s.bad,
        [_opt(b.rtt_ms, 100), _opt(b.jitter_ms, 100), _opt(b.loss, 1000)],
        listed,
    ]


def encode_record(r: RobotRecord) -> bytes:
    """The record as compact msgpack bytes (see the module docstring for the layout)."""
    components: list[str] = []
    instances = []
    for inst in r.instances:
        if inst.component not in components:
            components.append(inst.component)
        shared = _common_prefix(inst.component, inst.name)
        instances.append(
            [
                components.index(inst.component),
                shared,
                inst.name[shared:],
                _code(state_to_wire(inst.state), _STATES_WIRE),
                _code(inst.role, ROLES),
                _fix(inst.cpu_pct, 10),
                _kib(inst.rss),
                inst.data,
                max(0, int(inst.out_bps)),
                max(0, int(inst.out_lost)),
                max(0, int(inst.out_refused)),
            ]
        )
    e, p = r.election, r.plan
    wire = [
        FORMAT,
        _wire_metrics(r.metrics),
        _wire_links(r.links),
        r.api,
        round(LIMITS["priority"].clamp(r.priority)),
        components,
        instances,
        None if e is None else [e.epoch, e.leader, e.claiming],
        None if p is None else [p.epoch, p.version, p.digest, p.allocator],
        None if r.launch.is_default else [list(r.launch.launchers), list(r.launch.targets)],
    ]
    data: bytes = msgpack.packb(wire, use_bin_type=True)
    return data


def encode_vitals(v: Vitals) -> bytes:
    """Vitals as compact msgpack bytes (see the module docstring for the layout)."""
    loads: list[int] = []
    for cpu, rss, out, lost in v.loads:
        loads += [_fix(cpu, 10), _kib(rss), max(0, int(out)), max(0, int(lost))]
    metrics = _wire_metrics(v.metrics)
    del metrics[1]  # the capacity: a record's
    links = _wire_links(v.links)
    del links[5]  # the bounds: a record's
    data: bytes = msgpack.packb([FORMAT, metrics, links, loads], use_bin_type=True)
    return data


class _Malformed(Exception):
    """Internal: a field failed validation (turned into RecordError by the decoders)."""


def _list(x: object, what: str, n: int | None = None) -> list[Any]:
    """x must be a list (of exactly n items when n is given)."""
    if not isinstance(x, list) or (n is not None and len(x) != n) or len(x) > _MAX_ITEMS:
        raise _Malformed(f"{what}: expected a list" + (f" of {n}" if n is not None else ""))
    return x


def _int(x: object, what: str, lo: int | None = 0, hi: int | None = None) -> int:
    """x must be an int within [lo, hi]."""
    if isinstance(x, bool) or not isinstance(x, int):
        raise _Malformed(f"{what}: expected an integer")
    if (lo is not None and x < lo) or (hi is not None and x > hi):
        raise _Malformed(f"{what}: {x} out of range")
    return x


def _str(x: object, what: str, *, empty: bool = False) -> str:
    """x must be a (non-empty unless allowed) string of reasonable length."""
    if not isinstance(x, str) or len(x) > _MAX_NAME or (not empty and not x):
        raise _Malformed(f"{what}: expected a name")
    return x


def _named(x: object, table: tuple[str, ...], what: str) -> str:
    """A well-known index or a free string."""
    if isinstance(x, int) and not isinstance(x, bool):
        return table[_int(x, what, 0, len(table) - 1)]
    return _str(x, what)


_MAX_COORD = round(MAX_COORD_M * 100)
"""Largest position coordinate on the wire, in cm (10,000 km)."""
_RSSI_DDBM = (round(LIMITS["rssi"].low * 10), round(LIMITS["rssi"].high * 10))
"""RSSI range on the wire, in 0.1 dBm (what the encoder clamps to)."""
_MAX_KIB = 1 << 50
"""Largest memory figure on the wire, in KiB."""
_MAX_MS = 10**9
"""Largest RTT or jitter on the wire, in 0.01 ms (about 115 days)."""


def _metrics(x: object) -> Metrics:
    """Validate and scale the metrics array."""
    cpu, total, free, battery, rssi, pos = _list(x, "metrics", 6)
    xy = None
    if pos is not None:
        px, py = _list(pos, "metrics.pos", 2)
        xy = (
            _int(px, "pos.x", -_MAX_COORD, _MAX_COORD) / 100,
            _int(py, "pos.y", -_MAX_COORD, _MAX_COORD) / 100,
        )
    return Metrics(
        cpu_pct=_int(cpu, "cpu_pct", 0, 100_000) / 10,
        mem_total=_int(total, "mem_total", 0, _MAX_KIB) * 1024,
        mem_free=_int(free, "mem_free", 0, _MAX_KIB) * 1024,
        battery_pct=None if battery is None else _int(battery, "battery_pct", 0, 1000) / 10,
        rssi_dbm=None if rssi is None else _int(rssi, "rssi_dbm", *_RSSI_DDBM) / 10,
        pos=xy,
    )


def _stats(rtt: object, jitter: object, loss: object, what: str) -> LinkStats:
    return LinkStats(
        rtt_ms=_int(rtt, f"{what}.rtt_ms", 0, _MAX_MS) / 100,
        jitter_ms=_int(jitter, f"{what}.jitter_ms", 0, _MAX_MS) / 100,
        loss=_int(loss, f"{what}.loss", 0, 1000) / 1000,
    )


def _links(x: object) -> LinkSummary:
    """Validate the link summary."""
    peers, rtt, jitter, loss, bad, bounds, flat = _list(x, "links", 7)
    n = _int(peers, "links.peers", 0, 1 << 20)
    typical = None
    if rtt is not None or jitter is not None or loss is not None or n:
        typical = _stats(rtt, jitter, loss, "links.typical")
    b_rtt, b_jitter, b_loss = _list(bounds, "links.bounds", 3)
    summary_bounds = LinkBounds(
        rtt_ms=None if b_rtt is None else _int(b_rtt, "links.bounds", 0, _MAX_MS) / 100,
        jitter_ms=None if b_jitter is None else _int(b_jitter, "links.bounds", 0, _MAX_MS) / 100,
        loss=None if b_loss is None else _int(b_loss, "links.bounds", 0, 1000) / 1000,
    )
    flat = _list(flat, "links.listed")
    if len(flat) % 4 or len(flat) > 4 * MAX_LISTED:
        raise _Malformed(f"links.listed: expected at most {MAX_LISTED} groups of 4")
    listed: dict[str, LinkStats] = {}
    for i in range(0, len(flat), 4):
        peer = _str(flat[i], "links.peer")
        if peer in listed:
            raise _Malformed(f"links: peer {peer!r} twice")
        listed[peer] = _stats(flat[i + 1], flat[i + 2], flat[i + 3], "links.listed")
    return LinkSummary(
        peers=n,
        typical=typical,
        bad=_int(bad, "links.bad", len(listed), 1 << 20),
        bounds=summary_bounds,
        listed=listed,
    )


def _instances(comps: object, x: object) -> tuple[InstanceInfo, ...]:
    """Validate the component table and the instance arrays."""
    components = [_str(c, "component") for c in _list(comps, "components")]
    out = []
    for item in _list(x, "instances"):
        ci, shared, rest, state, role, cpu, rss, data, out_bps, lost, refused = _list(
            item, "instance", 11
        )
        component = components[_int(ci, "instance.component", 0, len(components) - 1)]
        prefix = component[: _int(shared, "instance.prefix", 0, len(component))]
        out.append(
            InstanceInfo(
                name=_str(prefix + _str(rest, "instance.name", empty=True), "instance.name"),
                component=component,
                state=state_from_wire(_named(state, _STATES_WIRE, "instance.state")),
                role=_ROLE_OF_WIRE.get(r := _named(role, ROLES, "instance.role"), r),
                cpu_pct=_int(cpu, "instance.cpu_pct", 0, 1_000_000) / 10,
                rss=_int(rss, "instance.rss", 0, 1 << 50) * 1024,
                data=None if data is None else _str(data, "instance.data"),
                out_bps=_int(out_bps, "instance.out_bps", 0, 1 << 40),
                out_lost=_int(lost, "instance.out_lost", 0, 1 << 40),
                out_refused=_int(refused, "instance.out_refused", 0, 1 << 20),
            )
        )
    return tuple(out)


def _election(x: object) -> ElectionInfo | None:
    if x is None:
        return None
    epoch, leader, claiming = _list(x, "election", 3)
    if not isinstance(claiming, bool):
        raise _Malformed("election.claiming: expected a boolean")
    return ElectionInfo(
        epoch=_int(epoch, "election.epoch", 0, 2**62),
        leader=None if leader is None else _str(leader, "election.leader"),
        claiming=claiming,
    )


def _plan(x: object) -> PlanInfo | None:
    if x is None:
        return None
    epoch, version, digest, allocator = _list(x, "plan", 4)
    return PlanInfo(
        epoch=_int(epoch, "plan.epoch", 0, 2**62),
        version=_int(version, "plan.version", 0, 2**62),
        digest=_str(digest, "plan.digest", empty=True),
        allocator=_str(allocator, "plan.allocator", empty=True),
    )


def _unpack(b: bytes, what: str) -> list[Any]:
    try:
        wire = msgpack.unpackb(b, raw=False, strict_map_key=True, use_list=True)
    except Exception as e:  # msgpack raises many types on garbage; all mean the same here
        raise RecordError("malformed", f"{what}: not msgpack ({type(e).__name__})") from None
    if not isinstance(wire, list) or not wire:
        raise RecordError("malformed", f"{what}: expected a list")
    fmt = wire[0]
    if fmt != FORMAT or isinstance(fmt, bool):
        raise RecordError("malformed", f"{what}: format {fmt!r} not understood")
    return wire


def _launch(x: object) -> LaunchPolicy:
    if x is None:
        return LaunchPolicy()
    launchers, targets = _list(x, "launch", 2)
    return LaunchPolicy(
        tuple(_str(n, "launch.launcher") for n in _list(launchers, "launch.launchers")),
        tuple(_str(t, "launch.target") for t in _list(targets, "launch.targets")),
    )


def decode_record(b: bytes) -> RobotRecord:
    """Bytes from the wire -> a checked record; raises RecordError("malformed", ...) otherwise."""
    wire = _unpack(b, "record")
    try:
        _, metrics, links, api, priority, comps, instances, elect, plan, launch = _list(
            wire, "record", 10
        )
        if api is not None:
            _str(api, "api")
        return RobotRecord(
            metrics=_metrics(metrics),
            links=_links(links),
            api=api,
            priority=_int(priority, "priority", -(2**31), 2**31 - 1),
            instances=_instances(comps, instances),
            election=_election(elect),
            plan=_plan(plan),
            launch=_launch(launch),
        )
    except (_Malformed, ValueError, TypeError) as e:
        # ValueError/TypeError come from unpacking a list of the wrong length.
        raise RecordError("malformed", str(e)) from None


def decode_vitals(b: bytes) -> Vitals:
    """Bytes from a probe -> checked vitals; raises RecordError("malformed", ...) otherwise."""
    wire = _unpack(b, "vitals")
    try:
        _, metrics, links, flat = _list(wire, "vitals", 4)
        flat = _list(flat, "vitals.loads")
        if len(flat) % 4:
            raise _Malformed("vitals.loads: expected groups of 4")
        loads = tuple(
            (
                _int(flat[i], "loads.cpu_pct", 0, 1_000_000) / 10,
                _int(flat[i + 1], "loads.rss", 0, 1 << 50) * 1024,
                _int(flat[i + 2], "loads.out_bps", 0, 1 << 40),
                _int(flat[i + 3], "loads.out_lost", 0, 1 << 40),
            )
            for i in range(0, len(flat), 4)
        )
        metrics = _list(metrics, "vitals.metrics", 5)
        links = _list(links, "vitals.links", 6)
        return Vitals(
            _metrics([metrics[0], 0, *metrics[1:]]),
            _links([*links[:5], [None, None, None], links[5]]),
            loads,
        )
    except (_Malformed, ValueError, TypeError) as e:
        raise RecordError("malformed", str(e)) from None


def metrics_to_json(m: Metrics) -> dict[str, Any]:
    """Metrics as the HTTP API shows them."""
    return {
        "cpu_pct": m.cpu_pct,
        "mem_total": m.mem_total,
        "mem_free": m.mem_free,
        "battery_pct": m.battery_pct,
        "rssi_dbm": m.rssi_dbm,
        "pos": None if m.pos is None else [m.pos[0], m.pos[1]],
    }


def link_to_json(s: LinkStats) -> dict[str, Any]:
    """One link as the HTTP API shows it."""
    return {"rtt_ms": s.rtt_ms, "jitter_ms": s.jitter_ms, "loss": s.loss}


def summary_to_json(s: LinkSummary) -> dict[str, Any]:
    """A link summary as the HTTP API shows it (`listed` are the links past the bounds)."""
    b = s.bounds
    return {
        "peers": s.peers,
        "typical": None if s.typical is None else link_to_json(s.typical),
        "bad": s.bad,
        "bounds": {"rtt_ms": b.rtt_ms, "jitter_ms": b.jitter_ms, "loss": b.loss},
        "listed": {peer: link_to_json(link) for peer, link in sorted(s.listed.items())},
    }


def record_to_json(r: RobotRecord) -> dict[str, Any]:
    """The record as JSON-ready dicts for the HTTP API (`links`: the listed links only; the
    whole summary is `link_summary`)."""
    return {
        "metrics": metrics_to_json(r.metrics),
        "links": {peer: link_to_json(s) for peer, s in sorted(r.links.listed.items())},
        "link_summary": summary_to_json(r.links),
        "api": r.api,
        "priority": r.priority,
        "instances": [
            {
                "name": i.name,
                "component": i.component,
                "state": state_to_wire(i.state),
                "role": i.role,
                "cpu_pct": i.cpu_pct,
                "rss": i.rss,
                "data": i.data,
                "out_bps": i.out_bps,
                "out_lost": i.out_lost,
                "out_refused": i.out_refused,
            }
            for i in r.instances
        ],
        "election": None
        if r.election is None
        else {
            "epoch": r.election.epoch,
            "leader": r.election.leader,
            "claiming": r.election.claiming,
        },
        "plan": None
        if r.plan is None
        else {
            "epoch": r.plan.epoch,
            "version": r.plan.version,
            "digest": r.plan.digest,
            "allocator": r.plan.allocator,
        },
        "launch": {"launchers": list(r.launch.launchers), "targets": list(r.launch.targets)},
    }


PAPER_COMPONENTS = (
    "OmnidirectionalCameraRTC",
    "AnomalyDetectionRTC",
    "CameraRTC",
    "REDControllerRTC",
    "PositionEstimationRTC",
)


def reference_record(peers: int = 10, instances: int = 10, bad: int = 2) -> RobotRecord:
    """The record whose encoded size we quote: `peers` measured links of which `bad` are past
    the bounds (listed), and `instances` hosted instances with the paper's component names (a
    realistic upper bound for one robot; the size no longer depends on `peers`)."""
    bounds = LinkBounds(rtt_ms=50.0, jitter_ms=10.0, loss=0.05)
    listed = {
        f"robot-{i}": LinkStats(rtt_ms=63.17 + i, jitter_ms=12.42 * i, loss=0.05 * (i % 3))
        for i in range(2, 2 + min(bad, MAX_LISTED))
    }
    hosted = tuple(
        InstanceInfo(
            name=f"{PAPER_COMPONENTS[i % 5]}{i + 1}",
            component=PAPER_COMPONENTS[i % 5],
            state=LifecycleState.ACTIVE if i % 2 else LifecycleState.INACTIVE,
            role=InstanceRole.ACTIVE if i < 7 else InstanceRole.STANDBY,
            cpu_pct=12.3 + i,
            rss=512_000_000 + i * 1_234_567,
        )
        for i in range(instances)
    )
    return RobotRecord(
        metrics=Metrics(37.5, 4_000_000_000, 1_234_567_890, 87.26, -47.0, (12.346, -3.2)),
        links=LinkSummary(
            peers=peers,
            typical=LinkStats(rtt_ms=3.17, jitter_ms=0.42, loss=0.01),
            bad=bad,
            bounds=bounds,
            listed=listed,
        ),
        api="http://192.168.10.11:8080",
        priority=3,
        instances=hosted,
    )
