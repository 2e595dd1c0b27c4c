"""RobotMonitor: robot-wide conditions from gossip (own metrics, link summaries), dwell."""

from __future__ import annotations

from sdrpeer.monitor.links import summarize
from sdrpeer.record.robot import LinkBounds, LinkStats
from sdrpeer.recovery.config import RecoveryConfig
from sdrpeer.recovery.events import Cleared, RobotCondition, RobotEvent
from sdrpeer.recovery.robot_conditions import RobotMonitor
from sdrpeer.system.recovery_defaults import default_recovery

CONFIG = RecoveryConfig(gossip_stale_after_s=12.0)
GOOD = LinkStats(rtt_ms=3.0, jitter_ms=1.0, loss=0.0)
LOSSY = LinkStats(rtt_ms=3.0, jitter_ms=1.0, loss=0.4)


def typical(links: dict[str, LinkStats]) -> dict[str, float | None]:
    """The link metrics a robot's record reports of the links it measures."""
    t = summarize(links, LinkBounds()).typical
    assert t is not None
    return {"delay": t.rtt_ms, "jitter": t.jitter_ms, "loss": t.loss}


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


def test_a_robot_whose_links_are_mostly_lossy_is_sick() -> None:
    """robot-1's radio is bad: every link it measures loses 40 %."""
    m = RobotMonitor(default_recovery(), CONFIG)
    for now in (0.0, 3.0, 6.0):
        m.observe_robot(now, "robot-1", typical({"robot-2": LOSSY, "robot-3": LOSSY}))
        m.observe_robot(now, "robot-2", typical({"robot-1": LOSSY, "robot-3": GOOD}))
        m.observe_robot(now, "robot-3", typical({"robot-1": LOSSY, "robot-2": GOOD}))
    [e] = events(m)
    assert e == RobotCondition("robot-1", "communication_failure", "loss", 0.4, 0.0, 6.0)
    assert m.degraded(6.0) == {"robot-1"}


def test_one_bad_peer_does_not_make_a_robot_sick() -> None:
    """robot-2 measures one lossy link (to robot-1, whose radio is bad) among four good ones."""
    m = RobotMonitor(default_recovery(), CONFIG)
    links = {"robot-1": LOSSY, **{f"robot-{k}": GOOD for k in (3, 4, 5, 6)}}
    for now in (0.0, 3.0, 6.0, 9.0):
        m.observe_robot(now, "robot-2", typical(links))
    assert m.degraded(9.0) == set()


def test_half_the_links_is_not_a_majority() -> None:
    m = RobotMonitor(default_recovery(), CONFIG)
    for now in (0.0, 3.0, 6.0, 9.0):
        m.observe_robot(now, "robot-2", typical({"robot-1": LOSSY, "robot-3": GOOD}))
    assert m.degraded(9.0) == set()


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


def test_robot_gone_forgets_it() -> None:
    m = RobotMonitor(default_recovery(), CONFIG)
    m.observe_robot(0.0, "robot-1", {"battery": 10.0})
    m.robot_gone(1.0, "robot-1")
    assert m.degraded(1.0) == set()
    assert m.excluded(1.0) == {"robot-1"}  # it may come back: not at once
    assert m.fired() == []


def test_cpu_and_memory_are_left_to_the_robot_s_agent() -> None:
    m = RobotMonitor(default_recovery(), CONFIG)
    for now in range(10):
        m.observe_robot(float(now), "robot-1", {"mem_free": 1.0, "cpu": 100.0})
    assert m.degraded(10.0) == set()
