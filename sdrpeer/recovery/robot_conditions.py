"""Robot-wide conditions (low battery, communication failure), judged by the allocator.

How it works: `RobotMonitor` keeps one `ConditionTracker` per (robot, robot-wide metric rule)
and feeds it from gossip:

- `observe_robot(now, robot, metrics)`: what a robot says of itself (battery, rssi, its typical
  link delay, jitter and loss, and any metric a plugin cause watches); `mem_free` and `cpu` are
  accepted and ignored here: memory shortage and high CPU blame one instance and are handled by
  the robot's own agent (`LocalRecovery`). The link values are the ones a strict majority of
  the links the robot measures reach or pass (`sdrpeer.monitor.links.summarize`): one peer
  with a bad radio cannot make a healthy robot sick (its other links stay good), while a robot
  whose own radio is bad is sick at once (all its links are). A probe measures the round trip,
  so a robot's view of its links is also its peers' view of it. With a single peer (two robots)
  that one link decides, and the robot's own RSSI is the tie-breaker the rules add;
- `robot_gone(now, robot)`: the robot left or died; its trackers are dropped.

Outputs: `next_event()` drains `RobotCondition` / `Cleared`; `fired()` lists what holds now.
`degraded(now)`: robots with a fired robot-wide rule: the allocator places nothing on them and
moves their components away; an allocator that is itself degraded abdicates. `excluded(now)`:
degraded robots plus those whose last condition cleared less than `min_dwell_s` ago, so that
components do not bounce back while a cause clears and returns. `next_timer()`/`handle_timer`
fire sustain deadlines between samples.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping

from sdrpeer.recovery.conditions import CLEARED, FIRED, ConditionTracker
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Cleared, RobotCondition, RobotEvent
from sdrpeer.recovery.plugins import CONDITIONS, Condition
from sdrpeer.system.model import RecoveryDef, RecoveryRule


def robot_wide_rules(recovery: RecoveryDef) -> list[tuple[RecoveryRule, Condition]]:
    """The metric rules whose cause makes a whole robot sick, with their conditions."""
    out = []
    for rule in recovery.rules:
        condition = CONDITIONS.get(rule.cause)
        if condition.robot_wide and rule.metric is not None:
            out.append((rule, condition))
    return out


class RobotMonitor:
    """The allocator's judgement of every robot's robot-wide conditions."""

    def __init__(self, recovery: RecoveryDef, config: RecoveryConfig | None = None) -> None:
        self.recovery = recovery
        self.config = config or RecoveryConfig()
        self.rules = robot_wide_rules(recovery)
        self._trackers: dict[tuple[str, int], ConditionTracker] = {}
        self._dwell_until: dict[str, float] = {}
        self._events: deque[RobotEvent] = deque()

    # -- inputs -------------------------------------------------------------------------------

    def observe_robot(self, now: float, robot: str, metrics: Mapping[str, float | None]) -> None:
        """A robot's own metrics and typical link values (from its gossiped record) at `now`."""
        for i, (rule, _) in enumerate(self.rules):
            assert rule.metric is not None
            if rule.metric in metrics:
                self._feed(now, robot, i, metrics[rule.metric])

    def robot_gone(self, now: float, robot: str) -> None:
        """`robot` left or died: forget it (a dwell still starts if it was sick)."""
        if robot in self.degraded(now):
            self._dwell_until[robot] = now + self.recovery.min_dwell_s
        for key in [k for k in self._trackers if k[0] == robot]:
            del self._trackers[key]

    def handle_timer(self, now: float) -> None:
        """The deadline of `next_timer()` has passed."""
        for (robot, _), tracker in list(self._trackers.items()):
            if tracker.next_timer() <= now and tracker.handle_timer(now) == FIRED:
                self._fired(robot, tracker)

    # -- outputs ------------------------------------------------------------------------------

    def next_timer(self) -> float:
        """The earliest sustain deadline (inf: none)."""
        return min((t.next_timer() for t in self._trackers.values()), default=math.inf)

    def next_event(self) -> RobotEvent | None:
        """The oldest condition fired or cleared not yet taken, or None."""
        return self._events.popleft() if self._events else None

    def fired(self) -> list[RobotCondition]:
        """Every robot-wide condition that holds now, by robot and rule."""
        return [
            self._condition(robot, t) for (robot, _), t in sorted(self._trackers.items()) if t.fired
        ]

    def degraded(self, now: float) -> set[str]:
        """Robots with a fired robot-wide condition: place nothing there, move their components."""
        return {robot for (robot, _), t in self._trackers.items() if t.fired}

    def excluded(self, now: float) -> set[str]:
        """Degraded robots, plus those whose condition cleared less than `min_dwell_s` ago."""
        dwelling = {r for r, until in self._dwell_until.items() if now < until}
        return self.degraded(now) | dwelling

    # -- internals ----------------------------------------------------------------------------

    def _feed(self, now: float, robot: str, i: int, value: float | None) -> None:
        tracker = self._trackers.get((robot, i))
        if tracker is None:
            if value is None:
                return
            rule, condition = self.rules[i]
            tracker = ConditionTracker(rule, condition, self.config.gossip_stale_after_s)
            self._trackers[(robot, i)] = tracker
        change = tracker.observe(now, value)
        if change == FIRED:
            self._fired(robot, tracker)
        elif change == CLEARED:
            value = tracker.value
            assert value is not None
            self._events.append(Cleared(robot, tracker.rule.cause, tracker.metric, value, now))
            if robot not in self.degraded(now):
                self._dwell_until[robot] = now + self.recovery.min_dwell_s

    def _fired(self, robot: str, tracker: ConditionTracker) -> None:
        self._events.append(self._condition(robot, tracker))

    def _condition(self, robot: str, tracker: ConditionTracker) -> RobotCondition:
        value, since, fired_at = tracker.value, tracker.since, tracker.fired_at
        assert value is not None
        assert since is not None
        assert fired_at is not None
        return RobotCondition(robot, tracker.rule.cause, tracker.metric, value, since, fired_at)
