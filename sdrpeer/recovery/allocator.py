"""Recovery on the allocator: moves off sick robots and escalated components, without bounce.

How it works: the allocator's shell feeds two kinds of trouble and gets `Move`s back:

| input                                         | moves                                          |
|-----------------------------------------------|------------------------------------------------|
| `robot_condition(now, event, components)`     | every component placed on `event.robot` (a     |
|  (a `RobotCondition` from `RobotMonitor`)     | robot-wide cause: low battery, communication   |
|                                               | failure), prefer = its rule's first move step  |
| `escalation(now, robot, decision)`            | `decision.component` off `robot`, prefer = the |
|  (a `Decision` with escalate=True from a      | step the robot chose (standby_other_robot ->   |
|  robot's `LocalRecovery`)                     | 'standby', launch_other_robot -> 'launch')     |

`prefer='standby'` tries a running standby on another robot first, then a launch (the ladder
standby_other_robot -> launch_other_robot); 'launch' skips the standby. A component with a move
in progress is not moved again until the shell reports `moved(now, component, from_robot)` or
`move_failed(now, component)`. After a move the component avoids the robot it left for
`min_dwell_s` (`avoid(component, now)`), on top of the robots `RobotMonitor.excluded(now)` keeps
everything off: so a component does not bounce back while a cause clears and returns.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Iterable

from sdrpeer.recovery.events import Decision, Move, RobotCondition
from sdrpeer.recovery.plugins import ACTIONS
from sdrpeer.system.model import RecoveryDef

LAUNCH = "launch"


class AllocatorRecovery:
    """The allocator's recovery moves and each moved component's dwell."""

    def __init__(self, recovery: RecoveryDef) -> None:
        """Raises ConfigError when a rule names an unknown action."""
        self.recovery = recovery
        self._prefer: dict[tuple[str, str | None], str] = {}
        for rule in recovery.rules:
            moves = [ACTIONS.get(a).prefer for a in rule.actions]
            first = next((p for p in moves if p is not None), LAUNCH)
            self._prefer.setdefault((rule.cause, rule.metric), first)
        self._moving: dict[str, str] = {}
        """Component -> the robot it is being moved off."""
        self._left: dict[str, dict[str, float]] = {}
        """Component -> robot it left -> until when it must not go back there."""
        self._moves: deque[Move] = deque()

    # -- inputs -------------------------------------------------------------------------------

    def robot_condition(self, now: float, event: RobotCondition, components: Iterable[str]) -> None:
        """`event.robot` is sick: move the `components` placed on it (its active instances)."""
        prefer = self._prefer.get((event.cause, event.metric), LAUNCH)
        for component in sorted(set(components)):
            self._move(Move(component, event.robot, event.cause, prefer, now))

    def escalation(self, now: float, robot: str, decision: Decision) -> None:
        """`robot` exhausted its local steps for `decision.component`: move it."""
        prefer = ACTIONS.get(decision.action).prefer or LAUNCH
        self._move(Move(decision.component, robot, decision.cause, prefer, now))

    def moved(self, now: float, component: str, from_robot: str) -> None:
        """A plan moved `component` off `from_robot`: it stays away for `min_dwell_s`."""
        self._moving.pop(component, None)
        self._left.setdefault(component, {})[from_robot] = now + self.recovery.min_dwell_s

    def move_failed(self, now: float, component: str) -> None:
        """The move of `component` could not be placed; a later condition or escalation retries."""
        self._moving.pop(component, None)

    # -- outputs ------------------------------------------------------------------------------

    def next_move(self) -> Move | None:
        """The oldest move not yet taken, or None."""
        return self._moves.popleft() if self._moves else None

    def moving(self) -> dict[str, str]:
        """Components with a move in progress -> the robot they are leaving."""
        return dict(self._moving)

    def avoid(self, component: str, now: float) -> set[str]:
        """Robots `component` left less than `min_dwell_s` ago: do not place it there."""
        left = self._left.get(component, {})
        for robot in [r for r, until in left.items() if now >= until]:
            del left[robot]
        return set(left)

    # -- internals ----------------------------------------------------------------------------

    def _move(self, move: Move) -> None:
        if move.component in self._moving:
            return
        self._moving[move.component] = move.from_robot
        self._moves.append(move)
