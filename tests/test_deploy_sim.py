"""Deployment cores in the simulator, 1,000 robots: a deploy, robot deaths (the allocator's too),
a planned move and a recovery request all converge — every running robot ends with the
allocator's newest plan and runs exactly its share of it, no placement sits on a dead robot, and
no component runs ACTIVE on two robots for longer than a handover's fence window."""

from __future__ import annotations

import pytest

from sdrpeer.deploy.plan_change import Deploy, Move, Recover
from sdrpeer.gossip.config import fast_test
from sdrpeer.plan import Plan
from sdrpeer.sim.cluster import Cluster
from sdrpeer.sim.deploy import DeploySim
from sdrpeer.system.model import StandbySpec, SystemDef
from tests.test_alloc_core import TABLE_V, comp

MB = 1000**2
SYSTEM = SystemDef(
    "fleet",
    (
        comp("Camera", 700 * MB, standby=StandbySpec(other_robots=1)),
        comp("Detector", 700 * MB),
        comp("Planner", 700 * MB),
        comp("Mapper", 700 * MB),
    ),
    allocation=TABLE_V,
)
"""One component a robot (700MB of 1600MB free above 500MB); the camera keeps a hot standby."""


def fleet(n: int, seed: int, loss: float = 0.0) -> DeploySim:
    cluster = Cluster(n, fast_test(), seed=seed, loss=loss, count_bytes=False)
    sim = DeploySim(cluster)
    assert cluster.wait_for(lambda: sim.allocator() is not None, 2.0)
    return sim


FENCE = 1.0
"""How long two copies of a component may both run ACTIVE (a handover: the plan reaches the new
robot and the old one at slightly different times; the chaos judge allows the same)."""


def settle(sim: DeploySim, timeout: float = 10.0) -> float:
    """Run until every running robot runs its share of the allocator's plan, checking every
    0.05 s that no component runs ACTIVE on two robots for `FENCE` or longer; the virtual
    seconds it took."""
    began = sim.cluster.now
    doubled_since: dict[str, float] = {}

    def done() -> bool:
        now = sim.cluster.now
        doubled = {c for c, robots in sim.actives().items() if len(robots) > 1}
        for c in doubled_since.keys() - doubled:
            del doubled_since[c]
        for c in doubled:
            since = doubled_since.setdefault(c, now)
            assert now - since < FENCE, f"{c} ACTIVE twice since {since:.2f}: {sim.actives()[c]}"
        return not doubled and sim.running_as_planned()

    assert sim.cluster.wait_for(done, timeout, step=0.05), "no convergence"
    return sim.cluster.now - began


def held(sim: DeploySim) -> Plan:
    leader = sim.allocator()
    assert leader is not None
    plan = sim.plan(leader)
    assert plan is not None
    return plan


def active(plan: Plan, component: str) -> str:
    placement = plan.active_of(component)
    assert placement is not None
    return placement.robot


@pytest.mark.parametrize("loss", [0.0, 0.1])
def test_a_thousand_robots_converge_through_deaths_moves_and_recovery(loss: float) -> None:
    sim = fleet(1000, seed=7, loss=loss)
    first = sim.allocator()
    assert first == "r0000"
    plan = sim.request(Deploy(SYSTEM, first))
    assert isinstance(plan, Plan)
    assert settle(sim) < 3.0 + 2 * sim.fetch_timeout * (loss > 0)
    assert len(held(sim).placements) == 5

    # two robots running components die: their components move, the rest stays
    before = held(sim)
    victims = sorted({active(before, "Detector"), active(before, "Planner")})
    for name in victims:
        sim.kill(name)
    settle(sim)
    after = held(sim)
    assert not {p.robot for p in after.placements} & set(victims)
    assert active(after, "Camera") == active(before, "Camera")  # smallest change
    assert active(after, "Mapper") == active(before, "Mapper")

    # the allocator dies: the next robot adopts the plan and re-issues it under its epoch
    epoch = sim.epoch
    sim.kill(first)
    settle(sim)
    leader = sim.allocator()
    assert leader is not None
    assert leader != first
    assert (held(sim).epoch, held(sim).allocator) == (epoch + 1, leader)
    assert first not in {p.robot for p in held(sim).placements}

    # a planned move to a named robot
    plan = sim.request(Move("Mapper", "r0500"))
    assert isinstance(plan, Plan)
    settle(sim)
    assert active(held(sim), "Mapper") == "r0500"

    # a robot's recovery step: its component leaves it
    camera = active(held(sim), "Camera")
    plan = sim.request(Recover(camera, "Camera", "Camera", "standby_other_robot"))
    assert isinstance(plan, Plan)
    settle(sim)
    assert active(held(sim), "Camera") != camera

    # every running robot holds the newest plan, and none ever took a plan older than its own
    assert sim.converged()
    assert sim.violations == []
    assert sim.accepted >= 5 * 990  # five plans, each taken by (nearly) every robot


def test_a_deposed_allocators_plan_is_refused_everywhere() -> None:
    sim = fleet(200, seed=3)
    first = sim.allocator()
    assert first is not None
    assert isinstance(sim.request(Deploy(SYSTEM, first)), Plan)
    settle(sim)
    old = held(sim)
    sim.kill(first)
    settle(sim)
    new = held(sim)
    stale = Plan(old.epoch, old.version + 1, old.system, old.placements, old.allocator)
    sim.push_from(first, stale)  # its last plan, still on its way
    sim.cluster.run_for(1.0)
    assert len(sim.kinds("plan.refused")) == 199  # every running robot, the new allocator too
    assert sim.converged()
    assert held(sim) == new
    assert sim.violations == []
