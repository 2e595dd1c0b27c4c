"""Strategies: the score terms (tables), first_fit order, objective picking the best per term."""

from __future__ import annotations

import itertools
import random

import pytest

from sdrpeer.alloc.constraints import RobotLoad
from sdrpeer.alloc.core import allocate
from sdrpeer.alloc.scores import (
    battery_score,
    closeness_score,
    load_score,
    mem_score,
    rssi_score,
    traffic_local_score,
)
from sdrpeer.alloc.strategies import Context, Objective, Peer, weights_of
from sdrpeer.alloc.view import ClusterView, RobotView
from sdrpeer.errors import ConfigError
from sdrpeer.record.robot import Metrics
from sdrpeer.system.model import (
    AllocationDef,
    ComponentDef,
    ConnectionDef,
    Requirements,
    SystemDef,
    Thresholds,
)

MB = 1000**2


def robot(
    name: str,
    *,
    cpu: float = 10.0,
    free: int = 2000 * MB,
    battery: float | None = 80.0,
    rssi: float | None = -45.0,
    pos: tuple[float, float] | None = (0.0, 0.0),
) -> RobotView:
    return RobotView(name, Metrics(cpu, 4000 * MB, free, battery, rssi, pos))


def comp(name: str, **kw: object) -> ComponentDef:
    return ComponentDef(name, "python", "m:C", requires=Requirements(5.0, 100 * MB), **kw)  # type: ignore[arg-type]


def where(system: SystemDef, view: ClusterView) -> dict[str, str]:
    result = allocate(system, view, epoch=1, version=1, allocator="r1")
    assert result.plan is not None, str(result.infeasible)
    return {p.instance: p.robot for p in result.plan.placements}


# -- terms ----------------------------------------------------------------------------------


@pytest.mark.parametrize(
    ("fn", "args", "expected"),
    [
        (mem_score, (2000.0, 4000.0), 0.5),
        (mem_score, (0.0, 4000.0), 0.0),
        (mem_score, (-400.0, 4000.0), -0.1),  # cannot hold it: lower still
        (mem_score, (100.0, 0.0), 0.0),
        (battery_score, (80.0,), 0.8),
        (battery_score, (None,), 1.0),  # mains power
        (battery_score, (120.0,), 1.0),
        (rssi_score, (-90.0,), 0.0),
        (rssi_score, (-60.0,), 0.5),
        (rssi_score, (-30.0,), 1.0),
        (rssi_score, (-20.0,), 1.0),
        (rssi_score, (-100.0,), 0.0),
        (rssi_score, (None,), 1.0),  # wired
        (closeness_score, (0.0, 50.0), 1.0),
        (closeness_score, (25.0, 50.0), 0.5),
        (closeness_score, (80.0, 50.0), 0.0),
        (closeness_score, (None, 50.0), 0.5),
        (closeness_score, (0.0, 0.0), 1.0),
        (closeness_score, (3.0, 0.0), 0.0),
        (traffic_local_score, (750.0, 1000.0), 0.75),
        (traffic_local_score, (0.0, 0.0), 0.0),
        (load_score, (30.0,), 0.7),
        (load_score, (110.0,), -0.1),
    ],
)
def test_terms(fn, args, expected: float):
    assert fn(*args) == pytest.approx(expected)


def test_weights_default_and_unknown_term():
    alloc = AllocationDef(strategy="objective", weights=(("battery", 3.0),))
    w = weights_of(alloc, Objective.terms)
    assert w["battery"] == 3.0
    assert w["mem_free"] == 1.0
    with pytest.raises(ConfigError, match="unknown term 'gpu'"):
        weights_of(AllocationDef(weights=(("gpu", 1.0),)), Objective.terms)


# -- first_fit ------------------------------------------------------------------------------


def test_first_fit_starts_at_the_origin_then_view_order():
    view = ClusterView((robot("r1"), robot("r2"), robot("r3")), origin="r2")
    system = SystemDef("s", (comp("A"),))
    assert where(system, view) == {"A": "r2"}
    full = ClusterView((robot("r1"), robot("r2", free=100 * MB), robot("r3")), origin="r2")
    t = AllocationDef(thresholds=Thresholds(mem_free_above_bytes=200 * MB))
    assert where(SystemDef("s", (comp("A"),), allocation=t), full) == {"A": "r1"}
    no_origin = ClusterView((robot("r1"), robot("r2"), robot("r3")), origin="gone")
    assert where(system, no_origin) == {"A": "r1"}


def test_prefer_first_then_order():
    view = ClusterView((robot("r1"), robot("r2"), robot("r3", battery=5.0)), origin="r1")
    t = AllocationDef(thresholds=Thresholds(battery_above_pct=20.0))
    system = SystemDef(
        "s",
        (comp("A", prefer=("r3", "r2")), comp("B", prefer=("nowhere",))),
        allocation=t,
    )
    # r3 is preferred but fails the battery constraint; r2 is next preferred
    assert where(system, view) == {"A": "r2", "B": "r1"}


# -- objective ------------------------------------------------------------------------------


def only(term: str) -> AllocationDef:
    weights = tuple((t, 1.0 if t == term else 0.0) for t in Objective.terms)
    return AllocationDef(strategy="objective", weights=weights)


@pytest.mark.parametrize(
    ("term", "robots", "best"),
    [
        ("mem_free", [robot("r1", free=1000 * MB), robot("r2", free=3000 * MB)], "r2"),
        ("battery", [robot("r1", battery=30.0), robot("r2", battery=None), robot("r3")], "r2"),
        ("rssi", [robot("r1", rssi=-70.0), robot("r2", rssi=-40.0), robot("r3")], "r2"),
        ("load", [robot("r1", cpu=60.0), robot("r2", cpu=5.0), robot("r3", cpu=20.0)], "r2"),
    ],
)
def test_objective_picks_the_best_robot_per_robot_term(
    term: str, robots: list[RobotView], best: str
):
    view = ClusterView(tuple(robots), origin="r1")
    assert where(SystemDef("s", (comp("A"),), allocation=only(term)), view)["A"] == best


def _pair_system(term: str) -> SystemDef:
    return SystemDef(
        "s",
        (comp("Peer", pin="r3"), comp("A")),
        (ConnectionDef("Peer", "out", "A", "in", traffic_bytes_per_s=1e5),),
        allocation=only(term),
    )


def test_objective_distance_prefers_the_robot_near_the_placed_peer():
    view = ClusterView(
        (robot("r1", pos=(0, 0)), robot("r2", pos=(90, 0)), robot("r3", pos=(100, 0))),
        origin="r1",
    )
    placed = where(_pair_system("distance"), view)
    assert placed == {"Peer": "r3", "A": "r3"}  # same robot: distance 0
    sys2 = SystemDef(
        "s",
        (comp("Peer", pin="r3"), comp("A")),
        (ConnectionDef("Peer", "out", "A", "in"),),
        allocation=AllocationDef(
            strategy="objective",
            weights=tuple((t, 1.0 if t == "distance" else 0.0) for t in Objective.terms),
            thresholds=Thresholds(mem_free_above_bytes=1850 * MB),  # r3 full after Peer
        ),
    )
    assert where(sys2, view) == {"Peer": "r3", "A": "r2"}  # nearest other robot


def test_objective_traffic_local_prefers_the_peers_robot():
    view = ClusterView((robot("r1"), robot("r2"), robot("r3", pos=None)), origin="r1")
    assert where(_pair_system("traffic_local"), view) == {"Peer": "r3", "A": "r3"}


def test_objective_ranking_matches_the_exact_weighted_score():
    rng = random.Random(7)
    robots = tuple(
        robot(
            f"r{k}",
            cpu=rng.uniform(0, 80),
            free=rng.randint(500, 3500) * MB,
            battery=rng.choice([None, rng.uniform(0, 100)]),
            rssi=rng.choice([None, rng.uniform(-90, -30)]),
            pos=rng.choice([None, (rng.uniform(0, 100), rng.uniform(0, 100))]),
        )
        for k in range(12)
    )
    loads = tuple(RobotLoad(r, rng.uniform(0, 10), rng.randint(0, 300) * MB) for r in robots)
    alloc = AllocationDef(
        strategy="objective", weights=(("distance", 2.0), ("rssi", 0.5), ("traffic_local", 3.0))
    )
    ctx = Context(robots, loads, alloc)
    strategy = Objective()
    ranker = strategy.ranker(ctx)
    weights = weights_of(alloc, Objective.terms)
    target = comp("A")
    for peers in ([], [Peer(3, 1000.0, "P")], [Peer(3, 10.0, "P"), Peer(5, 90.0, "Q")]):

        def score(i: int, peers: list[Peer] = peers) -> float:
            terms = strategy.terms_for(ctx, target, peers, i)
            return sum(weights[t] * v for t, v in terms.items())

        order = list(ranker.order(target, peers))
        assert sorted(order) == list(range(len(robots)))
        scores = [score(i) for i in order]
        assert all(a >= b - 1e-9 for a, b in itertools.pairwise(scores)), scores
