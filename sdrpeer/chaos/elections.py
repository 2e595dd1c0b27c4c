"""How many allocator elections a soak saw, and why each happened (pure).

How it works: every running robot's event log is read at the end of a soak. Each
`election.elected` event is one robot winning one epoch; the winners, in epoch order, say who held
the role before each win. Why the role changed hands is then read from what happened to that
previous allocator between its own win and the next one, first match wins:

- `first`: no allocator before (the fleet's first election);
- `allocator killed`: the soak SIGKILLed its agent (a `kill_agent` fault);
- `stepped down: REASON`: it gave the role up itself (`election.stepped_down`: `ineligible` when
  its robot fell below the allocation thresholds or lost touch with the fleet, `outranked` by a
  claim it learnt of, ...);
- `partition`: a partition fault was on;
- `declared dead while alive`: some robot declared it dead although nothing killed it (a false
  death: a starved agent, a lossy link);
- `other`: none of these.

A fleet whose members all live should hold one allocator: every election past the first that is
not `allocator killed` or `partition` is churn. A win is seen in the winner's own log or in any
robot's `election` event naming the new leader (the robots killed during the soak take their own
logs with them; a win no surviving robot learnt of is not counted, so the count is a floor).
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Iterable, Mapping
from typing import Any

from sdrpeer.eventlog import EventKind

WINDOW_AFTER_S = 1.0
"""A previous allocator's step-down logged this long after the next win still explains it (the
winner may claim as soon as it hears of the step-down, before the loser logs it)."""


def elections(
    events: Mapping[str, Iterable[Mapping[str, Any]]],
    faults: Iterable[Mapping[str, Any]],
    t0_wall: float,
) -> dict[str, Any]:
    """{"total", "by_reason", "churn", "list"} from every robot's events (robot -> entries of
    `GET /v1/events`) and the soak's faults done (`{"t", "kind", "robots"}`, t relative to
    `t0_wall`)."""
    wins: dict[int, tuple[float, str]] = {}
    stepped: list[tuple[float, str, str]] = []
    dead: list[tuple[float, str]] = []
    for entries in events.values():
        for e in entries:
            kind, ts, robot = e.get("kind"), float(e.get("ts", 0.0)), str(e.get("robot", ""))
            detail = e.get("detail") or {}
            winner = (
                robot
                if kind == EventKind.ELECTION_ELECTED
                else detail.get("leader")
                if kind == EventKind.ELECTION
                else None
            )
            if winner:  # a win, as the winner logged it or as another robot learnt of it
                epoch = int(detail.get("epoch", 0))
                if epoch not in wins or (ts, str(winner)) < wins[epoch]:
                    wins[epoch] = (ts, str(winner))
            elif kind == EventKind.ELECTION_STEPPED_DOWN:
                stepped.append((ts, robot, str(detail.get("reason", "?"))))
            elif kind == EventKind.MEMBER_DEAD:
                dead.append((ts, robot))
    kills = [
        (t0_wall + float(f["t"]), str(f["robots"][0])) for f in faults if f["kind"] == "kill_agent"
    ]
    cuts = [t0_wall + float(f["t"]) for f in faults if f["kind"] == "partition"]
    rows = []
    previous: tuple[float, str] | None = None
    for epoch in sorted(wins):
        ts, winner = wins[epoch]
        why = _why(previous, ts, kills=kills, stepped=stepped, cuts=cuts, dead=dead)
        rows.append({"epoch": epoch, "winner": winner, "t": round(ts - t0_wall, 3), "why": why})
        previous = (ts, winner)
    by_reason = Counter(str(r["why"]) for r in rows)
    churn = sum(n for why, n in by_reason.items() if why not in CAUSED)
    return {"total": len(rows), "by_reason": dict(by_reason), "churn": churn, "list": rows}


CAUSED = frozenset({"first", "allocator killed", "partition"})
"""Reasons a fault (or the start) explains; the rest is churn among living members."""


def _why(
    previous: tuple[float, str] | None,
    ts: float,
    *,
    kills: list[tuple[float, str]],
    stepped: list[tuple[float, str, str]],
    cuts: list[float],
    dead: list[tuple[float, str]],
) -> str:
    if previous is None:
        return "first"
    since, holder = previous
    if any(since <= t <= ts and r == holder for t, r in kills):
        return "allocator killed"
    for t, r, reason in stepped:
        if since <= t <= ts + WINDOW_AFTER_S and r == holder:
            return f"stepped down: {reason}"
    if any(since <= t <= ts for t in cuts):
        return "partition"
    if any(since <= t <= ts and r == holder for t, r in dead):
        return "declared dead while alive"
    return "other"
