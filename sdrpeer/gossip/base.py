"""Shared state of the membership core, its timers and its dissemination helpers.

The core is split by concern, one module each: `base.CoreState` (state, timers, the broadcast
queue and gossip rounds), `probing.Probing` (failure detection), `antientropy.AntiEntropy` (the
full-state exchange and joining) and `core.Membership` (inputs, outputs and the merge rules).
Only `Membership` is meant to be used from outside.
"""

from __future__ import annotations

import hashlib
import heapq
import random
from collections import deque
from collections.abc import Callable
from typing import Any

from sdrpeer.gossip import formulas
from sdrpeer.gossip.config import GossipConfig
from sdrpeer.gossip.events import (
    CoreEvent,
)
from sdrpeer.gossip.messages import (
    ALIVE,
    DEAD,
    LEFT,
    SUSPECT,
    Addr,
    Alive,
    Dead,
    Gossip,
    Packet,
    Suspect,
    Update,
    VitalsRevision,
)
from sdrpeer.gossip.queue import BroadcastQueue
from sdrpeer.gossip.table import Member, PeerSet, ProbeRing
from sdrpeer.gossip.wire import encoded_size

# Timer kinds.
PROBE, PROBE_TIMEOUT, PROBE_END, GOSSIP, SYNC, SUSPICION, FWD_END, REAP, JOIN, RECHECK = range(10)
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


class CoreState:
    """State shared by the parts of the membership core, and their common helpers."""

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
        self._fwd: dict[int, tuple[Addr, int, bool]] = {}
        self._gossip_armed = False
        self._urgent_at = float("-inf")
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
        suspicion): each hop then costs a network delay, not the wait for the next round, and
        the robots' suspicion timers start and end together. At most one such round per
        quarter gossip interval; the regular rounds carry the rest."""
        if self._now - self._urgent_at >= self.config.gossip_interval / 4:
            self._urgent_at = self._now
            self._gossip_round()

    def _gossip_round(self) -> None:
        if self._queue:
            for name in self._peers.sample(self.rng, self.config.gossip_fanout):
                updates = self._take(self._budget)
                if not updates:
                    break
                self._out.append((self._members[name].addr, Gossip(self.name, updates)))
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

    # ----------------------------------------------------------------- records & events

    # Merge rules, implemented by `core.Membership`; probing and anti-entropy call them.
    def _merge_alive(self, a: Alive) -> None:
        raise NotImplementedError

    def _merge_suspect(self, s: Suspect) -> None:
        raise NotImplementedError

    def _merge_dead(self, d: Dead) -> None:
        raise NotImplementedError

    def _store_own_record(self, version: int, payload: bytes, *, jump: bool = False) -> None:
        raise NotImplementedError
