"""The allocator's explanation (`Plan.why`): every placement says how its robot was chosen, which
robots were tried before and what ruled each out, what it passed and (objective) the scores; a
standby left out says why every robot refused it; a kept placement keeps the explanation of the
plan that decided it; plans carry it through JSON."""

from __future__ import annotations

from dataclasses import replace

from sdrpeer.alloc.core import allocate
from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.deploy.plan_change import EXCLUDED, Context, Deploy, Reissue, change
from sdrpeer.deploy.view import ClusterState
from sdrpeer.plan import Plan, Why, plan_from_json
from sdrpeer.record.robot import LinkStats, LinkSummary, Metrics, RobotRecord
from sdrpeer.system.model import (
    AllocationDef,
    ComponentDef,
    ConnectionDef,
    Requirements,
    StandbySpec,
    SystemDef,
    Thresholds,
)
from sdrpeer.vocabulary import InstanceRole

MB = 1000**2
T = Thresholds(mem_free_above_bytes=500 * MB, battery_above_pct=20.0, delay_below_ms=50.0)


def robot(
    name: str, *, free: int = 1600 * MB, battery: float = 80.0, rtt: dict[str, float] | None = None
) -> RobotView:
    listed = {peer: LinkStats(ms, 0.5, 0.0) for peer, ms in (rtt or {}).items()}
    summary = LinkSummary(peers=len(listed), bad=len(listed), listed=listed)
    return RobotView(name, Metrics(10.0, 4000 * MB, free, battery, -45.0, (0.0, 0.0)), summary, ())


def comp(name: str, **kw: object) -> ComponentDef:
    return ComponentDef(name, "python", "m:C", requires=Requirements(5.0, 500 * MB), **kw)  # type: ignore[arg-type]


def system(*comps: ComponentDef, strategy: str = "first_fit", **kw: object) -> SystemDef:
    allocation = AllocationDef(strategy=strategy, thresholds=T)
    return SystemDef("s", comps, allocation=allocation, **kw)  # type: ignore[arg-type]


def whys(plan: Plan | None) -> dict[str, Why]:
    assert plan is not None
    return {w.instance: w for w in plan.why}


def test_every_placement_says_which_robots_were_ruled_out_and_by_what() -> None:
    view = ClusterView(
        (
            robot("robot-1", battery=10.0),
            robot("robot-2", free=700 * MB),
            robot("robot-3"),
            robot("robot-4"),
        ),
        "robot-1",
    )
    s = system(comp("Det", standby=StandbySpec(other_robots=1)))
    result = allocate(s, view, epoch=1, version=1, allocator="robot-3")
    assert result.plan is not None
    w = whys(result.plan)
    assert set(w) == {p.instance for p in result.plan.placements} == {"Det", "Det-s1"}
    det = w["Det"]
    assert (det.robot, det.how, det.role) == ("robot-3", "ranked", InstanceRole.ACTIVE)
    assert [r for r, _ in det.ruled_out] == ["robot-1", "robot-2"]
    assert det.ruled_out[0][1] == "battery: battery 10% not above 20%"
    assert det.ruled_out[1][1].startswith("memory: free memory 200MB after adding 500MB")
    assert {"launch", "memory", "battery"} <= set(det.checked)
    standby = w["Det-s1"]
    assert (standby.robot, standby.how, standby.role) == ("robot-4", "ranked", "standby")
    assert [r for r, _ in standby.ruled_out] == ["robot-1", "robot-2", "robot-3"]
    assert standby.ruled_out[2] == ("robot-3", "already holds Det")  # another robot than its active
    assert (det.decided_in, det.reason) == ((0, 0), "")  # stamped by the deployment core


def test_a_standby_left_out_by_a_recovery_lists_every_robots_refusal() -> None:
    view = ClusterView((robot("robot-1", battery=10.0), robot("robot-2")), "robot-2")
    s = system(comp("Det", standby=StandbySpec(other_robots=1)))
    result = allocate(s, view, epoch=1, version=2, allocator="robot-2", standbys_optional=True)
    assert result.plan is not None
    assert [p.instance for p in result.plan.placements] == ["Det"]
    left = whys(result.plan)["Det-s1"]
    assert (left.robot, left.how, left.role) == (None, "left_out", InstanceRole.STANDBY)
    assert dict(left.ruled_out) == {
        "robot-1": "battery: battery 10% not above 20%",
        "robot-2": "already holds Det",
    }
    assert result.plan.standbys_short() == {"Det": 1}


def test_a_link_constraint_is_named_with_the_peer_and_its_robot() -> None:
    view = ClusterView(
        (
            robot("robot-1", rtt={"robot-2": 80.0, "robot-3": 5.0}),
            robot("robot-2", rtt={"robot-1": 80.0}),
            robot("robot-3", rtt={"robot-1": 5.0}),
        ),
        "robot-1",
    )
    cam, det = comp("Cam", pin="robot-1"), comp("Det", prefer=("robot-2", "robot-3"))
    conns = (ConnectionDef("Cam", "image", "Det", "image"),)
    result = allocate(
        system(cam, det, connections=conns), view, epoch=1, version=1, allocator="robot-1"
    )
    w = whys(result.plan)
    assert w["Cam"].how == "pinned"
    d = w["Det"]
    assert (d.robot, d.how) == ("robot-3", "preferred")
    assert d.ruled_out == (("robot-2", "link to Cam on robot-1: delay: delay 80ms not below 50ms"),)
    assert "link to Cam on robot-1: delay" in d.checked


def test_objective_scores_are_kept_for_the_robots_tried_in_the_order_tried() -> None:
    view = ClusterView(
        (robot("robot-1", battery=30.0), robot("robot-2", battery=100.0, free=900 * MB)),
        "robot-1",
    )
    result = allocate(
        system(comp("Det"), strategy="objective"), view, epoch=1, version=1, allocator="robot-1"
    )
    assert result.plan is not None
    d = whys(result.plan)["Det"]
    assert d.robot == "robot-1"
    assert [r for r, _ in d.ruled_out] == ["robot-2"]  # ranked first (battery), too little memory
    assert [r for r, _ in d.scores] == ["robot-2", "robot-1"]
    assert d.scores[0][1] > d.scores[1][1]
    first_fit = allocate(system(comp("Det")), view, epoch=1, version=1, allocator="robot-1")
    assert whys(first_fit.plan)["Det"].scores == ()


def test_plans_carry_their_explanation_through_json() -> None:
    view = ClusterView((robot("robot-1", battery=10.0), robot("robot-2")), "robot-1")
    result = allocate(system(comp("Det")), view, epoch=2, version=5, allocator="robot-2")
    assert result.plan is not None
    back = plan_from_json(result.plan.to_json())
    assert back.why == result.plan.why
    assert back.why_of("Det") is not None


def state(*robots: RobotView) -> ClusterState:
    records = {r.name: RobotRecord(r.metrics, r.links, None, 0, ()) for r in robots}
    return ClusterState(alive=records, order=list(records))


def test_a_kept_placement_keeps_the_explanation_of_the_plan_that_decided_it() -> None:
    s = system(comp("Det"), comp("Cam"))
    first_state = state(
        robot("robot-1", battery=10.0), robot("robot-2", free=1100 * MB), robot("robot-3")
    )
    first = change(Deploy(s, "robot-1"), None, Context("robot-2", 4, first_state)).result
    assert isinstance(first, Plan)
    assert {p.instance: p.robot for p in first.placements} == {"Det": "robot-2", "Cam": "robot-3"}
    cam = first.why_of("Cam")
    assert cam is not None
    assert (cam.reason, cam.decided_in, cam.checked_in) == ("deploy", (4, 1), (4, 1))
    assert dict(cam.ruled_out) == {
        "robot-1": "battery: battery 10% not above 20%",
        "robot-2": "memory: free memory 100MB after adding 500MB would not be above 500MB",
    }
    # robot-2 dies: Det moves and says why; Cam stays and keeps the reason it went to robot-3
    later = state(robot("robot-1", battery=10.0), robot("robot-3"))
    why = "robots gone: robot-2"
    plan = change(Reissue(why, recovery=True), first, Context("robot-3", 4, later)).result
    assert isinstance(plan, Plan)
    moved, kept = plan.why_of("Det"), plan.why_of("Cam")
    assert moved is not None
    assert kept is not None
    assert (moved.robot, moved.how, moved.reason, moved.decided_in) == (
        "robot-3",
        "ranked",
        why,
        (4, 2),
    )
    assert moved.ruled_out == (("robot-1", "battery: battery 10% not above 20%"),)
    assert kept == replace(cam, checked_in=(4, 2))


def test_robots_the_health_judge_excluded_are_named_in_new_decisions() -> None:
    s = system(comp("Det", standby=StandbySpec(other_robots=1)))
    everyone = state(robot("robot-1"), robot("robot-2"), robot("robot-3"))
    first = change(Deploy(s, "robot-2"), None, Context("robot-2", 1, everyone)).result
    assert isinstance(first, Plan)
    assert {p.instance: p.robot for p in first.placements} == {
        "Det": "robot-2",
        "Det-s1": "robot-1",
    }
    # robot-2 dies while robot-1 is degraded (excluded): Det goes to robot-3, its standby nowhere
    later = state(robot("robot-1"), robot("robot-3"))
    ctx = Context("robot-3", 1, later, excluded=frozenset({"robot-1"}))
    plan = change(Reissue("robots gone: robot-2", recovery=True), first, ctx).result
    assert isinstance(plan, Plan)
    det, left = plan.why_of("Det"), plan.why_of("Det-s1")
    assert det is not None
    assert left is not None
    assert (det.robot, det.how) == ("robot-3", "ranked")
    assert ("robot-1", EXCLUDED) in det.ruled_out
    assert (left.robot, left.how) == (None, "left_out")
    assert left.ruled_out == (("robot-3", "already holds Det"), ("robot-1", EXCLUDED))
