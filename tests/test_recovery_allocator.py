"""AllocatorRecovery: moves off sick robots and escalations, no bounce back (literal times)."""

from __future__ import annotations

from dataclasses import replace

import pytest

from sdrpeer.errors import ConfigError
from sdrpeer.recovery.allocator import AllocatorRecovery
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Decision, Move, RobotCondition
from sdrpeer.recovery.robot_conditions import RobotMonitor
from sdrpeer.system.model import RecoveryRule
from sdrpeer.system.recovery_defaults import default_recovery


def moves(a: AllocatorRecovery) -> list[Move]:
    out = []
    while (m := a.next_move()) is not None:
        out.append(m)
    return out


def test_weak_link_moves_every_component_of_the_robot_as_in_the_paper() -> None:
    """Fig. 3-(2): robot-1's components go to standbys elsewhere, else are launched there."""
    rec = default_recovery()
    monitor = RobotMonitor(rec, RecoveryConfig())
    alloc = AllocatorRecovery(rec)
    for now in (107.0, 110.0, 113.0):
        monitor.observe_robot(now, "robot-1", {"rssi": -55.0})
    event = monitor.next_event()
    assert isinstance(event, RobotCondition)
    alloc.robot_condition(113.0, event, ["OmnidirectionalCameraRTC", "AnomalyDetectionRTC"])
    assert moves(alloc) == [
        Move("AnomalyDetectionRTC", "robot-1", "communication_failure", "standby", 113.0),
        Move("OmnidirectionalCameraRTC", "robot-1", "communication_failure", "standby", 113.0),
    ]
    assert alloc.moving() == {
        "AnomalyDetectionRTC": "robot-1",
        "OmnidirectionalCameraRTC": "robot-1",
    }


def test_low_battery_moves_all_components_and_a_launch_ladder_prefers_launch() -> None:
    rec = default_recovery()
    rules = tuple(
        replace(r, actions=("launch_other_robot",)) if r.cause == "low_battery" else r
        for r in rec.rules
    )
    alloc = AllocatorRecovery(replace(rec, rules=rules))
    event = RobotCondition("robot-2", "low_battery", "battery", 12.0, 50.0, 50.0)
    alloc.robot_condition(50.0, event, ["Cam", "Ctl"])
    assert [(m.component, m.prefer) for m in moves(alloc)] == [("Cam", "launch"), ("Ctl", "launch")]


def test_an_escalation_moves_one_component_with_the_step_the_robot_chose() -> None:
    alloc = AllocatorRecovery(default_recovery())
    d = Decision("launch_other_robot", "Det#0", "Det", "memory_shortage", 3, True, 9.0)
    alloc.escalation(9.5, "robot-3", d)
    assert moves(alloc) == [Move("Det", "robot-3", "memory_shortage", "launch", 9.5)]


def test_a_component_being_moved_is_not_moved_twice() -> None:
    alloc = AllocatorRecovery(default_recovery())
    event = RobotCondition("robot-1", "communication_failure", "rssi", -55.0, 0.0, 6.0)
    alloc.robot_condition(6.0, event, ["Cam"])
    again = RobotCondition("robot-1", "communication_failure", "loss", 0.4, 0.0, 7.0)
    alloc.robot_condition(7.0, again, ["Cam"])
    assert len(moves(alloc)) == 1
    alloc.move_failed(8.0, "Cam")  # nowhere to go yet
    alloc.robot_condition(9.0, again, ["Cam"])
    assert len(moves(alloc)) == 1


def test_a_moved_component_does_not_bounce_back_within_min_dwell() -> None:
    rec = replace(default_recovery(), min_dwell_s=30.0)
    alloc = AllocatorRecovery(rec)
    event = RobotCondition("robot-1", "communication_failure", "rssi", -55.0, 107.0, 113.0)
    alloc.robot_condition(113.0, event, ["Cam"])
    moves(alloc)
    alloc.moved(114.0, "Cam", "robot-1")
    assert alloc.moving() == {}
    assert alloc.avoid("Cam", 114.0) == {"robot-1"}
    assert alloc.avoid("Cam", 143.9) == {"robot-1"}
    assert alloc.avoid("Cam", 144.0) == set()
    assert alloc.avoid("Det", 114.0) == set()


def test_the_cause_clearing_and_returning_keeps_the_robot_excluded() -> None:
    """Link back at 120 s, bad again at 130 s: robot-1 receives nothing in between."""
    rec = default_recovery()  # rssi clears above -50 dBm, min dwell 30 s
    monitor = RobotMonitor(rec, RecoveryConfig())
    for now in (107.0, 110.0, 113.0):
        monitor.observe_robot(now, "robot-1", {"rssi": -55.0})
    monitor.observe_robot(120.0, "robot-1", {"rssi": -45.0})
    assert monitor.degraded(120.0) == set()
    assert "robot-1" in monitor.excluded(125.0)
    monitor.observe_robot(130.0, "robot-1", {"rssi": -55.0})
    assert "robot-1" in monitor.excluded(131.0)
    monitor.observe_robot(133.0, "robot-1", {"rssi": -48.0})  # never held for 6 s: no fire
    assert monitor.degraded(150.0) == set()
    assert monitor.excluded(149.9) == {"robot-1"}
    assert monitor.excluded(150.0) == set()


def test_an_unknown_rule_action_is_a_config_error() -> None:
    rec = replace(default_recovery(), rules=(RecoveryRule("component_error", actions=("pray",)),))
    with pytest.raises(ConfigError, match="unknown recovery action 'pray'"):
        AllocatorRecovery(rec)
