"""The core's fleet-size-independent parts: vitals on pings, table digests, record floors."""

from __future__ import annotations

import random

from sdrpeer.gossip.config import lan
from sdrpeer.gossip.core import Membership
from sdrpeer.gossip.events import CoreEvent, RecordChanged, VitalsChanged
from sdrpeer.gossip.messages import (
    ALIVE,
    Ack,
    Addr,
    Alive,
    Dead,
    Digest,
    Gossip,
    Packet,
    Ping,
    Record,
    Suspect,
    Sync,
    VitalsRevision,
)
from sdrpeer.sim import Cluster
from tests.gossip_net import Net, addr

CONFIG = lan()


def robot(name: str = "r0", *, first_version: int = 1) -> Membership:
    i = int(name[1:])
    core = Membership(
        name, addr(i), CONFIG, now=0.0, rng=random.Random(i), first_version=first_version
    )
    core.receive(0.0, addr(1), Gossip("r1", (Alive("r1", addr(1), 0),)))
    core.datagrams_to_send()
    return core


def pings(core: Membership, until: float, t: float = 0.0, *, answer: bool = False) -> list[Ping]:
    """Run the core's timers to `until`; the direct pings it sent (acknowledged if `answer`)."""
    out: list[Ping] = []
    while t < until:
        t = round(t + 0.01, 6)
        core.handle_timer(t)
        sent = [p for _, p in core.datagrams_to_send() if isinstance(p, Ping)]
        if answer:
            for p in sent:
                core.receive(t, addr(1), Ack("r1", p.seq))
            core.datagrams_to_send()
        out += sent
    return out


def events(core: Membership) -> list[CoreEvent]:
    out: list[CoreEvent] = []
    while (e := core.next_event()) is not None:
        out.append(e)
    return out


# ------------------------------------------------------------------ vitals


def test_vitals_ride_on_pings_until_the_peer_acknowledges_them() -> None:
    core = robot()
    assert core.set_vitals(0.0, b"early") == 0  # no record yet: nothing to revise
    version = core.set_record(0.0, b"record")
    assert core.set_vitals(0.0, b"v1") == 1
    first = pings(core, 0.3)
    assert len(first) >= 2, "the core probes its peer, and again when no ack comes"
    assert all(p.vitals == VitalsRevision(version, 1, b"v1") for p in first)  # lost: again
    # r1 acknowledges one of them: the next pings carry nothing.
    core.receive(0.3, addr(1), Ack("r1", first[-1].seq))
    later = pings(core, 2.0, 0.3, answer=True)
    assert len(later) > 5
    assert all(p.vitals is None for p in later)
    assert core.set_vitals(2.0, b"v2") == 2
    assert pings(core, 3.0, 2.0, answer=True)[0].vitals == VitalsRevision(version, 2, b"v2")


def test_a_new_record_restarts_the_revisions_and_carries_the_values() -> None:
    core = robot()
    core.set_record(0.0, b"a")
    core.set_vitals(0.0, b"v1")
    version = core.set_record(0.1, b"b")
    assert core.vitals_of("r0") is None
    assert all(p.vitals is None for p in pings(core, 1.0, answer=True))
    assert core.set_vitals(1.0, b"v") == 1
    assert core.vitals_of("r0") == VitalsRevision(version, 1, b"v")


def test_received_vitals_are_ordered_and_tied_to_the_record_held() -> None:
    core = robot()
    core.receive(0.0, addr(1), Gossip("r1", (Record("r1", 5, b"rec5"),)))
    events(core)

    def ping(version: int, revision: int) -> None:
        v = VitalsRevision(version, revision, f"{version}.{revision}".encode())
        core.receive(0.1, addr(1), Ping("r1", 1, "r0", (), v))

    ping(5, 2)
    ping(5, 1)  # older: ignored
    ping(4, 9)  # a revision of a record older than the one held: ignored
    ping(6, 1)  # ahead of the record held: kept (the record is on its way)
    got = [(e.version, e.revision) for e in events(core) if isinstance(e, VitalsChanged)]
    assert got == [(5, 2), (6, 1)]
    assert core.vitals_of("r1") == VitalsRevision(6, 1, b"6.1")
    core.receive(0.2, addr(1), Gossip("r1", (Record("r1", 7, b"rec7"),)))
    assert core.vitals_of("r1") is None  # revisions of an older record are dropped
    core.receive(0.3, addr(9), Ping("r9", 1, "r0", (), VitalsRevision(1, 1, b"x")))
    assert core.vitals_of("r9") is None  # not a member


def test_vitals_of_a_record_we_lack_pull_it_at_once() -> None:
    """r1's ping revises its record version 6; we hold version 5 (we were cut off while the
    fleet moved on): we send r1 our table at once, asking for its newer records."""
    core = robot()
    core.receive(0.0, addr(1), Gossip("r1", (Record("r1", 5, b"rec5"),)))
    core.datagrams_to_send()

    def pulls(t: float, version: int, revision: int) -> list[Sync]:
        v = VitalsRevision(version, revision, b"v")
        core.receive(t, addr(1), Ping("r1", revision, "r0", (), v))
        return [p for dst, p in core.datagrams_to_send() if isinstance(p, Sync) and dst == addr(1)]

    assert pulls(0.1, 5, 1) == []  # vitals of the record we hold: nothing to fetch
    (pull,) = pulls(0.2, 6, 1)
    assert pull.reply  # r1 answers with the records we lack, and its own table
    assert ("r1", addr(1), 0, ALIVE, 5) in pull.entries
    assert pulls(0.5, 6, 2) == []  # at most one pull a second per peer
    assert len(pulls(1.3, 6, 3)) == 1  # still behind a second later: again
    assert core.counters["pulls"] == 2


def test_a_robot_declared_dead_pulls_what_it_missed() -> None:
    core = robot()
    core.receive(1.0, addr(2), Ack("r2", 1, (Dead("r0", 0, "r2"),)))  # "you were dead to us"
    out = core.datagrams_to_send()
    assert core.incarnation == 1  # refuted
    assert any(isinstance(p, Sync) and p.reply for dst, p in out if dst == addr(2))


def test_reaping_forgets_vitals() -> None:
    core = robot()
    core.receive(0.0, addr(1), Ping("r1", 1, "r0", (), VitalsRevision(1, 1, b"v")))
    core.receive(0.1, addr(2), Gossip("r2", (Dead("r1", 0, "r2"),)))
    core.handle_timer(0.1 + CONFIG.dead_reap_time)
    assert core.state_of("r1") is None
    assert core.vitals_of("r1") is None


def test_vitals_reach_every_peer_at_a_cost_flat_in_n() -> None:
    """In the simulator, every robot learns every other robot's vitals from its probes; the
    bytes each robot sends do not grow with the fleet."""
    sent: dict[int, float] = {}
    for n in (10, 40):
        cluster = Cluster(n, CONFIG, seed=3)
        cluster.start()
        cluster.run_until(5.0)
        for name in cluster.names:
            core = cluster.core(name)
            assert isinstance(core, Membership)
            core.set_record(cluster.now, b"r" + name.encode())
            core.set_vitals(cluster.now, b"v" * 40)
        cluster.run_until(5.0 + 2 * n * CONFIG.probe_interval)
        for name in cluster.names:
            core = cluster.core(name)
            assert isinstance(core, Membership)
            have = [other for other in cluster.names if core.vitals_of(other) is not None]
            assert len(have) == n, f"{name} has the vitals of {len(have)} of {n}"
        before = sum(cluster.sent_bytes)
        cluster.run_until(cluster.now + 30.0)
        sent[n] = (sum(cluster.sent_bytes) - before) / 30.0 / n
    assert sent[40] < 1.2 * sent[10], sent


# ------------------------------------------------------------------ digests


def test_equal_tables_end_anti_entropy_at_the_digest() -> None:
    net = Net(CONFIG)
    cores = [net.add(i) for i in range(4)]
    for core in cores[1:]:
        core.join(net.now, [addr(0)])
    net.run(20.0)
    digests = {c.table_digest() for c in cores}
    assert len(digests) == 1
    for c in cores:
        assert c.table_digest() == c.digest_from_scratch()
    syncs_before = sum(c.counters.get("digest_same", 0) for c in cores)
    full: list[Packet] = []

    def watch(src: Addr, dst: Addr, p: Packet) -> bool:
        if isinstance(p, Sync):
            full.append(p)
        return False

    net.drop = watch
    net.run(40.0)
    assert sum(c.counters.get("digest_same", 0) for c in cores) > syncs_before + 4
    assert full == []  # nobody needed the full exchange


def test_a_differing_digest_brings_the_full_exchange_both_ways() -> None:
    a, b = robot("r0"), robot("r2")
    a.set_record(0.0, b"a")
    b.receive(0.0, addr(3), Gossip("r3", (Alive("r3", addr(3), 0),)))
    b.datagrams_to_send()
    assert a.table_digest() != b.table_digest()
    b.receive(1.0, addr(0), Digest("r0", a.table_digest(), 2))
    answer = b.datagrams_to_send()
    assert [type(p) for _, p in answer] == [Sync]
    assert answer[0][1].reply  # type: ignore[union-attr]
    a.receive(1.0, addr(2), answer[0][1])
    back = a.datagrams_to_send()
    assert any(isinstance(p, Sync) and not p.reply for _, p in back)
    assert a.state_of("r3") is not None  # a learnt of r3 from b's table


def test_incremental_digest_matches_a_fresh_one_through_churn() -> None:
    cluster = Cluster(30, CONFIG, seed=11)
    cluster.start()
    cluster.run_until(5.0)
    rng = random.Random(5)
    for step in range(12):
        victim = cluster.names[1 + rng.randrange(29)]
        if cluster.is_up(victim):
            cluster.kill(victim)
        else:
            cluster.restart(victim)
        core = cluster.core(cluster.names[rng.randrange(30)])
        if cluster.is_up(core.name):
            core.set_record(cluster.now, b"x%d" % step)
        cluster.run_until(cluster.now + 4.0)
    for name in cluster.names:
        if cluster.is_up(name):
            core = cluster.core(name)
            assert isinstance(core, Membership)
            assert core.table_digest() == core.digest_from_scratch(), name


def test_digest_covers_incarnation_and_record_version_not_suspicion() -> None:
    core = robot()
    start = core.table_digest()
    core.receive(0.1, addr(2), Gossip("r2", (Suspect("r1", 0, "r2"),)))
    assert core.table_digest() == start  # suspect is still "up"
    core.receive(0.2, addr(1), Gossip("r1", (Alive("r1", addr(1), 1),)))
    after_refute = core.table_digest()
    assert after_refute != start
    core.receive(0.3, addr(1), Gossip("r1", (Record("r1", 1, b"x"),)))
    assert core.table_digest() != after_refute
    assert core.table_digest() == core.digest_from_scratch()


# ------------------------------------------------------------------ record versions


def test_first_record_version_comes_from_the_floor() -> None:
    core = robot(first_version=1_000_001)
    assert core.set_record(0.0, b"a") == 1_000_001
    assert core.set_record(0.1, b"b") == 1_000_002
    assert isinstance(events(core)[-1], RecordChanged)


def test_a_peer_with_a_new_incarnation_gets_our_vitals_again() -> None:
    core = robot()
    version = core.set_record(0.0, b"record")
    core.set_vitals(0.0, b"v1")
    first = pings(core, 0.2, answer=True)
    assert first[0].vitals is not None
    assert all(p.vitals is None for p in pings(core, 1.0, 0.2, answer=True))  # acknowledged
    core.receive(1.0, addr(1), Gossip("r1", (Alive("r1", addr(1), 1),)))  # r1 restarted
    again = pings(core, 1.5, 1.0, answer=True)
    assert again[0].vitals == VitalsRevision(version, 1, b"v1")
