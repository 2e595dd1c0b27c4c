"""What the simulated cores reported, with virtual times, indexed for the questions tests ask.

How it works:
- the cluster hands every drained core event to `record(observer, event, now)`;
- `MemberChanged` updates a mirror of each observer's view (member -> state) and a per-member
  history of (time, observer, state, incarnation); `RecordChanged` a per-owner history of
  (time, observer, version); `EventReceived` the first arrival per (source, seq) and observer;
- with `keep_all`, every event (probe outcomes included) is also kept in `events`, in order: two
  runs with the same seed must produce equal lists;
- `up`/`down` record when each node ran, which tells true deaths from false ones.
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence

from sdrpeer.gossip.events import REAPED, CoreEvent, EventReceived, MemberChanged, RecordChanged
from sdrpeer.gossip.messages import ALIVE, DEAD
from sdrpeer.vocabulary import MemberState


class Trace:
    """Core events of a simulated cluster, by observer and virtual time."""

    def __init__(self, names: Sequence[str], *, keep_all: bool = False) -> None:
        self.names = list(names)
        self.index = {name: i for i, name in enumerate(self.names)}
        self.keep_all = keep_all
        self.events: list[tuple[float, str, CoreEvent]] = []
        """Every event as (time, observer, event); filled only with keep_all."""
        self.views: list[dict[str, MemberState]] = [{} for _ in self.names]
        """Per observer: member -> state, as its events told (reaped members removed)."""
        self._alive = [0] * len(self.names)
        self._changes: dict[str, list[tuple[float, int, MemberState | None, int]]] = {}
        self._records: dict[str, list[tuple[float, int, int]]] = {}
        self.broadcasts: dict[tuple[str, int], dict[str, float]] = {}
        """(source, seq) -> observer -> first arrival time of that one-off event."""
        self.downs: list[list[float]] = [[] for _ in self.names]
        """Per node: the times it was killed."""
        self.boots: list[list[float]] = [[] for _ in self.names]
        """Per node: the times it booted (first start and restarts)."""

    def record(self, i: int, event: CoreEvent, now: float) -> None:
        """File one event reported by observer `i` at virtual time `now`."""
        if self.keep_all:
            self.events.append((now, self.names[i], event))
        kind = type(event)
        if kind is MemberChanged:
            assert isinstance(event, MemberChanged)
            name, state = event.name, event.state
            self._changes.setdefault(name, []).append((now, i, state, event.incarnation))
            if name == self.names[i]:
                return
            view = self.views[i]
            if view.get(name) == ALIVE:
                self._alive[i] -= 1
            if state is REAPED:
                view.pop(name, None)
            else:
                view[name] = state
                if state == ALIVE:
                    self._alive[i] += 1
        elif kind is RecordChanged:
            assert isinstance(event, RecordChanged)
            self._records.setdefault(event.name, []).append((now, i, event.version))
        elif kind is EventReceived:
            assert isinstance(event, EventReceived)
            seen = self.broadcasts.setdefault((event.source, event.seq), {})
            seen.setdefault(self.names[i], now)

    def up(self, i: int, now: float) -> None:
        """Node i booted (a restart starts with an empty view)."""
        self.boots[i].append(now)
        self.views[i] = {}
        self._alive[i] = 0

    def down(self, i: int, now: float) -> None:
        """Node i was killed."""
        self.downs[i].append(now)

    # -- questions ----------------------------------------------------------------------------

    def view(self, observer: str, member: str) -> MemberState | None:
        """The state `observer` holds for `member` (None: unknown or reaped)."""
        return self.views[self.index[observer]].get(member)

    def first_seen(
        self, observer: str, member: str, state: MemberState, after: float = 0.0
    ) -> float | None:
        """When `observer` first reported `member` in `state` at or after `after`."""
        i = self.index[observer]
        for t, obs, st, _ in self._changes.get(member, ()):
            if obs == i and st == state and t >= after:
                return t
        return None

    def first_seen_by(
        self, member: str, state: MemberState, after: float = 0.0
    ) -> dict[str, float]:
        """Observer -> first time (at or after `after`) it reported `member` in `state`."""
        seen: dict[str, float] = {}
        for t, obs, st, _ in self._changes.get(member, ()):
            if st == state and t >= after:
                seen.setdefault(self.names[obs], t)
        return seen

    def when_all_see(
        self, member: str, state: MemberState, observers: Iterable[str], after: float = 0.0
    ) -> float | None:
        """When the last of `observers` first reported `member` in `state` (None: one never did)."""
        seen = self.first_seen_by(member, state, after)
        times = [seen.get(o) for o in observers]
        if any(t is None for t in times):
            return None
        return max([t for t in times if t is not None], default=after)

    def record_arrivals(self, owner: str, version: int, after: float = 0.0) -> dict[str, float]:
        """Observer -> first time (at or after `after`) it had version >= `version` of `owner`."""
        seen: dict[str, float] = {}
        for t, obs, v in self._records.get(owner, ()):
            if v >= version and t >= after:
                seen.setdefault(self.names[obs], t)
        return seen

    def false_deaths(self, after: float = 0.0) -> list[tuple[float, str, str]]:
        """(time, observer, member) for every DEAD report about a member never killed by then."""
        return self.false_reports(DEAD, after)

    def false_reports(self, state: MemberState, after: float = 0.0) -> list[tuple[float, str, str]]:
        """(time, observer, member) for every report of `state` (SUSPECT, DEAD) about a member
        never killed by then."""
        found = []
        for member, changes in self._changes.items():
            downs = self.downs[self.index[member]]
            for t, obs, st, _ in changes:
                if st == state and t >= after and not any(d <= t for d in downs):
                    found.append((t, self.names[obs], member))
        return sorted(found)

    def all_alive(self, up: Sequence[int]) -> bool:
        """Whether each node in `up` sees every other node in `up` as alive."""
        need = len(up) - 1
        alive = self._alive
        if any(alive[i] < need for i in up):
            return False
        names = [self.names[i] for i in up]
        for i in up:
            view, own = self.views[i], self.names[i]
            if any(view.get(n) != ALIVE for n in names if n != own):
                return False
        return True

    def lagging(self, up: Sequence[int], limit: int = 5) -> str:
        """A short description of who does not yet see every running node alive, and why."""
        names = [self.names[i] for i in up]
        lines = []
        for i in up:
            view, own = self.views[i], self.names[i]
            wrong = [(n, view.get(n)) for n in names if n != own and view.get(n) != ALIVE]
            if wrong:
                shown = ", ".join(f"{n} ({'unknown' if s is None else s})" for n, s in wrong[:3])
                lines.append(f"{own} misses {len(wrong)}: {shown}")
        more = f" (+{len(lines) - limit} more nodes)" if len(lines) > limit else ""
        return f"{len(lines)} of {len(up)} nodes lag; " + "; ".join(lines[:limit]) + more
