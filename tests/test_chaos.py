"""The chaos soak: its seeded schedule and its invariants (pure), and a 60-second soak on a real
lab (namespaces when root, so partitions and packet loss are real) that must end with no
violation."""

from __future__ import annotations

from collections.abc import Mapping

import pytest

from sdrpeer.chaos.judge import Judge, Look
from sdrpeer.chaos.run import ChaosOptions, chaos_system, due_events, format_report, run_chaos
from sdrpeer.chaos.schedule import Fault, schedule


def test_the_schedule_is_the_seeds_and_keeps_a_majority_working() -> None:
    a = schedule(7, 10, 300, network=True)
    assert a == schedule(7, 10, 300, network=True)
    assert a != schedule(8, 10, 300, network=True)
    assert {f.kind for f in a} == {
        "kill_host",
        "kill_agent",
        "rssi",
        "battery",
        "partition",
        "loss",
    }
    assert [f.at for f in a] == sorted(f.at for f in a)
    for f in a:
        assert f.until is None or f.at + 2.0 <= f.until <= 300
        if f.kind == "partition":
            assert 1 <= len(f.robots) <= 4  # a minority of ten
        if f.kind == "loss":
            assert 0.3 <= f.amount <= 0.5
    for t in range(300):  # never more than (10 - 1) // 2 robots held by faults at once
        held = {r for f in a if f.until is not None and f.at <= t < f.until for r in f.robots}
        assert len(held) <= 4
        assert sum(1 for f in a if f.kind == "partition" and f.until and f.at <= t < f.until) <= 1
    loopback = schedule(7, 10, 300, network=False)
    assert not {f.kind for f in loopback} & {"partition", "loss"}


def look(t: float, actives: Mapping[str, set[str]], **kw: object) -> Look:
    return Look(t, {c: frozenset(r) for c, r in actives.items()}, **kw)  # type: ignore[arg-type]


def test_two_actives_are_a_violation_only_past_the_fence_window_of_a_whole_network() -> None:
    judge = Judge(["A", "B"], fence_window_s=5.0)
    assert judge.observe(look(0.0, {"A": {"r1"}, "B": {"r2"}}))
    for t in range(1, 20):  # a partition: each side may run its own A
        judge.observe(look(float(t), {"A": {"r1", "r3"}, "B": {"r2"}}, partitioned=True))
    assert judge.violations == []
    judge.healed(20.0)  # the clock starts at the heal, not at the last look of the partition
    judge.observe(look(21.0, {"A": {"r1", "r3"}, "B": {"r2"}}))
    judge.observe(look(23.0, {"A": {"r1", "r3"}, "B": {"r2"}}))
    judge.observe(look(25.0, {"A": {"r1", "r3"}, "B": {"r2"}}))  # 5 s after the heal: not past
    assert judge.violations == []
    judge.observe(look(25.5, {"A": {"r1", "r3"}, "B": {"r2"}}))  # 5.5 s after the heal
    judge.observe(look(26.0, {"A": {"r1", "r3"}, "B": {"r2"}}))  # reported once
    assert [(v["kind"], v["subject"]) for v in judge.violations] == [("two_active", "A")]
    judge.observe(look(27.0, {"A": {"r3"}, "B": {"r2"}}))  # seen until 26: 6 s after the heal
    assert judge.double_active_s == [6.0]
    report = judge.report()
    assert report["double_active_max_s"] == 6.0
    assert report["look_interval_s"]["max"] == 2.0


def test_recoveries_convergence_plans_and_memory() -> None:
    judge = Judge(["A"], converge_s=3.0, rss_limit=100)
    key = (2, "r1", 5)
    assert judge.observe(look(0.0, {"A": {"r1"}}, plans={"r1": key}, rss={"r1": 50}))
    judge.fault(1.0, "kill_host")
    assert not judge.observe(look(1.5, {"A": set()}, plans={"r1": key}))
    assert judge.observe(look(1.8, {"A": {"r2"}}, plans={"r1": (2, "r1", 6)}))
    assert judge.recoveries == pytest.approx([0.8])
    judge.observe(look(2.0, {"A": {"r2"}}, plans={"r1": (2, "r1", 4)}, rss={"r1": 150}))
    judge.faults_over(3.0)
    assert not judge.observe(look(4.0, {"A": set()}))
    assert judge.observe(look(7.5, {"A": {"r2"}}))
    judge.final_plan({"A": 0})
    kinds = [v["kind"] for v in judge.violations]
    assert kinds == ["plan_went_back", "memory", "slow_convergence", "plan_lost"]
    report = judge.report()
    assert report["converged_after_s"] == 4.5
    assert report["faults"] == {"kill_host": 1}
    assert report["recovery_s"]["p50"] == 0.8
    assert report["agent_rss_growth_mib"] == 0.0  # 100 bytes: rounds to nothing


def test_recoveries_are_reported_isolated_or_overlapping() -> None:
    judge = Judge(["A"])
    judge.observe(look(0.0, {"A": {"r1"}}))
    judge.fault(1.0, "kill_host")  # alone: isolated
    judge.observe(look(1.5, {"A": {"r2"}}))
    judge.fault(2.0, "partition", until=9.0)  # recovered at 3, before the next fault: isolated
    judge.observe(look(3.0, {"A": {"r2"}}))
    judge.fault(5.0, "kill_host")  # while the partition is on: overlapping
    judge.observe(look(6.0, {"A": {"r3"}}))
    judge.fault(10.0, "loss", until=12.0)  # after the partition ended: isolated
    judge.observe(look(13.0, {"A": {"r3"}}))
    report = judge.report()
    assert report["recovery_s"]["n"] == 4
    assert report["recovery_isolated_s"] == {"n": 3, "p50": 1.0, "p99": 3.0, "max": 3.0,
                                             "mean": 1.5}  # fmt: skip
    assert report["recovery_overlapping_s"] == {"n": 1, "p50": 1.0, "p99": 1.0, "max": 1.0,
                                                "mean": 1.0}  # fmt: skip
    assert report["recovery_isolated_by_kind"] == {"kill_host": [0.5], "partition": [1.0],
                                                   "loss": [3.0]}  # fmt: skip
    assert Judge(["A"]).fence_window_s == 1.0  # the window is the default


def test_the_chaos_system_pairs_cameras_and_detectors_with_standbys() -> None:
    system = chaos_system(5)
    assert [c["name"] for c in system["components"]] == ["Cam0", "Det0", "Cam1", "Det1", "Cam2"]
    assert all(c["standby"]["other_robots"] == 1 for c in system["components"])
    assert len(system["connections"]) == 2
    causes = sorted(r["cause"] for r in system["recovery"]["rules"])
    assert causes == ["communication_failure", "communication_failure", "component_error",
                      "low_battery"]  # fmt: skip


@pytest.mark.realnet
@pytest.mark.slow
def test_a_60_second_soak_ends_without_violations() -> None:
    report = run_chaos(ChaosOptions(robots=5, components=8, minutes=1.0, seed=2), say=print)
    print(format_report(report))
    assert report["violations"] == []
    assert report["faults_total"] >= 8
    assert report["recoveries"] >= 1
    assert report["converged_after_s"] is not None
    assert report["converged_after_s"] <= 3.0


def test_due_faults_start_and_end_in_the_order_they_fell_due() -> None:
    """A look stalled the loop: at t=17 the end of the first kill of robot-1 (15) and the
    second kill (16) are both due. The agent is restarted first, then killed again: the other
    way round, the second restart left two agents for robot-1 and the first one leaked."""
    faults = [
        Fault(10.0, "kill_agent", ("robot-1",), 15.0),
        Fault(16.0, "kill_agent", ("robot-1",), 20.0),
    ]
    ends = sorted((f.until, i) for i, f in enumerate(faults) if f.until is not None)
    due, started, ended = due_events(faults, ends, 0, 0, 11.0)
    assert due == [("start", 0)]
    due, started, ended = due_events(faults, ends, started, ended, 17.0)
    assert due == [("end", 0), ("start", 1)]
    assert due_events(faults, ends, started, ended, 18.0)[0] == []
    assert due_events(faults, ends, started, ended, 25.0)[0] == [("end", 1)]
