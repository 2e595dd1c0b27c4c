"""RobotMonitor: robot-wide conditions from gossip, others' views of a sick robot, dwell."""

from __future__ import annotations

from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Cleared, RobotCondition, RobotEvent
from sdrpeer.recovery.robot_conditions import RobotMonitor, majority_value
from sdrpeer.system.recovery_defaults import default_recovery

CONFIG = RecoveryConfig(gossip_stale_after_s=12.0)
GOOD = {"rtt_ms": 3.0, "jitter_ms": 1.0, "loss": 0.0}
LOSSY = {"rtt_ms": 3.0, "jitter_ms": 1.0, "loss": 0.4}


def events(m: RobotMonitor) -> list[RobotEvent]:
    out = []
    while (e := m.next_event()) is not None:
        out.append(e)
    return out


def test_weak_rssi_for_6_s_degrades_the_robot_as_in_the_paper() -> None:
    """Table VI: RSSI <= -52.5 dBm sustained for 6 s (Fig. 4b: -47 -> -55 dBm at ~107 s)."""
    m = RobotMonitor(default_recovery(), CONFIG)
    m.observe_robot(100.0, "robot-1", {"rssi": -47.0, "battery": 80.0, "mem_free": 9e8})
    m.observe_robot(107.0, "robot-1", {"rssi": -55.0, "battery": 80.0})
    assert m.next_timer() == 113.0
    m.handle_timer(112.9)
    assert events(m) == []
    assert m.degraded(112.9) == set()
    m.handle_timer(113.0)
    assert events(m) == [
        RobotCondition("robot-1", "communication_failure", "rssi", -55.0, 107.0, 113.0)
    ]
    assert m.degraded(113.0) == {"robot-1"}
    assert m.fired() == [
        RobotCondition("robot-1", "communication_failure", "rssi", -55.0, 107.0, 113.0)
    ]


def test_heartbeat_records_keep_a_run_alive_a_silence_breaks_it() -> None:
    m = RobotMonitor(default_recovery(), CONFIG)
    m.observe_robot(0.0, "robot-1", {"rssi": -55.0})
    m.observe_robot(13.0, "robot-1", {"rssi": -55.0})  # 13 s of silence > 12 s: starts again
    assert m.next_timer() == 19.0
    m.observe_robot(18.0, "robot-1", {"rssi": -55.0})  # a heartbeat 5 s later continues it
    m.handle_timer(19.0)
    assert [e.robot for e in events(m)] == ["robot-1"]


def test_peers_measuring_loss_make_a_silent_robot_sick() -> None:
    """robot-1's own record is silent; robot-2 and robot-3 measure 40% loss toward it."""
    m = RobotMonitor(default_recovery(), CONFIG)
    for now in (0.0, 3.0, 6.0):
        m.observe_link(now, "robot-2", "robot-1", **LOSSY)
        m.observe_link(now, "robot-3", "robot-1", **LOSSY)
        m.observe_link(now, "robot-2", "robot-3", **GOOD)
        m.observe_link(now, "robot-3", "robot-2", **GOOD)
    [e] = events(m)
    assert e == RobotCondition("robot-1", "communication_failure", "loss", 0.4, 0.0, 6.0)
    assert m.degraded(6.0) == {"robot-1"}


def test_one_observer_with_a_bad_link_does_not_make_the_target_sick() -> None:
    """robot-1's radio is bad: it sees robot-2 lossy, but robot-3 sees robot-2 fine."""
    m = RobotMonitor(default_recovery(), CONFIG)
    for now in (0.0, 3.0, 6.0, 9.0):
        m.observe_link(now, "robot-1", "robot-2", **LOSSY)
        m.observe_link(now, "robot-3", "robot-2", **GOOD)
        m.observe_link(now, "robot-2", "robot-1", **LOSSY)
        m.observe_link(now, "robot-3", "robot-1", **LOSSY)
    assert m.degraded(9.0) == {"robot-1"}


def test_stale_observers_no_longer_count() -> None:
    m = RobotMonitor(default_recovery(), CONFIG)
    m.observe_link(0.0, "robot-3", "robot-1", **LOSSY)  # robot-3 then goes quiet
    for now in (13.0, 16.0, 19.0):
        m.observe_link(now, "robot-2", "robot-1", **GOOD)
        m.observe_link(now, "robot-4", "robot-1", **GOOD)
    assert m.degraded(19.0) == set()
    m.observe_link(20.0, "robot-3", "robot-1", **LOSSY)  # one of three: not a majority
    assert m.degraded(20.0) == set()


def test_majority_value_is_the_view_of_more_than_half() -> None:
    assert majority_value([0.4], ">=") == 0.4
    assert majority_value([0.0, 0.4], ">=") == 0.0
    assert majority_value([0.0, 0.4, 0.5], ">=") == 0.4
    assert majority_value([0.4, 0.5, 0.0, 0.6], ">=") == 0.4
    assert majority_value([-60.0, -40.0, -55.0], "<=") == -55.0


def test_low_battery_clears_past_its_clear_level_then_dwells() -> None:
    rec = default_recovery()  # battery <= 15% clears at 20%, min_dwell 30 s
    m = RobotMonitor(rec, CONFIG)
    m.observe_robot(0.0, "robot-2", {"battery": 14.0})
    assert m.degraded(0.0) == {"robot-2"}
    m.observe_robot(5.0, "robot-2", {"battery": 19.0})  # charging, not past 20%
    assert m.degraded(5.0) == {"robot-2"}
    m.observe_robot(10.0, "robot-2", {"battery": 21.0})
    assert [type(e) for e in events(m)] == [RobotCondition, Cleared]
    assert m.degraded(10.0) == set()
    assert m.excluded(10.0) == {"robot-2"}
    assert m.excluded(39.9) == {"robot-2"}
    assert m.excluded(40.0) == set()


def test_dwell_starts_when_the_last_condition_clears() -> None:
    m = RobotMonitor(default_recovery(), CONFIG)
    m.observe_robot(0.0, "robot-1", {"battery": 10.0, "rssi": -60.0})
    for now in (3.0, 6.0):
        m.observe_robot(now, "robot-1", {"battery": 10.0, "rssi": -60.0})
    assert {e.metric for e in events(m) if isinstance(e, RobotCondition)} == {"battery", "rssi"}
    m.observe_robot(7.0, "robot-1", {"battery": 50.0, "rssi": -60.0})
    assert m.degraded(7.0) == {"robot-1"}
    m.observe_robot(20.0, "robot-1", {"battery": 50.0, "rssi": -45.0})
    assert m.excluded(49.9) == {"robot-1"}
    assert m.excluded(50.0) == set()


def test_robot_gone_forgets_it_and_its_measurements() -> None:
    m = RobotMonitor(default_recovery(), CONFIG)
    m.observe_robot(0.0, "robot-1", {"battery": 10.0})
    m.observe_link(0.0, "robot-1", "robot-2", **LOSSY)
    m.robot_gone(1.0, "robot-1")
    assert m.degraded(1.0) == set()
    assert m.excluded(1.0) == {"robot-1"}  # it may come back: not at once
    assert m.fired() == []
    m.observe_link(2.0, "robot-3", "robot-2", **GOOD)  # robot-1's old view is gone
    assert m.degraded(2.0) == set()


def test_cpu_and_memory_are_left_to_the_robot_s_agent() -> None:
    m = RobotMonitor(default_recovery(), CONFIG)
    for now in range(10):
        m.observe_robot(float(now), "robot-1", {"mem_free": 1.0, "cpu": 100.0})
    assert m.degraded(10.0) == set()
