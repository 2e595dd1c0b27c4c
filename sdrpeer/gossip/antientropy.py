"""Anti-entropy: the periodic full-state exchange, joining through seeds, partition healing.

How it works: every push-pull interval (scaled up above 32 robots) a robot sends a `Digest` of its
member table (who is alive or suspect, at which incarnation and record version) to one peer. Equal
tables end there: one small datagram, whatever the fleet's size. A peer whose digest differs answers
with its whole table in self-contained `Sync` chunks under the MTU and asks for ours: each side
merges the other's, pushes back the records the other lacks (at most one answer a second per robot).
Joining sends the whole table at once. A remote "dead" is merged as a suspicion only, since it may
be stale. One time in three the partner is the last address of a dead member or a seed instead: that
is how two halves of a healed partition find each other again.

A robot also *pulls* at once (`_pull`: our table to one peer, answered with the records we lack and
its table) when it learns it fell behind: a ping carries vitals revising a record newer than the one
we hold of its sender, or a member tells us we were declared dead (we were cut off: everything the
fleet decided meanwhile is in records we missed). The periodic exchange would repair both, but only
after a push-pull interval (5 s on the lan preset): after a partition heals, the side that was cut
off learns of the fleet's newer plan at once. At most one pull per peer per `SYNC_REPLY_GAP`.
"""

from __future__ import annotations

from sdrpeer.gossip.base import JOIN, SYNC, CoreState
from sdrpeer.gossip.messages import (
    ALIVE,
    DEAD,
    LEFT,
    SUSPECT,
    Addr,
    Alive,
    Dead,
    Digest,
    Gossip,
    Record,
    Suspect,
    Sync,
    SyncEntry,
    Update,
)

SYNC_REPLY_GAP = 1.0  # answer one robot's full-state exchange at most this often (seconds)
SYNC_ENTRY_OVERHEAD = 16  # msgpack bytes of one sync entry besides its name and host


class AntiEntropy(CoreState):
    """Full-state exchange with one peer at a time, and joining."""

    def _periodic_sync(self) -> None:
        self._at(self._now + self._sync_interval() * self.rng.uniform(0.5, 1.5), SYNC, None)
        if self.leaving:
            return
        target: Addr | None = None
        horizon = self._now - self.config.reconnect_time
        for name, (_, died) in list(self._dead_addrs.items()):
            if died < horizon:
                del self._dead_addrs[name]
        lost = [addr for addr, _ in self._dead_addrs.values()]
        if self._seeds:  # a seed is worth a reconnect only if it is not already a live peer
            live = {self._members[name].addr for name in self._peers.names()}
            lost += [seed for seed in self._seeds if seed not in live]
        if lost and (not self._peers or self.rng.random() < 1 / 3):
            target = self.rng.choice(lost)
        elif self._peers:
            target = self._members[self._peers.sample(self.rng, 1)[0]].addr
        if target is not None:
            n = self.num_alive()
            digest = Digest(self.name, self.table_digest(), n, self._take(self._budget - 32))
            self._out.append((target, digest))

    def _on_digest(self, src: Addr, d: Digest) -> None:
        if d.digest == self.table_digest():
            self._count("digest_same")
            return
        self._count("digest_differs")
        last = self._sync_replied.get(d.sender)
        if last is None or self._now - last >= SYNC_REPLY_GAP:
            self._sync_replied[d.sender] = self._now
            self._send_state(src, reply=True)

    def _pull(self, dest: Addr) -> None:
        """Ask the peer at `dest` for what we lack now (rate-limited per peer)."""
        last = self._pulled.get(dest)
        if last is not None and self._now - last < SYNC_REPLY_GAP:
            return
        self._pulled[dest] = self._now
        self._count("pulls")
        self._send_state(dest, reply=True)

    def _retry_join(self, delay: float) -> None:
        if len(self._members) > 1 or not self._seeds:
            return
        for seed in self._seeds:
            self._send_state(seed, reply=True)
        delay = min(delay * 2, 5.0)
        self._at(self._now + delay, JOIN, delay)

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
            size = len(e[0]) + len(e[1][0]) + SYNC_ENTRY_OVERHEAD
            if chunk and used + size > self._budget:
                self._out.append((dest, Sync(self.name, reply, tuple(chunk))))
                chunk, used = [], 0
            chunk.append(e)
            used += size
        if chunk:
            self._out.append((dest, Sync(self.name, reply, tuple(chunk))))

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
        self._push_records(src, push)
        if sync.reply:
            last = self._sync_replied.get(sync.sender)
            if last is None or self._now - last >= SYNC_REPLY_GAP:
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
