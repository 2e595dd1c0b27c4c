"""Continuous compliance: the running placements held to their constraints over time (pure).

How it works: `ComplianceMonitor.observe(now, readings)` takes every constraint of the running
placements as measured now (`sdrpeer.alloc.compliance.readings`) and keeps one
`ConditionTracker` (`sdrpeer.recovery.conditions`, the recovery rules' own) per reading key
(constraint, subject, robots). Each tracker watches the rule "value at or past the bound" with
the system's `compliance:` policy:
- it fires once the violation has held for `for:` (sustain) without a gap between samples
  longer than `stale_after_s`; a sample that is not past the bound restarts the run, so a
  noisy link that dips in and out of its bound does not fire;
- it clears only once the value is `clear:` (a share of the bound) inside it: the hysteresis;
- a reading whose key is gone (the placement moved, the connection's ends now share a robot,
  the system changed) drops its tracker; one that had fired is reported cleared ("placement
  changed").
Outputs: `next_event()` drains `Violated` / `Compliant`; `rows(now)` is the compliance table
(every reading with its value, bound, state and since when); `due_moves(now)` (the allocator,
`on_violation: replace` only) names the components to move now, each at most once per
`min_interval`, and the shell reports back with `moved(now, component)`; a violated placement
that changed counts as a move too, so every agent (a future allocator) knows when a component
last moved. `next_timer()` is the
earliest sustain deadline, so a shell wakes when it expires rather than at its next sample.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Iterable
from dataclasses import dataclass
from typing import Any

from sdrpeer.alloc.compliance import Reading
from sdrpeer.recovery.conditions import CLEARED, FIRED, ConditionTracker
from sdrpeer.recovery.plugins import Condition
from sdrpeer.system.model import ComplianceDef, RecoveryRule

CAUSE = "compliance"
"""The cause of the rules the trackers are built from (not a Table III cause: nothing else
acts on it)."""
_CONDITION = Condition()
Key = tuple[str, str, tuple[str, ...]]


@dataclass(frozen=True, slots=True)
class Violated:
    """A constraint of a running placement has been violated for the sustain time."""

    reading: Reading
    since: float
    """When the run of violating samples began."""
    at: float


@dataclass(frozen=True, slots=True)
class Compliant:
    """A violated constraint cleared: inside its bound past the hysteresis, or its placement
    changed (`value` None)."""

    reading: Reading
    at: float
    why: str


ComplianceEvent = Violated | Compliant


def clear_level(bound: float, above: bool, clear: float) -> float:
    """Where a violation of `bound` clears: `clear` (a share) of the bound inside it."""
    margin = abs(bound) * clear
    return bound + margin if above else bound - margin


class ComplianceMonitor:
    """Every running placement's constraints, tracked with sustain and hysteresis."""

    def __init__(self, policy: ComplianceDef, stale_after_s: float) -> None:
        self.policy = policy
        self.stale_after_s = stale_after_s
        self._trackers: dict[Key, ConditionTracker] = {}
        self._readings: dict[Key, Reading] = {}
        self._ok_since: dict[Key, float] = {}
        self._bad: set[Key] = set()
        """Keys that were past their bound (holding or fired) at their last sample."""
        self._last_move: dict[str, float] = {}
        self._events: deque[ComplianceEvent] = deque()

    def _tracker(self, r: Reading) -> ConditionTracker:
        tracker = self._trackers.get(r.key)
        if tracker is None or tracker.threshold != r.bound:
            rule = RecoveryRule(
                CAUSE,
                metric=r.constraint,
                op="<=" if r.above else ">=",
                threshold=r.bound,
                sustain_s=self.policy.sustain_s,
                clear=clear_level(r.bound, r.above, self.policy.clear),
            )
            tracker = self._trackers[r.key] = ConditionTracker(rule, _CONDITION, self.stale_after_s)
        return tracker

    # -- inputs -------------------------------------------------------------------------------

    def observe(self, now: float, readings: Iterable[Reading]) -> None:
        """Every reading of the running placements at `now` (keys not given are dropped)."""
        seen: set[Key] = set()
        for r in readings:
            seen.add(r.key)
            self._readings[r.key] = r
            self._ok_since.setdefault(r.key, now)
            tracker = self._tracker(r)
            outcome = tracker.observe(now, r.value)
            self._outcome(now, r.key, tracker, outcome)
            if tracker.fired or tracker.since is not None:
                self._bad.add(r.key)
            elif r.key in self._bad:
                self._bad.discard(r.key)
                self._ok_since[r.key] = now
        for key in [k for k in self._readings if k not in seen]:
            gone = self._trackers.pop(key)
            reading = self._readings.pop(key)
            self._ok_since.pop(key, None)
            self._bad.discard(key)
            if gone.fired:
                self._events.append(Compliant(reading, now, "placement changed"))
                if reading.movable:  # every agent learns the move from the plan it follows
                    comp = reading.movable[0]
                    self._last_move[comp] = max(self._last_move.get(comp, -math.inf), now)

    def handle_timer(self, now: float) -> None:
        """The deadline of `next_timer()` has passed."""
        for key, tracker in list(self._trackers.items()):
            if tracker.next_timer() <= now:
                self._outcome(now, key, tracker, tracker.handle_timer(now))

    def moved(self, now: float, component: str) -> None:
        """The allocator issued a plan that moves `component` for compliance at `now`."""
        self._last_move[component] = now

    # -- outputs ------------------------------------------------------------------------------

    def next_timer(self) -> float:
        """The earliest sustain deadline (inf: none pending)."""
        return min((t.next_timer() for t in self._trackers.values()), default=math.inf)

    def next_event(self) -> ComplianceEvent | None:
        """The oldest undrained event, or None."""
        return self._events.popleft() if self._events else None

    def violated(self) -> list[Reading]:
        """The readings whose constraint is violated now (fired, not cleared)."""
        return [self._readings[k] for k, t in self._trackers.items() if t.fired]

    def due_moves(self, now: float) -> list[tuple[str, Reading]]:
        """(component, reading) to move now under `on_violation: replace`: for each violated
        reading its first movable component (a connection's receiver, unless pinned), when that
        component's last compliance move is at least `min_interval` ago; nothing under `report`.
        Never the other end instead: a link would then move two components a minute."""
        if self.policy.on_violation != "replace":
            return []
        out: dict[str, Reading] = {}
        for r in self.violated():
            if not r.movable:
                continue
            comp = r.movable[0]
            last = self._last_move.get(comp, -math.inf)
            if now - last >= self.policy.min_interval_s and comp not in out:
                out[comp] = r
        return sorted(out.items())

    def rows(self, now: float) -> list[dict[str, Any]]:
        """The compliance table: every reading with its value, bound, state ("ok", "holding":
        past the bound for less than the sustain, "violated", "unknown": not measured) and
        since when (`now`'s clock) it is in that state."""
        out = []
        for key, r in self._readings.items():
            tracker = self._trackers[key]
            if tracker.fired:
                state, since = "violated", tracker.fired_at
            elif tracker.since is not None:
                state, since = "holding", tracker.since
            elif r.value is None:
                state, since = "unknown", None
            else:
                state, since = "ok", self._ok_since.get(key, now)
            out.append(
                {
                    "component": r.component,
                    "constraint": r.constraint,
                    "subject": r.subject,
                    "robots": list(r.robots),
                    "value": r.value,
                    "bound": r.bound,
                    "must_be": "above" if r.above else "below",
                    "clear": clear_level(r.bound, r.above, self.policy.clear),
                    "state": state,
                    "since": since,
                }
            )
        return out

    def _outcome(
        self, now: float, key: Key, tracker: ConditionTracker, outcome: str | None
    ) -> None:
        reading = self._readings[key]
        if outcome == FIRED:
            since = tracker.since if tracker.since is not None else now
            self._events.append(Violated(reading, since, now))
        elif outcome == CLEARED:
            self._events.append(Compliant(reading, now, "inside the bound"))
