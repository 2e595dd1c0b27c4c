"""The bully election of the allocator, as a pure core fed with the gossip view.

How it works:
- gossip already says who is alive, so the bully's "are you alive?" round is the membership
  view: the caller passes one `Candidate` per robot (itself included) to `update(now, view)`
  whenever membership or a record changes, and calls `handle_timer(now)` at `next_timer()`;
- the allocator a robot believes in is the valid claim (alive, eligible, claiming) with the
  highest `(epoch, name)`; with none, the role is vacant;
- on a vacancy, a robot that may hold the role (alive, eligible, not leaving) waits k * grace,
  k = the alive eligible robots ranked above it by (priority, health, name): the top one claims at
  once, the next only if the top one has not claimed within a grace period (a bully whose higher
  peers do not answer), and so on. A claim takes epoch = the highest epoch ever seen + 1;
- a claimer that sees a higher valid claim steps down; one that becomes ineligible or leaves
  abdicates (publishes claiming=False) and the others elect the next (the moves are the table in
  `rules.py`);
- a follower publishes the highest epoch it has followed (its fence), which may be above its
  allocator's: it followed an allocator of a newer epoch that died, and refuses older plans. An
  allocator that sees a follower fenced above its claim claims again past it. Epochs a robot has
  only heard of do not count: right after a heal they arrive before the other side's claim, and
  re-claiming past them would let the stale side win. Every epoch heard of still raises the
  next claim, so a new claim passes the fence of every robot whose record it has heard;
- without `preempt`, a valid allocator keeps the role whoever returns; with it (the config's, or
  the deployed system's passed to `update`), a robot ranked above the allocator starts the same
  grace countdown and claims at a higher epoch;
- priority counts at start: for `priority_window` seconds after a fresh start (`known_epoch` 0),
  a robot of strictly higher *priority* than the allocator contends the same way, so the first
  robot to claim does not keep the role from a higher-priority robot started a moment later;
- `state()` is what to publish in the robot's gossip record; `next_event()` drains what changed.
The core never reads a clock: every time is passed in.
"""

from __future__ import annotations

import math
from collections import deque
from collections.abc import Mapping

from sdrpeer.election.config import ElectionConfig
from sdrpeer.election.events import Elected, ElectionEvent, LeaderChanged, SteppedDown
from sdrpeer.election.rules import Role, next_role
from sdrpeer.election.state import Candidate, ClaimKey, ElectionState, rank

_EMPTY: Mapping[str, Candidate] = {}


class Election:
    """One robot's view of the allocator election."""

    def __init__(
        self, name: str, config: ElectionConfig, now: float, *, known_epoch: int = 0
    ) -> None:
        """`known_epoch`: the highest epoch this robot saw before a restart (its fence), if kept."""
        self.name = name
        self.config = config
        self.role = Role.FOLLOWER
        """FOLLOWER, WAITING or LEADER (see `rules.py`)."""
        self._started = now
        self._startup = config.rejoin_grace if known_epoch > 0 else config.startup_grace
        self._window_end = now + config.priority_window if known_epoch == 0 else -math.inf
        """Until when priority alone lets this robot take the role (a fresh start only)."""
        self._preempt = config.preempt
        """Whether a higher-ranked robot takes the role (config, or the deployed system)."""
        self._max_epoch = known_epoch
        self._adopted = known_epoch
        self._claim_epoch = 0
        self._leader: ClaimKey | None = None
        self._waiting_since = math.inf
        self._deadline = math.inf
        self._left = False
        self._view = _EMPTY
        self._events: deque[ElectionEvent] = deque()

    # -- inputs -------------------------------------------------------------------------------

    def update(self, now: float, view: Mapping[str, Candidate], *, preempt: bool = False) -> None:
        """The gossip view changed: `view` maps every known robot (this one included) to what
        gossip tells of it. The mapping is read now and on later timers, not copied.
        `preempt`: the deployed system asks for preemption (on top of the config's)."""
        self._view = view
        self._preempt = self.config.preempt or preempt
        self._evaluate(now)

    def handle_timer(self, now: float) -> None:
        """The deadline of `next_timer()` has passed."""
        self._evaluate(now)

    def leave(self, now: float) -> None:
        """This robot is leaving the cluster: abdicate for good, never claim again."""
        self._left = True
        self._evaluate(now)

    # -- outputs ------------------------------------------------------------------------------

    def state(self) -> ElectionState:
        """What to publish in this robot's gossip record now."""
        if self.role is Role.LEADER:
            return ElectionState(self._claim_epoch, self.name, True)
        return ElectionState(self._adopted, self.leader, False)

    def next_timer(self) -> float:
        """When to call `handle_timer` (inf: nothing pending)."""
        return self._deadline

    def next_event(self) -> ElectionEvent | None:
        """The oldest undrained event, or None."""
        return self._events.popleft() if self._events else None

    @property
    def leader(self) -> str | None:
        """The allocator this robot believes in (itself when it claims), None while vacant."""
        return None if self._leader is None else self._leader[1]

    @property
    def epoch(self) -> int:
        """The epoch of that allocator's claim (the highest epoch known while vacant)."""
        return self._max_epoch if self._leader is None else self._leader[0]

    @property
    def is_leader(self) -> bool:
        """Whether this robot claims the role."""
        return self.role is Role.LEADER

    @property
    def max_epoch(self) -> int:
        """The highest epoch this robot has heard of."""
        return self._max_epoch

    @property
    def adopted_epoch(self) -> int:
        """The highest epoch this robot has followed (or claimed): persist it across restarts
        and pass it back as `known_epoch`."""
        return self._adopted

    # -- the rules ----------------------------------------------------------------------------

    def _evaluate(self, now: float) -> None:
        view, name = self._view, self.name
        me = view.get(name)
        able = not self._left and me is not None and me.alive and me.eligible
        best: ClaimKey | None = None
        top = self._max_epoch
        fenced_above = 0  # the highest epoch known by an alive robot that follows us
        for other, c in view.items():
            s = c.state
            if s is None or other == name:
                continue
            top = max(top, s.epoch)
            if not c.alive:
                continue
            if s.claiming:
                if c.eligible and (best is None or (s.epoch, other) > best):
                    best = (s.epoch, other)
            elif s.leader == name:
                fenced_above = max(fenced_above, s.epoch)
        self._max_epoch = top
        before = self._leader

        if self.role is Role.LEADER:
            if not able:
                self._step_down(now, "left" if self._left else "ineligible")
            elif best is not None and best > (self._claim_epoch, name):
                self._step_down(now, "outranked")
            elif fenced_above > self._claim_epoch:
                self._move("newer_epoch")
                self._claim(now, previous=self._claim_epoch)
        if self.role is not Role.LEADER:
            self._leader = best
            self._deadline = math.inf
            if able and me is not None and self._may_claim(now, me):
                self._contend(now, me)
            elif self.role is Role.WAITING:
                self._move("settled")
                self._waiting_since = math.inf
        if self._leader != before:
            if self._leader is not None:
                self._adopted = max(self._adopted, self._leader[0])
            epoch, leader = self._leader or (self._max_epoch, None)
            previous = None if before is None else before[1]
            self._events.append(LeaderChanged(epoch, leader, previous, now))

    def _may_claim(self, now: float, me: Candidate) -> bool:
        """No valid claim; or preempt and we rank above the allocator; or, within the priority
        window of a fresh start, our priority is above the allocator's."""
        if self._leader is None:
            return True
        holder = self._view.get(self._leader[1])
        if self._preempt:
            return holder is None or rank(self._leader[1], holder) < rank(self.name, me)
        # a fresh start's priority window: checked at every evaluation (a countdown that ends
        # after the window finds it shut and settles)
        return now < self._window_end and holder is not None and holder.priority < me.priority

    def _contend(self, now: float, me: Candidate) -> None:
        """Wait for the robots ranked above us (k * grace), then claim."""
        if self.role is Role.FOLLOWER:
            self._move("vacancy")
            self._waiting_since = now
        mine = rank(self.name, me)
        above = sum(
            1
            for other, c in self._view.items()
            if c.alive and c.eligible and other != self.name and rank(other, c) > mine
        )
        # the higher-ranked get their grace counted from when they could first claim: after
        # the startup grace (a fleet booting together), not from our own boot
        awake = max(self._waiting_since, self._started + self._startup)
        due = awake + above * self.config.grace
        if now >= due:
            self._move("claim")
            self._waiting_since = math.inf
            self._claim(now, previous=None)
        else:
            self._deadline = due

    def _claim(self, now: float, previous: int | None) -> None:
        self._max_epoch += 1
        self._claim_epoch = self._max_epoch
        self._leader = (self._claim_epoch, self.name)
        self._events.append(Elected(self._claim_epoch, previous, now))

    def _step_down(self, now: float, reason: str) -> None:
        self._move(reason)
        self._events.append(SteppedDown(self._claim_epoch, reason, now))
        self._leader = None

    def _move(self, trigger: str) -> None:
        self.role = next_role(self.role, trigger)
