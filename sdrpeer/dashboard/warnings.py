"""What the dashboard warns about: components short of the standbys their system asks for, and
connections losing frames.

How it works (pure: the time is passed in): `fleet_warnings(status, overflows)` reads the
deployment status (GET /v1/status, built from gossip, so it covers the fleet) and returns one
warning per problem, each `{"kind", "subject", "text"}` plus the figures it is based on:

- `no_standby`: a component has fewer ready standbys than its system file asks for
  (`standbys_wanted` in the status): the plan placed fewer (after a death no robot had room), or a
  placed one is not usable (its robot is down, it failed, it is in ERROR);
- `dropping_frames`: a connection whose sender loses frames to full buffers now (`lost_per_s` in
  the status: the sender's OutPort counters, gossiped), or an instance of this robot that logged
  `port.overflow` within `recent_s` (`Overflows` keeps the last one per instance and port; the
  event log only knows this robot's).
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping
from typing import Any, Final

from sdrpeer.record.robot import state_to_wire
from sdrpeer.vocabulary import LifecycleState, ProcessState

__all__ = ["DROPPING_FRAMES", "NO_STANDBY", "Overflows", "fleet_warnings"]

NO_STANDBY: Final = "no_standby"
DROPPING_FRAMES: Final = "dropping_frames"
UNUSABLE: Final = frozenset(
    {"robot down", "lost", state_to_wire(LifecycleState.ERROR), state_to_wire(ProcessState.FAILED)}
)
"""Standby states that cannot take over."""
RECENT_S: Final = 60.0
"""How long a `port.overflow` event keeps its warning (s): the agent repeats it every 30 s while
frames go on being lost."""


class Overflows:
    """The newest `port.overflow` event of each (instance, port) on this robot."""

    def __init__(self, max_kept: int = 1024) -> None:
        self.max_kept = max_kept
        self._last: dict[tuple[str, str], dict[str, Any]] = {}

    def add(self, entry: Mapping[str, Any]) -> None:
        """Keep an event log entry of kind `port.overflow`."""
        detail = entry.get("detail") or {}
        key = (str(detail.get("instance") or detail.get("component")), str(detail.get("port")))
        self._last.pop(key, None)
        self._last[key] = dict(entry)
        while len(self._last) > self.max_kept:
            del self._last[next(iter(self._last))]

    def recent(self, now: float, within: float = RECENT_S) -> list[dict[str, Any]]:
        """The entries logged within `within` seconds of `now`, oldest first."""
        return [e for e in self._last.values() if now - float(e.get("ts", 0)) <= within]


def _standby_warnings(comps: Iterable[Mapping[str, Any]]) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    for comp in comps:
        wanted = comp.get("standbys_wanted")
        if not isinstance(wanted, int) or wanted <= 0:
            continue
        standbys = comp.get("standbys") or []
        down = [s for s in standbys if s.get("state") in UNUSABLE]
        ready = len(standbys) - len(down)
        if ready >= wanted:
            continue
        name = str(comp.get("component"))
        parts = [f"{ready} of {wanted} standbys the system asks for"]
        if len(standbys) < wanted:
            parts.append(f"{wanted - len(standbys)} not placed (no robot met the constraints)")
        parts.extend(f"{s.get('instance')} on {s.get('robot')}: {s.get('state')}" for s in down)
        out.append(
            {
                "kind": NO_STANDBY,
                "subject": name,
                "text": f"{name}: " + "; ".join(parts),
                "wanted": wanted,
                "ready": ready,
            }
        )
    return out


def _frame_warnings(
    conns: Iterable[Mapping[str, Any]], overflows: Iterable[Mapping[str, Any]]
) -> list[dict[str, Any]]:
    out: list[dict[str, Any]] = []
    senders = set()
    for c in conns:
        lost = c.get("lost_per_s")
        if isinstance(lost, bool) or not isinstance(lost, int | float) or lost <= 0:
            continue
        subject = f"{c.get('from')} → {c.get('to')}"
        senders.add(str(c.get("from")).split(".")[0])
        out.append(
            {
                "kind": DROPPING_FRAMES,
                "subject": subject,
                "text": f"{subject}: its sender loses {lost:g} frames/s to full buffers",
                "lost_per_s": lost,
            }
        )
    for e in overflows:
        d = e.get("detail") or {}
        if str(d.get("component")) in senders:
            continue  # already said, fleet-wide
        subject = f"{d.get('instance') or d.get('component')}.{d.get('port')}"
        out.append(
            {
                "kind": DROPPING_FRAMES,
                "subject": subject,
                "text": f"{subject}: port.overflow on {e.get('robot')}, "
                f"{d.get('frames', '?')} frames lost to full buffers",
                "lost_per_s": None,
            }
        )
    return out


def fleet_warnings(
    status: Mapping[str, Any] | None, overflows: Iterable[Mapping[str, Any]] = ()
) -> list[dict[str, Any]]:
    """Every warning the status and this robot's recent `port.overflow` events give."""
    doc = status or {}
    return _standby_warnings(doc.get("components") or []) + _frame_warnings(
        doc.get("connections") or [], overflows
    )
