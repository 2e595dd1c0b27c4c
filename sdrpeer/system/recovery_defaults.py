"""The paper's Table III as data: the recovery causes, actions and default rules.

How it works: `CAUSES` says, for each cause a rule may name, which metrics it watches (none for
events, which the platform reports itself: a component in ERROR, a failed device, abnormal
behaviour, an emergency stop). `ACTIONS` are the steps of an escalation ladder.
`default_recovery()` is what a system file without a `recovery:` section gets:

| cause                 | condition (clears at)                        | ladder                |
|-----------------------|----------------------------------------------|-----------------------|
| memory_shortage       | mem_free <= 200MB (250MB)                    | LOCAL_FIRST           |
| cpu_high              | cpu >= 90% for 5s (80%)                      | LOCAL_FIRST           |
| component_error, hardware_failure, abnormal_behaviour, emergency_stop | event | MOVE  |
| low_battery           | battery <= 15% (20%)                         | MOVE                  |
| communication_failure | rssi <= -52.5dBm for 6s (-50dBm)             | MOVE                  |
|                       | delay >= 200ms (150ms), jitter >= 50ms (30ms), loss >= 30% (20%), 6s |

LOCAL_FIRST = standby_same_robot, restart, standby_other_robot, launch_other_robot (Table III:
switch to a standby on the same robot, else restart; if still unresolved, a standby on another
robot, else launch on another robot). MOVE = standby_other_robot, launch_other_robot. The
memory, RSSI, battery and CPU levels are those of the agent's traps (sdrpeer.monitor.traps) and
of Table VI; low_battery moves every component of the robot, the engine knows that from the cause.
"""

from __future__ import annotations

from sdrpeer.system.model import RecoveryDef, RecoveryRule

CAUSES: dict[str, tuple[str, ...]] = {
    "memory_shortage": ("mem_free",),
    "cpu_high": ("cpu",),
    "component_error": (),
    "hardware_failure": (),
    "abnormal_behaviour": (),
    "emergency_stop": (),
    "low_battery": ("battery",),
    "communication_failure": ("rssi", "delay", "jitter", "loss"),
}
"""Cause -> the metrics its `when:` may watch (empty: an event, no `when:`)."""

ACTIONS = ("standby_same_robot", "restart", "standby_other_robot", "launch_other_robot")
"""The steps a ladder may list, in the order Table III tries them."""

LOCAL_FIRST = ACTIONS
MOVE = ("standby_other_robot", "launch_other_robot")

_MB = 1_000_000


def default_recovery() -> RecoveryDef:
    """Table III with the paper's (Table VI) and the agent's trap levels."""
    rules = (
        RecoveryRule("memory_shortage", "mem_free", "<=", 200 * _MB, 0.0, 250 * _MB, LOCAL_FIRST),
        RecoveryRule("cpu_high", "cpu", ">=", 90.0, 5.0, 80.0, LOCAL_FIRST),
        RecoveryRule("component_error", actions=MOVE),
        RecoveryRule("hardware_failure", actions=MOVE),
        RecoveryRule("abnormal_behaviour", actions=MOVE),
        RecoveryRule("emergency_stop", actions=MOVE),
        RecoveryRule("low_battery", "battery", "<=", 15.0, 0.0, 20.0, MOVE),
        RecoveryRule("communication_failure", "rssi", "<=", -52.5, 6.0, -50.0, MOVE),
        RecoveryRule("communication_failure", "delay", ">=", 200.0, 6.0, 150.0, MOVE),
        RecoveryRule("communication_failure", "jitter", ">=", 50.0, 6.0, 30.0, MOVE),
        RecoveryRule("communication_failure", "loss", ">=", 0.3, 6.0, 0.2, MOVE),
    )
    return RecoveryDef(rules=rules)
