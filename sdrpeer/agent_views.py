"""The JSON views of an agent shown by its API: members with their records, and its counters.

How it works: plain functions of the `Agent` (kept out of agent.py so that file stays about
wiring); they read the gossip core's table, the decoded records and the shell's counters.
"""

from __future__ import annotations

import asyncio
import time
from typing import TYPE_CHECKING, Any

from sdrpeer import __version__
from sdrpeer.monitor.links import distance
from sdrpeer.record import RobotRecord, link_to_json, record_to_json
from sdrpeer.vocabulary import MemberState
from sdrpeer.wire import REASONS

if TYPE_CHECKING:
    from sdrpeer.agent import Agent


def _wall_of(t: float) -> float:
    return round(time.time() - (asyncio.get_running_loop().time() - t), 3)


def members_view(self: Agent) -> list[dict[str, Any]]:
    """Every known member with its metrics and links (see AgentView): this robot's own links
    are all listed, another robot's only those its record lists (past the bounds); every
    member's `link_summary` sums up all of its links. A dead or departed member's instances are
    shown `lost` (with their `last_state`) from the moment it is declared so: its last record
    still lists them until it is reaped."""
    if self.core is None:
        return []
    out = []
    positions = {n: r.metrics.pos for n, (_, r) in self.records.items()}
    positions[self.name] = self.metrics.pos if self.metrics else None
    for m in sorted(self.core.members(), key=lambda m: m.name):
        rec: RobotRecord | None
        if m.name == self.name:
            own = self.core.record_of(self.name)
            rec = self.current
            version = own[0] if own else 0
        else:
            version, rec = self.records.get(m.name, (0, None))
        doc = _record_json(self, m.name, rec)
        if m.name == self.name:
            now = asyncio.get_running_loop().time()
            doc["links"] = {p: link_to_json(s) for p, s in self.links.snapshot(now).items()}
        for peer, link in doc["links"].items():
            d = distance(positions.get(m.name), positions.get(peer))
            link["distance_m"] = None if d is None else round(d, 2)
        state = m.state
        instances = doc.get("instances", [])
        if state in (MemberState.DEAD, MemberState.LEFT):  # its last record lists them: gone
            instances = [{**i, "state": "lost", "last_state": i.get("state")} for i in instances]
        out.append(
            {
                "name": m.name,
                "addr": f"{m.addr[0]}:{m.addr[1]}",
                "state": state,
                "incarnation": m.incarnation,
                "since": _wall_of(m.since),
                "api": rec.api if rec is not None else None,
                "record_version": version,
                "vitals_revision": _revision(self, m.name, version),
                "metrics": doc["metrics"],
                "links": doc["links"],
                "link_summary": doc.get("link_summary"),
                "instances": instances,
                "launch": doc.get("launch"),
            }
        )
    return out


def _record_json(self: Agent, name: str, rec: RobotRecord | None) -> dict[str, Any]:
    """`record_to_json(rec)`, made once per record (records are immutable: most robots'
    records do not change between two dashboard frames), copied where the view adds to it."""
    if rec is None:
        return {"metrics": None, "links": {}}
    cached = self.record_json.get(name)
    if cached is None or cached[0] is not rec:
        cached = (rec, record_to_json(rec))
        self.record_json[name] = cached
    doc = dict(cached[1])
    doc["links"] = {peer: dict(link) for peer, link in doc["links"].items()}
    return doc


def _revision(self: Agent, name: str, version: int) -> int:
    """The vitals revision of record `version` that `name`'s entry shows (0: the record's own)."""
    if self.core is None:
        return 0
    vitals = self.core.vitals_of(name)
    return vitals.revision if vitals is not None and vitals.version == version else 0


def agent_view(self: Agent) -> dict[str, Any]:
    """This agent's counters and settings (see AgentView)."""
    assert self.core is not None
    assert self.shell is not None
    c = self.shell.counters
    codec = self.shell.codec.counters
    site = self.api_site
    states = dict.fromkeys(MemberState, 0)
    for m in self.core.members():
        states[m.state] += 1
    return {
        "name": self.name,
        "addr": f"{self.core.addr[0]}:{self.core.addr[1]}",
        "api": self.api_url,
        "version": __version__,
        "uptime_s": round(time.time() - self._started_wall, 3),
        "insecure": self.keyring is None,
        "preset": self.config.preset,
        "health_score": self.core.health_score,
        "messages": {
            "in": c["messages_in"],
            "out": c["messages_out"],
            "bytes_in": c["bytes_in"],
            "bytes_out": c["bytes_out"],
            "bytes_in_per_s": round(self._rate["in_s"], 1),
            "bytes_out_per_s": round(self._rate["out_s"], 1),
            "sent_by_kind": dict(sorted(self.shell.sent_by_kind.items())),
        },
        "rejected": {r: codec.get(r, 0) for r in REASONS},
        "api_connections": {
            "open": 0 if site is None else len(site.connections()),
            "refused": 0 if site is None else site.refused,
        },
        "clock": {
            "offset_ms": self.shell.codec.clock.offset_ms,
            "advanced": codec.get("clock_advanced", 0),
            "nudges": c["clock_nudges"],
        },
        "members": states,
        "gossip": dict(self.core.counters),
        "published": {k: self.published[k] for k in ("record", "vitals")},
    }


def deploy_view(self: Agent) -> dict[str, Any]:
    """Election, recovery and handoff counters, event counts (see Agent.deploy_view)."""
    coord = self.coordinator
    info = None if coord is None else coord.election.info()
    return {
        "election": {
            "epoch": 0 if info is None else info.epoch,
            "leader": None if info is None else info.leader,
        },
        "recovery_actions": dict(self.recovery.actions),
        "recovery_moves": dict(self.recovery.moves),
        "handoff": {} if coord is None else dict(coord.handoff.counters),
        "events": dict(self.events.counts),
        "dashboard_streams": self.dashboard.hub.clients,
    }
