"""Fleet moments seen from one robot: state changes of every instance, elections, plans, moves.

How it works (pure): an agent's event log holds what happened on its own robot; the dashboard
also needs what happened elsewhere (the paper's Figs. 4-6 mark the allocation and recovery
moments and show every component's state). `diff_status(prev, cur, ts)` compares two deployment
statuses (GET /v1/status, which every robot builds from gossip) and returns one moment per
change: `state` (an instance's state or role), `election` (allocator or epoch), `allocation` (a
new plan), `move` (a component's active instance on another robot) and `component` (what the
component's timeline shows: the state of whichever instance is its active now, with `was_standby`
when that instance was placed as a standby and promoted). `Moments` keeps them for `window_s` (and
at most `maxlen`), so a page opened late sees the past; a component's last `component` moment is
kept past the window while the component exists, so a state that has held longer than the window
is still drawn.

Why `component` moments: a timeline drawn from the per-instance `state` moments mixes instances.
After a failover the promoted instance's new state and the old active's `gone` arrive in the same
diff, the `gone` last; drawn in that order the component showed blank (`gone`) from the failover
until its next change, or for good when the new active was already ACTIVE at the first look
(issue 18: a component blank for 31 s, another not shown at all, both ACTIVE).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterator, Mapping
from typing import Any

from sdrpeer.vocabulary import InstanceRole

__all__ = ["GONE", "Moments", "diff_status", "was_standby"]

GONE = "gone"
"""The state of a `state` or `component` moment whose instance or component left the plan."""
UNPLACED = "unplaced"
"""The status's state of a component without an active instance."""

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
            out.append(_state(ts, component, row, GONE))
    out.extend(_components(prev, cur, ts))
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


def was_standby(component: str, instance: str | None) -> bool:
    """Whether a component's active instance was placed as one of its standbys and promoted: the
    allocator names a fresh active after its component and a standby `<component>-s<k>`, and a
    promoted standby keeps its name (its name is its identity: gossip records, data addresses,
    logs, handed-off state)."""
    return bool(instance) and instance != component


def _active_of(comp: Doc) -> tuple[Any, Any, Any]:
    return (comp.get("instance"), comp.get("robot"), comp.get("state") or UNPLACED)


def _components(prev: Doc | None, cur: Doc, ts: float) -> list[dict[str, Any]]:
    """One `component` moment per component whose active (instance, robot, state) changed, and
    one `gone` per component no longer in the plan."""
    before = {str(c.get("component")): c for c in (prev or {}).get("components") or []}
    out = []
    names = set()
    for comp in cur.get("components") or []:
        name = str(comp.get("component"))
        names.add(name)
        old = before.get(name)
        if old is not None and _active_of(old) == _active_of(comp):
            continue
        instance, robot, state = _active_of(comp)
        out.append(
            {
                "ts": ts,
                "kind": "component",
                "component": name,
                "instance": instance,
                "robot": robot,
                "state": state,
                "was_standby": was_standby(name, instance),
            }
        )
    for name in before:
        if name not in names:
            out.append(
                {
                    "ts": ts,
                    "kind": "component",
                    "component": name,
                    "instance": None,
                    "robot": None,
                    "state": GONE,
                    "was_standby": False,
                }
            )
    return out


class Moments:
    """The moments of the last `window_s` seconds, oldest first."""

    def __init__(self, window_s: float = 900.0, maxlen: int = 20_000) -> None:
        self.window_s = window_s
        self._items: deque[dict[str, Any]] = deque(maxlen=maxlen)
        self._last: Doc | None = None
        self._latest: dict[str, dict[str, Any]] = {}
        """component -> its newest `component` moment (kept past the window: the state holds)."""

    def observe(self, ts: float, status: Doc | None) -> list[dict[str, Any]]:
        """Compare with the last status; keep and return the new moments."""
        new = diff_status(self._last, status, ts)
        if status is not None:
            self._last = status
        for m in new:
            if m["kind"] == "component":
                if m["state"] == GONE:
                    self._latest.pop(m["component"], None)
                else:
                    self._latest[m["component"]] = m
        self._items.extend(new)
        while self._items and self._items[0]["ts"] < ts - self.window_s:
            self._items.popleft()
        return new

    def all(self) -> list[dict[str, Any]]:
        """Every moment kept, after the `component` moments of states older than the window
        that still hold (oldest first)."""
        cut = self._items[0]["ts"] if self._items else float("inf")
        held = sorted(
            (m for m in self._latest.values() if m["ts"] < cut), key=lambda m: float(m["ts"])
        )
        return held + list(self._items)

    def __len__(self) -> int:
        return len(self._items)
