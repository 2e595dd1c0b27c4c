"""Recovery on one robot, for its own instances (runs in the robot's agent).

How it works: component faults are handled at once, here, without asking anyone:

| input                                        | rule used                                      |
|----------------------------------------------|------------------------------------------------|
| `instance_fault(now, instance, component,    | the rule of `cause` (component_error,          |
|  cause, detail)`                             | hardware_failure, abnormal_behaviour,          |
|                                              | emergency_stop, a plugin's); `crashed` (the    |
|                                              | host process died) uses a `crashed` rule if    |
|                                              | there is one, else component_error's           |
| `robot_metrics(now, metrics, instances)`     | metric rules of non-robot-wide causes          |
|                                              | (memory_shortage, cpu_high): when one fires,   |
|                                              | the faulty instance is the active one with the |
|                                              | largest load the cause names (RSS, CPU)        |

Each (component, cause, metric) has an `Escalation` over its rule's ladder. A step is available
when it is an allocator step (the allocator decides between standby and launch), or a local one
other than `standby_same_robot`, which needs a standby of the component on this robot
(`set_standbys`). A `Decision` with `escalate=False` is for the agent (stop the faulty instance
and activate the standby, or restart it); `escalate=True` means the local steps are exhausted
or the rule starts with a move: the agent sends the decision to the allocator
(`AllocatorRecovery.escalation`). `action_result(now, decision, ok)` reports whether the step
could be carried out (for an escalation: whether the allocator took it); a failed step is not
repeated and the next one is decided at once. Until it is reported, more faults of the same
component and cause are the same fault (an instance in ERROR whose host then exits) and ignored.

A metric condition is re-armed after each step: samples are ignored for `settle_s`, and if the
condition still holds afterwards for its whole `for:`, it fires again and the step was
unresolved. Robot-wide causes (low battery, communication failure) are not judged here: the
allocator does, from gossip (`RobotMonitor`), because a robot with a bad link may not be able
to speak for itself. Every time is passed in; the shell wakes at `next_timer()`.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Collection, Mapping

from sdrpeer.recovery.conditions import FIRED, ConditionTracker
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Decision, Exhausted, InstanceLoad, LocalOutput
from sdrpeer.recovery.ladder import Escalation
from sdrpeer.recovery.plugins import ACTIONS, CONDITIONS
from sdrpeer.system.model import RecoveryDef, RecoveryRule

CRASHED = "crashed"
"""The host process of an instance died (the supervisor saw it exit)."""
FALLBACK_CAUSES = {CRASHED: "component_error"}
"""A cause without a rule of its own uses this cause's rule."""
STANDBY_SAME_ROBOT = "standby_same_robot"

_Key = tuple[str, str, str | None]


class LocalRecovery:
    """The recovery decisions of one robot's agent about its own instances."""

    def __init__(
        self, robot: str, recovery: RecoveryDef, config: RecoveryConfig | None = None
    ) -> None:
        """Raises ConfigError when a rule names an unknown cause or action."""
        self.robot = robot
        self.recovery = recovery
        self.config = config or RecoveryConfig()
        self._local_steps = {
            a for rule in recovery.rules for a in rule.actions if ACTIONS.get(a).scope == "local"
        }
        self._events: dict[str, RecoveryRule] = {}
        self._trackers: list[ConditionTracker] = []
        for rule in recovery.rules:
            condition = CONDITIONS.get(rule.cause)
            if rule.metric is None:
                self._events.setdefault(rule.cause, rule)
            elif not condition.robot_wide:
                stale = self.config.local_stale_after_s
                self._trackers.append(ConditionTracker(rule, condition, stale))
        self._standbys: frozenset[str] = frozenset()
        self._instances: dict[str, InstanceLoad] = {}
        self._ladders: dict[_Key, Escalation] = {}
        self._pending: dict[_Key, str] = {}
        """Ladders with a decision not yet reported done -> the instance it was for."""
        self._queue: deque[LocalOutput] = deque()

    # -- inputs -------------------------------------------------------------------------------

    def set_standbys(self, components: Collection[str]) -> None:
        """The components that have a standby instance on this robot now (ready to switch to)."""
        self._standbys = frozenset(components)

    def instance_fault(
        self, now: float, instance: str, component: str, cause: str, detail: str = ""
    ) -> None:
        """`instance` (of `component`) reported or showed a fault: decide at once."""
        rule = self._events.get(cause)
        if rule is None and cause in FALLBACK_CAUSES:
            rule = self._events.get(FALLBACK_CAUSES[cause])
        if rule is None:
            return  # no rule for this cause in the system file: nothing to do
        if rule.cause != cause:
            detail = f"{cause}: {detail}" if detail else cause
        self._decide(now, rule, (component, rule.cause, None), instance, detail)

    def robot_metrics(
        self, now: float, metrics: Mapping[str, float | None], instances: Mapping[str, InstanceLoad]
    ) -> None:
        """This robot's metrics at `now` (mem_free bytes, cpu %, ...) and its active instances
        by name with their load (the faulty one is chosen among them)."""
        self._instances = dict(instances)
        for tracker in self._trackers:
            if tracker.observe(now, metrics.get(tracker.metric)) == FIRED:
                self._metric_fired(now, tracker)

    def handle_timer(self, now: float) -> None:
        """The deadline of `next_timer()` has passed."""
        for tracker in self._trackers:
            if tracker.next_timer() <= now and tracker.handle_timer(now) == FIRED:
                self._metric_fired(now, tracker)

    def action_result(self, now: float, decision: Decision, ok: bool) -> None:
        """The agent carried out `decision` (`ok`; for an escalation: the allocator took it), or
        could not: then the next step is decided at once. Until this is called, further faults
        of the same component and cause are taken as the same fault and ignored."""
        key = (decision.component, decision.cause, decision.metric)
        ladder = self._ladders.get(key)
        if ladder is None or self._pending.get(key) != decision.instance:
            return
        del self._pending[key]
        ladder.outcome(now, ok)
        if not ok:
            rule = self._rule_of(key)
            if rule is not None:
                self._decide(now, rule, key, decision.instance, decision.detail)

    # -- outputs ------------------------------------------------------------------------------

    def next_decision(self) -> LocalOutput | None:
        """The oldest decision (or exhausted ladder) not yet taken, or None."""
        return self._queue.popleft() if self._queue else None

    def next_timer(self) -> float:
        """The earliest sustain deadline of a metric condition (inf: none)."""
        return min((t.next_timer() for t in self._trackers), default=math.inf)

    # -- internals ----------------------------------------------------------------------------

    def _metric_fired(self, now: float, tracker: ConditionTracker) -> None:
        culprit = tracker.condition.culprit or "rss"
        if not self._instances:
            return  # nothing runs here: nothing to blame (the condition stays fired)
        instance = max(self._instances, key=lambda n: (getattr(self._instances[n], culprit), n))
        component = self._instances[instance].component
        detail = f"{tracker.metric} {tracker.value:g} {tracker.op} {tracker.threshold:g}"
        key = (component, tracker.rule.cause, tracker.metric)
        self._decide(now, tracker.rule, key, instance, detail)
        tracker.rearm(now, self.config.settle_s)

    def _decide(
        self, now: float, rule: RecoveryRule, key: _Key, instance: str, detail: str
    ) -> None:
        component, cause, metric = key
        if key in self._pending:
            return  # a step for this component and cause is still being carried out
        ladder = self._ladders.get(key)
        if ladder is None or ladder.idle(now):
            ladder = Escalation(
                rule.actions,
                self._local_steps,
                self.recovery.max_attempts,
                self.recovery.window_s,
            )
            self._ladders[key] = ladder
        available = {
            a for a in rule.actions if a != STANDBY_SAME_ROBOT or component in self._standbys
        }
        step = ladder.next_action(now, available)
        if step is None:
            self._queue.append(Exhausted(instance, component, cause, now, detail))
            return
        index, action = step
        escalate = ACTIONS.get(action).scope == "allocator"
        self._pending[key] = instance
        self._queue.append(
            Decision(action, instance, component, cause, index, escalate, now, detail, metric)
        )

    def _rule_of(self, key: _Key) -> RecoveryRule | None:
        _, cause, metric = key
        if metric is None:
            return self._events.get(cause)
        for tracker in self._trackers:
            if (tracker.rule.cause, tracker.metric) == (cause, metric):
                return tracker.rule
        return None
