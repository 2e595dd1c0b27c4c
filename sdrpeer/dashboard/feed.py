"""What the dashboard shows, taken from the agent: history frames, live samples, events.

How it works: `tick(now)` runs once a second in the agent: it reads the members view once, adds
a frame to the `History` (always, so a page opened late still sees the past) and, only while a
page listens, publishes a `sample` (every robot's state, metrics, link summary and instances, and
the deployment status: allocator, plan, components, connections with their traffic). Every event
log entry is published as an `event` the moment it is added. A new page first gets `hello`
(which robot, the window), `history` (the series and the fleet moments of `moments.Moments`),
`events` (the log since the page's last event id, or the newest `replay` entries) and the current
`sample`. Every sample also carries the moments since the one before. A change the page draws
(an instance's state, an election, a plan, a member, another robot's new record: `poke()`) sends
a sample within 50 ms instead of at the next tick, so a state change shows at once.

A sample's robots come through a `roster.Roster`, so a robot that died stays on the page, with
`dead_since`, after gossip has reaped it; its active instances say `was_standby` when a promoted
standby holds the role (`moments.was_standby`); and it carries the `warnings.fleet_warnings` of
the status and this robot's recent `port.overflow` events. A page in snapshot mode (`/?snapshot=1`)
reads `GET /v1/stream?once=1`: `hello()`'s messages, then the end (`Hub.serve(once=True)`).
"""

from __future__ import annotations

import asyncio
import contextlib
import logging
import math
import time
from collections.abc import Mapping
from typing import Any, Protocol

from sdrpeer.dashboard.history import History, typical_link
from sdrpeer.dashboard.moments import Moments, was_standby
from sdrpeer.dashboard.roster import Roster
from sdrpeer.dashboard.stream import Hub, encode_event
from sdrpeer.dashboard.warnings import Overflows, fleet_warnings
from sdrpeer.eventlog import EventKind
from sdrpeer.vocabulary import InstanceRole

log = logging.getLogger(__name__)

POKE_KINDS = (
    EventKind.INSTANCE_STATE,
    EventKind.ELECTION,
    "plan.",
    "member.",
    "compliance.",
    EventKind.RECOVERY_MOVE,
)
"""Event kinds after which pages get a fresh sample at once."""

__all__ = ["DashboardSource", "Feed", "member_summary"]


class DashboardSource(Protocol):
    """What the feed reads from an agent."""

    @property
    def name(self) -> str:
        """This robot's name."""
        ...

    def members_view(self) -> list[dict[str, Any]]:
        """Every member with metrics, links and instances (sdrpeer.api.view.AgentView)."""
        ...

    def events_view(self, since: int = 0, limit: int = 500) -> list[dict[str, Any]]:
        """Event log entries after `since`."""
        ...

    def status_view(self) -> dict[str, Any] | None:
        """The deployment status (GET /v1/status), None on an agent that deploys nothing."""
        ...


def _rounded(value: Any) -> float | None:
    if isinstance(value, bool) or not isinstance(value, int | float) or math.isnan(value):
        return None
    return round(float(value), 3)


def _instance(inst: Mapping[str, Any]) -> dict[str, Any]:
    """An instance of a member, with `was_standby` when it is a promoted standby."""
    promoted = inst.get("role") == InstanceRole.ACTIVE and was_standby(
        str(inst.get("component")), inst.get("name")
    )
    return {**inst, "was_standby": promoted}


def member_summary(member: Mapping[str, Any]) -> dict[str, Any]:
    """One robot as a live sample shows it: its links summed up (its typical link), not listed
    pair by pair; a dead or departed one with `dead_since` (and `reaped` once gossip forgot it,
    see `roster.Roster`)."""
    summary = member.get("link_summary")
    typical = typical_link(member)
    row = {
        "name": member.get("name"),
        "state": member.get("state"),
        "api": member.get("api"),
        "metrics": member.get("metrics"),
        "link": {
            "peers": summary.get("peers", 0) if isinstance(summary, Mapping) else 0,
            "rtt_ms": _rounded(typical.get("rtt_ms")),
            "jitter_ms": _rounded(typical.get("jitter_ms")),
            "loss": _rounded(typical.get("loss")),
        },
        "instances": [_instance(i) for i in member.get("instances") or []],
    }
    if "dead_since" in member:
        row["dead_since"] = member["dead_since"]
        row["reaped"] = bool(member.get("reaped"))
    return row


def _with_roles(status: dict[str, Any] | None) -> dict[str, Any] | None:
    """The status with `was_standby` on each component's active (a copy; the agent's stays)."""
    if status is None:
        return None
    comps = [
        {**c, "was_standby": was_standby(str(c.get("component")), c.get("instance"))}
        for c in status.get("components") or []
    ]
    return {**status, "components": comps}


class Feed:
    """Keeps the history and feeds the live streams of one agent."""

    def __init__(
        self,
        source: DashboardSource,
        *,
        history: History | None = None,
        hub: Hub | None = None,
        interval_s: float = 1.0,
        replay: int = 1000,
        poke_s: float = 0.05,
    ) -> None:
        self.source = source
        self.history = history or History()
        self.hub = hub or Hub()
        self.interval_s = interval_s
        self.replay = replay
        self.poke_s = poke_s
        self.moments = Moments(self.history.window_s)
        self.roster = Roster(self.history.window_s)
        self.overflows = Overflows()
        self._poke: asyncio.TimerHandle | None = None

    def on_event(self, entry: dict[str, Any]) -> None:
        """An event log listener: publish the entry at once (and a fresh sample soon after a
        change the pages draw: an instance's state, an election, a plan, a member)."""
        self.hub.publish("event", entry, int(entry["id"]))
        if entry["kind"] == EventKind.PORT_OVERFLOW:
            self.overflows.add(entry)
        if str(entry["kind"]).startswith(POKE_KINDS):
            self.poke()

    def poke(self) -> None:
        """Something changed: publish a sample within `poke_s`, not at the next tick (several
        pokes in that time make one sample; the history keeps its one frame per tick)."""
        if self._poke is not None or not self.hub.clients:
            return
        with contextlib.suppress(RuntimeError):  # no running loop: nothing is streaming
            loop = asyncio.get_running_loop()
            self._poke = loop.call_later(self.poke_s, self._poked)

    def _poked(self) -> None:
        self._poke = None
        if self.hub.clients:
            self.tick(time.time(), history=False)

    def tick(self, now: float, *, history: bool = True) -> None:
        """One frame: into the history (unless a poke) and the moments; to the pages, if any."""
        members = self.roster.observe(now, self.source.members_view())
        status = self.source.status_view()
        if history:
            self.history.add(now, members)
        moments = self.moments.observe(now, status)
        if self.hub.clients:
            self.hub.publish("sample", self.sample(now, members, status, moments))

    def sample(
        self,
        now: float,
        members: list[dict[str, Any]] | None = None,
        status: dict[str, Any] | None = None,
        moments: list[dict[str, Any]] | None = None,
    ) -> dict[str, Any]:
        """The live state of the fleet as this agent sees it, with the moments since the last."""
        if members is None:
            members = self.roster.observe(now, self.source.members_view())
            status = self.source.status_view()
        return {
            "ts": round(now, 3),
            "robot": self.source.name,
            "members": [member_summary(m) for m in members],
            "status": _with_roles(status),
            "moments": moments or [],
            "warnings": fleet_warnings(status, self.overflows.recent(now)),
        }

    def hello(self, last_event_id: str | None) -> list[bytes]:
        """What a new (or reconnecting) page gets before the live messages."""
        try:
            since = max(0, int(last_event_id)) if last_event_id else None
        except ValueError:
            since = None
        if since is None:
            tail = self.source.events_view(0, 10**9)[-self.replay :]
        else:
            tail = self.source.events_view(since, self.replay)
        now = time.time()
        return [
            encode_event(
                "hello",
                {
                    "robot": self.source.name,
                    "window_s": self.history.window_s,
                    "interval_s": self.interval_s,
                },
            ),
            encode_event("history", {**self.history.series(), "moments": self.moments.all()}),
            encode_event("events", tail, int(tail[-1]["id"]) if tail else None),
            encode_event("sample", self.sample(now)),
        ]

    async def run(self) -> None:
        """Tick every `interval_s` until cancelled."""
        while True:
            try:
                self.tick(time.time())
            except Exception:
                log.exception("dashboard frame failed")
            await asyncio.sleep(self.interval_s)

    def close(self) -> None:
        """End the live streams."""
        with contextlib.suppress(Exception):
            self.hub.close()
