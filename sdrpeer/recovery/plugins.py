"""Recovery plugins: causes (what a rule watches) and actions (the steps of a ladder).

How it works: two registries over entry point groups, like the allocator's (`sdrpeer.alloc.
registry`). A rule's `cause` names a `Condition` in `sdrpeer.recovery_conditions`; each step of
its ladder names an `Action` in `sdrpeer.recovery_actions`. The engine reads only what is here:

| Condition field | meaning                                                                  |
|-----------------|--------------------------------------------------------------------------|
| metrics         | the metrics a rule of this cause may watch (empty: an event)             |
| robot_wide      | True: the whole robot is sick (judged by the allocator, all components   |
|                 | move); False: one instance is at fault (handled by the robot's agent)    |
| culprit         | for a non-robot-wide metric: the `InstanceLoad` field ('rss' or 'cpu')   |
|                 | whose largest instance is the faulty one                                 |
| holds()         | the comparison (default: `value op level`); override for other kinds     |

| Action field | meaning                                                                     |
|--------------|-----------------------------------------------------------------------------|
| scope        | 'local': the robot's agent does it; 'allocator': the component moves to     |
|              | another robot (the agent escalates, the allocator acts)                     |
| prefer       | for allocator actions: 'standby' (switch to a running standby) or 'launch'  |

A plugin adds a cause by registering a `Condition` (e.g. `overheating = Condition(("temperature",),
robot_wide=True)`; robots then report `temperature` among their metrics) or a step by registering
an `Action`. The engine only needs names, scope and availability; executing a step is the
shell's job (it maps the action name to its own code).
"""

from __future__ import annotations

import operator
from collections.abc import Callable
from dataclasses import dataclass

from sdrpeer.plugins.registry import Registry
from sdrpeer.system.recovery_defaults import CAUSES

OPS: dict[str, Callable[[float, float], bool]] = {
    "<": operator.lt,
    "<=": operator.le,
    ">": operator.gt,
    ">=": operator.ge,
}
"""A rule's `op` -> the comparison between a sample and a level."""

SCOPES = ("local", "allocator")
PREFERS = ("standby", "launch")
CULPRITS = ("rss", "cpu")


@dataclass(frozen=True, slots=True)
class Condition:
    """A cause a recovery rule may name."""

    metrics: tuple[str, ...] = ()
    """The metrics a rule of this cause may watch; empty: an event reported by the platform."""
    robot_wide: bool = False
    """True: the robot is sick and all its components move (allocator); False: one instance is
    at fault and the robot's own agent handles it first."""
    culprit: str | None = None
    """Non-robot-wide metric causes: 'rss' or 'cpu', the load whose largest instance is at fault."""

    def __post_init__(self) -> None:
        if self.culprit is not None and self.culprit not in CULPRITS:
            raise ValueError(f"culprit must be one of {', '.join(CULPRITS)}, got {self.culprit!r}")

    def holds(self, value: float, op: str, level: float) -> bool:
        """Whether `value op level` (a sample exactly at the level holds for <= and >=)."""
        return OPS[op](value, level)


@dataclass(frozen=True, slots=True)
class Action:
    """A step an escalation ladder may list."""

    scope: str
    """'local' (the robot's agent) or 'allocator' (a move to another robot)."""
    prefer: str | None = None
    """Allocator steps: 'standby' or 'launch' (what the allocator tries for the move)."""

    def __post_init__(self) -> None:
        if self.scope not in SCOPES:
            raise ValueError(f"scope must be one of {', '.join(SCOPES)}, got {self.scope!r}")
        if (self.scope == "allocator") != (self.prefer in PREFERS):
            raise ValueError("an allocator action needs prefer ('standby' or 'launch'), only it")


MEMORY_SHORTAGE = Condition(CAUSES["memory_shortage"], culprit="rss")
CPU_HIGH = Condition(CAUSES["cpu_high"], culprit="cpu")
COMPONENT_ERROR = Condition()
HARDWARE_FAILURE = Condition()
ABNORMAL_BEHAVIOUR = Condition()
EMERGENCY_STOP = Condition()
LOW_BATTERY = Condition(CAUSES["low_battery"], robot_wide=True)
COMMUNICATION_FAILURE = Condition(CAUSES["communication_failure"], robot_wide=True)

STANDBY_SAME_ROBOT = Action("local")
RESTART = Action("local")
STANDBY_OTHER_ROBOT = Action("allocator", "standby")
LAUNCH_OTHER_ROBOT = Action("allocator", "launch")

CONDITIONS: Registry[Condition] = Registry(
    "sdrpeer.recovery_conditions", (Condition,), "recovery condition"
)
"""Every cause by name (entry points of `sdrpeer.recovery_conditions`, plus registered)."""
ACTIONS: Registry[Action] = Registry("sdrpeer.recovery_actions", (Action,), "recovery action")
"""Every ladder step by name (entry points of `sdrpeer.recovery_actions`, plus registered)."""
