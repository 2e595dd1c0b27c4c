"""The deployment core with literal times: plan sync, adopting and re-issuing after an election,
re-allocation when robots die, `retry_every`, recovery requests, moves, fencing, and applying
the plan to the robot (handover, superseded copies, launch policy, cut off). No asyncio, no
sockets: every test feeds `step(now, view)` or `apply(now, state, here)` and reads the effects."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import replace

import pytest

from sdrpeer.deploy.config import DeployConfig
from sdrpeer.deploy.core import DeployCore, DeployView, Here
from sdrpeer.deploy.disconnect import CutOff
from sdrpeer.deploy.effects import Adopted, Desired, Effect, Fetch, Log, Push
from sdrpeer.deploy.move import MoveError
from sdrpeer.deploy.placer import Infeasible
from sdrpeer.deploy.plan_change import Deploy, Move, Recover
from sdrpeer.deploy.planstore import PlanStore
from sdrpeer.deploy.view import ClusterState
from sdrpeer.errors import NotAllocator
from sdrpeer.plan import Placement, Plan
from sdrpeer.record.robot import (
    ElectionInfo,
    InstanceInfo,
    LinkSummary,
    Metrics,
    PlanInfo,
    RobotRecord,
)
from sdrpeer.system.model import DisconnectSpec, SystemDef
from sdrpeer.vocabulary import InstanceRole, LifecycleState
from tests.test_alloc_core import TABLE_V, comp

MB = 1000**2
METRICS = Metrics(10.0, 4000 * MB, 1600 * MB, 80.0, -45.0, (0.0, 0.0))
SYSTEM = SystemDef("s", (comp("A", 700 * MB), comp("B", 700 * MB)), allocation=TABLE_V)
"""Two components of 700MB on robots with 1600MB free above a 500MB threshold: one a robot."""
CONFIG = DeployConfig()


def record(name: str, plan: Plan | None = None, claim: int | None = None) -> RobotRecord:
    info = None if plan is None else PlanInfo(plan.epoch, plan.version, "d", plan.allocator)
    election = None if claim is None else ElectionInfo(claim, name, True)
    return RobotRecord(METRICS, LinkSummary(), f"http://{name}", 0, (), election, info)


def fleet(
    *names: str, plans: dict[str, Plan] | None = None, claims: dict[str, int] | None = None
) -> ClusterState:
    alive = {n: record(n, (plans or {}).get(n), (claims or {}).get(n)) for n in names}
    return ClusterState(alive, list(names))


def leading(state: ClusterState, epoch: int, me: str = "r1") -> DeployView:
    return DeployView(state, allocator=True, epoch=epoch, leader=me)


def following(state: ClusterState, epoch: int, leader: str) -> DeployView:
    return DeployView(state, allocator=False, epoch=epoch, leader=leader)


def core_holding(plan: Plan | None = None, me: str = "r1") -> DeployCore:
    store = PlanStore()
    if plan is not None:
        assert store.offer(plan)
    return DeployCore(me, store, CONFIG)


def adopted(effects: Sequence[Effect]) -> list[Plan]:
    return [e.plan for e in effects if isinstance(e, Adopted)]


def logs(effects: Sequence[Effect], kind: str) -> list[dict[str, object]]:
    return [e.detail for e in effects if isinstance(e, Log) and e.kind == kind]


def where(plan: Plan) -> dict[str, str]:
    return {p.instance: p.robot for p in plan.placements if p.role == InstanceRole.ACTIVE}


def deployed(core: DeployCore, state: ClusterState, epoch: int = 1, now: float = 1.0) -> Plan:
    """`core` (the allocator at `epoch`) deploys SYSTEM: A on r1, B on r2."""
    plan = core.request(now, leading(state, epoch, core.name), Deploy(SYSTEM, core.name))
    assert isinstance(plan, Plan)
    assert where(plan) == {"A": "r1", "B": "r2"}
    core.effects()
    return plan


HELD = Plan(1, 3, SYSTEM, (Placement("A", "A", "r1"), Placement("B", "B", "r2")), "r0")
"""The plan the previous allocator (r0, epoch 1) issued."""


# -- adopting after an election --------------------------------------------------------------


def test_a_new_allocator_reissues_the_plan_under_its_epoch_at_once_when_none_is_newer() -> None:
    core = core_holding(HELD)
    state = fleet("r1", "r2", "r3", plans={"r2": HELD, "r3": HELD})
    core.step(10.0, leading(state, 2))
    effects = core.effects()
    (plan,) = adopted(effects)
    assert (plan.epoch, plan.allocator, plan.version) == (2, "r1", 1)
    assert plan.placements == HELD.placements  # losing the allocator loses nothing
    assert core.store.plan == plan
    assert logs(effects, "allocation") == [{"reason": "new allocator", "epoch": 2}]
    pushed = {(e.robot, e.plan.key) for e in effects if isinstance(e, Push)}
    assert pushed == {("r2", plan.key), ("r3", plan.key)}
    core.step(10.1, leading(state, 2))
    assert core.effects() == []  # adopted once


def test_a_new_allocator_fetches_a_newer_plan_first_and_reissues_that_one() -> None:
    newer = Plan(1, 4, SYSTEM, (Placement("A", "A", "r3"), Placement("B", "B", "r2")), "r0")
    core = core_holding(HELD)
    state = fleet("r1", "r2", "r3", plans={"r2": HELD, "r3": newer})
    core.step(10.0, leading(state, 2))
    assert core.effects() == [Fetch("r3", "http://r3")]
    assert core.next_timer() == 10.0 + CONFIG.adopt_after
    core.step(10.5, leading(state, 2))
    assert core.effects() == []  # still waiting for the newer plan
    core.fetched("r3", newer)
    assert adopted(core.effects()) == [newer]
    core.step(10.6, leading(state, 2))  # caught up before adopt_after: re-issue at once
    (plan,) = adopted(core.effects())
    assert (plan.epoch, plan.version, plan.placements) == (2, 1, newer.placements)


def test_a_new_allocator_waits_at_most_adopt_after_for_a_newer_plan() -> None:
    newer = Plan(1, 4, SYSTEM, HELD.placements, "r0")
    core = core_holding(HELD)
    state = fleet("r1", "r2", "r3", plans={"r3": newer})
    core.step(10.0, leading(state, 2))
    assert core.effects() == [Fetch("r3", "http://r3")]  # and it never answers
    core.step(10.0 + CONFIG.adopt_after - 0.01, leading(state, 2))
    assert core.effects() == []
    core.step(10.0 + CONFIG.adopt_after, leading(state, 2))
    (plan,) = adopted(core.effects())
    assert plan.key == (2, "r1", 1)
    assert plan.placements == HELD.placements


def test_a_deploy_while_waiting_to_adopt_ends_the_wait() -> None:
    newer = Plan(1, 4, SYSTEM, HELD.placements, "r0")
    core = core_holding(HELD)
    state = fleet("r1", "r2", "r3", plans={"r3": newer})
    core.step(10.0, leading(state, 2))
    assert core.effects() == [Fetch("r3", "http://r3")]  # it never answers
    plan = core.request(10.2, leading(state, 2), Deploy(SYSTEM, "r1"))
    assert isinstance(plan, Plan)
    assert plan.key == (2, "r1", 1)
    core.effects()
    assert core.next_timer() == float("inf")  # no deadline left behind in the past
    core.step(10.0 + CONFIG.adopt_after, leading(state, 2))
    assert core.effects() == []  # our deploy is the plan of this epoch: nothing to adopt


def test_versions_grow_under_our_epoch_and_restart_at_one_under_a_new_one() -> None:
    core = core_holding()
    state = fleet("r1", "r2", "r3")
    first = deployed(core, state, epoch=1)
    assert first.key == (1, "r1", 1)
    moved = core.request(2.0, leading(state, 1), Move("A", "r3"))
    assert isinstance(moved, Plan)
    assert moved.key == (1, "r1", 2)
    assert adopted(core.effects()) == [moved]
    core.step(3.0, leading(state, 1))
    assert core.effects() == []  # our own plan under our epoch: nothing to re-issue
    core.step(4.0, leading(state, 5))  # a later election: the same robot at epoch 5
    (plan,) = adopted(core.effects())
    assert plan.key == (5, "r1", 1)


# -- re-allocation ---------------------------------------------------------------------------


def test_a_dead_robots_component_moves_and_the_rest_stays() -> None:
    core = core_holding()
    first = deployed(core, fleet("r1", "r2", "r3"))
    core.step(5.0, leading(fleet("r1", "r3"), 1))  # r2 died
    effects = core.effects()
    (plan,) = adopted(effects)
    assert plan.key == (1, "r1", 2)
    assert where(plan)["A"] == "r1"  # smallest change
    assert where(plan)["B"] in {"r1", "r3"}
    assert logs(effects, "allocation") == [{"reason": "robots gone: r2", "epoch": 1}]
    assert logs(effects, "recovery.move") == [
        {"reason": "robots gone: r2", "moved": {"B": ["r2", where(plan)["B"]]}}
    ]
    assert {e.robot for e in effects if isinstance(e, Push)} == {"r3"}
    assert first.key < plan.key


def test_a_degraded_robots_components_move_off_it() -> None:
    core = core_holding()
    deployed(core, fleet("r1", "r2", "r3"))
    view = DeployView(fleet("r1", "r2", "r3"), True, 1, "r1", frozenset({"r2"}), frozenset({"r2"}))
    core.step(5.0, view)
    effects = core.effects()
    (plan,) = adopted(effects)
    assert "r2" not in where(plan).values()
    assert logs(effects, "allocation")[0]["reason"] == "robots degraded: r2"


def test_an_infeasible_reallocation_is_retried_every_retry_every_or_on_a_change() -> None:
    system = SystemDef(
        "s", (comp("A", 700 * MB), comp("B", 700 * MB, pin="r2")), allocation=TABLE_V
    )
    core = core_holding()
    state = fleet("r1", "r2", "r3")
    plan = core.request(1.0, leading(state, 1), Deploy(system, "r1"))
    assert isinstance(plan, Plan)
    core.effects()
    without_r2 = fleet("r1", "r3")
    core.step(20.0, leading(without_r2, 1))
    effects = core.effects()
    assert len(logs(effects, "allocation.infeasible")) == 1
    assert adopted(effects) == []  # nothing better: the plan held stays
    assert core.next_timer() == 20.0 + CONFIG.retry_every
    core.step(21.0, leading(without_r2, 1))
    assert core.effects() == []
    core.step(20.0 + CONFIG.retry_every, leading(without_r2, 1))
    assert len(logs(core.effects(), "allocation.infeasible")) == 1
    core.step(26.0, leading(fleet("r1", "r3", "r4"), 1))  # a robot came: try at once
    assert len(logs(core.effects(), "allocation.infeasible")) == 1
    assert core.store.plan == plan


def test_held_components_wait_lost_after_before_they_are_replaced() -> None:
    slow = DisconnectSpec(lost_after_s=3.0)
    system = SystemDef(
        "s", (comp("A", 700 * MB), comp("B", 700 * MB, disconnect=slow)), allocation=TABLE_V
    )
    core = core_holding()
    plan = core.request(1.0, leading(fleet("r1", "r2", "r3"), 1), Deploy(system, "r1"))
    assert isinstance(plan, Plan)
    assert where(plan) == {"A": "r1", "B": "r2"}
    core.effects()
    core.step(10.0, leading(fleet("r1", "r3"), 1))
    assert adopted(core.effects()) == []
    assert core.next_timer() == 13.0
    core.step(13.0, leading(fleet("r1", "r3"), 1))
    (new,) = adopted(core.effects())
    assert where(new)["B"] != "r2"


def test_a_keep_original_component_moves_back_when_its_robot_returns() -> None:
    back = DisconnectSpec(reconcile="keep_original")
    system = SystemDef(
        "s", (comp("A", 700 * MB), comp("B", 700 * MB, disconnect=back)), allocation=TABLE_V
    )
    core = core_holding()
    core.request(1.0, leading(fleet("r1", "r2", "r3"), 1), Deploy(system, "r1"))
    core.effects()
    core.step(5.0, leading(fleet("r1", "r3"), 1))
    (away,) = adopted(core.effects())
    assert where(away)["B"] != "r2"
    assert away.origins == (("B", "r2"),)
    core.step(9.0, leading(fleet("r1", "r2", "r3"), 1))
    effects = core.effects()
    assert logs(effects, "reconcile") == [{"component": "B", "to": "r2", "policy": "keep_original"}]
    (home,) = adopted(effects)
    assert where(home)["B"] == "r2"
    assert home.origins == ()


# -- requests --------------------------------------------------------------------------------


def test_a_recovery_request_moves_the_component_off_the_faulty_robot() -> None:
    core = core_holding()
    state = fleet("r1", "r2", "r3")
    deployed(core, state)
    step = Recover("r1", "A", "A", "launch_other_robot")
    plan = core.request(5.0, leading(state, 1), step)
    assert isinstance(plan, Plan)
    assert where(plan)["A"] != "r1"
    effects = core.effects()
    assert adopted(effects) == [plan]
    assert logs(effects, "recovery.move") == [
        {"reason": "launch_other_robot for A on r1", "moved": {"A": ["r1", where(plan)["A"]]}}
    ]
    with pytest.raises(LookupError):
        core.request(6.0, leading(state, 1), Recover("r1", "Z", "Z", "launch_other_robot"))


def test_a_move_pins_the_component_for_one_allocation_only() -> None:
    core = core_holding()
    state = fleet("r1", "r2", "r3")
    deployed(core, state)
    plan = core.request(5.0, leading(state, 1), Move("A", "r3"))
    assert isinstance(plan, Plan)
    assert where(plan) == {"A": "r3", "B": "r2"}
    assert plan.system == SYSTEM  # the pin is not remembered
    effects = core.effects()
    assert logs(effects, "move") == [
        {"reason": "move A from r1 to r3", "moved": {"A": ["r1", "r3"]}}
    ]
    off = core.request(6.0, leading(state, 1), Move("B", None))
    assert isinstance(off, Plan)
    assert where(off)["B"] != "r2"
    with pytest.raises(MoveError, match="already runs on r3"):
        core.request(7.0, leading(state, 1), Move("A", "r3"))


def test_an_infeasible_deploy_is_reported_and_changes_nothing() -> None:
    core = core_holding()
    state = fleet("r1", "r2")
    held = deployed(core, state)
    big = SystemDef("big", (comp("Huge", 3000 * MB),), allocation=TABLE_V)
    result = core.request(2.0, leading(state, 1), Deploy(big, "r1"))
    assert isinstance(result, Infeasible)
    effects = core.effects()
    assert adopted(effects) == []
    assert len(logs(effects, "allocation.infeasible")) == 1
    assert core.store.plan == held
    undeploy = core.request(3.0, leading(state, 1), Deploy(None, "r1"))
    assert isinstance(undeploy, Plan)
    assert (undeploy.system, undeploy.placements, undeploy.version) == (None, (), 2)


# -- plan sync and fencing -------------------------------------------------------------------


def test_a_follower_fetches_the_newest_plan_one_at_a_time_and_waits_after_a_failure() -> None:
    newer = Plan(1, 5, SYSTEM, HELD.placements, "r0")
    core = core_holding(HELD, me="r2")
    state = fleet("r1", "r2", "r3", plans={"r1": HELD, "r3": newer})
    view = following(state, 1, "r0")
    core.step(5.0, view)
    assert core.effects() == [Fetch("r3", "http://r3")]
    assert not core.caught_up(state)
    core.step(5.1, view)
    assert core.effects() == []  # one fetch in flight
    core.fetch_failed(5.2, "r3")
    core.step(5.3, view)
    assert core.effects() == []
    assert core.next_timer() == 5.2 + CONFIG.fetch_retry
    core.step(5.2 + CONFIG.fetch_retry, view)
    assert core.effects() == [Fetch("r3", "http://r3")]
    core.fetched("r3", newer)
    assert adopted(core.effects()) == [newer]
    assert core.caught_up(state)


def test_a_plan_from_an_older_epoch_is_refused() -> None:
    core = core_holding(Plan(2, 1, SYSTEM, HELD.placements, "r2"), me="r3")
    assert not core.offer(Plan(1, 9, SYSTEM, (), "r1"), source="r1")
    assert logs(core.effects(), "plan.refused") == [
        {"epoch": 1, "version": 9, "allocator": "r1", "fence": 2, "source": "r1"}
    ]
    core.step(1.0, following(fleet("r1", "r2", "r3", claims={"r4": 3}), 2, "r2"))
    core.step(1.0, following(fleet("r1", "r4", claims={"r4": 3}), 3, "r4"))
    assert not core.offer(Plan(2, 5, SYSTEM, (), "r2"), source="r2")  # r4 claimed epoch 3
    assert core.offer(Plan(3, 1, SYSTEM, (), "r4"), source="r4")


def test_a_deposed_allocator_issues_nothing() -> None:
    core = core_holding()
    deployed(core, fleet("r1", "r2", "r3"))
    view = following(fleet("r1", "r3", "r4", claims={"r4": 2}), 2, "r4")
    core.step(5.0, view)  # r2 died, but r1 no longer holds the role
    assert core.effects() == []
    assert core.next_timer() == float("inf")
    with pytest.raises(NotAllocator) as raised:
        core.request(5.1, view, Move("A", "r3"))
    assert raised.value.leader == "r4"
    assert core.effects() == []


# -- applying the plan to this robot ---------------------------------------------------------


class NoExec:
    """A launch policy that refuses the exec launcher."""

    def refusal(self, launcher: str, target: str | Sequence[str]) -> str | None:
        return "exec is off" if launcher == "exec" else None


def desired(core: DeployCore) -> dict[str, str]:
    """instance -> desired state, from the Desired effect the last apply queued."""
    (effect,) = [e for e in core.effects() if isinstance(e, Desired)]
    return {s.name: s.desired for s in effect.specs}


def running(name: str, component: str, plan: Plan | None = None) -> RobotRecord:
    """A robot that runs `component` ACTIVE as its active instance `name`."""
    inst = InstanceInfo(
        name, component, LifecycleState.ACTIVE, InstanceRole.ACTIVE, 1.0, 10**7, "tcp://10.0.0.9:7"
    )
    return replace(record("r2", plan), instances=(inst,))


def test_a_moved_active_waits_for_the_old_copy_at_most_handover_wait() -> None:
    core = core_holding(HELD, me="r2")  # HELD places B on r2; r3 still runs B ACTIVE
    state = fleet("r1", "r2", "r3")
    state.alive["r3"] = replace(running("B-old", "B"), api="http://r3")
    core.apply(10.0, state, Here())
    assert desired(core) == {"B": LifecycleState.INACTIVE}
    core.apply(10.0 + CONFIG.handover_wait - 0.01, state, Here())
    assert desired(core) == {"B": LifecycleState.INACTIVE}
    core.apply(10.0 + CONFIG.handover_wait, state, Here())
    assert desired(core) == {"B": LifecycleState.ACTIVE}  # the old robot never heard of the plan


def test_the_old_side_stands_down_for_a_newer_plans_copy_and_says_so_once() -> None:
    core = core_holding(HELD, me="r1")  # A on r1
    newer = Plan(2, 1, SYSTEM, (Placement("A", "A", "r2"),), "r2")
    state = fleet("r1", "r2")
    state.alive["r2"] = running("A", "A", newer)
    core.apply(10.0, state, Here())
    effects = core.effects()
    assert logs(effects, "plan.superseded") == [{"instance": "A", "newer": ["r2"]}]
    (want,) = [e for e in effects if isinstance(e, Desired)]
    assert {s.name: s.desired for s in want.specs} == {"A": LifecycleState.INACTIVE}
    core.apply(10.1, state, Here())
    assert logs(core.effects(), "plan.superseded") == []


def test_what_the_launch_policy_refuses_is_left_out_and_said_once() -> None:
    sh = replace(comp("Sh", 100 * MB), launcher="exec", target=("/bin/sh",))
    system = SystemDef("s", (sh, comp("A", 100 * MB)), allocation=TABLE_V)
    plan = Plan(1, 1, system, (Placement("Sh", "Sh", "r1"), Placement("A", "A", "r1")), "r2")
    core = core_holding(plan)
    core.apply(1.0, fleet("r1"), Here(policy=NoExec()))
    effects = core.effects()
    assert logs(effects, "launch.refused") == [{"instance": "Sh", "reason": "exec is off"}]
    assert [s.name for e in effects if isinstance(e, Desired) for s in e.specs] == ["A"]
    core.apply(1.1, fleet("r1"), Here(policy=NoExec()))
    assert logs(core.effects(), "launch.refused") == []


def test_nothing_is_applied_before_joining_and_dropped_placements_are_removed() -> None:
    core = core_holding(HELD, me="r1")
    core.apply(1.0, fleet("r1", "r2"), Here(joined=False))
    assert core.effects() == []
    core.apply(1.1, fleet("r1", "r2"), Here())
    assert desired(core) == {"A": LifecycleState.ACTIVE}
    assert core.offer(Plan(1, 4, SYSTEM, (Placement("A", "A", "r2"),), "r0"), source="r0")
    core.effects()
    core.apply(1.2, fleet("r1", "r2"), Here())
    (effect,) = [e for e in core.effects() if isinstance(e, Desired)]
    assert (effect.specs, effect.removed) == ((), ("A",))


def test_a_robot_cut_off_holds_its_actives_down() -> None:
    core = core_holding(HELD, me="r1")
    cutoff = CutOff()
    cutoff.update(5.0, quorum=False, caught_up=True)
    core.apply(5.0, fleet("r1"), Here(cutoff=cutoff))
    assert desired(core) == {"A": LifecycleState.INACTIVE}  # stop_after 0 s: at once


# -- a predecessor's plan the fence refuses ----------------------------------------------------


def carried_on(
    core: DeployCore, now: float, state: ClusterState, epoch: int, *, robot: str, plan: Plan
) -> list[Effect]:
    """The allocator `core` fetches `plan` from `robot` (the fence refuses it) and re-issues it
    at its next step: that step's effects."""
    core.step(now, leading(state, epoch))
    assert core.effects() == [Fetch(robot, f"http://{robot}")]
    core.fetched(robot, plan)
    core.effects()
    core.step(now + 0.1, leading(state, epoch))
    return core.effects()


def test_a_new_allocator_whose_claim_raised_the_fence_still_catches_up_with_a_newer_plan() -> None:
    newer = Plan(1, 4, SYSTEM, (Placement("A", "A", "r3"), Placement("B", "B", "r2")), "r0")
    core = core_holding(HELD)
    state = fleet("r1", "r2", "r3", plans={"r2": HELD, "r3": newer}, claims={"r1": 2})
    core.step(10.0, leading(state, 2))
    assert core.effects() == [Fetch("r3", "http://r3")]  # the fence (2, r1) does not stop it
    core.fetched("r3", newer)
    effects = core.effects()
    assert logs(effects, "plan.refused")  # the store still refuses it...
    assert core.store.plan == HELD
    core.step(10.1, leading(state, 2))
    (plan,) = adopted(core.effects())  # ...and the allocator re-issues it under its epoch
    assert (plan.key, plan.placements) == ((2, "r1", 1), newer.placements)
    assert core.store.plan == plan


def test_an_allocator_holding_no_plan_carries_on_a_deploy_its_predecessor_took_late() -> None:
    """r0 (epoch 1) had not heard of r1's claim (epoch 2) when a deploy reached it: the robots
    that had heard refuse its plan; r1 fetches it and re-issues it, so the deploy is not lost."""
    late = Plan(1, 1, SYSTEM, (Placement("A", "A", "r1"), Placement("B", "B", "r2")), "r0")
    core = core_holding(None)
    quiet = fleet("r0", "r1", "r2", claims={"r1": 2, "r0": 1})
    core.step(10.0, leading(quiet, 2))
    assert core.effects() == []  # nothing to adopt
    state = fleet("r0", "r1", "r2", plans={"r0": late}, claims={"r1": 2, "r0": 1})
    effects = carried_on(core, 12.0, state, 2, robot="r0", plan=late)
    (plan,) = adopted(effects)
    assert (plan.key, plan.placements) == ((2, "r1", 1), late.placements)
    assert {e.robot for e in effects if isinstance(e, Push)} == {"r0", "r2"}
    reasons = [d["reason"] for d in logs(effects, "allocation")]
    assert reasons == ["carried on r0's plan (epoch 1, version 1)"]


def test_an_allocator_with_a_plan_of_its_own_epoch_refuses_a_predecessors_later_plan() -> None:
    core = core_holding()
    state = fleet("r1", "r2", "r0", claims={"r1": 2})
    mine = deployed(core, state, epoch=2)
    minority = Plan(1, 7, SYSTEM, (Placement("A", "A", "r0"), Placement("B", "B", "r0")), "r0")
    state = fleet("r1", "r2", "r0", plans={"r0": minority, "r1": mine}, claims={"r1": 2})
    core.step(20.0, leading(state, 2))
    assert core.effects() == []  # not fetched: a cut-off old allocator does not undo the fleet
    core.fetched("r0", minority)  # even if it arrives somehow
    core.step(20.1, leading(state, 2))
    assert adopted(core.effects()) == []
    assert core.store.plan == mine


def test_an_allocator_carries_on_the_plan_of_a_rival_it_outranks_at_the_same_epoch() -> None:
    """r0 and r1 both claimed epoch 3 (the election keeps the higher name, r1, and so does every
    fence); r0 took a deploy first: r1 re-issues it rather than leave it to nobody."""
    rival = Plan(3, 1, SYSTEM, (Placement("A", "A", "r1"), Placement("B", "B", "r2")), "r0")
    core = core_holding(None)
    state = fleet("r0", "r1", "r2", plans={"r0": rival}, claims={"r1": 3, "r0": 3})
    (plan,) = adopted(carried_on(core, 10.0, state, 3, robot="r0", plan=rival))
    assert (plan.key, plan.placements) == ((3, "r1", 2), rival.placements)
    assert core.store.plan == plan


def test_a_predecessors_plan_is_issued_at_adoption_even_when_what_must_move_is_held() -> None:
    """The newer plan fetched while adopting places B on r4, which is gone, and B's disconnect
    policy holds it there for 30 s: nothing may move yet, but the plan is issued under the new
    epoch at once (kept in memory only, r1 would go on applying the older plan it holds, and
    the robots that heard of r1 refuse the predecessor's: A active twice)."""
    slow = DisconnectSpec(lost_after_s=30.0)
    system = SystemDef(
        "s", (comp("A", 700 * MB), comp("B", 700 * MB, disconnect=slow)), allocation=TABLE_V
    )
    held = Plan(1, 3, system, (Placement("A", "A", "r1"), Placement("B", "B", "r2")), "r0")
    newer = Plan(1, 5, system, (Placement("A", "A", "r3"), Placement("B", "B", "r4")), "r0")
    core = core_holding(held)
    state = fleet("r1", "r2", "r3", plans={"r2": held, "r3": newer}, claims={"r1": 2})
    (plan,) = adopted(carried_on(core, 10.0, state, 2, robot="r3", plan=newer))
    assert (plan.key, plan.placements) == ((2, "r1", 1), newer.placements)
    assert core.store.plan == plan
    assert core.caught_up(state)


def test_a_request_while_adopting_starts_from_the_predecessors_newer_plan() -> None:
    newer = Plan(1, 5, SYSTEM, (Placement("A", "A", "r3"), Placement("B", "B", "r2")), "r0")
    core = core_holding(HELD)
    state = fleet("r1", "r2", "r3", plans={"r3": newer}, claims={"r1": 2})
    core.step(10.0, leading(state, 2))
    assert core.effects() == [Fetch("r3", "http://r3")]
    core.fetched("r3", newer)
    core.effects()
    assert not core.caught_up(state)  # the predecessor's plan waits to be re-issued
    moved = core.request(10.05, leading(state, 2), Move("B", "r1"))
    assert isinstance(moved, Plan)
    assert where(moved) == {"A": "r3", "B": "r1"}  # A where the newer plan has it
    core.effects()
    core.step(10.1, leading(state, 2))
    assert adopted(core.effects()) == []  # our own plan already: nothing left to adopt


def test_deploying_the_system_held_again_moves_nothing() -> None:
    """A client that retries a deploy (its first answer lost to a timeout) or applies the same
    file again gets the plan held: no new allocation, which would judge robots by metrics that
    do not count yet the instances the first plan is starting, and move them."""
    core = core_holding()
    state = fleet("r1", "r2", "r3")
    first = deployed(core, state, epoch=1)
    full = fleet("r2", "r1", "r3")  # another order: a new allocation would place A on r2
    again = core.request(2.0, leading(full, 1), Deploy(SYSTEM, "r2"))
    assert again == first
    effects = core.effects()
    assert adopted(effects) == []
    assert not [e for e in effects if isinstance(e, Push)]
    assert logs(effects, "allocation") == [{"reason": "deploy: the system held, unchanged"}]
    other = SystemDef("s", (comp("A", 700 * MB),), allocation=TABLE_V)
    changed = core.request(3.0, leading(state, 1), Deploy(other, "r1"))
    assert isinstance(changed, Plan)
    assert changed.key == (1, "r1", 2)  # a different system is deployed as ever
