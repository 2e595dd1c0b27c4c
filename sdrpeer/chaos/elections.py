"""How many allocator elections a soak saw, and why each happened (pure).

How it works: every running robot's event log is read at the end of a soak. Each
`election.elected` event is one robot winning one epoch; the winners, in epoch order, say who held
the role before each win. Why the role changed hands is then read from what happened to that
previous allocator between its own win and the next one, first match wins:

- `first`: no allocator before (the fleet's first election);
- `allocator killed`: the soak SIGKILLed its agent (a `kill_agent` fault);
- `partition`: a partition fault was on meanwhile (the side cut off steps down);
- `fault on the allocator's robot`: the soak pushed its RSSI, battery or packet loss past the
  rules;
- `stepped down: REASON`: it gave the role up itself, with no fault to explain it
  (`election.stepped_down`: `ineligible` when its robot fell below the allocation thresholds or
  lost touch with the fleet, `outranked` by a claim it learnt of, ...);
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

CHANGE_WINDOW_S = 5.0
"""A partition or a robot fault on at some moment this long before a win explains it (the
condition's sustain, the step-down, the claim); one that ended earlier does not, even if the
previous allocator held the role meanwhile."""

ROBOT_FAULTS = ("rssi", "battery", "loss")
"""Faults that push a robot past the allocation thresholds or the recovery rules (it steps down,
ineligible)."""


def elections(
    events: Mapping[str, Iterable[Mapping[str, Any]]],
    faults: Iterable[Mapping[str, Any]],
    t0_wall: float,
) -> dict[str, Any]:
    """{"total", "by_reason", "churn", "list"} from every robot's events (robot -> entries of
    `GET /v1/events`) and the soak's faults done (`{"t", "kind", "robots", "until"?}`, times
    relative to `t0_wall`)."""
    claimed: dict[int, tuple[str, float]] = {}  # epoch -> (winner, first seen), winners' logs
    heard: dict[int, tuple[str, float]] = {}  # the same, as other robots learnt of it
    stepped: list[tuple[float, str, str]] = []
    dead: list[tuple[float, str]] = []
    for entries in events.values():
        for e in entries:
            kind, ts, robot = e.get("kind"), float(e.get("ts", 0.0)), str(e.get("robot", ""))
            detail = e.get("detail") or {}
            epoch = int(detail.get("epoch", 0))
            if kind == EventKind.ELECTION_ELECTED:
                _won(claimed, epoch, robot, ts)
            elif kind == EventKind.ELECTION and detail.get("leader"):
                _won(heard, epoch, str(detail["leader"]), ts)
            elif kind == EventKind.ELECTION_STEPPED_DOWN:
                stepped.append((ts, robot, str(detail.get("reason", "?"))))
            elif kind == EventKind.MEMBER_DEAD:
                dead.append((ts, robot))
    spans = [_span(f, t0_wall) for f in faults]
    rows = []
    previous: tuple[float, str] | None = None
    for epoch in sorted(claimed.keys() | heard.keys()):
        winner, ts = claimed.get(epoch) or heard[epoch]
        why = _why(previous, ts, spans=spans, stepped=stepped, dead=dead)
        rows.append({"epoch": epoch, "winner": winner, "t": round(ts - t0_wall, 3), "why": why})
        previous = (ts, winner)
    by_reason = Counter(str(r["why"]) for r in rows)
    churn = sum(n for why, n in by_reason.items() if why not in CAUSED)
    return {"total": len(rows), "by_reason": dict(by_reason), "churn": churn, "list": rows}


CAUSED = frozenset({"first", "allocator killed", "partition", "fault on the allocator's robot"})
"""Reasons a fault (or the start) explains; the rest is churn among living members."""


def _won(wins: dict[int, tuple[str, float]], epoch: int, robot: str, ts: float) -> None:
    """Note `robot` winning `epoch` at `ts`: two claims of one epoch are settled as the
    election settles them (the higher name), at the first time either was seen."""
    known = wins.get(epoch)
    if known is None:
        wins[epoch] = (robot, ts)
    else:
        wins[epoch] = (max(known[0], robot), min(known[1], ts))


def _span(fault: Mapping[str, Any], t0_wall: float) -> tuple[str, str, float, float]:
    """(kind, robot, from, until) of a fault done, in wall time (a fault with no end: an
    instant)."""
    start = t0_wall + float(fault["t"])
    until = fault.get("until")
    end = start if until is None else t0_wall + float(until)
    return str(fault["kind"]), str(fault["robots"][0]), start, end


def _why(
    previous: tuple[float, str] | None,
    ts: float,
    *,
    spans: list[tuple[str, str, float, float]],
    stepped: list[tuple[float, str, str]],
    dead: list[tuple[float, str]],
) -> str:
    if previous is None:
        return "first"
    since, holder = previous
    held = [(k, r) for k, r, a, b in spans if a <= ts and b >= since]  # while it held the role
    recent = [(k, r) for k, r, a, b in spans if a <= ts and b >= max(since, ts - CHANGE_WINDOW_S)]
    if any(k == "kill_agent" and r == holder for k, r in held):
        return "allocator killed"
    if any(k == "partition" for k, _ in recent):  # a side cut off steps down: ineligible
        return "partition"
    if any(k in ROBOT_FAULTS and r == holder for k, r in recent):
        return "fault on the allocator's robot"
    for t, r, reason in stepped:
        if since <= t <= ts + WINDOW_AFTER_S and r == holder:
            return f"stepped down: {reason}"
    if any(since <= t <= ts and r == holder for t, r in dead):
        return "declared dead while alive"
    return "other"
