"""Fleet moments seen from one robot: state changes of every instance, elections, plans, moves.

How it works (pure): an agent's event log holds what happened on its own robot; the dashboard
also needs what happened elsewhere (the paper's Figs. 4-6 mark the allocation and recovery
moments and show every component's state). `diff_status(prev, cur, ts)` compares two deployment
statuses (GET /v1/status, which every robot builds from gossip) and returns one moment per
change: `state` (an instance's state or role), `election` (allocator or epoch), `allocation` (a
new plan) and `move` (a component's active instance on another robot). `Moments` keeps them for
`window_s` (and at most `maxlen`), so a page opened late sees the past.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Mapping
from typing import Any

from sdrpeer.vocabulary import InstanceRole

__all__ = ["Moments", "diff_status"]

Doc = Mapping[str, Any]


def _instances(doc: Doc | None) -> Iterator[tuple[str, dict[str, Any]]]:
    for comp in (doc or {}).get("components") or []:
        name = str(comp.get("component"))
        if comp.get("instance"):
            yield name, {**comp, "role": InstanceRole.ACTIVE}
        for standby in comp.get("standbys") or []:
            yield name, {**standby, "role": InstanceRole.STANDBY}


def _state(ts: float, component: str, row: dict[str, Any], state: Any) -> dict[str, Any]:
    return {
        "ts": ts,
        "kind": "state",
        "component": component,
        "instance": row.get("instance"),
        "robot": row.get("robot"),
        "role": row["role"],
        "state": state,
    }


def diff_status(prev: Doc | None, cur: Doc | None, ts: float) -> list[dict[str, Any]]:
    """The moments between two statuses (`prev` None: the first look, every state is news)."""
    if cur is None:
        return []
    out: list[dict[str, Any]] = []
    before = (prev or {}).get("allocator") or {}
    now = cur.get("allocator") or {}
    if prev is not None and (before.get("name"), before.get("epoch")) != (
        now.get("name"),
        now.get("epoch"),
    ):
        out.append(
            {"ts": ts, "kind": "election", "leader": now.get("name"), "epoch": now.get("epoch")}
        )
    old_plan = (prev or {}).get("plan") or {}
    plan = cur.get("plan") or {}
    if plan and (old_plan.get("epoch"), old_plan.get("version")) != (
        plan.get("epoch"),
        plan.get("version"),
    ):
        out.append(
            {
                "ts": ts,
                "kind": "allocation",
                "epoch": plan.get("epoch"),
                "version": plan.get("version"),
                "system": plan.get("system"),
            }
        )
    seen = {
        (row.get("instance"), row.get("robot")): (row.get("state"), row["role"])
        for _, row in _instances(prev)
    }
    current = set()
    for component, row in _instances(cur):
        key = (row.get("instance"), row.get("robot"))
        current.add(key)
        if seen.get(key) != (row.get("state"), row["role"]):
            out.append(_state(ts, component, row, row.get("state")))
    for component, row in _instances(prev):
        if (row.get("instance"), row.get("robot")) not in current:
            out.append(_state(ts, component, row, "gone"))
    was = {c.get("component"): c.get("robot") for c in (prev or {}).get("components") or []}
    for comp in cur.get("components") or []:
        src, dst = was.get(comp.get("component")), comp.get("robot")
        if src and dst and src != dst:
            out.append(
                {
                    "ts": ts,
                    "kind": "move",
                    "component": comp.get("component"),
                    "from": src,
                    "to": dst,
                }
            )
    return out


class Moments:
    """The moments of the last `window_s` seconds, oldest first."""

    def __init__(self, window_s: float = 900.0, maxlen: int = 20_000) -> None:
        self.window_s = window_s
        self._items: deque[dict[str, Any]] = deque(maxlen=maxlen)
        self._last: Doc | None = None

    def observe(self, ts: float, status: Doc | None) -> list[dict[str, Any]]:
        """Compare with the last status; keep and return the new moments."""
        new = diff_status(self._last, status, ts)
        if status is not None:
            self._last = status
        self._items.extend(new)
        while self._items and self._items[0]["ts"] < ts - self.window_s:
            self._items.popleft()
        return new

    def all(self) -> list[dict[str, Any]]:
        """Every moment kept."""
        return list(self._items)

    def __len__(self) -> int:
        return len(self._items)
