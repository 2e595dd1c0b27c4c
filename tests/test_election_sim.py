"""The election on the simulator: election cores over real membership cores, with kills, leaves,
abdications, returns, partitions and heals; plans fenced by epoch throughout."""

from __future__ import annotations

import functools
import random

import pytest

from sdrpeer.election import Elected, ElectionConfig, SteppedDown
from sdrpeer.election import fast_test as election_fast
from sdrpeer.gossip.config import fast_test
from sdrpeer.sim import Cluster
from sdrpeer.sim.election import ElectionSim, run_until_settled

SETTLE = 20.0


def booted(
    n: int, seed: int, config: ElectionConfig | None = None, spread: float = 0.5
) -> tuple[Cluster, ElectionSim]:
    """A converged, settled cluster of n robots booted within `spread` seconds (all priorities
    0: the highest name ranks first, and leads unless it booted too late to claim first)."""
    cluster = Cluster(n, fast_test(), seed=seed, count_bytes=False)
    sim = ElectionSim(cluster, config or election_fast())
    cluster.start(spread=spread)
    cluster.converge(30.0)
    assert run_until_settled(sim, SETTLE) is not None, sim.describe()
    return cluster, sim


def allocator(sim: ElectionSim) -> tuple[str, int]:
    """The single allocator of a settled cluster, and its epoch."""
    (part,) = sim.parts()
    name = sim.part_allocator(part)
    assert name, sim.describe()
    return name, sim.belief(name)[0]


def test_10_robots_a_killed_allocator_is_replaced_by_the_next_at_a_higher_epoch() -> None:
    cluster, sim = booted(10, seed=1)
    first, epoch = allocator(sim)
    assert first == "r0009"
    cluster.kill(first)
    took = run_until_settled(sim, SETTLE)
    assert took is not None, sim.describe()
    second, new_epoch = allocator(sim)
    assert second == "r0008"
    assert new_epoch > epoch
    assert all(sim.belief(name) == (new_epoch, second) for name in cluster.up_names())
    cluster.run_for(1.0)  # the new allocator's plans reach everyone, the old ones are fenced off
    for name in cluster.up_names():
        assert sim.plans.last(cluster.index[name]) == (new_epoch, second)
    assert sim.plans.violations == []


def test_an_abdicating_or_leaving_allocator_is_replaced_before_any_death_is_detected() -> None:
    _, sim = booted(10, seed=2)
    first, epoch = allocator(sim)
    sim.set_facts(first, eligible=False)  # battery below the threshold
    assert run_until_settled(sim, 1.0) is not None, sim.describe()
    second, epoch2 = allocator(sim)
    assert second != first
    assert epoch2 > epoch
    assert sim.belief(first) == (epoch2, second)  # it follows, it does not leave
    sim.leave(second)
    assert run_until_settled(sim, 1.0) is not None, sim.describe()
    third, epoch3 = allocator(sim)
    assert third not in (first, second)
    assert epoch3 > epoch2
    assert sim.plans.violations == []


@pytest.mark.parametrize("preempt", [False, True])
def test_a_returning_higher_robot_takes_the_role_only_with_preempt(preempt: bool) -> None:
    cluster, sim = booted(10, seed=3, config=election_fast().with_(preempt=preempt), spread=0.0)
    first, _ = allocator(sim)
    assert first == "r0009"
    cluster.kill(first)
    assert run_until_settled(sim, SETTLE) is not None
    second, epoch2 = allocator(sim)
    cluster.restart(first)
    cluster.run_for(3.0)
    assert run_until_settled(sim, SETTLE) is not None, sim.describe()
    now, epoch3 = allocator(sim)
    if preempt:
        assert now == first
        assert epoch3 > epoch2
    else:
        assert (now, epoch3) == (second, epoch2)
        assert not any(isinstance(e, Elected) for t, _, e in sim.log if t > cluster.now - 3.0)
    assert sim.plans.violations == []


@pytest.mark.parametrize("window", [True, False])
def test_a_higher_priority_robot_started_last_takes_the_role_within_its_window(
    window: bool,
) -> None:
    """5 robots, all priority 0 but r0002 (10), which boots 3 s after the others (a fleet started
    one robot after the other): the first allocator is r0004 (the highest name); r0002 takes
    the role from it once, at a higher epoch, and the fleet stays with it. Without the window
    (priority_window 0) r0004 keeps the role (the behaviour before)."""
    config = election_fast() if window else election_fast().with_(priority_window=0.0)
    cluster = Cluster(5, fast_test(), seed=6, count_bytes=False)
    sim = ElectionSim(cluster, config, priorities={"r0002": 10})
    cluster.start(spread=0.0)
    cluster.kill("r0002")  # booted with the others, gone before it heard anything
    cluster.run_for(3.0)
    assert run_until_settled(sim, SETTLE) is not None, sim.describe()
    first, epoch = allocator(sim)
    assert first == "r0004"
    started = cluster.now
    cluster.restart("r0002")  # its fence knows no epoch: a fresh start
    cluster.converge(30.0)
    cluster.run_for(config.startup_grace + 1.0)
    assert run_until_settled(sim, SETTLE) is not None, sim.describe()
    now, epoch2 = allocator(sim)
    if window:
        assert (now, epoch2) == ("r0002", epoch + 1)
        assert any(
            isinstance(e, SteppedDown) and n == "r0004" and e.reason == "outranked"
            for t, n, e in sim.log
            if t >= started
        )
    else:
        assert (now, epoch2) == ("r0004", epoch)
    settled_at = cluster.now
    cluster.run_for(10.0)  # once the window is shut, nobody claims again
    assert not any(isinstance(e, Elected) for t, _, e in sim.log if t > settled_at)
    assert allocator(sim) == (now, epoch2)
    assert sim.plans.violations == []


def test_partition_each_side_elects_and_after_the_heal_the_higher_epoch_wins() -> None:
    cluster, sim = booted(20, seed=4, spread=0.0)
    assert allocator(sim)[0] == "r0019"
    cluster.partition([f"r{i:04d}" for i in range(10, 19)])
    assert run_until_settled(sim, SETTLE) is not None, sim.describe()
    assert {sim.part_allocator(p) for p in sim.parts()} == {"r0019", "r0018"}
    for dead, successor in (("r0019", "r0009"), ("r0009", "r0008")):
        cluster.kill(dead)  # the low side elects twice: its epoch passes the other side's
        assert run_until_settled(sim, SETTLE) is not None, sim.describe()
        assert {sim.part_allocator(p) for p in sim.parts()} == {successor, "r0018"}
    assert sim.belief("r0008")[0] > sim.belief("r0018")[0]
    healed_at = cluster.now
    cluster.heal()
    assert run_until_settled(sim, SETTLE) is not None, sim.describe()
    assert allocator(sim) == ("r0008", sim.belief("r0008")[0])  # a lower name, a higher epoch
    assert any(isinstance(e, SteppedDown) and n == "r0018" for t, n, e in sim.log if t >= healed_at)
    cluster.run_for(1.0)
    stale = sim.belief("r0018")[0] - 1  # r0018's own epoch from before the heal
    sim.issue_plan("r0018", epoch=stale)  # a stale allocator, or its plan delayed
    cluster.run_for(1.0)
    final = (sim.belief("r0008")[0], "r0008")
    for name in cluster.up_names():
        if name != "r0018":
            assert sim.plans.last(cluster.index[name]) == final, name
    assert sim.plans.refused() >= len(cluster.up_names()) - 1
    assert sim.plans.violations == []


def kill_if_up(cluster: Cluster, name: str) -> None:
    if cluster.is_up(name):
        cluster.kill(name)


def chaos(n: int, seed: int, events: int) -> list[tuple[str, float]]:
    """Seeded random faults on n robots; after each, the cluster must settle. Returns (fault,
    settle time) per event."""
    cluster, sim = booted(n, seed=seed)
    rng = random.Random(f"election/{n}/{seed}")
    split = False
    settles = []
    for step in range(events):
        up = cluster.up_names()
        down = [name for name in cluster.names if not cluster.is_up(name)]
        leaders = [a for p in sim.parts() if (a := sim.part_allocator(p))]
        kind = rng.choice(["kill_allocator", "kill", "restart", "split", "abdicate", "leave"])
        if step == events - 1 or (split and rng.random() < 0.4):
            kind = "heal" if split else "kill_allocator"
        elif kind == "split" and split:
            kind = "kill_allocator"
        if kind == "kill_allocator":
            cluster.kill(rng.choice(leaders))
        elif kind == "kill":
            for name in rng.sample(up, n // 30 + 1):
                cluster.kill(name)
        elif kind == "restart":
            for name in rng.sample(down, min(n // 30 + 1, len(down))):
                cluster.restart(name)
        elif kind == "split":
            cluster.partition(rng.sample(cluster.names, rng.randint(n // 5, n - n // 5)))
            split = True
        elif kind == "heal":
            cluster.heal()
            split = False
        elif kind == "abdicate":
            sim.set_facts(rng.choice(leaders), eligible=False)
        else:
            gone = rng.choice(leaders)
            sim.leave(gone)
            cluster.schedule(cluster.now + 0.5, functools.partial(kill_if_up, cluster, gone))
        took = run_until_settled(sim, SETTLE)
        assert took is not None, f"step {step} ({kind}): {sim.describe()}"
        settles.append((kind, round(took, 2)))
    assert len(sim.parts()) == 1
    final, epoch = allocator(sim)
    cluster.run_for(1.0)
    for name in cluster.up_names():  # the last allocator's plans reached everyone
        assert sim.plans.last(cluster.index[name]) == (epoch, final), name
    assert sim.plans.violations == []
    return settles


def test_100_robots_random_kills_partitions_and_heals() -> None:
    """After every fault the cluster settles to one allocator per connected part, known by all
    of it; no robot ever applies a plan older than one it applied before."""
    settles = chaos(100, seed=5, events=16)
    assert {kind for kind, _ in settles} >= {"split", "heal", "kill_allocator", "abdicate"}
