"""The allocation core: Fig. 3, standbys, reuse, pins, smallest change, infeasible reports."""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import pytest

from sdrpeer.alloc.constraints import CONSTRAINTS, RobotConstraint
from sdrpeer.alloc.core import allocate
from sdrpeer.alloc.result import AllocationResult
from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.errors import ConfigError
from sdrpeer.launch.policy import LaunchPolicy
from sdrpeer.plan import Plan
from sdrpeer.record.robot import InstanceInfo, LinkStats, LinkSummary, Metrics
from sdrpeer.system.loader import load_system
from sdrpeer.system.model import (
    AllocationDef,
    ComponentDef,
    ConnectionDef,
    Requirements,
    StandbySpec,
    SystemDef,
    Thresholds,
)
from sdrpeer.vocabulary import LifecycleState, ProcessState

MB = 1000**2
ROOT = Path(__file__).resolve().parent.parent
TABLE_V = AllocationDef(thresholds=Thresholds(mem_free_above_bytes=500 * MB))


def robot(
    name: str,
    *,
    free: int = 1600 * MB,
    battery: float | None = 80.0,
    rssi: float | None = -45.0,
    pos: tuple[float, float] | None = (0.0, 0.0),
    instances: tuple[InstanceInfo, ...] = (),
    links: dict[str, LinkStats] | None = None,
) -> RobotView:
    metrics = Metrics(10.0, 4000 * MB, free, battery, rssi, pos)
    return RobotView(name, metrics, listing(links or {}), instances)


def listing(links: dict[str, LinkStats]) -> LinkSummary:
    """A summary that lists `links` exactly and says nothing of any other link."""
    return LinkSummary(peers=len(links), bad=len(links), listed=links)


def comp(name: str, mem: int = 500 * MB, **kw: object) -> ComponentDef:
    return ComponentDef(name, "python", "m:C", requires=Requirements(5.0, mem), **kw)  # type: ignore[arg-type]


def cluster(*robots: RobotView, origin: str = "robot-1") -> ClusterView:
    return ClusterView(tuple(robots), origin)


def run(system: SystemDef, view: ClusterView, previous: Plan | None = None) -> AllocationResult:
    return allocate(system, view, epoch=3, version=7, allocator="robot-1", previous=previous)


def where(result: AllocationResult) -> dict[str, str]:
    assert result.plan is not None, str(result.infeasible)
    return {p.instance: p.robot for p in result.plan.placements}


def three(free: int = 1600 * MB) -> ClusterView:
    return cluster(*(robot(f"robot-{k}", free=free) for k in (1, 2, 3)))


PAPER = SystemDef(
    "paper",
    (
        comp("OmnidirectionalCameraRTC"),
        comp("AnomalyDetectionRTC"),
        comp("CameraRTC"),
        comp("REDControllerRTC"),
        comp("PositionEstimationRTC"),
    ),
    (
        ConnectionDef("OmnidirectionalCameraRTC", "image", "AnomalyDetectionRTC", "image"),
        ConnectionDef("CameraRTC", "image", "AnomalyDetectionRTC", "image2"),
        ConnectionDef("AnomalyDetectionRTC", "alarm", "REDControllerRTC", "alarm"),
        ConnectionDef("REDControllerRTC", "odometry", "PositionEstimationRTC", "odometry"),
        ConnectionDef("PositionEstimationRTC", "pose", "REDControllerRTC", "pose"),
    ),
    TABLE_V,
)


# -- the paper's Fig. 3 ---------------------------------------------------------------------


def test_fig3_memory_accumulates_and_five_components_spread_over_three_robots():
    result = run(PAPER, three())
    assert where(result) == {
        "OmnidirectionalCameraRTC": "robot-1",
        "AnomalyDetectionRTC": "robot-1",
        "CameraRTC": "robot-2",
        "REDControllerRTC": "robot-2",
        "PositionEstimationRTC": "robot-3",
    }
    assert result.plan is not None
    assert result.plan.key[0] == 3
    assert result.plan.version == 7
    assert result.plan.allocator == "robot-1"
    assert result.plan.system is PAPER
    assert all(p.role == "active" and p.mode == "hot" for p in result.plan.placements)


def test_fig3_from_the_paper_system_file():
    system = load_system(ROOT / "examples" / "paper" / "system.yaml")
    actives_only = replace(
        system, components=tuple(replace(c, standby=StandbySpec()) for c in system.components)
    )
    placed = where(run(actives_only, three(1700 * MB)))
    per_robot = sorted(list(placed.values()).count(r) for r in ("robot-1", "robot-2", "robot-3"))
    assert per_robot == [1, 2, 2]
    assert placed == {  # the paper's Fig. 3 exactly
        "OmnidirectionalCameraRTC": "robot-1",
        "AnomalyDetectionRTC": "robot-1",
        "CameraRTC": "robot-2",
        "REDControllerRTC": "robot-2",
        "PositionEstimationRTC": "robot-3",
    }

    # with the file's hot standby on another robot each: ten 550MB instances need more room
    with_standbys = run(
        system, cluster(*(robot(f"robot-{k}", free=2300 * MB) for k in range(1, 5)))
    )
    assert with_standbys.plan is not None, str(with_standbys.infeasible)
    plan = with_standbys.plan
    for c in system.components:
        active = plan.active_of(c.name)
        standbys = [p for p in plan.placements if p.component == c.name and p.role == "standby"]
        assert active is not None
        assert [s.instance for s in standbys] == [f"{c.name}-s1"]
        assert standbys[0].robot != active.robot


def test_not_enough_memory_reports_every_robot():
    result = run(PAPER, cluster(robot("robot-1", free=1200 * MB), robot("robot-2", free=1200 * MB)))
    assert result.plan is None
    assert result.infeasible is not None
    text = str(result.infeasible)
    assert text.splitlines()[0] == (
        "cannot place system 'paper' on 2 robot(s): 3 instance(s) found no robot"
    )
    assert "CameraRTC:\n  robot-1: memory: free memory 200MB after adding 500MB" in text
    assert result.infeasible.reason_for("CameraRTC", "robot-2") == (
        "memory: free memory 200MB after adding 500MB would not be above 500MB"
    )


def test_a_robot_that_would_refuse_a_component_never_gets_it():
    """robot-1 allows only python (the default), robot-2 also exec, robot-3 only components.*
    python targets: an exec component (and its cold standby) and a python one land where they
    may run, and with nowhere to go the reason names the setting."""
    shell = ComponentDef(
        "Sh",
        "exec",
        ("/bin/true",),
        requires=Requirements(5.0, 10 * MB),
        standby=StandbySpec(other_robots=1, mode="cold"),
    )
    mine = ComponentDef("Mine", "python", "mylab.nav:Nav", requires=Requirements(5.0, 10 * MB))
    view = cluster(
        robot("robot-1"),
        replace(robot("robot-2"), launch=LaunchPolicy(("python", "exec"))),
        replace(robot("robot-3"), launch=LaunchPolicy(("python", "exec"), ("components.*",))),
    )
    placed = where(run(SystemDef("s", (shell, mine)), view))
    assert placed == {"Sh": "robot-2", "Sh-s1": "robot-3", "Mine": "robot-1"}
    alone = run(SystemDef("s", (shell,)), cluster(robot("robot-1")))
    assert alone.infeasible is not None
    assert alone.infeasible.reason_for("Sh", "robot-1") == (
        "launch: launcher 'exec' is off on this robot (allowed: python); enable it in the agent's"
        " configuration: allow_launchers: [exec] (or --allow-launcher exec)"
    )
    narrow = cluster(replace(robot("robot-1"), launch=LaunchPolicy(targets=("components.*",))))
    refused = run(SystemDef("s", (mine,)), narrow).infeasible
    assert refused is not None
    assert "matches none of this robot's allow_targets (components.*)" in str(refused)


# -- standbys -------------------------------------------------------------------------------


def test_other_robot_standbys_each_on_their_own_robot_and_same_robot_ones_with_the_active():
    system = SystemDef(
        "s", (comp("A", mem=100 * MB, standby=StandbySpec(same_robot=1, other_robots=2)),)
    )
    result = run(system, three())
    assert where(result) == {
        "A": "robot-1",
        "A-s1": "robot-1",
        "A-s2": "robot-2",
        "A-s3": "robot-3",
    }
    assert result.plan is not None
    assert [p.role for p in result.plan.placements] == ["active", "standby", "standby", "standby"]


def test_too_few_robots_for_the_standbys_is_infeasible_with_reasons():
    system = SystemDef("s", (comp("A", mem=100 * MB, standby=StandbySpec(other_robots=2)),))
    result = run(system, cluster(robot("robot-1"), robot("robot-2")))
    assert result.infeasible is not None
    (unplaced,) = result.infeasible.unplaced
    assert unplaced.instance == "A-s2"
    assert unplaced.role == "standby"
    assert dict(unplaced.reasons) == {"robot-1": "already holds A", "robot-2": "already holds A-s1"}
    assert str(unplaced).startswith("A-s2 (standby):")


def test_hot_standbys_need_memory_cold_ones_only_battery_and_links():
    t = AllocationDef(thresholds=Thresholds(mem_free_above_bytes=500 * MB, battery_above_pct=20.0))
    view = cluster(robot("robot-1"), robot("robot-2", free=600 * MB), robot("robot-3", battery=5))
    hot = SystemDef("s", (comp("A", standby=StandbySpec(other_robots=1)),), allocation=t)
    result = run(hot, view)
    assert result.infeasible is not None
    assert dict(result.infeasible.unplaced[0].reasons) == {
        "robot-1": "already holds A",
        "robot-2": "memory: free memory 100MB after adding 500MB would not be above 500MB",
        "robot-3": "battery: battery 5% not above 20%",
    }
    cold = SystemDef(
        "s", (comp("A", standby=StandbySpec(other_robots=1, mode="cold")),), allocation=t
    )
    result = run(cold, view)
    assert where(result) == {"A": "robot-1", "A-s1": "robot-2"}
    assert result.plan is not None
    assert result.plan.placements[1].mode == "cold"


def test_running_standbys_are_reused_and_their_memory_is_not_counted_twice():
    active = InstanceInfo("A", "A", LifecycleState.ACTIVE, "active", 5.0, 520 * MB)
    standby = InstanceInfo("A-s1", "A", LifecycleState.INACTIVE, "standby", 0.5, 510 * MB)
    view = cluster(
        robot("robot-1"),
        robot("robot-2", free=700 * MB, instances=(active,)),  # their memory is already gone
        robot("robot-3", free=700 * MB, instances=(standby,)),
    )
    system = SystemDef("s", (comp("A", standby=StandbySpec(other_robots=1)),), allocation=TABLE_V)
    result = run(system, view)
    assert where(result) == {"A": "robot-2", "A-s1": "robot-3"}
    assert result.kept == 2
    # a standby that still lacks memory it needs: 400MB more would leave 300MB
    small = replace(standby, rss=100 * MB)
    view = replace(
        view, robots=(*view.robots[:2], robot("robot-3", free=700 * MB, instances=(small,)))
    )
    assert where(run(system, view)) == {"A": "robot-2", "A-s1": "robot-1"}


def test_a_fresh_deployment_activates_a_running_standby():
    running = InstanceInfo("A-s1", "A", LifecycleState.INACTIVE, "standby", 0.5, 510 * MB)
    view = cluster(robot("robot-1"), robot("robot-2", free=700 * MB, instances=(running,)))
    system = SystemDef("s", (comp("A", standby=StandbySpec(other_robots=1)),), allocation=TABLE_V)
    result = run(system, view)
    assert where(result) == {"A-s1": "robot-2", "A-s2": "robot-1"}
    assert result.plan is not None
    active = result.plan.active_of("A")
    assert active is not None
    assert active.instance == "A-s1"
    assert result.kept == 1


def test_when_the_active_robot_dies_its_running_standby_takes_over():
    system = SystemDef("s", (comp("A", standby=StandbySpec(other_robots=1)),), allocation=TABLE_V)
    first = run(system, three())
    assert where(first) == {"A": "robot-1", "A-s1": "robot-2"}
    warm = InstanceInfo("A-s1", "A", LifecycleState.INACTIVE, "standby", 0.5, 510 * MB)
    view = cluster(robot("robot-2", free=1100 * MB, instances=(warm,)), robot("robot-3"))
    result = run(system, view, previous=first.plan)
    assert where(result) == {"A-s1": "robot-2", "A-s2": "robot-3"}
    assert result.plan is not None
    active = result.plan.active_of("A")
    assert active is not None
    assert active.instance == "A-s1"


def test_a_hot_standby_not_reported_yet_takes_over_before_another_robot_is_tried():
    """The active's robot died while its hot standby was still starting (robot-2 has not
    gossiped it yet): the standby's robot takes the active, although robot-3 comes first."""
    system = SystemDef("s", (comp("A", standby=StandbySpec(other_robots=1)),), allocation=TABLE_V)
    first = run(system, three())
    assert where(first) == {"A": "robot-1", "A-s1": "robot-2"}
    view = cluster(robot("robot-3"), robot("robot-2"))
    result = run(system, view, previous=first.plan)
    assert where(result) == {"A-s1": "robot-2", "A-s2": "robot-3"}
    failed = InstanceInfo("A-s1", "A", ProcessState.FAILED, "standby", 0.0, 0)
    view = cluster(robot("robot-3"), robot("robot-2", instances=(failed,)))
    result = run(system, view, previous=first.plan)  # a standby reported failed is not taken
    assert where(result) == {"A": "robot-3", "A-s1": "robot-2"}
    cold = SystemDef(
        "s", (comp("A", standby=StandbySpec(other_robots=1, mode="cold")),), allocation=TABLE_V
    )
    first = run(cold, three())
    assert where(first) == {"A": "robot-1", "A-s1": "robot-2"}
    result = run(cold, view, previous=first.plan)  # a cold standby runs nothing: first fit
    assert where(result) == {"A": "robot-3", "A-s1": "robot-2"}


def test_gone_instances_are_not_reused():
    failed = InstanceInfo("A", "A", ProcessState.FAILED, "active", 0.0, 0)
    view = cluster(robot("robot-1"), robot("robot-2", instances=(failed,)))
    assert where(run(SystemDef("s", (comp("A"),)), view)) == {"A": "robot-1"}


# -- pins -----------------------------------------------------------------------------------


def test_pins_go_to_their_robot_or_fail():
    system = SystemDef("s", (comp("A"), comp("B", pin="robot-3")), allocation=TABLE_V)
    assert where(run(system, three())) == {"A": "robot-1", "B": "robot-3"}
    # pinned components are placed before the others take the room
    tight = SystemDef("s", (comp("A"), comp("B"), comp("C", pin="robot-1")), allocation=TABLE_V)
    assert where(run(tight, three())) == {"C": "robot-1", "A": "robot-1", "B": "robot-2"}

    full = cluster(robot("robot-1"), robot("robot-2"), robot("robot-3", free=800 * MB))
    result = run(system, full)
    assert result.infeasible is not None
    assert [(u.instance, [r for r, _ in u.reasons]) for u in result.infeasible.unplaced] == [
        ("B", ["robot-3"])
    ]
    gone = run(replace(system, components=(comp("B", pin="robot-9"),)), three())
    assert gone.infeasible is not None
    assert gone.infeasible.unplaced[0].reasons == (
        ("robot-9", "not in view (dead, left or unknown)"),
    )


# -- links ----------------------------------------------------------------------------------


def test_links_are_checked_only_between_robots():
    t = AllocationDef(
        thresholds=Thresholds(
            mem_free_above_bytes=500 * MB, rssi_above_dbm=-52.5, jitter_below_ms=20
        )
    )
    system = SystemDef(
        "s", (comp("A"), comp("B"), comp("C")), (ConnectionDef("A", "o", "C", "i"),), allocation=t
    )
    good = {"robot-1": LinkStats(5, 2, 0), "robot-3": LinkStats(5, 2, 0)}
    view = cluster(
        robot("robot-1", free=1100 * MB, rssi=-60.0),  # weak signal; room for one component
        robot("robot-2", links=good),
        robot("robot-3", links={"robot-2": LinkStats(5, 2, 0)}),
    )
    result = run(system, view)
    assert result.infeasible is not None
    reasons = dict(result.infeasible.unplaced[0].reasons)
    assert result.infeasible.unplaced[0].instance == "C"
    assert reasons["robot-1"].startswith("memory:")
    weak = "link to A on robot-1: rssi: rssi of robot-1 -60dBm not above -52.5dBm"
    assert reasons["robot-2"] == weak
    assert reasons["robot-3"] == weak  # rssi is checked before the (missing) jitter measurement

    strong = cluster(
        robot("robot-1", free=1100 * MB, links={"robot-3": LinkStats(5, 2, 0)}),
        robot("robot-2", links={"robot-1": LinkStats(5, 30, 0)}),
        robot("robot-3"),
    )
    placed = where(run(system, strong))
    assert placed == {"A": "robot-1", "C": "robot-3", "B": "robot-2"}
    no_link = run(system, replace(strong, robots=strong.robots[:2]))
    assert no_link.infeasible is not None
    assert no_link.infeasible.reason_for("C", "robot-2") == (
        "link to A on robot-1: jitter: jitter 30ms not below 20ms"
    )


# -- smallest change ------------------------------------------------------------------------


def test_reallocation_keeps_every_valid_placement():
    t = AllocationDef(thresholds=Thresholds(mem_free_above_bytes=500 * MB, battery_above_pct=20))
    system = replace(
        PAPER,
        allocation=t,
        components=tuple(
            replace(c, standby=StandbySpec(other_robots=1)) if c.name == "CameraRTC" else c
            for c in PAPER.components
        ),
    )
    robots = [robot(f"robot-{k}", free=2200 * MB) for k in (1, 2, 3, 4)]
    first = run(system, cluster(*robots))
    assert first.plan is not None
    before = where(first)
    assert before["CameraRTC-s1"] != before["CameraRTC"]

    # robot-2's battery runs low: only what ran there moves
    low = replace(robots[1], metrics=replace(robots[1].metrics, battery_pct=10.0))
    again = run(system, cluster(robots[0], low, robots[2], robots[3]), previous=first.plan)
    after = where(again)
    moved = {i for i in before if before[i] != after[i]}
    assert moved == {i for i, r in before.items() if r == "robot-2"}
    assert all(r != "robot-2" for r in after.values())
    assert set(after) == set(before)  # instance names are stable
    assert again.kept == len(before) - len(moved)

    # a new component joins: nothing else moves
    grown = replace(system, components=(*system.components, comp("Logger", mem=100 * MB)))
    third = run(grown, cluster(*robots), previous=first.plan)
    assert {i: r for i, r in where(third).items() if i != "Logger"} == before


def test_previous_robot_gone_is_named_in_a_failure():
    system = SystemDef("s", (comp("A", pin="robot-2"),))
    first = run(system, three())
    result = run(system, cluster(robot("robot-1")), previous=first.plan)
    assert result.infeasible is not None
    assert result.infeasible.unplaced[0].reasons == (
        ("robot-2", "not in view (dead, left or unknown)"),
    )


# -- plugins --------------------------------------------------------------------------------


class NeedsCamera(RobotConstraint):
    """Components whose name ends in Camera only go to robots with a camera."""

    name = "camera"

    def check(self, load, need, component, t):
        if not component.name.endswith("Camera") or load.robot.name in ("robot-3",):
            return None
        return "no camera"


def test_a_plugin_constraint_registered_in_a_test():
    CONSTRAINTS.register("camera", NeedsCamera)
    try:
        system = SystemDef(
            "s",
            (comp("Camera"), comp("Other")),
            allocation=AllocationDef(constraints=("camera",)),
        )
        assert where(run(system, three())) == {"Camera": "robot-3", "Other": "robot-1"}
        result = run(system, cluster(robot("robot-1")))
        assert result.infeasible is not None
        assert result.infeasible.reason_for("Camera", "robot-1") == "camera: no camera"
    finally:
        CONSTRAINTS.unregister("camera")


def test_unknown_strategy_is_a_config_error():
    with pytest.raises(ConfigError, match="unknown allocation strategy 'best'"):
        run(SystemDef("s", (comp("A"),), allocation=AllocationDef(strategy="best")), three())


def test_empty_view_reports_no_robot():
    result = run(SystemDef("s", (comp("A"),)), cluster())
    assert result.infeasible is not None
    assert str(result.infeasible.unplaced[0]) == "A: no robot in view"


def test_avoid_moves_one_component_off_a_robot_and_keeps_the_others():
    system = SystemDef("s", (comp("A", mem=10 * MB), comp("B", mem=10 * MB)))
    view = three()
    first = run(system, view)
    assert where(first) == {"A": "robot-1", "B": "robot-1"}
    moved = allocate(
        system,
        view,
        epoch=3,
        version=8,
        allocator="robot-1",
        previous=first.plan,
        avoid={"A": {"robot-1"}},
    )
    assert where(moved) == {"A": "robot-2", "B": "robot-1"}
    nowhere = allocate(
        system,
        cluster(robot("robot-1")),
        epoch=3,
        version=8,
        allocator="robot-1",
        previous=first.plan,
        avoid={"A": {"robot-1"}},
    )
    assert nowhere.infeasible is not None
    assert "avoid" in (nowhere.infeasible.reason_for("A", "robot-1") or "")


def test_optional_standbys_let_the_actives_run_on_too_few_robots() -> None:
    system = SystemDef("s", (comp("A", standby=StandbySpec(same_robot=0, other_robots=2)),))
    view = cluster(robot("robot-1"), robot("robot-2"))
    strict = run(system, view)
    assert strict.infeasible is not None  # one other robot for two standbys
    assert [u.instance for u in strict.infeasible.unplaced] == ["A-s2"]
    loose = allocate(system, view, epoch=3, version=7, allocator="robot-1", standbys_optional=True)
    assert where(loose) == {"A": "robot-1", "A-s1": "robot-2"}
    assert loose.plan is not None
    assert loose.plan.standbys_short() == {"A": 1}
    alone = allocate(
        system, cluster(robot("robot-1")), epoch=3, version=7, allocator="r", standbys_optional=True
    )
    assert where(alone) == {"A": "robot-1"}
    assert alone.plan is not None
    assert alone.plan.standbys_short() == {"A": 2}
    assert replace(alone.plan, system=None).standbys_short() == {}
