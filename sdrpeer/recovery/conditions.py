"""One rule's condition for one subject, over time: sustain, hysteresis, staleness.

How it works: a `ConditionTracker` is fed timestamped samples of one metric and says when the
rule fires and when it clears:

| state   | sample                                   | becomes                            |
|---------|------------------------------------------|------------------------------------|
| healthy | holds (`value op threshold`)             | holding, since = now               |
| holding | holds, gap to previous <= stale_after    | holding; fires once now - since    |
|         |                                          | >= sustain_s                       |
| holding | holds, gap to previous > stale_after     | holding, since = now (run restarts)|
| holding | does not hold                            | healthy                            |
| fired   | `value op clear` no longer holds         | healthy ("cleared")                |
| fired   | anything else                            | fired (hysteresis)                 |

- A sample exactly at the threshold holds for `<=` and `>=`. `clear` defaults to the threshold:
  `rssi <= -52.5, clear -50` clears only at a sample above -50.
- A run of holding samples counts only while consecutive samples are at most `stale_after`
  apart: no samples means no evidence. Fired, though, stays fired without samples (a robot does
  not become healthy by going quiet); the caller drops the tracker when its subject is gone.
- The deadline `since + sustain_s` is in `next_timer()` while the last sample is fresh enough to
  reach it, so a shell wakes exactly when the sustain expires, not at the next sample.
- A missing sample (None) changes nothing. `rearm(now, quiet_s)` forgets a fired state and
  ignores samples until `now + quiet_s`: the rule fires again only if it still holds afterwards
  for its whole sustain (the recovery engine judges whether its step worked this way).
"""

from __future__ import annotations

import math

from sdrpeer.recovery.plugins import Condition
from sdrpeer.system.model import RecoveryRule

FIRED = "fired"
CLEARED = "cleared"


class ConditionTracker:
    """The condition of one metric rule for one subject (a robot)."""

    def __init__(self, rule: RecoveryRule, condition: Condition, stale_after_s: float) -> None:
        if rule.metric is None or rule.op is None or rule.threshold is None:
            raise ValueError(f"rule for {rule.cause} watches no metric: it is an event")
        self.rule = rule
        self.condition = condition
        self.stale_after_s = stale_after_s
        self.metric: str = rule.metric
        self.op: str = rule.op
        self.threshold = rule.threshold
        self.clear = rule.threshold if rule.clear is None else rule.clear
        self.fired = False
        """Whether the rule has fired and not cleared."""
        self.since: float | None = None
        """Start of the current run of holding samples (None: not holding)."""
        self.fired_at: float | None = None
        self.value: float | None = None
        """The last sample's value."""
        self.last_at: float | None = None
        """The last sample's time."""
        self._quiet_until = -math.inf

    def observe(self, now: float, value: float | None) -> str | None:
        """A sample at `now`: FIRED, CLEARED, or None when nothing changed."""
        if value is None or now < self._quiet_until:
            return None
        previous = self.last_at
        self.value, self.last_at = value, now
        if self.fired:
            if not self.condition.holds(value, self.op, self.clear):
                self.fired, self.since, self.fired_at = False, None, None
                return CLEARED
            return None
        if not self.condition.holds(value, self.op, self.threshold):
            self.since = None
            return None
        if self.since is None or previous is None or now - previous > self.stale_after_s:
            self.since = now
        return self._maybe_fire(now)

    def handle_timer(self, now: float) -> str | None:
        """The deadline of `next_timer()` has passed: FIRED if the sustain has expired."""
        if self.fired or self.since is None or self.last_at is None:
            return None
        if now > self.last_at + self.stale_after_s:
            return None
        return self._maybe_fire(now)

    def next_timer(self) -> float:
        """When the sustain of the current run expires (inf: nothing to wait for)."""
        if self.fired or self.since is None or self.last_at is None:
            return math.inf
        deadline = self.since + self.rule.sustain_s
        return deadline if deadline <= self.last_at + self.stale_after_s else math.inf

    def rearm(self, now: float, quiet_s: float) -> None:
        """Forget the fired state and ignore samples for `quiet_s`; it may fire again later."""
        self.fired, self.since, self.fired_at = False, None, None
        self._quiet_until = now + quiet_s

    def _maybe_fire(self, now: float) -> str | None:
        assert self.since is not None
        if now >= self.since + self.rule.sustain_s:  # the same sum as next_timer(): no float gap
            self.fired, self.fired_at = True, now
            return FIRED
        return None
