"""Recovery plugins: built-in causes and actions as entry points; plugins added in a test."""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import replace

import pytest

from sdrpeer.errors import ConfigError
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Decision, RobotCondition
from sdrpeer.recovery.local import LocalRecovery
from sdrpeer.recovery.plugins import ACTIONS, CONDITIONS, Action, Condition
from sdrpeer.recovery.robot_conditions import RobotMonitor
from sdrpeer.system.model import RecoveryRule
from sdrpeer.system.recovery_defaults import ACTIONS as TABLE_III_ACTIONS
from sdrpeer.system.recovery_defaults import CAUSES, MOVE, default_recovery


@pytest.fixture
def plugins() -> Iterator[None]:
    CONDITIONS.register("overheating", Condition(("temperature",), robot_wide=True))
    CONDITIONS.register("camera_blind", Condition())
    ACTIONS.register("reset_device", Action("local"))
    yield
    CONDITIONS.unregister("overheating")
    CONDITIONS.unregister("camera_blind")
    ACTIONS.unregister("reset_device")


def test_every_table_iii_cause_and_action_is_an_installed_entry_point() -> None:
    assert set(CAUSES) <= set(CONDITIONS.names())
    assert set(TABLE_III_ACTIONS) <= set(ACTIONS.names())
    for cause, metrics in CAUSES.items():
        assert CONDITIONS.get(cause).metrics == metrics
    assert CONDITIONS.get("low_battery").robot_wide
    assert not CONDITIONS.get("memory_shortage").robot_wide
    assert ACTIONS.get("standby_other_robot") == Action("allocator", "standby")


@pytest.mark.usefixtures("plugins")
def test_a_plugin_cause_on_a_new_metric_degrades_a_robot() -> None:
    rule = RecoveryRule("overheating", "temperature", ">=", 80.0, 2.0, 70.0, MOVE)
    rec = replace(default_recovery(), rules=(*default_recovery().rules, rule))
    m = RobotMonitor(rec, RecoveryConfig())
    for now in (0.0, 1.0, 2.0):
        m.observe_robot(now, "robot-1", {"temperature": 85.0})
    assert m.next_event() == RobotCondition("robot-1", "overheating", "temperature", 85.0, 0.0, 2.0)
    assert m.degraded(2.0) == {"robot-1"}


@pytest.mark.usefixtures("plugins")
def test_a_plugin_event_cause_with_a_plugin_action_first() -> None:
    rule = RecoveryRule("camera_blind", actions=("reset_device", "launch_other_robot"))
    rec = replace(default_recovery(), rules=(rule,), max_attempts=1)
    r = LocalRecovery("robot-1", rec, RecoveryConfig())
    r.instance_fault(1.0, "Cam#0", "Cam", "camera_blind", "all black")
    d = r.next_decision()
    assert isinstance(d, Decision)
    assert (d.action, d.escalate) == ("reset_device", False)
    r.action_result(1.5, d, ok=True)
    r.instance_fault(4.0, "Cam#0", "Cam", "camera_blind")
    d = r.next_decision()
    assert isinstance(d, Decision)
    assert (d.action, d.escalate) == ("launch_other_robot", True)


def test_an_unknown_cause_is_a_config_error_naming_the_known_ones() -> None:
    rec = replace(default_recovery(), rules=(RecoveryRule("gremlins", actions=MOVE),))
    with pytest.raises(ConfigError, match=r"unknown recovery condition 'gremlins'.*low_battery"):
        LocalRecovery("robot-1", rec)


def test_plugin_objects_are_checked() -> None:
    with pytest.raises(ValueError, match="needs prefer"):
        Action("allocator")
    with pytest.raises(ValueError, match="scope"):
        Action("elsewhere")
    with pytest.raises(ValueError, match="culprit"):
        Condition(("x",), culprit="disk")
    with pytest.raises(ConfigError, match="is a str, not a Condition"):
        CONDITIONS.register("bad", "not a condition")  # type: ignore[arg-type]
