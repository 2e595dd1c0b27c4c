"""What the recovery cores report to their shells: conditions, decisions and moves.

Everything is a frozen dataclass; times are the `now` values the caller passed in.
"""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True, slots=True)
class InstanceLoad:
    """One active instance on this robot, as the agent measures it (input of `LocalRecovery`)."""

    component: str
    rss: float
    """Resident memory, bytes."""
    cpu: float
    """CPU, percent of one core."""


@dataclass(frozen=True, slots=True)
class RobotCondition:
    """A robot-wide rule fired for `robot` (low battery, communication failure, plugins)."""

    robot: str
    cause: str
    metric: str
    value: float
    """The sample that fired it (for link metrics: the majority view of the robot's peers)."""
    since: float
    """When the condition started to hold."""
    fired_at: float


@dataclass(frozen=True, slots=True)
class Cleared:
    """A robot-wide condition of `robot` crossed its clearing level."""

    robot: str
    cause: str
    metric: str
    value: float
    at: float


RobotEvent = RobotCondition | Cleared


@dataclass(frozen=True, slots=True)
class Decision:
    """What the robot's agent must do now about one instance (output of `LocalRecovery`)."""

    action: str
    """The ladder step: standby_same_robot, restart, standby_other_robot, launch_other_robot, or
    a plugin's."""
    instance: str
    """The faulty instance (stop it for standby_same_robot; restart it for restart)."""
    component: str
    cause: str
    step_index: int
    """The step's position in the rule's ladder."""
    escalate: bool
    """True: the local steps are exhausted, the allocator must move the component (send it this
    decision); False: the agent acts itself."""
    at: float
    detail: str = ""
    """What was seen (e.g. 'mem_free 1.5e+08 <= 2e+08', or the fault's own message)."""
    metric: str | None = None
    """The metric of the rule that fired (None for an event such as component_error)."""


@dataclass(frozen=True, slots=True)
class Exhausted:
    """Every step of the ladder was tried within the window and the fault is back: nothing more
    is done until a fault comes after the window (the shell logs it, an operator looks)."""

    instance: str
    component: str
    cause: str
    at: float
    detail: str = ""


LocalOutput = Decision | Exhausted


@dataclass(frozen=True, slots=True)
class Move:
    """The allocator must move `component` off `from_robot` (output of `AllocatorRecovery`)."""

    component: str
    from_robot: str
    cause: str
    prefer: str
    """'standby': switch to a running standby on another robot, else launch; 'launch': launch
    on another robot (a standby may still be reused by the placer)."""
    at: float
