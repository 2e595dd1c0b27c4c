"""Tests of the deterministic simulator: its mechanics (with a stand-in core) and the real
membership core at scale (convergence, failure detection, partitions, loss, restarts)."""

from __future__ import annotations

import random
from collections.abc import Sequence
from typing import Any

import pytest

from sdrpeer.gossip.config import GossipConfig, fast_test, lan
from sdrpeer.gossip.events import CoreEvent, MemberChanged, ProbeOutcome, RecordChanged
from sdrpeer.gossip.messages import ALIVE, DEAD, SUSPECT, Ack, Addr, Alive, Packet, Ping
from sdrpeer.sim import Cluster, Network, Trace
from sdrpeer.vocabulary import MemberState

# -- a stand-in core: pings every known peer each tick, reports rtts ---------------------------


class Beacon:
    """Minimal core: says hello to its seeds, then pings every known peer every `tick`."""

    tick = 0.1

    def __init__(
        self, name: str, addr: Addr, config: GossipConfig, now: float, rng: random.Random
    ) -> None:
        self.name, self.addr, self.rng = name, addr, rng
        self.known: dict[str, Addr] = {}
        self.out: list[tuple[Addr, Packet]] = []
        self.events: list[CoreEvent] = []
        self.sent: dict[int, float] = {}
        self.seq = 0
        self.deadline = now + rng.random() * self.tick
        self.fired: list[float] = []
        self.received: list[tuple[float, str]] = []

    def join(self, now: float, seeds: Sequence[Addr]) -> None:
        self.out += [(s, Ping(self.name, 0, "")) for s in seeds]

    def leave(self, now: float) -> None:
        pass

    def receive(self, now: float, src: Addr, packet: Packet) -> None:
        self.received.append((now, packet.sender))
        if packet.sender not in self.known:
            self.known[packet.sender] = src
            self.events.append(MemberChanged(packet.sender, src, ALIVE, 0, None, now))
        for update in packet.updates:  # a seed's answer to a hello introduces its peers
            if isinstance(update, Alive) and update.name not in {*self.known, self.name}:
                self.known[update.name] = update.addr
                self.events.append(MemberChanged(update.name, update.addr, ALIVE, 0, None, now))
        if isinstance(packet, Ping):
            peers = tuple(Alive(n, a, 0) for n, a in self.known.items()) if not packet.seq else ()
            self.out.append((src, Ack(self.name, packet.seq, peers)))
        elif isinstance(packet, Ack) and packet.seq in self.sent:
            rtt = now - self.sent.pop(packet.seq)
            self.events.append(ProbeOutcome(packet.sender, rtt, now))

    def handle_timer(self, now: float) -> None:
        self.fired.append(now)
        for addr in self.known.values():
            self.seq += 1
            self.sent[self.seq] = now
            self.out.append((addr, Ping(self.name, self.seq, "")))
        self.deadline = now + self.tick * (0.5 + self.rng.random())

    def next_timer(self) -> float:
        return self.deadline

    def datagrams_to_send(self) -> list[tuple[Addr, Packet]]:
        out, self.out = self.out, []
        return out

    def next_event(self) -> CoreEvent | None:
        return self.events.pop(0) if self.events else None

    def set_record(self, now: float, payload: bytes, *, urgent: bool = False) -> int:
        self.events.append(RecordChanged(self.name, 1, payload, now))
        return 1

    def broadcast_event(self, now: float, kind: str, payload: bytes) -> None:
        pass

    def members(self) -> list[Any]:
        return []

    def state_of(self, name: str) -> MemberState | None:
        return ALIVE if name in self.known else None


def beacons(n: int, seed: int = 1, **kw: Any) -> Cluster:
    cluster = Cluster(n, fast_test(), seed=seed, core_factory=Beacon, trace=True, **kw)
    cluster.start()
    return cluster


def beacon(cluster: Cluster, name: str) -> Beacon:
    core = cluster.core(name)
    assert isinstance(core, Beacon)
    return core


def rtts(cluster: Cluster) -> list[float]:
    return [e.rtt for _, _, e in cluster.trace.events if isinstance(e, ProbeOutcome) and e.rtt]


def test_delay_is_base_plus_jitter() -> None:
    cluster = beacons(5, base_delay=0.010, jitter=0.020)
    assert cluster.converge(2.0) < 0.2
    cluster.run_for(3.0)
    got = rtts(cluster)
    assert len(got) > 500
    assert 0.020 <= min(got) < 0.024
    assert 0.056 < max(got) <= 0.060


def test_loss_rate_global_and_per_link() -> None:
    cluster = beacons(3, loss=0.0)
    cluster.converge(1.0)
    cluster.set_loss(0.3)
    cluster.set_link_loss("r0000", "r0001", 1.0)
    before = len(beacon(cluster, "r0001").received)
    cluster.run_for(20.0)
    from_0 = [s for t, s in beacon(cluster, "r0001").received[before:] if s == "r0000"]
    assert from_0 == []
    pings, lost = sum(cluster.sent_datagrams), cluster.network.dropped_loss
    received = sum(len(beacon(cluster, n).received) for n in cluster.names)
    assert 0 <= pings - received - lost < 10  # nothing else drops datagrams (a few in flight)
    # Per round: 2 pings on 0-1 all lost; 4 pings on 0-2, 1-2 lose 30 %; the 2.8 acks lose 30 %.
    assert 0.43 < lost / pings < 0.49  # expected 4.04 / 8.8 = 0.459


def test_partition_drops_cross_traffic_until_healed() -> None:
    cluster = beacons(4)
    cluster.converge(1.0)
    cluster.partition(["r0000", "r0001"])
    cut = cluster.now
    cluster.run_for(2.0)
    for name in cluster.names:
        side = {"r0000", "r0001"} if name in {"r0000", "r0001"} else {"r0002", "r0003"}
        late = {s for t, s in beacon(cluster, name).received if t > cut + 0.01}
        assert late == side - {name}
    assert cluster.network.dropped_partition > 0
    cluster.heal()
    cluster.run_for(1.0)
    assert {s for t, s in beacon(cluster, "r0000").received if t > cluster.now - 0.5} == {
        "r0001",
        "r0002",
        "r0003",
    }


def test_kill_stops_timers_and_delivery_restart_boots_fresh() -> None:
    cluster = beacons(3)
    cluster.converge(1.0)
    old = beacon(cluster, "r0002")
    cluster.kill("r0002")
    killed_at = cluster.now
    cluster.run_for(2.0)
    assert not cluster.is_up("r0002")
    assert all(t <= killed_at for t in old.fired)
    assert all(t <= killed_at + 0.01 for t, _ in old.received)  # only what was in flight
    assert not any(
        t > killed_at + 0.01 and s == "r0002" for t, s in beacon(cluster, "r0000").received
    )
    with pytest.raises(ValueError, match="down"):
        cluster.set_record("r0002", b"x")
    cluster.restart("r0002")
    new = beacon(cluster, "r0002")
    assert new is not old
    assert new.rng.random() != random.Random(f"{cluster.seed}/r0002/0").random()
    cluster.run_for(1.0)
    assert any(s == "r0002" for t, s in beacon(cluster, "r0000").received if t > cluster.now - 0.5)
    assert cluster.trace.downs[2] == [killed_at]
    assert len(cluster.trace.boots[2]) == 2


def test_same_seed_same_run_other_seed_other_run() -> None:
    def run(seed: int) -> list[tuple[float, str, CoreEvent]]:
        cluster = beacons(6, seed=seed, loss=0.2)
        cluster.run_for(3.0)
        return cluster.trace.events

    assert run(3) == run(3)
    assert run(3) != run(4)


def test_scheduled_actions_run_at_their_time() -> None:
    cluster = beacons(3)
    cluster.schedule(1.5, lambda: cluster.kill("r0001"))
    cluster.run_until(2.0)
    assert cluster.trace.downs[1] == [1.5]
    assert cluster.now == 2.0


def test_a_timer_that_never_advances_is_reported() -> None:
    class Stuck(Beacon):
        def handle_timer(self, now: float) -> None:
            pass

    cluster = Cluster(2, fast_test(), core_factory=Stuck)
    cluster.start()
    with pytest.raises(RuntimeError, match="next_timer"):
        cluster.run_for(1.0)


def test_network_rejects_bad_rates_and_double_groups() -> None:
    net = Network(4, random.Random(0))
    with pytest.raises(ValueError, match="loss rate"):
        net.loss = 1.5
    with pytest.raises(ValueError, match="two partition groups"):
        net.partition([[0, 1], [1, 2]])
    net.partition([[0]])
    assert net.partitioned(0, 3)
    assert not net.partitioned(2, 3)


def test_trace_questions() -> None:
    trace = Trace(["a", "b", "c"])
    trace.record(1, MemberChanged("a", ("h", 1), ALIVE, 0, None, 1.0), 1.0)
    trace.record(2, MemberChanged("a", ("h", 1), SUSPECT, 0, ALIVE, 2.0), 2.0)
    trace.record(2, MemberChanged("a", ("h", 1), DEAD, 0, SUSPECT, 3.0), 3.0)
    trace.record(1, MemberChanged("a", ("h", 1), DEAD, 0, ALIVE, 4.0), 4.0)
    trace.record(1, RecordChanged("c", 2, b"", 5.0), 5.0)
    trace.record(2, RecordChanged("c", 3, b"", 6.0), 6.0)
    assert trace.first_seen("c", "a", DEAD) == 3.0
    assert trace.when_all_see("a", DEAD, ["b", "c"]) == 4.0
    assert trace.when_all_see("a", DEAD, ["b", "c"], after=3.5) is None
    assert trace.view("b", "a") == DEAD
    assert trace.record_arrivals("c", 2) == {"b": 5.0, "c": 6.0}
    assert trace.record_arrivals("c", 3) == {"c": 6.0}
    assert trace.false_deaths() == [(3.0, "c", "a"), (4.0, "b", "a")]
    trace.down(0, 3.5)
    assert trace.false_deaths() == [(3.0, "c", "a")]


# -- the real membership core ------------------------------------------------------------------


def alive_everywhere(cluster: Cluster) -> bool:
    """Ask the cores themselves (not the event mirror) whether everyone sees everyone alive."""
    up = cluster.up_names()
    return all(cluster.core(o).state_of(m) == ALIVE for o in up for m in up if m != o)


def dead_everywhere(cluster: Cluster, member: str, observers: Sequence[str]) -> bool:
    return all(cluster.core(o).state_of(member) == DEAD for o in observers)


def test_real_core_runs_are_deterministic() -> None:
    def run(seed: int) -> list[tuple[float, str, CoreEvent]]:
        cluster = Cluster(20, fast_test(), seed=seed, loss=0.05, trace=True)
        cluster.start(spread=0.3)
        cluster.converge(10.0)
        cluster.kill("r0007")
        cluster.set_record("r0003", b"v1")
        cluster.run_for(5.0)
        return cluster.trace.events

    first = run(11)
    assert len(first) > 1000
    assert first == run(11)
    assert first != run(12)


def test_100_robots_converge() -> None:
    cluster = Cluster(100, fast_test(), seed=2, count_bytes=False)
    cluster.start(spread=0.5)
    took = cluster.converge(15.0)
    assert took < 10.0
    assert alive_everywhere(cluster)
    assert all(len(cluster.core(n).members()) == 100 for n in cluster.names)
    assert cluster.trace.false_deaths() == []


def test_a_killed_robot_is_agreed_dead_by_all() -> None:
    cluster = Cluster(50, fast_test(), seed=3, count_bytes=False)
    cluster.start()
    cluster.converge(10.0)
    cluster.run_for(2.0)
    cluster.kill("r0013")
    killed = cluster.now
    others = cluster.up_names()
    assert cluster.wait_for(lambda: dead_everywhere(cluster, "r0013", others), timeout=10.0)
    agreed = cluster.trace.when_all_see("r0013", DEAD, others, after=killed)
    assert agreed is not None
    assert agreed - killed < 5.0
    assert cluster.trace.false_deaths() == []
    assert all(cluster.core(o).state_of(m) == ALIVE for o in others for m in others if m != o)


@pytest.mark.parametrize("hold", [1.0, 15.0], ids=["brief", "past-reap-time"])
def test_partition_marks_other_side_dead_then_heals(hold: float) -> None:
    cluster = Cluster(40, fast_test(), seed=4, count_bytes=False)
    cluster.start()
    cluster.converge(10.0)
    left, right = cluster.names[:20], cluster.names[20:]
    cluster.partition(left)

    def sides_split() -> bool:
        return all(
            cluster.core(o).state_of(m) == DEAD
            for side, other in ((left, right), (right, left))
            for o in side
            for m in other
        )

    assert cluster.wait_for(sides_split, timeout=30.0)
    cluster.run_for(hold)
    cluster.heal()
    healed = cluster.now
    assert cluster.wait_for(lambda: alive_everywhere(cluster), timeout=60.0), cluster.trace.lagging(
        range(40)
    )
    assert cluster.now - healed < 60.0


@pytest.mark.parametrize("n", [20, 100])
def test_30_percent_loss_causes_no_false_death(n: int) -> None:
    cluster = Cluster(n, lan(), seed=5, count_bytes=False)
    cluster.start()
    cluster.converge(20.0)
    began = cluster.now
    cluster.set_loss(0.3)
    cluster.run_for(60.0)
    assert cluster.trace.false_deaths(after=began) == []
    cluster.set_loss(0.0)
    cluster.converge(10.0)


def test_a_restarted_robot_is_alive_again_despite_higher_dead_incarnation() -> None:
    cluster = Cluster(30, fast_test(), seed=6, count_bytes=False)
    cluster.start()
    cluster.converge(10.0)
    victim, others = "r0009", [n for n in cluster.names if n != "r0009"]
    # Cut the victim off until it is suspected, then let it refute: its incarnation rises.
    cluster.partition([victim])
    cut = cluster.now
    assert cluster.wait_for(lambda: bool(cluster.trace.first_seen_by(victim, SUSPECT, cut)), 5.0)
    cluster.heal()
    cluster.converge(10.0)
    incarnation = _incarnation(cluster, "r0000", victim)
    assert incarnation > 0
    cluster.kill(victim)
    assert cluster.wait_for(lambda: dead_everywhere(cluster, victim, others), timeout=10.0)
    cluster.restart(victim)
    back = cluster.now
    assert cluster.wait_for(lambda: alive_everywhere(cluster), timeout=5.0), cluster.trace.lagging(
        range(30)
    )
    assert cluster.now - back < 3.0
    assert all(_incarnation(cluster, o, victim) > incarnation for o in others)


def _incarnation(cluster: Cluster, observer: str, member: str) -> int:
    (info,) = [m for m in cluster.core(observer).members() if m.name == member]
    return info.incarnation
