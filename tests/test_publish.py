"""The publisher: which samples make a record (spread), vitals (on probes) or nothing."""

from __future__ import annotations

from dataclasses import replace

import pytest

from sdrpeer.monitor.publish import (
    NO_LINK_BOUNDS,
    NONE,
    RECORD,
    VITALS,
    Average,
    Publisher,
    boundaries,
    link_bounds,
)
from sdrpeer.record.robot import (
    ElectionInfo,
    InstanceInfo,
    LinkBounds,
    LinkStats,
    LinkSummary,
    Metrics,
    PlanInfo,
    RobotRecord,
)
from sdrpeer.system.model import RecoveryDef, RecoveryRule, Thresholds

GB = 1 << 30
CAM = InstanceInfo("Cam1", "Cam", "active", "active", 10.0, 100 << 20)
BASE = RobotRecord(
    Metrics(10.0, 4 * GB, 3 * GB, 80.0, -47.0, (1.0, 2.0)),
    LinkSummary(peers=4, typical=LinkStats(0.5, 0.1, 0.0), bounds=LinkBounds(50.0, 10.0, 0.05)),
    "http://127.0.0.1:1",
    0,
    (CAM,),
)


def metrics(**changes: object) -> RobotRecord:
    return replace(BASE, metrics=replace(BASE.metrics, **changes))  # type: ignore[arg-type]


def typical(**changes: object) -> RobotRecord:
    assert BASE.links.typical is not None
    t = replace(BASE.links.typical, **changes)  # type: ignore[arg-type]
    return replace(BASE, links=replace(BASE.links, typical=t))


def instance(**changes: object) -> RobotRecord:
    return replace(BASE, instances=(replace(CAM, **changes),))  # type: ignore[arg-type]


def published() -> Publisher:
    p = Publisher()
    assert p.decide(0.0, BASE) == RECORD  # the first sample is always a record
    return p


@pytest.mark.parametrize(
    ("new", "expected"),
    [
        (BASE, NONE),
        (metrics(cpu_pct=14.9), NONE),
        (metrics(cpu_pct=15.0), VITALS),
        (metrics(mem_free=3 * GB - 20 * 2**20), NONE),  # 20 MiB < 1 % of 4 GB
        (metrics(mem_free=3 * GB - 50 * 2**20), VITALS),
        (metrics(battery_pct=79.5), NONE),
        (metrics(battery_pct=79.0), VITALS),
        (metrics(rssi_dbm=-48.9), NONE),
        (metrics(rssi_dbm=-49.5), VITALS),
        (metrics(pos=(1.05, 2.0)), NONE),
        (metrics(pos=(1.5, 2.0)), VITALS),
        (typical(rtt_ms=1.4), NONE),  # 0.9 ms < 1 ms
        (typical(rtt_ms=1.6), VITALS),
        (typical(loss=0.009), NONE),
        (typical(jitter_ms=0.9), NONE),
        (instance(cpu_pct=20.0), VITALS),
        (instance(out_bps=12345), NONE),  # rides along with the next revision
        # What the fleet decides with: a new record.
        (replace(BASE, priority=5), RECORD),
        (replace(BASE, api="http://127.0.0.1:2"), RECORD),
        (metrics(pos=None), RECORD),
        (metrics(mem_total=8 * GB), RECORD),
        (instance(state="error"), RECORD),
        (instance(data="tcp://127.0.0.1:9"), RECORD),
        (instance(out_refused=1), RECORD),  # a connection its receiver refuses: status shows it
        (replace(BASE, instances=()), RECORD),
        (replace(BASE, election=ElectionInfo(1, "robot-1", True)), RECORD),
        (replace(BASE, plan=PlanInfo(1, 1, "d", "robot-1")), RECORD),
        (replace(BASE, links=replace(BASE.links, bounds=LinkBounds(loss=0.01))), RECORD),
        # Boundaries: the broadcast trap levels; not the election's health steps.
        (metrics(rssi_dbm=-52.5), RECORD),  # onto the trap threshold
        (metrics(battery_pct=19.9), RECORD),  # the battery trap
        (metrics(battery_pct=74.9), VITALS),  # health step 75 %: vitals, not a record
        (metrics(cpu_pct=91.0), VITALS),  # CPU and memory: the robot's own agent decides
        (metrics(mem_free=199_000_000), VITALS),
        (typical(loss=0.06), VITALS),  # health steps 1 % and 5 %: vitals
        (metrics(battery_pct=None), RECORD),
    ],
)
def test_decisions(new: RobotRecord, expected: str) -> None:
    assert published().decide(1.0, new) == expected


@pytest.mark.parametrize(
    ("new", "urgent"),
    [
        # a placement others wait for: in a gossip round at once
        (instance(state="inactive"), True),  # stood down: the new robot may activate
        (instance(role="standby"), True),
        (replace(BASE, instances=()), True),
        (replace(BASE, plan=PlanInfo(1, 1, "d", "robot-1")), True),
        # what the robot is: the next regular round (a join storm raises no extra rounds)
        (replace(BASE, priority=5), False),
        (metrics(mem_total=8 * GB), False),
        (replace(BASE, election=ElectionInfo(1, "robot-1", True)), True),  # a claim
        (replace(BASE, election=ElectionInfo(1, "robot-2", False)), False),  # a belief
        (instance(data="tcp://127.0.0.1:9"), False),
        (metrics(battery_pct=19.9), False),
    ],
)
def test_only_a_record_that_changes_a_placement_is_urgent(new: RobotRecord, urgent: bool) -> None:
    p = Publisher()
    assert p.decide(0.0, BASE) == RECORD
    assert p.urgent is False  # the first record says what the robot is
    assert p.decide(10.0, new) == RECORD
    assert p.urgent is urgent


def test_deadband_is_measured_from_the_last_values_sent() -> None:
    p = published()
    assert p.decide(1.0, metrics(cpu_pct=13.0)) == NONE
    assert p.decide(2.0, metrics(cpu_pct=16.0)) == VITALS  # 6 points from the record
    assert p.decide(3.0, metrics(cpu_pct=19.0)) == NONE  # 3 points from the vitals sent
    assert p.decide(4.0, metrics(cpu_pct=21.0)) == VITALS


def test_a_crossing_soon_after_a_record_waits_for_the_gap_as_vitals() -> None:
    p = published()
    assert p.decide(0.5, metrics(rssi_dbm=-53.0)) == VITALS  # 0.5 s < min_gap 1 s
    assert p.decide(0.9, metrics(rssi_dbm=-53.0)) == NONE
    assert p.decide(1.0, metrics(rssi_dbm=-53.0)) == RECORD  # still across: now a record
    assert p.decide(1.5, metrics(rssi_dbm=-47.0)) == VITALS  # back across, within the gap
    assert p.decide(2.0, metrics(rssi_dbm=-47.0)) == RECORD


def test_force_always_makes_a_record() -> None:
    assert published().decide(0.1, BASE, force=True) == RECORD


def test_nothing_is_resent_on_a_timer() -> None:
    p = published()
    assert all(p.decide(float(t), BASE) == NONE for t in range(1, 3600, 7))


def test_boundaries_of_a_deployed_system() -> None:
    recovery = RecoveryDef(
        rules=(
            RecoveryRule("low_battery", "battery", "<=", 30.0, 6.0, 35.0),
            RecoveryRule("communication_failure", "delay", ">=", 200.0, 6.0, 150.0),
            RecoveryRule("memory_shortage", "mem_free", "<=", 2e8, 0.0, 2.5e8),  # local: no cut
            RecoveryRule("component_error"),
        )
    )
    b = boundaries(recovery, Thresholds(battery_above_pct=40.0, loss_below=0.1))
    assert set(b.cuts["battery"]) == {20.0, 25.0, 30.0, 35.0, 40.0}
    assert b.cuts["delay"] == (150.0, 200.0)
    assert 0.1 in b.cuts["loss"]
    assert "mem_free" not in b.cuts
    p = Publisher(b)
    base = replace(BASE, links=replace(BASE.links, typical=LinkStats(100.0, 0.1, 0.0)))
    assert p.decide(0.0, base) == RECORD
    slower = replace(base, links=replace(base.links, typical=LinkStats(149.0, 0.1, 0.0)))
    assert p.decide(2.0, slower) == VITALS
    past = replace(base, links=replace(base.links, typical=LinkStats(151.0, 0.1, 0.0)))
    assert p.decide(3.0, past) == RECORD
    assert boundaries().crossed(BASE, typical(rtt_ms=300.0)) is None  # no rule: no cut


def test_link_bounds_are_the_deployed_systems() -> None:
    assert link_bounds(None) == NO_LINK_BOUNDS == LinkBounds()  # nothing deployed: none listed
    t = Thresholds(jitter_below_ms=30.0, loss_below=0.01, delay_below_ms=20.0)
    assert link_bounds(t) == LinkBounds(rtt_ms=20.0, jitter_ms=30.0, loss=0.01)
    assert link_bounds(Thresholds(loss_below=0.1)) == LinkBounds(loss=0.1)


def test_the_cpu_average_follows_the_load_not_the_noise() -> None:
    avg = Average(tau=10.0)
    assert avg.add(0.0, 30.0) == 30.0
    noisy = [avg.add(float(t), 30.0 + (8.0 if t % 2 else -8.0)) for t in range(1, 60)]
    assert max(noisy) - min(noisy) < 2.0  # +-8 points every second: the average barely moves
    for t in range(60, 100):
        value = avg.add(float(t), 90.0)
    assert 85.0 < value < 90.0  # a real change arrives within a few time constants
    assert avg.add(100.0 + 1e-9, 0.0) < value  # a sample at the same moment weighs ~nothing
