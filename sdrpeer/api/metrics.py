"""Prometheus exposition: a collector that reads the agent view at scrape time.

Nothing is stored between scrapes: every scrape calls `members_view()` and `agent_view()` once and
turns them into metric families (`sdrpeer_` prefix, base units: ratios, bytes, seconds, dBm).
Each app gets its own `CollectorRegistry`, so several agents (or tests) can live in one process.
"""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

from prometheus_client import CollectorRegistry, generate_latest
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector

from sdrpeer.api.connections import COUNTERS
from sdrpeer.api.view import AgentView
from sdrpeer.record.robot import state_to_wire
from sdrpeer.vocabulary import LifecycleState, MemberState, ProcessState

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"

# Per-robot gauges: family name -> (metrics key, scale to the base unit, help).
ROBOT_GAUGES: dict[str, tuple[str, float, str]] = {
    "sdrpeer_robot_cpu_ratio": ("cpu_pct", 0.01, "CPU use of the robot, 0..1."),
    "sdrpeer_robot_memory_free_bytes": ("mem_free", 1.0, "Free memory of the robot."),
    "sdrpeer_robot_memory_total_bytes": ("mem_total", 1.0, "Memory capacity of the robot."),
    "sdrpeer_robot_battery_ratio": ("battery_pct", 0.01, "Battery level of the robot, 0..1."),
    "sdrpeer_robot_rssi_dbm": ("rssi_dbm", 1.0, "Wi-Fi signal strength at the robot."),
}
# Per-link gauges: family name -> (links key, scale, help). Every link of this robot, and the
# links other robots' records list (those past the deployed system's bounds).
LINK_GAUGES: dict[str, tuple[str, float, str]] = {
    "sdrpeer_link_rtt_seconds": ("rtt_ms", 0.001, "Round-trip time from robot to peer."),
    "sdrpeer_link_jitter_seconds": ("jitter_ms", 0.001, "RTT jitter from robot to peer."),
    "sdrpeer_link_loss_ratio": ("loss", 1.0, "Probe loss from robot to peer, 0..1."),
}
# Per-robot typical link (its record's link summary): family name -> (key, scale, help).
TYPICAL_GAUGES: dict[str, tuple[str, float, str]] = {
    "sdrpeer_robot_link_rtt_seconds": ("rtt_ms", 0.001, "Typical RTT of the robot's links."),
    "sdrpeer_robot_link_jitter_seconds": ("jitter_ms", 0.001, "Typical jitter of its links."),
    "sdrpeer_robot_link_loss_ratio": ("loss", 1.0, "Typical probe loss of its links, 0..1."),
}
MEMBER_STATES = tuple(MemberState)


def _number(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float):
        return None
    return float(value)


class ViewCollector(Collector):
    """Builds every `sdrpeer_*` family from an `AgentView` when Prometheus scrapes."""

    def __init__(self, view: AgentView) -> None:
        self._view = view

    def collect(self) -> Iterator[Metric]:
        """Yield one family per metric, read from the view now."""
        members = self._view.members_view()
        agent = self._view.agent_view()
        yield from self._member_families(members)
        yield from instance_families(members)
        yield from self._agent_families(agent)
        local = getattr(self._view, "instances", None)
        if local is not None and callable(getattr(local, "status", None)):
            yield from local_instance_families(self._view.name, local.status())
        deploy = getattr(self._view, "deploy_view", None)
        if callable(deploy):
            yield from deploy_families(self._view.name, deploy())

    def _member_families(self, members: list[dict[str, Any]]) -> Iterator[Metric]:
        up = GaugeMetricFamily(
            "sdrpeer_member_up",
            "1 if the member is alive, else 0; `state` is its current state.",
            labels=["robot", "state"],
        )
        robot = {
            name: GaugeMetricFamily(name, text, labels=["robot"])
            for name, (_, _, text) in ROBOT_GAUGES.items()
        }
        link = {
            name: GaugeMetricFamily(name, text, labels=["robot", "peer"])
            for name, (_, _, text) in LINK_GAUGES.items()
        }
        typical = {
            name: GaugeMetricFamily(name, text, labels=["robot"])
            for name, (_, _, text) in TYPICAL_GAUGES.items()
        }
        for member in members:
            name = str(member.get("name"))
            state = str(member.get("state"))
            up.add_metric([name, state], 1.0 if state == MemberState.ALIVE else 0.0)
            for family, (key, scale, _) in ROBOT_GAUGES.items():
                value = _number((member.get("metrics") or {}).get(key))
                if value is not None:
                    robot[family].add_metric([name], value * scale)
            t = (member.get("link_summary") or {}).get("typical") or {}
            for family, (key, scale, _) in TYPICAL_GAUGES.items():
                value = _number(t.get(key))
                if value is not None:
                    typical[family].add_metric([name], value * scale)
            for peer, stats in sorted((member.get("links") or {}).items()):
                for family, (key, scale, _) in LINK_GAUGES.items():
                    value = _number(stats.get(key))
                    if value is not None:
                        link[family].add_metric([name, str(peer)], value * scale)
        yield up
        yield from robot.values()
        yield from typical.values()
        yield from link.values()

    def _agent_families(self, agent: dict[str, Any]) -> Iterator[Metric]:
        messages = agent.get("messages") or {}
        for name, text, keys in (
            ("sdrpeer_gossip_messages", "Gossip datagrams.", ("in", "out")),
            ("sdrpeer_gossip_bytes", "Gossip bytes.", ("bytes_in", "bytes_out")),
        ):
            family = CounterMetricFamily(name, text, labels=["direction"])
            for direction, key in zip(("in", "out"), keys, strict=True):
                family.add_metric([direction], _number(messages.get(key)) or 0.0)
            yield family
        rejected = CounterMetricFamily(
            "sdrpeer_gossip_rejected", "Datagrams dropped, by reason.", labels=["reason"]
        )
        for reason, count in sorted((agent.get("rejected") or {}).items()):
            rejected.add_metric([str(reason)], _number(count) or 0.0)
        yield rejected
        yield from _api_connection_families(agent.get("api_connections") or {})
        counts = agent.get("members") or {}
        members = GaugeMetricFamily(
            "sdrpeer_members", "Members this agent knows, by state.", labels=["state"]
        )
        for state in MEMBER_STATES:
            members.add_metric([state], _number(counts.get(state)) or 0.0)
        yield members
        for name, key, text in (
            ("sdrpeer_health_score", "health_score", "Local health (0 = healthy)."),
            ("sdrpeer_uptime_seconds", "uptime_s", "Seconds since the agent started."),
        ):
            value = _number(agent.get(key))
            yield GaugeMetricFamily(name, text, value=value if value is not None else 0.0)


def _api_connection_families(conns: dict[str, Any]) -> Iterator[Metric]:
    """The HTTP API's connections: open now, and closed by the agent by reason."""
    open_now = GaugeMetricFamily("sdrpeer_api_connections", "HTTP API connections open now.")
    open_now.add_metric([], _number(conns.get("open")) or 0.0)
    yield open_now
    closed = CounterMetricFamily(
        "sdrpeer_api_connections_closed",
        "HTTP API connections the agent closed: refused (all busy), shed (room for a newcomer), "
        "idle_closed, header_closed (a request head unfinished in time).",
        labels=["reason"],
    )
    for reason in COUNTERS:
        closed.add_metric([reason], _number(conns.get(reason)) or 0.0)
    yield closed


def make_registry(view: AgentView) -> CollectorRegistry:
    """A fresh registry holding only the view collector (no process/platform defaults)."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(ViewCollector(view))
    return registry


def render(registry: CollectorRegistry) -> bytes:
    """The Prometheus text exposition of `registry`."""
    return generate_latest(registry)


INSTANCE_STATES = tuple(
    state_to_wire(s)
    for s in (
        LifecycleState.ACTIVE,
        LifecycleState.INACTIVE,
        LifecycleState.ERROR,
        LifecycleState.CREATED,
        ProcessState.STARTING,
        ProcessState.STOPPING,
        ProcessState.STOPPED,
    )
)
"""The instance states every instance has a series for, as records spell them."""
PORT_COUNTERS = ("frames", "bytes", "dropped", "lost", "refused", "replayed", "duplicates")


def instance_families(members: list[dict[str, Any]]) -> Iterator[Metric]:
    """Every robot's gossiped instances: state (one series per state, 1 for the current one)."""
    state = GaugeMetricFamily(
        "sdrpeer_instance_state",
        "1 for the lifecycle state an instance is in (as its robot gossips it), else 0.",
        labels=["robot", "instance", "component", "role", "state"],
    )
    sent = GaugeMetricFamily(
        "sdrpeer_instance_sent_bytes_per_second",
        "Bytes per second an instance's OutPorts sent over the last metrics interval.",
        labels=["robot", "instance", "component"],
    )
    lost = GaugeMetricFamily(
        "sdrpeer_instance_lost_frames_per_second",
        "Frames per second an instance's outgoing connections lost to a full buffer at either "
        "end (its queues or the receiving InPorts), over the last metrics interval.",
        labels=["robot", "instance", "component"],
    )
    for member in members:
        robot = str(member.get("name"))
        for inst in member.get("instances") or []:
            name, comp = str(inst.get("name")), str(inst.get("component"))
            now = str(inst.get("state"))
            states = INSTANCE_STATES if now in INSTANCE_STATES else (*INSTANCE_STATES, now)
            for s in states:
                state.add_metric([robot, name, comp, str(inst.get("role")), s], float(s == now))
            sent.add_metric([robot, name, comp], _number(inst.get("out_bps")) or 0.0)
            lost.add_metric([robot, name, comp], _number(inst.get("out_lost")) or 0.0)
    yield state
    yield sent
    yield lost


def local_instance_families(robot: str, rows: list[dict[str, Any]]) -> Iterator[Metric]:
    """This robot's instances: restarts, CPU, RSS and port traffic (from its supervisors)."""
    restarts = CounterMetricFamily(
        "sdrpeer_instance_restarts", "Restarts of an instance's host.", labels=["robot", "instance"]
    )
    cpu = GaugeMetricFamily(
        "sdrpeer_instance_cpu_ratio",
        "CPU use of an instance's host, 0..1 of a core.",
        labels=["robot", "instance"],
    )
    rss = GaugeMetricFamily(
        "sdrpeer_instance_memory_rss_bytes",
        "Resident memory of an instance's host.",
        labels=["robot", "instance"],
    )
    ports = {
        name: CounterMetricFamily(
            f"sdrpeer_port_{name}",
            f"Port {name} of an instance (direction in: received, out: sent).",
            labels=["robot", "instance", "port", "direction"],
        )
        for name in PORT_COUNTERS
    }
    for row in rows:
        inst = str(row.get("name"))
        restarts.add_metric([robot, inst], _number(row.get("restarts")) or 0.0)
        cpu.add_metric([robot, inst], (_number(row.get("cpu_pct")) or 0.0) / 100)
        rss.add_metric([robot, inst], _number(row.get("rss")) or 0.0)
        for port, c in sorted((row.get("ports") or {}).items()):
            if not isinstance(c, dict):
                continue
            direction = "in" if (c.get("frames_in") or c.get("bytes_in")) else "out"
            for name in PORT_COUNTERS:
                key = f"{name}_{direction}" if name in ("frames", "bytes") else name
                ports[name].add_metric(
                    [robot, inst, str(port), direction], _number(c.get(key)) or 0.0
                )
    yield restarts
    yield cpu
    yield rss
    yield from ports.values()


def deploy_families(robot: str, doc: dict[str, Any]) -> Iterator[Metric]:
    """Election epoch and allocator, recovery actions, state handoffs, dashboard streams."""
    election = doc.get("election") or {}
    yield GaugeMetricFamily(
        "sdrpeer_election_epoch",
        "The allocator epoch this robot follows.",
        value=_number(election.get("epoch")) or 0.0,
    )
    leader = GaugeMetricFamily(
        "sdrpeer_allocator",
        "1 for the robot this robot believes is the allocator.",
        labels=["robot"],
    )
    if election.get("leader"):
        leader.add_metric([str(election["leader"])], 1.0)
    yield leader
    yield GaugeMetricFamily(
        "sdrpeer_is_allocator",
        "1 while this robot holds the allocator role.",
        value=1.0 if election.get("leader") == robot else 0.0,
    )
    for name, key, label, text in (
        ("sdrpeer_recovery_actions", "recovery_actions", "action", "Recovery steps decided here."),
        ("sdrpeer_recovery_moves", "recovery_moves", "component", "Components moved by recovery."),
        ("sdrpeer_state_handoffs", "handoff", "what", "State handoff messages, by outcome."),
        ("sdrpeer_events", "events", "kind", "Event log entries added, by kind."),
    ):
        family = CounterMetricFamily(name, text, labels=[label])
        for k, v in sorted((doc.get(key) or {}).items()):
            family.add_metric([str(k)], _number(v) or 0.0)
        yield family
    yield GaugeMetricFamily(
        "sdrpeer_dashboard_streams",
        "Dashboard pages streaming from this agent now.",
        value=_number(doc.get("dashboard_streams")) or 0.0,
    )
