"""A robot's gossip record: its metrics, its measured links and the instances it hosts.

How it works: the owning robot builds a `RobotRecord`, `encode_record` turns it into compact
msgpack and gossip versions and spreads those bytes without looking inside. Every receiver calls
`decode_record`, which checks each field and raises `WireError("malformed", ...)` on anything
unexpected (never another exception), so a bad peer cannot crash an agent.

Wire layout (msgpack arrays, not maps; fixed-point integers, not floats):

    [FORMAT, metrics, links, api, priority, components, instances, ts, election, plan]
    metrics   = [cpu_dpct, mem_total_kib, mem_free_kib, battery_dpct|nil, rssi_ddbm|nil,
                 [x_cm, y_cm]|nil]
    links     = [peer, rtt_10us, jitter_10us, loss_permille, peer, ...]   (flat, 4 per link)
    components= [component name, ...]                 (each distinct component once)
    instances = [[component_index, shared_prefix_len, name_rest, state, role, cpu_dpct,
                  rss_kib, data_addr|nil, out_bytes_per_s], ...]
    election  = [epoch, leader|nil, claiming] | nil   (who this robot believes is the allocator)
    plan      = [epoch, version, digest, allocator] | nil   (the newest plan this robot holds)

Records of the first layout (8 fields, 7 per instance) and instances of 8 fields (no traffic)
are still accepted.

`dpct` is 0.1 %, `ddbm` 0.1 dB, `10us` 0.01 ms, `permille` 0.1 % loss. An instance name usually
starts with its component's name (`CameraRTC2` of `CameraRTC`), so only the differing tail is
sent. Well-known states and roles are sent as a small index, any other as its string.
Decoding returns the rounded values: `decode_record(encode_record(r))` equals `r` only once `r`
is already on that grid.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any

import msgpack

from sdrpeer.errors import WireError

FORMAT = 1
"""Version of the wire layout above; a decoder refuses any other."""

STATES = ("created", "inactive", "active", "error", "finalized", "starting", "stopping")
"""Instance states sent as an index; others go as strings."""
ROLES = ("active", "standby")
"""Instance roles sent as an index; others go as strings."""

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
class InstanceInfo:
    """One component instance hosted by the robot, with its measured cpu % and RSS bytes."""

    name: str
    component: str
    state: str
    role: str
    cpu_pct: float
    rss: int
    data: str | None = None
    """Where other robots' senders reach its InPorts (tcp://host:port), while it runs."""
    out_bps: int = 0
    """Bytes per second its OutPorts sent, over the last metrics interval."""


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
    """Everything a robot gossips about itself; `ts` is when it was sampled."""

    metrics: Metrics
    links: dict[str, LinkStats]
    api: str | None
    priority: int
    instances: tuple[InstanceInfo, ...]
    ts: float
    election: ElectionInfo | None = None
    plan: PlanInfo | None = None


def _fix(x: float, scale: float) -> int:
    """A float on a fixed-point grid (0.1 % -> scale 10)."""
    return round(x * scale)


def _kib(n: int) -> int:
    """Bytes rounded to whole KiB."""
    return (n + 512) // 1024


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


def encode_record(r: RobotRecord) -> bytes:
    """The record as compact msgpack bytes (see the module docstring for the layout)."""
    m = r.metrics
    metrics = [
        _fix(m.cpu_pct, 10),
        _kib(m.mem_total),
        _kib(m.mem_free),
        None if m.battery_pct is None else _fix(m.battery_pct, 10),
        None if m.rssi_dbm is None else _fix(m.rssi_dbm, 10),
        None if m.pos is None else [_fix(m.pos[0], 100), _fix(m.pos[1], 100)],
    ]
    links: list[Any] = []
    for peer in sorted(r.links):
        s = r.links[peer]
        links += [peer, _fix(s.rtt_ms, 100), _fix(s.jitter_ms, 100), _fix(s.loss, 1000)]
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
                _code(inst.state, STATES),
                _code(inst.role, ROLES),
                _fix(inst.cpu_pct, 10),
                _kib(inst.rss),
                inst.data,
                max(0, int(inst.out_bps)),
            ]
        )
    e, p = r.election, r.plan
    wire = [
        FORMAT,
        metrics,
        links,
        r.api,
        r.priority,
        components,
        instances,
        float(r.ts),
        None if e is None else [e.epoch, e.leader, e.claiming],
        None if p is None else [p.epoch, p.version, p.digest, p.allocator],
    ]
    data: bytes = msgpack.packb(wire, use_bin_type=True)
    return data


class _Malformed(Exception):
    """Internal: a field failed validation (turned into WireError by decode_record)."""


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


def _metrics(x: object) -> Metrics:
    """Validate and scale the metrics array."""
    cpu, total, free, battery, rssi, pos = _list(x, "metrics", 6)
    xy = None
    if pos is not None:
        px, py = _list(pos, "metrics.pos", 2)
        xy = (_int(px, "pos.x", None) / 100, _int(py, "pos.y", None) / 100)
    return Metrics(
        cpu_pct=_int(cpu, "cpu_pct", 0, 100_000) / 10,
        mem_total=_int(total, "mem_total") * 1024,
        mem_free=_int(free, "mem_free") * 1024,
        battery_pct=None if battery is None else _int(battery, "battery_pct", 0, 1000) / 10,
        rssi_dbm=None if rssi is None else _int(rssi, "rssi_dbm", -2000, 1000) / 10,
        pos=xy,
    )


def _links(x: object) -> dict[str, LinkStats]:
    """Validate the flat [peer, rtt, jitter, loss, ...] array."""
    flat = _list(x, "links")
    if len(flat) % 4:
        raise _Malformed("links: expected groups of 4")
    links: dict[str, LinkStats] = {}
    for i in range(0, len(flat), 4):
        peer = _str(flat[i], "links.peer")
        if peer in links:
            raise _Malformed(f"links: peer {peer!r} twice")
        links[peer] = LinkStats(
            rtt_ms=_int(flat[i + 1], "rtt_ms") / 100,
            jitter_ms=_int(flat[i + 2], "jitter_ms") / 100,
            loss=_int(flat[i + 3], "loss", 0, 1000) / 1000,
        )
    return links


def _instances(comps: object, x: object) -> tuple[InstanceInfo, ...]:
    """Validate the component table and the instance arrays."""
    components = [_str(c, "component") for c in _list(comps, "components")]
    out = []
    for item in _list(x, "instances"):
        fields = _list(item, "instance")
        if len(fields) == 7:
            fields = [*fields, None]
        if len(fields) == 8:
            fields = [*fields, 0]
        ci, shared, rest, state, role, cpu, rss, data, out_bps = _list(fields, "instance", 9)
        component = components[_int(ci, "instance.component", 0, len(components) - 1)]
        prefix = component[: _int(shared, "instance.prefix", 0, len(component))]
        out.append(
            InstanceInfo(
                name=_str(prefix + _str(rest, "instance.name", empty=True), "instance.name"),
                component=component,
                state=_named(state, STATES, "instance.state"),
                role=_named(role, ROLES, "instance.role"),
                cpu_pct=_int(cpu, "instance.cpu_pct", 0, 1_000_000) / 10,
                rss=_int(rss, "instance.rss") * 1024,
                data=None if data is None else _str(data, "instance.data"),
                out_bps=_int(out_bps, "instance.out_bps", 0, 1 << 40),
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


def decode_record(b: bytes) -> RobotRecord:
    """Bytes from the wire -> a checked record; raises WireError("malformed", ...) otherwise."""
    try:
        wire = msgpack.unpackb(b, raw=False, strict_map_key=True, use_list=True)
    except Exception as e:  # msgpack raises many types on garbage; all mean the same here
        raise WireError("malformed", f"record: not msgpack ({type(e).__name__})") from None
    try:
        top = _list(wire, "record")
        if len(top) == 8:
            top = [*top, None, None]
        fmt, metrics, links, api, priority, comps, instances, ts, elect, plan = _list(
            top, "record", 10
        )
        if fmt != FORMAT or isinstance(fmt, bool):
            raise _Malformed(f"record: format {fmt!r} not understood")
        if not isinstance(ts, float) or not math.isfinite(ts):
            raise _Malformed("ts: expected a finite float")
        if api is not None:
            _str(api, "api")
        return RobotRecord(
            metrics=_metrics(metrics),
            links=_links(links),
            api=api,
            priority=_int(priority, "priority", -(2**31), 2**31 - 1),
            instances=_instances(comps, instances),
            ts=ts,
            election=_election(elect),
            plan=_plan(plan),
        )
    except (_Malformed, ValueError, TypeError) as e:
        # ValueError/TypeError come from unpacking a list of the wrong length.
        raise WireError("malformed", str(e)) from None


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


def record_to_json(r: RobotRecord) -> dict[str, Any]:
    """The record as JSON-ready dicts for the HTTP API."""
    return {
        "metrics": metrics_to_json(r.metrics),
        "links": {
            peer: {"rtt_ms": s.rtt_ms, "jitter_ms": s.jitter_ms, "loss": s.loss}
            for peer, s in sorted(r.links.items())
        },
        "api": r.api,
        "priority": r.priority,
        "instances": [
            {
                "name": i.name,
                "component": i.component,
                "state": i.state,
                "role": i.role,
                "cpu_pct": i.cpu_pct,
                "rss": i.rss,
                "data": i.data,
                "out_bps": i.out_bps,
            }
            for i in r.instances
        ],
        "ts": r.ts,
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
    }


PAPER_COMPONENTS = (
    "OmnidirectionalCameraRTC",
    "AnomalyDetectionRTC",
    "CameraRTC",
    "REDControllerRTC",
    "PositionEstimationRTC",
)


def reference_record(peers: int = 10, instances: int = 10, ts: float = 0.0) -> RobotRecord:
    """The record whose encoded size we quote: `peers` measured links and `instances` hosted
    instances with the paper's component names (a realistic upper bound for one robot)."""
    links = {
        f"robot-{i}": LinkStats(rtt_ms=3.17 + i, jitter_ms=0.42 * i, loss=0.05 * (i % 3))
        for i in range(2, 2 + peers)
    }
    hosted = tuple(
        InstanceInfo(
            name=f"{PAPER_COMPONENTS[i % 5]}{i + 1}",
            component=PAPER_COMPONENTS[i % 5],
            state="active" if i % 2 else "inactive",
            role="active" if i < 7 else "standby",
            cpu_pct=12.3 + i,
            rss=512_000_000 + i * 1_234_567,
        )
        for i in range(instances)
    )
    return RobotRecord(
        metrics=Metrics(37.5, 4_000_000_000, 1_234_567_890, 87.26, -47.0, (12.346, -3.2)),
        links=links,
        api="http://192.168.10.11:8080",
        priority=3,
        instances=hosted,
        ts=ts,
    )
