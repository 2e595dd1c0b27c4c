"""SWIM membership with Lifeguard refinements, as a sans-IO core.

How it works:
- Inputs are `receive(now, src, packet)`, `handle_timer(now)`, `join`, `leave`, `set_record` and
  `broadcast_event`; outputs are drained with `datagrams_to_send()` and `next_event()`, and the
  shell calls `handle_timer` at `next_timer()`. The core never reads a clock or touches a socket.
- Failure detection is in `probing`, the full-state exchange in `antientropy`, shared state,
  timers and dissemination in `base`; this module holds the inputs, outputs and merge rules.
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
"""

from __future__ import annotations

import heapq
from collections.abc import Iterable, Mapping, Sequence

from sdrpeer.gossip import formulas
from sdrpeer.gossip.antientropy import AntiEntropy
from sdrpeer.gossip.base import (
    FWD_END,
    GOSSIP,
    JOIN,
    PROBE,
    PROBE_END,
    PROBE_TIMEOUT,
    REAP,
    RECHECK,
    SEEN_EVENTS_MAX,
    SUSPICION,
    SYNC,
)
from sdrpeer.gossip.events import (
    REAPED,
    CoreEvent,
    EventReceived,
    MemberChanged,
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
    Update,
    VitalsRevision,
)
from sdrpeer.gossip.probing import Probing
from sdrpeer.gossip.table import Member, MemberInfo, ProbeRing, Suspicion
from sdrpeer.vocabulary import MemberState


class Membership(Probing, AntiEntropy):
    """One robot's membership view and protocol state (see the module docstring)."""

    # ----------------------------------------------------------------- inputs
    def join(self, now: float, seeds: Sequence[Addr]) -> None:
        """Contact the seed addresses with a full-state exchange (retried until someone answers)."""
        self._now = now
        self._seeds = [s for s in seeds if s != self.addr]
        for seed in self._seeds:
            self._send_state(seed, reply=True)
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
            self._out.append((self._members[name].addr, Gossip(self.name, (dead,))))

    def set_record(self, now: float, payload: bytes) -> int:
        """Publish a new version of our own record (spread to everyone); returns its version."""
        self._now = now
        old = self._records.get(self.name)
        version = old[0] + 1 if old else self._first_version
        self._store_own_record(version, payload)
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
        if probe is not None and not isinstance(packet, Ack):
            self._probe_succeeded(probe)  # any datagram from the target proves it alive
        if packet.updates:
            self._merge_updates(packet.updates, src)
        if isinstance(packet, Ping):
            if packet.vitals is not None and self._merge_vitals(sender, packet.vitals):
                self._pull(src)  # they revise a record we never got: fetch it now
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
    def _merge_updates(self, updates: tuple[Update, ...], src: Addr) -> None:
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
                        self._pull(src)  # we were cut off: fetch what the fleet decided
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
            self._out.append((m.addr, Gossip(self.name, (s,))))

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
            if (
                mine is None
                or r.version > mine[0]
                or (r.version == mine[0] and r.payload != mine[1])
            ):
                self._store_own_record(r.version + 1, mine[1] if mine else b"", jump=True)
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
                (m.addr, Gossip(self.name, (Suspect(name, m.incarnation, self.name),)))
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
