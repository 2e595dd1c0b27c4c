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

from sdrpeer.api.view import AgentView

CONTENT_TYPE = "text/plain; version=0.0.4; charset=utf-8"

# Per-robot gauges: family name -> (metrics key, scale to the base unit, help).
ROBOT_GAUGES: dict[str, tuple[str, float, str]] = {
    "sdrpeer_robot_cpu_ratio": ("cpu_pct", 0.01, "CPU use of the robot, 0..1."),
    "sdrpeer_robot_memory_free_bytes": ("mem_free", 1.0, "Free memory of the robot."),
    "sdrpeer_robot_memory_total_bytes": ("mem_total", 1.0, "Memory capacity of the robot."),
    "sdrpeer_robot_battery_ratio": ("battery_pct", 0.01, "Battery level of the robot, 0..1."),
    "sdrpeer_robot_rssi_dbm": ("rssi_dbm", 1.0, "Wi-Fi signal strength at the robot."),
}
# Per-link gauges: family name -> (links key, scale, help).
LINK_GAUGES: dict[str, tuple[str, float, str]] = {
    "sdrpeer_link_rtt_seconds": ("rtt_ms", 0.001, "Round-trip time from robot to peer."),
    "sdrpeer_link_jitter_seconds": ("jitter_ms", 0.001, "RTT jitter from robot to peer."),
    "sdrpeer_link_loss_ratio": ("loss", 1.0, "Probe loss from robot to peer, 0..1."),
}
MEMBER_STATES = ("alive", "suspect", "dead", "left")


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
        yield from self._agent_families(agent)

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
        for member in members:
            name = str(member.get("name"))
            state = str(member.get("state"))
            up.add_metric([name, state], 1.0 if state == "alive" else 0.0)
            for family, (key, scale, _) in ROBOT_GAUGES.items():
                value = _number((member.get("metrics") or {}).get(key))
                if value is not None:
                    robot[family].add_metric([name], value * scale)
            for peer, stats in sorted((member.get("links") or {}).items()):
                for family, (key, scale, _) in LINK_GAUGES.items():
                    value = _number(stats.get(key))
                    if value is not None:
                        link[family].add_metric([name, str(peer)], value * scale)
        yield up
        yield from robot.values()
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


def make_registry(view: AgentView) -> CollectorRegistry:
    """A fresh registry holding only the view collector (no process/platform defaults)."""
    registry = CollectorRegistry(auto_describe=False)
    registry.register(ViewCollector(view))
    return registry


def render(registry: CollectorRegistry) -> bytes:
    """The Prometheus text exposition of `registry`."""
    return generate_latest(registry)
