"""Placement and readings under a component's own Table I thresholds and a connection's own
Table II bounds (`sdrpeer.alloc.feasibility`, `sdrpeer.alloc.compliance`)."""

from __future__ import annotations

from sdrpeer.alloc.compliance import readings
from sdrpeer.alloc.core import allocate
from sdrpeer.alloc.result import AllocationResult
from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.plan import Placement
from sdrpeer.record.robot import LinkStats, LinkSummary, Metrics
from sdrpeer.system.model import (
    AllocationDef,
    ComponentDef,
    ConnectionDef,
    Requirements,
    SystemDef,
    Thresholds,
)
from sdrpeer.vocabulary import InstanceRole

MB = 1000**2
GOOD = LinkStats(rtt_ms=4.0, jitter_ms=0.5, loss=0.0)
SLOW = LinkStats(rtt_ms=35.0, jitter_ms=0.5, loss=0.0)


def robot(
    name: str,
    *,
    cpu: float = 10.0,
    free: int = 1600 * MB,
    battery: float | None = 80.0,
    rssi: float | None = -45.0,
    links: dict[str, LinkStats] | None = None,
) -> RobotView:
    links = links or {}
    summary = LinkSummary(peers=len(links), bad=len(links), listed=links)
    return RobotView(name, Metrics(cpu, 4000 * MB, free, battery, rssi, (0.0, 0.0)), summary)


def comp(name: str, **kw: object) -> ComponentDef:
    return ComponentDef(name, "python", "m:C", requires=Requirements(5.0, 100 * MB), **kw)  # type: ignore[arg-type]


def run(system: SystemDef, *robots: RobotView) -> AllocationResult:
    view = ClusterView(tuple(robots), "robot-1")
    return allocate(system, view, epoch=1, version=1, allocator="robot-1")


def where(result: AllocationResult) -> dict[str, str]:
    assert result.plan is not None, str(result.infeasible)
    return {p.instance: p.robot for p in result.plan.placements}


def test_a_component_threshold_narrows_the_fleets_for_it_only() -> None:
    system = SystemDef(
        "s",
        (comp("Planner", thresholds=Thresholds(battery_above_pct=40.0)), comp("Logger")),
        allocation=AllocationDef(thresholds=Thresholds(battery_above_pct=10.0)),
    )
    robots = (robot("robot-1", battery=30.0), robot("robot-2", battery=60.0))
    assert where(run(system, *robots)) == {"Planner": "robot-2", "Logger": "robot-1"}
    # nowhere above 40 %: infeasible, and the reason names the component's own threshold
    result = run(system, robot("robot-1", battery=30.0), robot("robot-2", battery=35.0))
    assert result.infeasible is not None
    text = str(result.infeasible)
    assert "battery 30% not above 40%" in text
    assert "battery 35% not above 40%" in text


def test_a_component_threshold_the_fleet_leaves_out_is_checked() -> None:
    system = SystemDef("s", (comp("Hot", thresholds=Thresholds(cpu_below_pct=50.0)),))
    assert where(run(system, robot("robot-1", cpu=60.0), robot("robot-2", cpu=20.0))) == {
        "Hot": "robot-2"
    }


def test_a_looser_component_threshold_does_not_widen_the_fleets() -> None:
    system = SystemDef(
        "s",
        (comp("C", thresholds=Thresholds(mem_free_above_bytes=100 * MB)),),
        allocation=AllocationDef(thresholds=Thresholds(mem_free_above_bytes=1000 * MB)),
    )
    result = run(system, robot("robot-1", free=1050 * MB), robot("robot-2", free=1200 * MB))
    assert where(result) == {"C": "robot-2"}  # robot-1 would keep 950MB: below the fleet's


def control_loop(bounds: Thresholds) -> SystemDef:
    """Ctrl pinned to robot-1, Motor on the first robot that fits (too big for robot-1)."""
    return SystemDef(
        "s",
        (
            comp("Ctrl", pin="robot-1"),
            ComponentDef(
                "Motor", "python", "m:C", requires=Requirements(5.0, 900 * MB), prefer=("robot-2",)
            ),
        ),
        (ConnectionDef("Ctrl", "cmd", "Motor", "cmd", bounds=bounds),),
    )


def test_a_connection_bound_picks_the_robot_with_the_good_link() -> None:
    robots = (
        robot("robot-1", free=800 * MB, links={"robot-2": SLOW, "robot-3": GOOD}),
        robot("robot-2", links={"robot-1": SLOW}),
        robot("robot-3", links={"robot-1": GOOD}),
    )
    assert where(run(control_loop(Thresholds()), *robots))["Motor"] == "robot-2"  # preferred
    tight = control_loop(Thresholds(delay_below_ms=20.0))
    assert where(run(tight, *robots))["Motor"] == "robot-3"
    result = run(control_loop(Thresholds(delay_below_ms=3.0)), *robots)
    assert result.infeasible is not None
    assert "delay 4ms not below 3ms" in str(result.infeasible)


def test_a_connection_bound_counts_the_worse_end() -> None:
    # robot-1 measures the link to robot-2 as good, robot-2 measures it as slow: slow counts
    robots = (
        robot("robot-1", free=800 * MB, links={"robot-2": GOOD, "robot-3": GOOD}),
        robot("robot-2", links={"robot-1": SLOW}),
        robot("robot-3", links={"robot-1": GOOD}),
    )
    assert where(run(control_loop(Thresholds(delay_below_ms=20.0)), *robots))["Motor"] == "robot-3"


def placements(**at: str) -> list[Placement]:
    return [Placement(c, c, r, InstanceRole.ACTIVE) for c, r in at.items()]


def test_readings_of_the_running_placements() -> None:
    system = SystemDef(
        "s",
        (comp("Ctrl", pin="robot-1", thresholds=Thresholds(battery_above_pct=40.0)), comp("Motor")),
        (ConnectionDef("Ctrl", "cmd", "Motor", "cmd", bounds=Thresholds(loss_below=0.05)),),
        allocation=AllocationDef(thresholds=Thresholds(cpu_below_pct=80.0, delay_below_ms=50.0)),
    )
    lossy = LinkStats(rtt_ms=8.0, jitter_ms=1.0, loss=0.25)
    view = ClusterView(
        (
            robot("robot-1", cpu=30.0, battery=35.0, links={"robot-2": GOOD}),
            robot("robot-2", cpu=85.0, battery=None, links={"robot-1": lossy}),
        )
    )
    got = {
        (r.component, r.constraint, r.subject): (r.value, r.bound, r.violated(), r.movable)
        for r in readings(system, placements(Ctrl="robot-1", Motor="robot-2"), view)
    }
    conn = "Ctrl.cmd->Motor.cmd"
    assert got == {
        ("Ctrl", "cpu", "robot-1"): (30.0, 80.0, False, ()),  # pinned: nothing to move
        ("Ctrl", "battery", "robot-1"): (35.0, 40.0, True, ()),
        ("Motor", "cpu", "robot-2"): (85.0, 80.0, True, ("Motor",)),
        ("Motor", "loss", conn): (0.25, 0.05, True, ("Motor",)),  # robot-2's (worse) view
        ("Motor", "delay", conn): (8.0, 50.0, False, ("Motor",)),  # the fleet's bound
    }
    # both on one robot: no link, no Table II reading
    same = readings(system, placements(Ctrl="robot-1", Motor="robot-1"), view)
    assert {r.constraint for r in same} == {"cpu", "battery"}
    # a standby is not a running placement's reading; a robot out of the view gives none
    standby = [Placement("Motor", "Motor-s1", "robot-1", InstanceRole.STANDBY)]
    assert {r.subject for r in readings(system, standby, view)} == set()
    assert readings(system, placements(Motor="robot-9"), view) == []
