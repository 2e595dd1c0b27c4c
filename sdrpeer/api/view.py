"""What the HTTP API needs from an agent: a read-only view plus a few token-protected actions.

The agent implements this protocol; the API and its tests depend only on it.
"""

from __future__ import annotations

from collections.abc import Iterable
from pathlib import Path
from typing import Any, Protocol, runtime_checkable


class AgentView(Protocol):
    """The agent as the HTTP API sees it. All returned values are JSON-ready."""

    @property
    def name(self) -> str:
        """This robot's name."""
        ...

    def members_view(self) -> list[dict[str, Any]]:
        """Every known member (self included), sorted by name.

        Each dict: name, addr ("host:port"), state ("alive"|"suspect"|"dead"|"left"), incarnation,
        since (unix seconds of the last state change), api (URL or None), record_version,
        metrics (dict or None: cpu_pct, mem_total, mem_free, battery_pct, rssi_dbm, pos [x, y]),
        links (dict peer -> {rtt_ms, jitter_ms, loss, distance_m}), instances (the robot's
        gossiped component instances: name, component, state, role, cpu_pct, rss), launch
        ({launchers, targets}: what it lets hosts run; None before its first record).
        """
        ...

    def agent_view(self) -> dict[str, Any]:
        """This agent's own counters and settings.

        Keys: name, addr, api, version, uptime_s, insecure (bool), preset, health_score,
        messages {in, out, bytes_in, bytes_out, bytes_in_per_s, bytes_out_per_s},
        rejected {reason: count}, api_connections {open, refused, shed, idle_closed,
        header_closed} (`sdrpeer.api.connections`), members {alive, suspect, dead, left}.
        """
        ...

    def events_view(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        """Event log entries with id > since, oldest first (at most `limit`).

        Each dict: id (int, increasing), ts (unix seconds), kind (e.g. "member.join",
        "member.suspect", "member.dead", "member.alive", "member.left", "member.reaped", "trap",
        "agent.start", "wire.rejected"), robot (the robot concerned), detail (dict).
        """
        ...

    def set_virtual(self, changes: dict[str, Any]) -> dict[str, Any]:
        """Change this virtual robot's hardware facts live (battery, rssi, pos, drain, ...).

        Returns the new metrics dict. Raises sdrpeer.errors.ConfigError on a bad field.
        """
        ...


@runtime_checkable
class InstancesView(Protocol):
    """The component instances an agent hosts (`sdrpeer.runtime.manager.InstanceManager`).

    An agent that hosts instances has it as its `instances` attribute; the /v1/instances routes
    answer 404 on an agent without one.
    """

    def status(self) -> list[dict[str, Any]]:
        """Every desired or running instance: name, component, state, desired, role, pid,
        cpu_pct, rss, restarts, since, connections, data, services (the host's service ports),
        last_error, ports, start_latency_s."""
        ...

    def status_of(self, name: str) -> dict[str, Any]:
        """One instance's status dict."""
        ...

    def desired(self) -> dict[str, Any]:
        """The desired set: name -> InstanceSpec."""
        ...

    def set_desired(self, specs: Iterable[Any], *, replace_all: bool = False) -> list[str]:
        """Merge InstanceSpecs into the desired set (or replace it); the names now desired."""
        ...

    def remove(self, name: str) -> bool:
        """Take an instance out of the desired set; False if it was not there."""
        ...

    async def act(self, name: str, action: str) -> dict[str, Any]:
        """activate | deactivate | reset | restart; KeyError for an unknown instance."""
        ...

    def log_file(self, name: str) -> Path | None:
        """The instance's log file, None for an instance the agent does not know."""
        ...
