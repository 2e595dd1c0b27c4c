"""Automatic recovery (the paper's Table III) as pure cores: samples and faults in, decisions out.

How it works:
- `conditions.ConditionTracker`: one metric rule for one subject (threshold, `for:`, `clear:`);
- `ladder.Escalation`: one subject's escalation ladder, attempts counted within a window;
- `local.LocalRecovery` (every robot's agent): component faults and memory / CPU shortage of its
  own instances, handled at once; escalates to the allocator when its local steps are spent;
- `robot_conditions.RobotMonitor` (the allocator): low battery and communication failure of any
  robot, from gossip, including other robots' measurements of the sick robot's links;
- `allocator.AllocatorRecovery` (the allocator): turns both into `Move`s, with a minimum dwell;
- `plugins`: causes and actions as entry point plugins (`sdrpeer.recovery_conditions`,
  `sdrpeer.recovery_actions`).
Nothing here reads a clock or does I/O: the shells pass `now` in and wake at `next_timer()`.
"""

from sdrpeer.recovery.allocator import AllocatorRecovery
from sdrpeer.recovery.conditions import ConditionTracker
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import (
    Cleared,
    Decision,
    Exhausted,
    InstanceLoad,
    Move,
    RobotCondition,
)
from sdrpeer.recovery.ladder import Escalation
from sdrpeer.recovery.local import LocalRecovery
from sdrpeer.recovery.plugins import ACTIONS, CONDITIONS, Action, Condition
from sdrpeer.recovery.robot_conditions import RobotMonitor

__all__ = [
    "ACTIONS",
    "CONDITIONS",
    "Action",
    "AllocatorRecovery",
    "Cleared",
    "Condition",
    "ConditionTracker",
    "Decision",
    "Escalation",
    "Exhausted",
    "InstanceLoad",
    "LocalRecovery",
    "Move",
    "RecoveryConfig",
    "RobotCondition",
    "RobotMonitor",
]
