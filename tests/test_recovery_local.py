"""LocalRecovery: a robot's own faults and memory/CPU shortage, step by step (literal times)."""

from __future__ import annotations

from dataclasses import replace

from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Decision, Exhausted, InstanceLoad, LocalOutput
from sdrpeer.recovery.local import LocalRecovery
from sdrpeer.system.recovery_defaults import default_recovery

MB = 1_000_000
CONFIG = RecoveryConfig(local_stale_after_s=3.0, settle_s=5.0)


def drain(r: LocalRecovery) -> list[LocalOutput]:
    out = []
    while (d := r.next_decision()) is not None:
        out.append(d)
    return out


def steps(r: LocalRecovery) -> list[tuple[str, str, bool]]:
    return [(d.action, d.instance, d.escalate) for d in drain(r) if isinstance(d, Decision)]


def done(r: LocalRecovery, now: float, ok: bool = True) -> list[LocalOutput]:
    """Carry out every queued decision and report it; what follows."""
    out = drain(r)
    for d in out:
        if isinstance(d, Decision):
            r.action_result(now, d, ok)
    return out


def test_component_error_goes_to_another_robot_then_launches() -> None:
    r = LocalRecovery("robot-1", default_recovery(), CONFIG)
    r.instance_fault(10.0, "Cam#0", "Cam", "component_error", "on_execute raised")
    [d] = drain(r)
    assert d == Decision(
        "standby_other_robot", "Cam#0", "Cam", "component_error", 0, True, 10.0, "on_execute raised"
    )
    r.action_result(10.1, d, ok=True)
    r.instance_fault(20.0, "Cam#0", "Cam", "component_error")  # back within the window
    assert steps(r) == [("launch_other_robot", "Cam#0", True)]


def test_hardware_abnormal_and_emergency_stop_move_the_component() -> None:
    r = LocalRecovery("robot-1", default_recovery(), CONFIG)
    for i, cause in enumerate(("hardware_failure", "abnormal_behaviour", "emergency_stop")):
        r.instance_fault(float(i), f"C{i}#0", f"C{i}", cause)
    assert [(d.action, d.cause) for d in drain(r) if isinstance(d, Decision)] == [
        ("standby_other_robot", "hardware_failure"),
        ("standby_other_robot", "abnormal_behaviour"),
        ("standby_other_robot", "emergency_stop"),
    ]


def test_crashed_uses_the_component_error_rule_and_its_ladder() -> None:
    r = LocalRecovery("robot-1", default_recovery(), CONFIG)
    r.instance_fault(1.0, "Cam#0", "Cam", "crashed", "exit code -9")
    [d] = done(r, 1.1)
    assert isinstance(d, Decision)
    assert (d.action, d.cause, d.detail) == (
        "standby_other_robot",
        "component_error",
        "crashed: exit code -9",
    )
    r.instance_fault(2.0, "Cam#0", "Cam", "component_error")  # the same ladder
    assert steps(r) == [("launch_other_robot", "Cam#0", True)]


def test_a_repeated_report_of_the_same_fault_is_ignored_until_the_step_is_done() -> None:
    r = LocalRecovery("robot-1", default_recovery(), CONFIG)
    r.instance_fault(1.0, "Cam#0", "Cam", "component_error")
    r.instance_fault(1.2, "Cam#0", "Cam", "crashed")  # its host exits right after
    assert steps(r) == [("standby_other_robot", "Cam#0", True)]


def test_a_cause_without_a_rule_does_nothing() -> None:
    rec = default_recovery()
    rec = replace(rec, rules=tuple(x for x in rec.rules if x.cause != "emergency_stop"))
    r = LocalRecovery("robot-1", rec, CONFIG)
    r.instance_fault(1.0, "Cam#0", "Cam", "emergency_stop")
    assert drain(r) == []


def test_memory_shortage_escalates_step_by_step() -> None:
    """standby_same_robot -> restart -> standby_other_robot -> launch_other_robot."""
    rec = replace(default_recovery(), max_attempts=2)
    r = LocalRecovery("robot-1", rec, CONFIG)
    big = {"Det#0": InstanceLoad("Det", 550 * MB, 20.0), "Cam#0": InstanceLoad("Cam", 90 * MB, 5.0)}
    r.set_standbys({"Det"})
    r.robot_metrics(0.0, {"mem_free": 400 * MB}, big)
    assert drain(r) == []
    r.robot_metrics(1.0, {"mem_free": 150 * MB}, big)  # <= 200MB, for 0 s: at once
    [d] = done(r, 1.5)
    assert isinstance(d, Decision)
    assert (d.action, d.instance, d.component, d.escalate, d.metric) == (
        "standby_same_robot",
        "Det#0",
        "Det",
        False,
        "mem_free",
    )
    assert d.detail == "mem_free 1.5e+08 <= 2e+08"
    # the standby took over (Det#1), no standby left; during settle_s samples are ignored
    r.set_standbys(set())
    big = {"Det#1": InstanceLoad("Det", 550 * MB, 20.0), "Cam#0": InstanceLoad("Cam", 90 * MB, 5.0)}
    r.robot_metrics(2.0, {"mem_free": 150 * MB}, big)
    r.robot_metrics(5.0, {"mem_free": 150 * MB}, big)
    assert drain(r) == []
    r.robot_metrics(6.0, {"mem_free": 150 * MB}, big)  # settled, still short: unresolved
    assert steps_after(r, 6.1) == [("restart", "Det#1", False)]
    for now in (8.0, 10.0):
        r.robot_metrics(now, {"mem_free": 150 * MB}, big)
    r.robot_metrics(11.0, {"mem_free": 150 * MB}, big)
    assert steps_after(r, 11.1) == [("standby_other_robot", "Det#1", True)]
    r.robot_metrics(16.0, {"mem_free": 150 * MB}, big)  # the move did not happen in time
    assert steps_after(r, 16.1) == [("launch_other_robot", "Det#1", True)]
    r.robot_metrics(21.0, {"mem_free": 150 * MB}, big)
    [x] = drain(r)
    assert isinstance(x, Exhausted)
    assert (x.component, x.cause) == ("Det", "memory_shortage")


def steps_after(r: LocalRecovery, now: float) -> list[tuple[str, str, bool]]:
    return [(d.action, d.instance, d.escalate) for d in done(r, now) if isinstance(d, Decision)]


def test_memory_recovered_after_the_step_needs_no_more() -> None:
    r = LocalRecovery("robot-1", default_recovery(), CONFIG)
    load = {"Det#0": InstanceLoad("Det", 550 * MB, 20.0)}
    r.robot_metrics(1.0, {"mem_free": 150 * MB}, load)
    assert steps_after(r, 1.5) == [("restart", "Det#0", False)]  # no standby here: restart
    for now in (7.0, 8.0, 9.0):
        r.robot_metrics(now, {"mem_free": 600 * MB}, load)
    assert drain(r) == []


def test_cpu_high_blames_the_busiest_instance_after_5_s() -> None:
    r = LocalRecovery("robot-1", default_recovery(), CONFIG)
    load = {
        "Det#0": InstanceLoad("Det", 550 * MB, 20.0),
        "Cam#0": InstanceLoad("Cam", 9 * MB, 70.0),
    }
    for now in (0.0, 1.0, 2.0, 3.0, 4.0):
        r.robot_metrics(now, {"cpu": 95.0, "mem_free": 900 * MB}, load)
    assert r.next_timer() == 5.0
    r.handle_timer(4.9)
    assert drain(r) == []
    r.handle_timer(5.0)
    assert steps(r) == [("restart", "Cam#0", False)]


def test_failed_step_decides_the_next_at_once() -> None:
    r = LocalRecovery("robot-1", default_recovery(), CONFIG)
    r.set_standbys({"Det"})
    load = {"Det#0": InstanceLoad("Det", 550 * MB, 20.0)}
    r.robot_metrics(1.0, {"mem_free": 150 * MB}, load)
    [d] = drain(r)
    assert isinstance(d, Decision)
    r.action_result(1.2, d, ok=False)  # the standby would not activate
    assert steps(r) == [("restart", "Det#0", False)]


def test_robot_wide_causes_are_not_judged_here() -> None:
    r = LocalRecovery("robot-1", default_recovery(), CONFIG)
    load = {"Det#0": InstanceLoad("Det", 550 * MB, 20.0)}
    for now in range(10):
        r.robot_metrics(float(now), {"battery": 5.0, "rssi": -70.0, "mem_free": 900 * MB}, load)
    assert drain(r) == []
