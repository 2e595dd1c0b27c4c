"""The member table: who is known, in which state, and which of them can be picked at random.

How it works: `Member` holds one robot's view (address, incarnation, state, suspicion). `PeerSet`
keeps the names of members that are alive or suspect (never ourselves) in a list with an index,
so that adding, removing and picking k at random are all O(1) or O(k) even with 1,000 robots.
`ProbeRing` walks the peers in a shuffled round-robin order (a full pass before any repeat, which
bounds the time until a dead robot is probed), reshuffling after each pass.
"""

from __future__ import annotations

import random
from dataclasses import dataclass

from sdrpeer.gossip.messages import Addr
from sdrpeer.vocabulary import MemberState


@dataclass(frozen=True, slots=True)
class MemberInfo:
    """A snapshot of one member for callers outside the core."""

    name: str
    addr: Addr
    state: MemberState
    incarnation: int
    since: float


class Suspicion:
    """An open suspicion: when it started, who confirmed it, and its current deadline."""

    __slots__ = ("confirmers", "deadline", "k", "max_t", "min_t", "origin", "start")

    def __init__(self, start: float, k: int, min_t: float, max_t: float, origin: str) -> None:
        self.start = start
        self.origin = origin
        self.k = k
        self.min_t = min_t
        self.max_t = max_t
        self.confirmers: set[str] = set()
        self.deadline = start + (min_t if k < 1 else max_t)


class Member:
    """One robot as this robot sees it."""

    __slots__ = ("addr", "incarnation", "name", "since", "state", "suspicion")

    def __init__(
        self, name: str, addr: Addr, incarnation: int, state: MemberState, since: float
    ) -> None:
        self.name = name
        self.addr = addr
        self.incarnation = incarnation
        self.state = state
        self.since = since
        self.suspicion: Suspicion | None = None

    def info(self) -> MemberInfo:
        """A frozen snapshot."""
        return MemberInfo(self.name, self.addr, self.state, self.incarnation, self.since)


class PeerSet:
    """Names of reachable peers (alive or suspect) with O(1) add, remove and random picks."""

    __slots__ = ("_index", "_names")

    def __init__(self) -> None:
        self._names: list[str] = []
        self._index: dict[str, int] = {}

    def __len__(self) -> int:
        return len(self._names)

    def __contains__(self, name: object) -> bool:
        return name in self._index

    def names(self) -> list[str]:
        """All names, in no particular order (a copy)."""
        return list(self._names)

    def add(self, name: str) -> None:
        """Add `name` if absent."""
        if name not in self._index:
            self._index[name] = len(self._names)
            self._names.append(name)

    def remove(self, name: str) -> None:
        """Remove `name` if present (swap with the last)."""
        i = self._index.pop(name, None)
        if i is None:
            return
        last = self._names.pop()
        if i < len(self._names):
            self._names[i] = last
            self._index[last] = i

    def sample(self, rng: random.Random, k: int, exclude: str | None = None) -> list[str]:
        """Up to k distinct names chosen at random, never `exclude`."""
        names = self._names
        n = len(names)
        if n == 0 or k <= 0:
            return []
        if k >= n - 1:
            picked = [x for x in names if x != exclude]
            rng.shuffle(picked)
            return picked[:k]
        out: list[str] = []
        seen: set[int] = set()
        while len(out) < k:
            i = rng.randrange(n)
            if i in seen:
                continue
            seen.add(i)
            if names[i] != exclude:
                out.append(names[i])
        return out


class ProbeRing:
    """Shuffled round-robin probe order over the peers; a new pass reshuffles."""

    __slots__ = ("_order", "_pos")

    def __init__(self) -> None:
        self._order: list[str] = []
        self._pos = 0

    def insert(self, rng: random.Random, name: str) -> None:
        """Put a new peer at a random place in the remaining order."""
        lo = self._pos
        self._order.insert(rng.randint(lo, len(self._order)), name)

    def next(self, rng: random.Random, peers: PeerSet) -> str | None:
        """The next peer to probe, skipping names no longer in `peers`."""
        for _ in range(2):
            while self._pos < len(self._order):
                name = self._order[self._pos]
                self._pos += 1
                if name in peers:
                    return name
            self._order = peers.names()
            rng.shuffle(self._order)
            self._pos = 0
            if not self._order:
                return None
        return None
