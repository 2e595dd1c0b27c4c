"""SWIM membership with Lifeguard refinements, as a sans-IO core.

How it works:
- Inputs are `receive(now, src, packet)`, `handle_timer(now)`, `join`, `leave`, `set_record` and
  `broadcast_event`; outputs are drained with `datagrams_to_send()` and `next_event()`, and the
  shell calls `handle_timer` at `next_timer()`. The core never reads a clock or touches a socket.
- Failure detection: every probe interval the next peer in a shuffled round robin is pinged. No
  ack within the probe timeout: the ping is sent again and k other peers are asked to ping it
  (PingReq), answering with a Nack when they cannot reach it. Any datagram from the target during
  the probe counts as proof of life. No ack by the end of the interval: the target is suspected.
- Suspicion (Lifeguard): the timeout starts at max and shrinks towards min as independent
  confirmations arrive; the suspect is told at once (buddy system) and refutes by raising its
  incarnation. Missing nacks and refutations raise our local-health score, which stretches our
  own timeouts so an overloaded robot does not accuse healthy ones.
- Dissemination: updates (alive/suspect/dead, records, events) ride on every packet from a
  transmit-limited queue, plus gossip rounds to `fanout` random peers while the queue is not
  empty. A periodic full-state exchange (chunked `Sync`) with a random peer - sometimes a dead
  member's last address or a seed - repairs anything missed and heals partitions.
- Records: each robot owns one versioned record; the higher version wins. A robot that finds a
  record of its own with a version at or above its current one (it restarted) jumps past it.
"""

from __future__ import annotations

import heapq
import random
from collections import deque
from collections.abc import Callable, Sequence
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
)
from sdrpeer.gossip.queue import BroadcastQueue
from sdrpeer.gossip.table import Member, MemberInfo, PeerSet, ProbeRing, Suspicion
from sdrpeer.wire import encoded_size

# Timer kinds.
_PROBE, _PROBE_TIMEOUT, _PROBE_END, _GOSSIP, _SYNC, _SUSPICION, _FWD_END, _REAP, _JOIN = range(9)
_RECHECK = 9
_SYNC_REPLY_GAP = 1.0  # answer one robot's full-state exchange at most this often (seconds)
_SYNC_ENTRY_OVERHEAD = 16  # msgpack bytes of one sync entry besides its name and host
_SEEN_EVENTS_MAX = 8192


class _Probe:
    """One probe round of one target; `pings` maps each ping's seq to when it was sent."""

    __slots__ = ("acked", "nacks", "pings", "target", "want_nacks")

    def __init__(self, target: str) -> None:
        self.target = target
        self.pings: dict[int, float] = {}
        self.acked = False
        self.want_nacks = 0
        self.nacks = 0


class Membership:
    """One robot's membership view and protocol state (see the module docstring)."""

    def __init__(
        self,
        name: str,
        addr: Addr,
        config: GossipConfig,
        *,
        now: float,
        rng: random.Random,
        sizer: Callable[[Update], int] | None = None,
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
        self._queue = BroadcastQueue()
        self._out: list[tuple[Addr, Packet]] = []
        self._events: deque[CoreEvent] = deque()
        self._timers: list[tuple[float, int, int, Any]] = []
        self._tseq = 0
        self._seq = 0
        self._probes: dict[int, _Probe] = {}
        self._probing: dict[str, _Probe] = {}
        self._fwd: dict[int, tuple[Addr, int, bool]] = {}
        self._gossip_armed = False
        self._event_seq = 0
        self._seen_events: dict[tuple[str, int], None] = {}
        self._sync_replied: dict[str, float] = {}
        self._dead_addrs: dict[str, tuple[Addr, float]] = {}
        self._seeds: list[Addr] = []
        self.counters: dict[str, int] = {}
        self._budget = config.max_datagram - config.packet_overhead - 64
        self._at(now + rng.uniform(0, config.probe_interval), _PROBE, None)
        self._at(now + self._sync_interval() * rng.uniform(0.5, 1.0), _SYNC, None)

    # ----------------------------------------------------------------- inputs
    def join(self, now: float, seeds: Sequence[Addr]) -> None:
        """Contact the seed addresses with a full-state exchange (retried until someone answers)."""
        self._now = now
        self._seeds = [s for s in seeds if s != self.addr]
        for seed in self._seeds:
            self._send_state(seed, reply=True)
        if self._seeds:
            self._at(now + 1.0, _JOIN, 1.0)

    def leave(self, now: float) -> None:
        """Announce a graceful leave to everyone reachable."""
        self._now = now
        self.leaving = True
        self._me.state = LEFT
        self._me.since = now
        dead = Dead(self.name, self.incarnation, self.name)
        self._enqueue(("m", self.name), dead)
        for name in self._peers.names():
            self._out.append((self._members[name].addr, Gossip(self.name, (dead,))))

    def set_record(self, now: float, payload: bytes) -> int:
        """Publish a new version of our own record; returns its version."""
        self._now = now
        old = self._records.get(self.name)
        version = (old[0] if old else 0) + 1
        self._store_own_record(version, payload)
        return version

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
        if probe is not None and not isinstance(packet, Ack):
            self._probe_succeeded(probe)  # any datagram from the target proves it alive
        if packet.updates:
            self._merge_updates(packet.updates, src)
        if isinstance(packet, Ping):
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

    def handle_timer(self, now: float) -> None:
        """Run every timer that is due at `now`."""
        self._now = now
        timers = self._timers
        while timers and timers[0][0] <= now:
            _, _, kind, arg = heapq.heappop(timers)
            if kind == _PROBE:
                self._start_probe()
            elif kind == _PROBE_TIMEOUT:
                self._probe_timeout(arg)
            elif kind == _PROBE_END:
                self._probe_end(arg)
            elif kind == _GOSSIP:
                self._gossip_armed = False
                if self._queue:
                    self._gossip_round()
            elif kind == _SUSPICION:
                self._suspicion_expired(*arg)
            elif kind == _FWD_END:
                self._fwd_end(arg)
            elif kind == _SYNC:
                self._periodic_sync()
            elif kind == _REAP:
                self._reap(*arg)
            elif kind == _JOIN:
                self._retry_join(arg)
            elif kind == _RECHECK:
                self._recheck(*arg)

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

    def state_of(self, name: str) -> int | None:
        """The state of `name`, or None if unknown."""
        m = self._members.get(name)
        return m.state if m else None

    def record_of(self, name: str) -> tuple[int, bytes] | None:
        """(version, payload) of the record owned by `name`, if known."""
        return self._records.get(name)

    def num_alive(self) -> int:
        """Members alive or suspect, ourselves included."""
        return len(self._peers) + 1

    def queue_len(self) -> int:
        """Updates waiting to be disseminated."""
        return len(self._queue)

    # ----------------------------------------------------------------- probing
    def _start_probe(self) -> None:
        cfg = self.config
        interval = formulas.scaled(cfg.probe_interval, self.health_score)
        self._at(self._now + interval, _PROBE, None)
        if self.leaving:
            return
        target = self._ring.next(self.rng, self._peers)
        if target is None:
            return
        probe = _Probe(target)
        self._probing[target] = probe
        self._ping(probe)
        self._at(
            self._now + formulas.scaled(cfg.probe_timeout, self.health_score), _PROBE_TIMEOUT, probe
        )
        self._at(self._now + interval, _PROBE_END, probe)

    def _ping(self, probe: _Probe) -> int:
        m = self._members[probe.target]
        seq = self._next_seq()
        probe.pings[seq] = self._now
        self._probes[seq] = probe
        self._out.append((m.addr, Ping(self.name, seq, m.name, self._piggyback(m))))
        return seq

    def _probe_timeout(self, probe: _Probe) -> None:
        m = self._members.get(probe.target)
        if probe.acked or m is None or m.state not in (ALIVE, SUSPECT):
            return
        seq = self._ping(probe)  # a second direct ping, then k indirect ones
        for name in self._peers.sample(self.rng, self.config.indirect_checks, exclude=m.name):
            req = PingReq(self.name, seq, m.name, m.addr, True, self._take(self._budget))
            self._out.append((self._members[name].addr, req))
            probe.want_nacks += 1

    def _probe_end(self, probe: _Probe) -> None:
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
        if m is not None and m.state in (ALIVE, SUSPECT):
            self._merge_suspect(Suspect(m.name, m.incarnation, self.name))

    def _probe_succeeded(self, probe: _Probe) -> None:
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
        self._out.append((src, Ack(self.name, ping.seq, updates)))

    def _on_ack(self, ack: Ack) -> None:
        probe = self._probes.get(ack.seq)
        if probe is not None:
            if ack.sender == probe.target:
                sent = probe.pings.pop(ack.seq, None)
                if sent is not None:
                    self._events.append(ProbeOutcome(probe.target, self._now - sent, self._now))
            self._probe_succeeded(probe)
            return
        fwd = self._fwd.pop(ack.seq, None)
        if fwd is not None:
            self._out.append((fwd[0], Ack(self.name, fwd[1], self._take(self._budget))))

    def _on_ping_req(self, src: Addr, req: PingReq) -> None:
        seq = self._next_seq()
        self._fwd[seq] = (src, req.seq, req.want_nack)
        m = self._members.get(req.target)
        updates = self._piggyback(m) if m is not None else self._take(self._budget)
        self._out.append((req.target_addr, Ping(self.name, seq, req.target, updates)))
        self._at(self._now + self.config.probe_timeout * 0.8, _FWD_END, seq)

    def _fwd_end(self, seq: int) -> None:
        fwd = self._fwd.pop(seq, None)
        if fwd is not None and fwd[2]:
            self._out.append((fwd[0], Nack(self.name, fwd[1])))

    def _adjust_health(self, delta: int) -> None:
        self.health_score = min(max(0, self.health_score + delta), self.config.awareness_max - 1)

    # ----------------------------------------------------------------- merging
    def _merge_updates(self, updates: tuple[Update, ...], src: Addr) -> None:
        corrections: list[Update] = []
        for u in updates:
            t = type(u)
            if t is Alive:
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
            elif t is Record:
                self._merge_record(u)  # type: ignore[arg-type]
            elif t is Event:
                self._merge_event(u)  # type: ignore[arg-type]
        if corrections:
            self._count("corrections")
            self._out.append((src, Gossip(self.name, tuple(corrections))))

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
            if s.source in susp.confirmers or s.source in (self.name, susp.origin):
                return
            susp.confirmers.add(s.source)
            timeout = formulas.suspicion_timeout(
                len(susp.confirmers), susp.k, susp.min_t, susp.max_t
            )
            if susp.start + timeout < susp.deadline:
                susp.deadline = susp.start + timeout
                self._at(susp.deadline, _SUSPICION, (m.name, susp))
            self._enqueue(("m", m.name), s)
            return
        n = self.num_alive()
        cfg = self.config
        min_t = formulas.suspicion_min_timeout(cfg.suspicion_mult, n, cfg.probe_interval)
        k = formulas.suspicion_confirmations_wanted(cfg.suspicion_mult, n)
        susp = Suspicion(self._now, k, min_t, min_t * cfg.suspicion_max_mult, s.source)
        self._set_state(m, SUSPECT, s.incarnation)
        m.suspicion = susp
        self._at(susp.deadline, _SUSPICION, (m.name, susp))
        self._at(self._now + min_t / 2, _RECHECK, (m.name, susp))
        self._enqueue(("m", m.name), s)
        # Buddy system: tell the suspect at once so it can refute before anyone times out (the
        # accuser always; others with a probability that keeps ~4 direct notices per suspicion).
        if s.source == self.name or self.rng.random() < 4.0 / n:
            self._out.append((m.addr, Gossip(self.name, (s,))))

    def _merge_dead(self, d: Dead) -> None:
        if d.name == self.name:
            if not self.leaving:
                self._refute(d.incarnation)
            return
        m = self._members.get(d.name)
        if m is None or d.incarnation < m.incarnation or m.state in (DEAD, LEFT):
            return
        self._set_state(m, LEFT if d.source == d.name else DEAD, d.incarnation)
        self._enqueue(("m", m.name), d)

    def _merge_record(self, r: Record) -> None:
        if r.name == self.name:  # a record of ours from an earlier life: jump past it
            mine = self._records.get(self.name)
            if (
                mine is None
                or r.version > mine[0]
                or (r.version == mine[0] and r.payload != mine[1])
            ):
                self._store_own_record(r.version + 1, mine[1] if mine else b"")
            return
        old = self._records.get(r.name)
        if old is not None and old[0] >= r.version:
            return
        self._records[r.name] = (r.version, r.payload)
        self._events.append(RecordChanged(r.name, r.version, r.payload, self._now))
        self._enqueue(("r", r.name), r)

    def _merge_event(self, e: Event) -> None:
        key = (e.source, e.seq)
        if key in self._seen_events:
            return
        self._remember_event(e.source, e.seq)
        self._events.append(EventReceived(e.source, e.seq, e.kind, e.payload, self._now))
        self._enqueue(("e", e.source, e.seq), e)

    def _refute(self, incarnation: int) -> None:
        self.incarnation = max(self.incarnation, incarnation) + 1
        self._me.incarnation = self.incarnation
        self._adjust_health(1)
        self._count("refutations")
        self._enqueue(("m", self.name), Alive(self.name, self.addr, self.incarnation))
        self._gossip_round()

    def _set_state(self, m: Member, state: int, incarnation: int) -> None:
        previous = m.state
        m.incarnation = incarnation
        if state != SUSPECT:
            m.suspicion = None
        if state == previous:
            return
        m.state = state
        m.since = self._now
        if state in (ALIVE, SUSPECT):
            if m.name not in self._peers and m is not self._me:
                self._peers.add(m.name)
                self._ring.insert(self.rng, m.name)
        else:
            self._peers.remove(m.name)
            if state == DEAD:
                self._dead_addrs[m.name] = (m.addr, self._now)
            self._at(self._now + self.config.dead_reap_time, _REAP, (m.name, self._now))
        self._events.append(MemberChanged(m.name, m.addr, state, incarnation, previous, self._now))

    def _suspicion_expired(self, name: str, susp: Suspicion) -> None:
        m = self._members.get(name)
        if m is None or m.suspicion is not susp or self._now < susp.deadline:
            return
        d = Dead(name, m.incarnation, self.name)
        self._set_state(m, DEAD, m.incarnation)
        self._enqueue(("m", name), d)

    def _recheck(self, name: str, susp: Suspicion) -> None:
        """Every half minimum timeout, tell the suspect directly: it answers with its Alive if it
        refuted (or refutes now), so we do not time out merely for missing the refutation."""
        m = self._members.get(name)
        if m is not None and m.suspicion is susp:
            self._out.append(
                (m.addr, Gossip(self.name, (Suspect(name, m.incarnation, self.name),)))
            )
            self._at(self._now + susp.min_t / 2, _RECHECK, (name, susp))

    def _reap(self, name: str, since: float) -> None:
        m = self._members.get(name)
        if m is None or m.state not in (DEAD, LEFT) or m.since != since:
            return
        del self._members[name]
        self._records.pop(name, None)
        self._queue.discard(("m", name))
        self._queue.discard(("r", name))
        self._events.append(MemberChanged(name, m.addr, REAPED, m.incarnation, m.state, self._now))

    def _fact_about(self, m: Member) -> Update:
        if m.state == SUSPECT:
            return Suspect(m.name, m.incarnation, self.name)
        if m.state in (DEAD, LEFT):
            return Dead(m.name, m.incarnation, m.name if m.state == LEFT else self.name)
        return Alive(m.name, m.addr, m.incarnation)

    # ----------------------------------------------------------------- records & events
    def _store_own_record(self, version: int, payload: bytes) -> None:
        self._records[self.name] = (version, payload)
        r = Record(self.name, version, payload)
        self._events.append(RecordChanged(self.name, version, payload, self._now))
        self._enqueue(("r", self.name), r)

    def _remember_event(self, source: str, seq: int) -> None:
        seen = self._seen_events
        seen[(source, seq)] = None
        if len(seen) > _SEEN_EVENTS_MAX:
            del seen[next(iter(seen))]

    # ----------------------------------------------------------------- dissemination
    def _enqueue(self, key: tuple[Any, ...], update: Update) -> None:
        self._queue.push(key, update, self._size(update))
        if not self._gossip_armed:
            self._gossip_armed = True
            self._at(self._now + self.config.gossip_interval, _GOSSIP, None)

    def _limit(self) -> int:
        return formulas.retransmit_limit(self.config.retransmit_mult, self.num_alive())

    def _take(self, budget: int) -> tuple[Update, ...]:
        if not self._queue:
            return ()
        return tuple(self._queue.take(budget, self._limit()))

    def _piggyback(self, target: Member) -> tuple[Update, ...]:
        if target.state == SUSPECT:  # buddy system: the suspect hears it on our next ping
            fact = self._fact_about(target)
            return (fact, *self._take(self._budget - 64))
        return self._take(self._budget)

    def _gossip_round(self) -> None:
        if self._queue:
            for name in self._peers.sample(self.rng, self.config.gossip_fanout):
                updates = self._take(self._budget)
                if not updates:
                    break
                self._out.append((self._members[name].addr, Gossip(self.name, updates)))
        if self._queue and not self._gossip_armed:
            self._gossip_armed = True
            self._at(self._now + self.config.gossip_interval, _GOSSIP, None)

    # ----------------------------------------------------------------- anti-entropy
    def _sync_interval(self) -> float:
        return formulas.push_pull_scale(self.config.push_pull_interval, self.num_alive())

    def _periodic_sync(self) -> None:
        self._at(self._now + self._sync_interval() * self.rng.uniform(0.5, 1.5), _SYNC, None)
        if self.leaving:
            return
        target: Addr | None = None
        horizon = self._now - self.config.reconnect_time
        for name, (_, died) in list(self._dead_addrs.items()):
            if died < horizon:
                del self._dead_addrs[name]
        lost = list(self._dead_addrs.values())
        if (lost or self._seeds) and (not self._peers or self.rng.random() < 1 / 3):
            pool = [a for a, _ in lost] + self._seeds
            target = self.rng.choice(pool)
        elif self._peers:
            target = self._members[self._peers.sample(self.rng, 1)[0]].addr
        if target is not None:
            self._send_state(target, reply=True)

    def _retry_join(self, delay: float) -> None:
        if len(self._members) > 1 or not self._seeds:
            return
        for seed in self._seeds:
            self._send_state(seed, reply=True)
        delay = min(delay * 2, 5.0)
        self._at(self._now + delay, _JOIN, delay)

    def _entries(self) -> list[SyncEntry]:
        out: list[SyncEntry] = []
        records = self._records
        for m in self._members.values():
            rec = records.get(m.name)
            out.append((m.name, m.addr, m.incarnation, m.state, rec[0] if rec else 0))
        return out

    def _send_state(self, dest: Addr, *, reply: bool) -> None:
        chunk: list[SyncEntry] = []
        used = 0
        for e in self._entries():
            size = len(e[0]) + len(e[1][0]) + _SYNC_ENTRY_OVERHEAD
            if chunk and used + size > self._budget:
                self._out.append((dest, Sync(self.name, reply, tuple(chunk))))
                chunk, used = [], 0
            chunk.append(e)
            used += size
        if chunk:
            self._out.append((dest, Sync(self.name, reply, tuple(chunk))))

    def _on_sync(self, src: Addr, sync: Sync) -> None:
        push: list[Update] = []
        for name, addr, inc, state, rec_version in sync.entries:
            if state == ALIVE:
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
        self._push_records(src, push)
        if sync.reply:
            last = self._sync_replied.get(sync.sender)
            if last is None or self._now - last >= _SYNC_REPLY_GAP:
                self._sync_replied[sync.sender] = self._now
                self._send_state(src, reply=False)

    def _push_records(self, dest: Addr, records: list[Update]) -> None:
        batch: list[Update] = []
        used = 0
        for r in records:
            size = self._size(r)
            if batch and used + size > self._budget:
                self._out.append((dest, Gossip(self.name, tuple(batch))))
                batch, used = [], 0
            batch.append(r)
            used += size
        if batch:
            self._out.append((dest, Gossip(self.name, tuple(batch))))

    # ----------------------------------------------------------------- helpers
    def _at(self, when: float, kind: int, arg: Any) -> None:
        self._tseq += 1
        heapq.heappush(self._timers, (when, self._tseq, kind, arg))

    def _next_seq(self) -> int:
        self._seq += 1
        return self._seq

    def _count(self, key: str) -> None:
        self.counters[key] = self.counters.get(key, 0) + 1
