"""SWIM membership with Lifeguard refinements, as a sans-IO core.

How it works:
- Inputs are `receive(now, src, packet)`, `handle_timer(now)`, `join`, `leave`, `set_record` and
  `broadcast_event`; outputs are drained with `datagrams_to_send()` and `next_event()`, and the
  shell calls `handle_timer` at `next_timer()`. The core never reads a clock or touches a socket.
- One class, `Membership`, in four sections: its state and helpers (timers, the broadcast
  queue, gossip rounds), probing, anti-entropy, and the inputs, outputs and merge rules.
- Probing (SWIM + Lifeguard): every probe interval (stretched by the local-health score) the next
  peer of a shuffled round robin is pinged. No ack within the probe timeout: the ping is sent
  again and k other peers are asked to ping it (PingReq), answering with a Nack when they cannot
  reach it. Any datagram from the target during the round counts as proof of life. No ack by the
  end of the round: one more round is run at once (a false suspicion costs a broadcast to every
  robot and a refutation back, so squaring its rate under loss is worth one probe interval); a
  second failure makes the target suspect. Missing nacks raise our own health score. Every
  direct ping's ack gives an RTT sample; a ping without one counts as lost. A direct ping also
  carries our newest vitals revision until the target acknowledges it.
- Anti-entropy: every push-pull interval (scaled up above 32 robots) a robot sends a `Digest` of
  its member table to one peer; equal tables end there. A peer whose digest differs answers with
  its whole table in `Sync` chunks under the MTU and asks for ours; each side merges the other's
  and pushes back the records the other lacks. Joining sends the whole table at once. A remote
  "dead" is merged as a suspicion only. One time in three the partner is the last address of a
  dead member or a seed: that is how two halves of a healed partition find each other. A robot
  also *pulls* at once (`_pull`) when it learns it fell behind (a ping carries vitals of a record
  newer than ours of its sender, or we were declared dead), at most once per peer per
  `SYNC_REPLY_GAP`.
- Suspicion (Lifeguard): the timeout starts at max and shrinks towards min as independent
  confirmations arrive; a suspicion at a newer incarnation starts afresh. The suspect is told at
  once and again every quarter minimum timeout (buddy system), answers each with its Alive, and a
  refuter answers its accuser directly.
- Corrections: a robot that receives a Suspect or Dead older than the Alive it holds answers the
  sender with that Alive. Push gossip reaches almost everyone; corrections reach exactly the
  robots the epidemic missed. Together these took false deaths at 30 % loss to zero.
- Stale verdicts: a Dead declared by a member that is dead in our view, or came back from the
  dead less than `stale_verdict_time` ago, is merged as a Suspect (the named member refutes it):
  such a verdict was made on the far side of a partition and arrives with the heal.
- Records: each robot owns one versioned record; the higher version wins. A robot that finds a
  record of its own with a higher version (it restarted) jumps past it; its first version comes
  from the shell (a floor kept across restarts), so a new life does not reuse an old version.
- Vitals: revisions of the measured part of a record (`set_vitals`) travel only on our direct
  pings, to each peer until it acknowledges one, and are ordered by (record version, revision).
- Anti-entropy starts with a digest of the member table; only a peer whose table differs gets
  the full exchange.
- Receivers: every packet names the robot it is addressed to (`to`; the codec binds the datagram
  to it, so a replay to another robot does not open). Only a join or reconnect to a seed's
  address, whose robot we do not know yet, goes to no robot: it piggybacks no update, and from
  a probe's target it is no proof of life (it could be a replay made elsewhere).
"""

from __future__ import annotations

import hashlib
import heapq
import random
from collections import deque
from collections.abc import Callable, Iterable, Mapping, Sequence
from typing import Any

from sdrpeer.gossip import formulas
from sdrpeer.gossip.config import GossipConfig
from sdrpeer.gossip.events import (
    REAPED,
    CoreEvent,
    EventReceived,
    MemberChanged,
    ProbeOutcome,
    RecordChanged,
    VitalsChanged,
)
from sdrpeer.gossip.messages import (
    ALIVE,
    DEAD,
    LEFT,
    SUSPECT,
    Ack,
    Addr,
    Alive,
    Dead,
    Digest,
    Event,
    Gossip,
    Nack,
    Packet,
    Ping,
    PingReq,
    Record,
    Suspect,
    Sync,
    SyncEntry,
    Update,
    VitalsRevision,
)
from sdrpeer.gossip.queue import BroadcastQueue
from sdrpeer.gossip.table import Member, MemberInfo, PeerSet, ProbeRing, Suspicion
from sdrpeer.gossip.wire import encoded_size
from sdrpeer.vocabulary import MemberState

# Timer kinds.
(PROBE, PROBE_TIMEOUT, PROBE_END, GOSSIP, SYNC, SUSPICION, FWD_END, REAP, JOIN, RECHECK, URGENT) = (
    range(11)
)


SEEN_EVENTS_MAX = 8192


class Probe:
    """One probe round of one target; `pings` maps each ping's seq to when it was sent."""

    __slots__ = ("acked", "confirming", "nacks", "pings", "target", "vitals", "want_nacks")

    def __init__(self, target: str, confirming: bool = False) -> None:
        self.target = target
        self.confirming = confirming
        """This round repeats a failed one before the target is suspected."""
        self.pings: dict[int, float] = {}
        self.acked = False
        self.want_nacks = 0
        self.nacks = 0
        self.vitals: dict[int, tuple[int, int]] = {}
        """For each ping of this round that carried our vitals, which revision (its ack tells
        that the target has it)."""


SYNC_REPLY_GAP = 1.0  # answer one robot's full-state exchange at most this often (seconds)


SYNC_ENTRY_OVERHEAD = 16  # msgpack bytes of one sync entry besides its name and host


class Membership:
    """One robot's membership view and protocol state (see the module docstring)."""

    # ============================================== state and helpers

    def __init__(
        self,
        name: str,
        addr: Addr,
        config: GossipConfig,
        *,
        now: float,
        rng: random.Random,
        sizer: Callable[[Update], int] | None = None,
        first_version: int = 1,
    ) -> None:
        if sizer is None:
            sizer = encoded_size
        self.name = name
        self.addr = addr
        self.config = config
        self.rng = rng
        self._size = sizer
        self._now = now
        self.incarnation = 0
        self.health_score = 0
        self.leaving = False
        self._me = Member(name, addr, 0, ALIVE, now)
        self._members: dict[str, Member] = {name: self._me}
        self._peers = PeerSet()
        self._ring = ProbeRing()
        self._records: dict[str, tuple[int, bytes]] = {}
        self._first_version = first_version
        """The version of our first record (a floor kept across restarts by the shell, so a new
        life never reuses a version an old one spread with other bytes)."""
        self._vitals: dict[str, VitalsRevision] = {}
        """The newest vitals revision received from each member."""
        self._my_vitals: VitalsRevision | None = None
        self._vitals_acked: dict[str, tuple[int, int]] = {}
        """Per peer, the newest of our vitals revisions it acknowledged (an ack of a ping that
        carried it)."""
        self._entry_hash: dict[str, int] = {}
        self._dirty: set[str] = {name}
        self._digest = 0
        self._queue = BroadcastQueue()
        self._out: list[tuple[Addr, Packet]] = []
        self._events: deque[CoreEvent] = deque()
        self._timers: list[tuple[float, int, int, Any]] = []
        self._tseq = 0
        self._seq = 0
        self._probes: dict[int, Probe] = {}
        self._probing: dict[str, Probe] = {}
        self._fwd: dict[int, tuple[Addr, int, bool, str]] = {}
        """Our probe seq -> (requester's address, its seq, want_nack, its name) of a PingReq."""
        self._gossip_armed = False
        self._urgent_at = float("-inf")
        self._urgent_armed = False
        self._event_seq = 0
        self._seen_events: dict[tuple[str, int], None] = {}
        self._sync_replied: dict[str, float] = {}
        self._pulled: dict[Addr, float] = {}
        """Peer address -> when we last pulled from it (`AntiEntropy._pull`)."""
        self._dead_addrs: dict[str, tuple[Addr, float]] = {}
        self._revived: dict[str, float] = {}
        """Member -> when it last came back from the dead (its verdicts may be stale a while)."""
        self._seeds: list[Addr] = []
        self.counters: dict[str, int] = {}
        self._budget = config.max_datagram - config.packet_overhead - 64
        self._at(now + rng.uniform(0, config.probe_interval), PROBE, None)
        self._at(now + self._sync_interval() * rng.uniform(0.5, 1.0), SYNC, None)

    # ----------------------------------------------------------------- dissemination
    def _enqueue(self, key: tuple[Any, ...], update: Update) -> None:
        self._queue.push(key, update, self._size(update))
        if not self._gossip_armed:
            self._gossip_armed = True
            self._at(self._now + self.config.gossip_interval, GOSSIP, None)

    def _limit(self) -> int:
        return formulas.retransmit_limit(self.config.retransmit_mult, self.num_alive())

    def _take(self, budget: int) -> tuple[Update, ...]:
        if not self._queue:
            return ()
        return tuple(self._queue.take(budget, self._limit()))

    def _piggyback(self, target: Member, reserved: int = 0) -> tuple[Update, ...]:
        budget = self._budget - reserved
        if target.state == SUSPECT:  # buddy system: the suspect hears it on our next ping
            fact = self._fact_about(target)
            return (fact, *self._take(budget - 64))
        return self._take(budget)

    def _urgent_round(self) -> None:
        """A gossip round now for news that decides life and death (a death, a new
        suspicion) or a placement (our own new record: an instance stood down, a plan taken):
        each hop then costs a network delay, not the wait for the next round, and the robots'
        timers start and end together. At most one such round per quarter gossip interval:
        news arriving inside that gap goes in one round at its end, not at the next regular
        round (a robot standing down five instances within 60 ms publishes five records; the
        last one decides when the new robot may activate)."""
        soonest = self._urgent_at + self.config.gossip_interval / 4
        if self._now >= soonest:
            self._urgent_at = self._now
            self._gossip_round()
        elif not self._urgent_armed:
            self._urgent_armed = True
            self._at(soonest, URGENT, None)

    def _gossip_round(self) -> None:
        if self._queue:
            for name in self._peers.sample(self.rng, self.config.gossip_fanout):
                updates = self._take(self._budget)
                if not updates:
                    break
                self._out.append((self._members[name].addr, Gossip(self.name, updates, name)))
        if self._queue and not self._gossip_armed:
            self._gossip_armed = True
            self._at(self._now + self.config.gossip_interval, GOSSIP, None)

    # ----------------------------------------------------------------- helpers
    def _at(self, when: float, kind: int, arg: Any) -> None:
        self._tseq += 1
        heapq.heappush(self._timers, (when, self._tseq, kind, arg))

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _count(self, key: str) -> None:
        self.counters[key] = self.counters.get(key, 0) + 1

    def num_alive(self) -> int:
        """Members alive or suspect, ourselves included."""
        return len(self._peers) + 1

    def _sync_interval(self) -> float:
        return formulas.push_pull_scale(self.config.push_pull_interval, self.num_alive())

    def _fact_about(self, m: Member) -> Update:
        if m.state == SUSPECT:
            return Suspect(m.name, m.incarnation, self.name)
        if m.state in (DEAD, LEFT):
            return Dead(m.name, m.incarnation, m.name if m.state == LEFT else self.name)
        return Alive(m.name, m.addr, m.incarnation)

    # ----------------------------------------------------------------- table digest
    def _mark(self, name: str) -> None:
        """`name`'s incarnation, state or record version may have changed (digest upkeep)."""
        self._dirty.add(name)

    def table_digest(self) -> int:
        """A 64-bit digest of the members alive or suspect, with their incarnations and record
        versions: equal tables give equal digests, so anti-entropy can skip the full exchange.
        Kept up to date incrementally (XOR of per-member hashes over the members marked)."""
        digest = self._digest
        for name in self._dirty:
            old = self._entry_hash.pop(name, None)
            if old is not None:
                digest ^= old
            h = self._hash_of(name)
            if h is not None:
                self._entry_hash[name] = h
                digest ^= h
        self._dirty.clear()
        self._digest = digest
        return digest

    def _hash_of(self, name: str) -> int | None:
        m = self._members.get(name)
        if m is None or m.state not in (ALIVE, SUSPECT):
            return None
        rec = self._records.get(name)
        text = f"{name}\0{m.incarnation}\0{rec[0] if rec else 0}".encode()
        return int.from_bytes(hashlib.blake2b(text, digest_size=8).digest(), "big")

    def digest_from_scratch(self) -> int:
        """The same digest computed over the whole table (tests check the incremental one)."""
        digest = 0
        for name in self._members:
            h = self._hash_of(name)
            if h is not None:
                digest ^= h
        return digest

    # ============================================== probing (SWIM + Lifeguard)

    def _start_probe(self) -> None:
        interval = formulas.scaled(self.config.probe_interval, self.health_score)
        self._at(self._now + interval, PROBE, None)
        if self.leaving:
            return
        target = self._ring.next(self.rng, self._peers)
        if target is not None:
            self._probe(target, confirming=False)

    def _probe(self, target: str, *, confirming: bool) -> None:
        cfg = self.config
        probe = Probe(target, confirming)
        self._probing[target] = probe
        self._ping(probe)
        timeout = formulas.scaled(cfg.probe_timeout, self.health_score)
        self._at(self._now + timeout, PROBE_TIMEOUT, probe)
        self._at(
            self._now + formulas.scaled(cfg.probe_interval, self.health_score), PROBE_END, probe
        )

    def _ping(self, probe: Probe) -> int:
        m = self._members[probe.target]
        seq = self._next_seq()
        probe.pings[seq] = self._now
        self._probes[seq] = probe
        vitals = self._my_vitals
        if vitals is not None and self._vitals_acked.get(m.name, (0, 0)) < vitals.key:
            probe.vitals[seq] = vitals.key
            updates = self._piggyback(m, len(vitals.payload) + 16)
        else:
            vitals = None
            updates = self._piggyback(m)
        self._out.append((m.addr, Ping(self.name, seq, m.name, updates, vitals)))
        return seq

    def _probe_timeout(self, probe: Probe) -> None:
        m = self._members.get(probe.target)
        if probe.acked or m is None or m.state not in (ALIVE, SUSPECT):
            return
        seq = self._ping(probe)  # a second direct ping, then k indirect ones
        for name in self._peers.sample(self.rng, self.config.indirect_checks, exclude=m.name):
            req = PingReq(self.name, seq, m.name, m.addr, True, self._take(self._budget), name)
            self._out.append((self._members[name].addr, req))
            probe.want_nacks += 1

    def _probe_end(self, probe: Probe) -> None:
        for seq in probe.pings:
            self._probes.pop(seq, None)
        for _ in probe.pings:  # every ping whose own ack never came counts as lost
            self._events.append(ProbeOutcome(probe.target, None, self._now))
        probe.pings.clear()
        if self._probing.get(probe.target) is probe:
            del self._probing[probe.target]
        if probe.acked:
            return
        missing = probe.want_nacks - probe.nacks if probe.want_nacks else 1
        self._adjust_health(max(0, missing))
        m = self._members.get(probe.target)
        if m is None or m.state not in (ALIVE, SUSPECT):
            return
        if m.state == ALIVE and not probe.confirming and self.config.confirm_round:
            self._probe(m.name, confirming=True)  # one more round before accusing anyone
            return
        self._merge_suspect(Suspect(m.name, m.incarnation, self.name))

    def _probe_succeeded(self, probe: Probe) -> None:
        if probe.acked:
            return
        probe.acked = True
        self._adjust_health(-1)

    def _on_ping(self, src: Addr, ping: Ping) -> None:
        if ping.target != self.name:
            self._count("misdirected")
            return
        m = self._members.get(ping.sender)
        buddy: list[Update] = []
        if m is not None and m.state != ALIVE:
            buddy.append(self._fact_about(m))
        updates = tuple(buddy) + self._take(self._budget - 64 * len(buddy))
        self._out.append((src, Ack(self.name, ping.seq, updates, ping.sender)))

    def _on_ack(self, ack: Ack) -> None:
        probe = self._probes.get(ack.seq)
        if probe is not None:
            if ack.sender == probe.target:
                sent = probe.pings.pop(ack.seq, None)
                if sent is not None:
                    self._events.append(ProbeOutcome(probe.target, self._now - sent, self._now))
                carried = probe.vitals.pop(ack.seq, None)
                if carried is not None and carried > self._vitals_acked.get(ack.sender, (0, 0)):
                    self._vitals_acked[ack.sender] = carried
            self._probe_succeeded(probe)
            return
        fwd = self._fwd.pop(ack.seq, None)
        if fwd is not None:
            self._out.append((fwd[0], Ack(self.name, fwd[1], self._take(self._budget), fwd[3])))

    def _on_ping_req(self, src: Addr, req: PingReq) -> None:
        seq = self._next_seq()
        self._fwd[seq] = (src, req.seq, req.want_nack, req.sender)
        m = self._members.get(req.target)
        updates = self._piggyback(m) if m is not None else self._take(self._budget)
        self._out.append((req.target_addr, Ping(self.name, seq, req.target, updates)))
        self._at(self._now + self.config.probe_timeout * 0.8, FWD_END, seq)

    def _fwd_end(self, seq: int) -> None:
        fwd = self._fwd.pop(seq, None)
        if fwd is not None and fwd[2]:
            self._out.append((fwd[0], Nack(self.name, fwd[1], (), fwd[3])))

    def _adjust_health(self, delta: int) -> None:
        self.health_score = min(max(0, self.health_score + delta), self.config.awareness_max - 1)

    # ============================================== anti-entropy (digests, push-pull, pulls)

    def _periodic_sync(self) -> None:
        self._at(self._now + self._sync_interval() * self.rng.uniform(0.5, 1.5), SYNC, None)
        if self.leaving:
            return
        target: tuple[Addr, str] | None = None
        horizon = self._now - self.config.reconnect_time
        for name, (_, died) in list(self._dead_addrs.items()):
            if died < horizon:
                del self._dead_addrs[name]
        lost = [(addr, name) for name, (addr, _) in self._dead_addrs.items()]
        if self._seeds:  # a seed is worth a reconnect only if it is not already a live peer
            live = {self._members[name].addr for name in self._peers.names()}
            lost += [(seed, "") for seed in self._seeds if seed not in live]
        if lost and (not self._peers or self.rng.random() < 1 / 3):
            target = self.rng.choice(lost)
        elif self._peers:
            name = self._peers.sample(self.rng, 1)[0]
            target = (self._members[name].addr, name)
        if target is not None:
            dest, to = target
            # To a seed by address (to == ""): nothing piggybacked, so a replay carries no fact.
            updates = self._take(self._budget - 32) if to else ()
            self._out.append(
                (dest, Digest(self.name, self.table_digest(), self.num_alive(), updates, to))
            )

    def _on_digest(self, src: Addr, d: Digest) -> None:
        if d.digest == self.table_digest():
            self._count("digest_same")
            return
        self._count("digest_differs")
        last = self._sync_replied.get(d.sender)
        if last is None or self._now - last >= SYNC_REPLY_GAP:
            self._sync_replied[d.sender] = self._now
            self._send_state(src, d.sender, reply=True)

    def _pull(self, dest: Addr, to: str) -> None:
        """Ask the peer `to` at `dest` for what we lack now (rate-limited per peer)."""
        last = self._pulled.get(dest)
        if last is not None and self._now - last < SYNC_REPLY_GAP:
            return
        self._pulled[dest] = self._now
        self._count("pulls")
        self._send_state(dest, to, reply=True)

    def _retry_join(self, delay: float) -> None:
        if len(self._members) > 1 or not self._seeds:
            return
        for seed in self._seeds:
            self._send_state(seed, "", reply=True)
        delay = min(delay * 2, 5.0)
        self._at(self._now + delay, JOIN, delay)

    def _entries(self) -> list[SyncEntry]:
        out: list[SyncEntry] = []
        records = self._records
        for m in self._members.values():
            rec = records.get(m.name)
            out.append((m.name, m.addr, m.incarnation, m.state, rec[0] if rec else 0))
        return out

    def _send_state(self, dest: Addr, to: str, *, reply: bool) -> None:
        """Our whole member table to `to` at `dest` ("": a seed by address), in chunks."""
        chunk: list[SyncEntry] = []
        used = 0
        for e in self._entries():
            size = len(e[0]) + len(e[1][0]) + SYNC_ENTRY_OVERHEAD
            if chunk and used + size > self._budget:
                self._out.append((dest, Sync(self.name, reply, tuple(chunk), (), to)))
                chunk, used = [], 0
            chunk.append(e)
            used += size
        if chunk:
            self._out.append((dest, Sync(self.name, reply, tuple(chunk), (), to)))

    def _on_sync(self, src: Addr, sync: Sync) -> None:
        push: list[Update] = []
        members = self._members
        for name, addr, inc, state, rec_version in sync.entries:
            if state == ALIVE:
                m = members.get(name)
                if m is None or m is self._me or inc > m.incarnation:
                    self._merge_alive(Alive(name, addr, inc))
            elif state in (SUSPECT, DEAD):
                # A remote death is only a suspicion here: it may be stale (memberlist does this).
                if name not in self._members and name != self.name:
                    continue
                self._merge_suspect(Suspect(name, inc, sync.sender))
            elif state == LEFT:
                self._merge_dead(Dead(name, inc, name))
            mine = self._records.get(name)
            if mine is not None and mine[0] > rec_version:
                push.append(Record(name, mine[0], mine[1]))
            elif name == self.name and mine is not None and rec_version > mine[0]:
                self._store_own_record(rec_version + 1, mine[1])
                push.append(Record(name, rec_version + 1, mine[1]))
            elif name == self.name and mine is None:  # an earlier life's, before our first
                self._first_version = max(self._first_version, rec_version + 1)
        self._push_records(src, sync.sender, push)
        if sync.reply:
            last = self._sync_replied.get(sync.sender)
            if last is None or self._now - last >= SYNC_REPLY_GAP:
                self._sync_replied[sync.sender] = self._now
                self._send_state(src, sync.sender, reply=False)

    def _push_records(self, dest: Addr, to: str, records: list[Update]) -> None:
        batch: list[Update] = []
        used = 0
        for r in records:
            size = self._size(r)
            if batch and used + size > self._budget:
                self._out.append((dest, Gossip(self.name, tuple(batch), to)))
                batch, used = [], 0
            batch.append(r)
            used += size
        if batch:
            self._out.append((dest, Gossip(self.name, tuple(batch), to)))

    # ============================================== merges, records, events, timers

    # ----------------------------------------------------------------- inputs
    def join(self, now: float, seeds: Sequence[Addr]) -> None:
        """Contact the seed addresses with a full-state exchange (retried until someone answers)."""
        self._now = now
        self._seeds = [s for s in seeds if s != self.addr]
        for seed in self._seeds:
            self._send_state(seed, "", reply=True)
        if self._seeds:
            self._at(now + 1.0, JOIN, 1.0)

    def preload(
        self,
        now: float,
        members: Iterable[tuple[str, Addr]],
        records: Mapping[str, tuple[int, bytes]],
    ) -> None:
        """Start as a member of a fleet that has already converged: every one of `members`
        alive at incarnation 0, `records` held (ours among them, if given). Nothing is queued
        for dissemination and no event is reported. The simulator's shortcut past a join storm
        it cannot afford at thousands of robots; an agent always joins."""
        self._now = now
        for name, addr in members:
            if name == self.name or name in self._members:
                continue
            self._members[name] = Member(name, addr, 0, ALIVE, now)
            self._peers.add(name)
            self._mark(name)
        self._ring = ProbeRing()
        for name, record in records.items():
            self._records[name] = record
            self._mark(name)

    def leave(self, now: float) -> None:
        """Announce a graceful leave to everyone reachable."""
        self._now = now
        self.leaving = True
        self._me.state = LEFT
        self._me.since = now
        self._mark(self.name)
        dead = Dead(self.name, self.incarnation, self.name)
        self._enqueue(("m", self.name), dead)
        for name in self._peers.names():
            self._out.append((self._members[name].addr, Gossip(self.name, (dead,), name)))

    def set_record(self, now: float, payload: bytes, *, urgent: bool = False) -> int:
        """Publish a new version of our own record (spread to everyone); returns its version.
        `urgent`: it carries a placement others wait for (an instance stood down, a plan
        taken), so it goes out in an urgent round rather than the next regular one; a record
        that only says what the robot is (its first, a link bound, its metrics' identity) waits
        for the regular round, as the join storm of a large fleet must not raise a round per
        robot per change."""
        self._now = now
        old = self._records.get(self.name)
        version = old[0] + 1 if old else self._first_version
        self._store_own_record(version, payload)
        if urgent:
            self._urgent_round()
        return version

    def set_vitals(self, now: float, payload: bytes) -> int:
        """A new revision of the measured part of our current record, carried on our pings to
        each peer until it acknowledges it (not spread); returns the revision (0: no record
        published yet, nothing done)."""
        self._now = now
        own = self._records.get(self.name)
        if own is None:
            return 0
        last = self._my_vitals
        revision = last.revision + 1 if last is not None and last.version == own[0] else 1
        self._my_vitals = VitalsRevision(own[0], revision, payload)
        return revision

    def broadcast_event(self, now: float, kind: str, payload: bytes) -> None:
        """Broadcast a one-off event (a trap) at once, without waiting for the next round."""
        self._now = now
        self._event_seq += 1
        ev = Event(self.name, self._event_seq, kind, payload)
        self._remember_event(ev.source, ev.seq)
        self._enqueue(("e", ev.source, ev.seq), ev)
        self._gossip_round()

    def receive(self, now: float, src: Addr, packet: Packet) -> None:
        """Handle one authenticated packet from `src`."""
        self._now = now
        sender = packet.sender
        if sender == self.name:
            self._count("self_loop")
            return
        probe = self._probing.get(sender)
        if probe is not None and packet.to == self.name and not isinstance(packet, Ack):
            # Any datagram from the target addressed to us proves it alive; one to whoever
            # listens at our address (a join by address) may be a replay made elsewhere.
            self._probe_succeeded(probe)
        if packet.updates:
            self._merge_updates(packet.updates, src, sender)
        if isinstance(packet, Ping):
            if packet.vitals is not None and self._merge_vitals(sender, packet.vitals):
                self._pull(src, sender)  # they revise a record we never got: fetch it now
            self._on_ping(src, packet)
        elif isinstance(packet, Ack):
            self._on_ack(packet)
        elif isinstance(packet, PingReq):
            self._on_ping_req(src, packet)
        elif isinstance(packet, Nack):
            probe = self._probes.get(packet.seq)
            if probe is not None:
                probe.nacks += 1
        elif isinstance(packet, Sync):
            self._on_sync(src, packet)
        elif isinstance(packet, Digest):
            self._on_digest(src, packet)

    def handle_timer(self, now: float) -> None:
        """Run every timer that is due at `now`."""
        self._now = now
        timers = self._timers
        while timers and timers[0][0] <= now:
            _, _, kind, arg = heapq.heappop(timers)
            if kind == PROBE:
                self._start_probe()
            elif kind == PROBE_TIMEOUT:
                self._probe_timeout(arg)
            elif kind == PROBE_END:
                self._probe_end(arg)
            elif kind == GOSSIP:
                self._gossip_armed = False
                if self._queue:
                    self._gossip_round()
            elif kind == SUSPICION:
                self._suspicion_expired(*arg)
            elif kind == FWD_END:
                self._fwd_end(arg)
            elif kind == SYNC:
                self._periodic_sync()
            elif kind == REAP:
                self._reap(*arg)
            elif kind == JOIN:
                self._retry_join(arg)
            elif kind == RECHECK:
                self._recheck(*arg)
            elif kind == URGENT:
                self._urgent_armed = False
                if self._queue:
                    self._urgent_round()

    # ----------------------------------------------------------------- outputs
    def next_timer(self) -> float:
        """Absolute time of the earliest pending deadline."""
        return self._timers[0][0] if self._timers else float("inf")

    def datagrams_to_send(self) -> list[tuple[Addr, Packet]]:
        """Drain the packets queued for sending."""
        out, self._out = self._out, []
        return out

    def next_event(self) -> CoreEvent | None:
        """The next event for the shell, or None."""
        return self._events.popleft() if self._events else None

    # ----------------------------------------------------------------- views
    def members(self) -> list[MemberInfo]:
        """Snapshots of every known member, ourselves included."""
        return [m.info() for m in self._members.values()]

    def state_of(self, name: str) -> MemberState | None:
        """The state of `name`, or None if unknown."""
        m = self._members.get(name)
        return m.state if m else None

    def record_of(self, name: str) -> tuple[int, bytes] | None:
        """(version, payload) of the record owned by `name`, if known."""
        return self._records.get(name)

    def vitals_of(self, name: str) -> VitalsRevision | None:
        """The newest vitals revision of `name` (ours included), if any."""
        return self._my_vitals if name == self.name else self._vitals.get(name)

    def queue_len(self) -> int:
        """Updates waiting to be disseminated."""
        return len(self._queue)

    # ----------------------------------------------------------------- merging
    def _merge_updates(self, updates: tuple[Update, ...], src: Addr, sender: str) -> None:
        corrections: list[Update] = []
        members = self._members
        for u in updates:
            t = type(u)
            if t is Alive:
                m = members.get(u.name)  # type: ignore[union-attr]
                if m is not None and m is not self._me and u.incarnation <= m.incarnation:  # type: ignore[union-attr]
                    continue  # already known: the common case, kept cheap
                self._merge_alive(u)  # type: ignore[arg-type]
            elif t is Suspect or t is Dead:
                stale = self._stale(u.name, u.incarnation)  # type: ignore[union-attr]
                if stale is not None:
                    corrections.append(stale)
                elif t is Suspect:
                    self._merge_suspect(u)  # type: ignore[arg-type]
                else:
                    self._merge_dead(u)  # type: ignore[arg-type]
                if u.name == self.name and not self.leaving:  # type: ignore[union-attr]
                    corrections.append(Alive(self.name, self.addr, self.incarnation))
                    if t is Dead:
                        self._pull(src, sender)  # we were cut off: fetch what the fleet decided
            elif t is Record:
                self._merge_record(u)  # type: ignore[arg-type]
            elif t is Event:
                self._merge_event(u)  # type: ignore[arg-type]
        if corrections:
            self._count("corrections")
            self._out.append((src, Gossip(self.name, tuple(corrections), sender)))

    def _stale(self, name: str, incarnation: int) -> Alive | None:
        """Our newer Alive when a suspicion or death about `name` is out of date, else None.

        The sender is behind (it missed a refutation); answering it directly reaches exactly the
        robots the epidemic missed, which push gossip alone leaves to chance.
        """
        m = self._me if name == self.name else self._members.get(name)
        if m is None or m.state != ALIVE or incarnation >= m.incarnation or self.leaving:
            return None
        return Alive(name, m.addr, m.incarnation)

    def _merge_alive(self, a: Alive) -> None:
        if a.name == self.name:
            if a.incarnation > self.incarnation or (
                a.incarnation == self.incarnation and a.addr != self.addr
            ):
                self._refute(a.incarnation)
            return
        m = self._members.get(a.name)
        if m is None:
            m = Member(a.name, a.addr, a.incarnation, ALIVE, self._now)
            self._members[a.name] = m
            self._mark(a.name)
            self._dead_addrs.pop(a.name, None)
            self._peers.add(a.name)
            self._ring.insert(self.rng, a.name)
            self._events.append(
                MemberChanged(a.name, a.addr, ALIVE, a.incarnation, None, self._now)
            )
            self._enqueue(("m", a.name), a)
            return
        if a.incarnation <= m.incarnation:
            return
        m.addr = a.addr
        self._set_state(m, ALIVE, a.incarnation)
        self._enqueue(("m", a.name), a)
        self._vitals_acked.pop(a.name, None)  # a new life may not hold our vitals: send again

    def _merge_suspect(self, s: Suspect) -> None:
        if s.name == self.name:
            if s.incarnation >= self.incarnation and not self.leaving:
                self._refute(s.incarnation)
            return
        m = self._members.get(s.name)
        if m is None or s.incarnation < m.incarnation or m.state in (DEAD, LEFT):
            return
        if m.state == SUSPECT and m.suspicion is not None and s.incarnation == m.incarnation:
            susp = m.suspicion
            if s.source in susp.confirmers or s.source == susp.origin:
                return
            susp.confirmers.add(s.source)
            timeout = formulas.suspicion_timeout(
                len(susp.confirmers), susp.k, susp.min_t, susp.max_t
            )
            if susp.start + timeout < susp.deadline:
                susp.deadline = susp.start + timeout
                self._at(susp.deadline, SUSPICION, (m.name, susp))
            self._enqueue(("m", m.name), s)
            return
        n = self.num_alive()
        cfg = self.config
        min_t = formulas.suspicion_min_timeout(cfg.suspicion_mult, n, cfg.probe_interval)
        k = formulas.suspicion_confirmations_wanted(cfg.suspicion_mult, n)
        susp = Suspicion(self._now, k, min_t, min_t * cfg.suspicion_max_mult, s.source)
        self._set_state(m, SUSPECT, s.incarnation)
        m.suspicion = susp
        self._at(susp.deadline, SUSPICION, (m.name, susp))
        self._at(self._now + min_t / 4, RECHECK, (m.name, susp))
        self._enqueue(("m", m.name), s)
        # Buddy system: tell the suspect at once so it can refute before anyone times out (the
        # accuser always; others with a probability that keeps ~4 direct notices per suspicion).
        if s.source == self.name or self.rng.random() < 4.0 / n:
            self._out.append((m.addr, Gossip(self.name, (s,), m.name)))

    def _merge_dead(self, d: Dead) -> None:
        if d.name == self.name:
            if not self.leaving:
                self._refute(d.incarnation)
            return
        m = self._members.get(d.name)
        if m is None or d.incarnation < m.incarnation or m.state in (DEAD, LEFT):
            return
        if d.source != d.name and self._stale_verdict(d.source):
            self._merge_suspect(Suspect(d.name, d.incarnation, d.source))
            return
        self._set_state(m, LEFT if d.source == d.name else DEAD, d.incarnation)
        self._enqueue(("m", m.name), d)
        self._urgent_round()

    def _merge_record(self, r: Record) -> None:
        if r.name == self.name:  # a record of ours from an earlier life: jump past it
            mine = self._records.get(self.name)
            if mine is None:  # nothing published yet: our first record goes out past it (an
                # empty one now reached every robot as a malformed record, and they kept the
                # earlier life's instances until our first real one came)
                self._first_version = max(self._first_version, r.version + 1)
            elif r.version > mine[0] or (r.version == mine[0] and r.payload != mine[1]):
                self._store_own_record(r.version + 1, mine[1], jump=True)
            return
        old = self._records.get(r.name)
        if old is not None and old[0] >= r.version:
            return
        self._records[r.name] = (r.version, r.payload)
        self._mark(r.name)
        vitals = self._vitals.get(r.name)
        if vitals is not None and vitals.version < r.version:
            del self._vitals[r.name]  # revisions of an older record
        self._events.append(RecordChanged(r.name, r.version, r.payload, self._now))
        self._enqueue(("r", r.name), r)

    def _merge_event(self, e: Event) -> None:
        key = (e.source, e.seq)
        if key in self._seen_events:
            return
        self._remember_event(e.source, e.seq)
        self._events.append(EventReceived(e.source, e.seq, e.kind, e.payload, self._now))
        self._enqueue(("e", e.source, e.seq), e)

    def _merge_vitals(self, sender: str, v: VitalsRevision) -> bool:
        """Take `sender`'s vitals; True when they revise a record newer than the one we hold."""
        if sender not in self._members:
            return False
        rec = self._records.get(sender)
        behind = rec is None or rec[0] < v.version
        old = self._vitals.get(sender)
        if old is not None and old.key >= v.key:
            return behind
        if rec is not None and rec[0] > v.version:
            return False  # a revision of a record older than the one we hold
        self._vitals[sender] = v
        self._events.append(VitalsChanged(sender, v.version, v.revision, v.payload, self._now))
        return behind

    def _refute(self, incarnation: int) -> None:
        self.incarnation = max(self.incarnation, incarnation) + 1
        self._me.incarnation = self.incarnation
        self._mark(self.name)
        self._adjust_health(1)
        self._count("refutations")
        self._enqueue(("m", self.name), Alive(self.name, self.addr, self.incarnation))
        self._gossip_round()

    def _stale_verdict(self, source: str) -> bool:
        """Whether a death declared by `source` is likely from the far side of a partition."""
        src = self._members.get(source)
        if src is None or src is self._me:
            return False
        if src.state in (DEAD, LEFT):
            return True
        back = self._revived.get(source)
        return back is not None and self._now - back < self.config.stale_verdict_time

    def _set_state(self, m: Member, state: MemberState, incarnation: int) -> None:
        previous = m.state
        if previous == DEAD and state in (ALIVE, SUSPECT):
            self._revived[m.name] = self._now
        self._mark(m.name)
        m.incarnation = incarnation
        if state != SUSPECT:
            m.suspicion = None
        if state == previous:
            return
        m.state = state
        m.since = self._now
        if state in (ALIVE, SUSPECT):
            self._dead_addrs.pop(m.name, None)  # back: no more reconnect syncs to its old life
            if m.name not in self._peers and m is not self._me:
                self._peers.add(m.name)
                self._ring.insert(self.rng, m.name)
        else:
            self._peers.remove(m.name)
            if state == DEAD:
                self._dead_addrs[m.name] = (m.addr, self._now)
            self._at(self._now + self.config.dead_reap_time, REAP, (m.name, self._now))
        self._events.append(MemberChanged(m.name, m.addr, state, incarnation, previous, self._now))

    def _suspicion_expired(self, name: str, susp: Suspicion) -> None:
        m = self._members.get(name)
        if m is None or m.suspicion is not susp or self._now < susp.deadline:
            return
        d = Dead(name, m.incarnation, self.name)
        self._set_state(m, DEAD, m.incarnation)
        self._enqueue(("m", name), d)
        self._urgent_round()

    def _recheck(self, name: str, susp: Suspicion) -> None:
        """Every quarter minimum timeout, tell the suspect directly: it answers with its Alive if it
        refuted (or refutes now), so we do not time out merely for missing the refutation."""
        m = self._members.get(name)
        if m is not None and m.suspicion is susp:
            self._out.append(
                (m.addr, Gossip(self.name, (Suspect(name, m.incarnation, self.name),), name))
            )
            self._at(self._now + susp.min_t / 4, RECHECK, (name, susp))

    def _reap(self, name: str, since: float) -> None:
        m = self._members.get(name)
        if m is None or m.state not in (DEAD, LEFT) or m.since != since:
            return
        del self._members[name]
        self._revived.pop(name, None)
        self._records.pop(name, None)
        self._vitals.pop(name, None)
        self._vitals_acked.pop(name, None)
        self._mark(name)
        self._queue.discard(("m", name))
        self._queue.discard(("r", name))
        self._events.append(MemberChanged(name, m.addr, REAPED, m.incarnation, m.state, self._now))

    def _store_own_record(self, version: int, payload: bytes, *, jump: bool = False) -> None:
        self._records[self.name] = (version, payload)
        vitals = self._my_vitals
        if jump and vitals is not None:  # the same record under a new version: keep its values
            self._my_vitals = VitalsRevision(version, 1, vitals.payload)
        else:
            self._my_vitals = None  # the record carries the current values; revisions restart
        self._mark(self.name)
        r = Record(self.name, version, payload)
        self._events.append(RecordChanged(self.name, version, payload, self._now))
        self._enqueue(("r", self.name), r)

    def _remember_event(self, source: str, seq: int) -> None:
        seen = self._seen_events
        seen[(source, seq)] = None
        if len(seen) > SEEN_EVENTS_MAX:
            del seen[next(iter(seen))]
