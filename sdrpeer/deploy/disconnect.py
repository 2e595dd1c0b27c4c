"""The disconnect policy: one active copy of a component, also across partitions (pure: no clock).

How it works, in three parts that share one notion of the fleet:
- **quorum** (`has_quorum`): a robot is *in touch* with the fleet while the robots it hears (alive
  or suspect, itself included) are a strict majority of the fleet it knows: every member not gone
  for good (alive, suspect, or dead and not yet forgotten; a robot that left is not counted) and,
  before this robot has heard of any other member since it started, every robot its plan places
  something on (an agent restarted into a running fleet is not a fleet of one). An even split
  keeps the quorum on the half that holds the fleet's first name, so exactly one side of any cut
  acts. Without the quorum a robot neither claims nor keeps the allocator role, so the side cut
  off issues no plan: at a heal the only newer plan is the fleet's.
- **the robot side** (`CutOff`): a robot cut off stops each active copy it holds after that
  component's `stop_after` (`DisconnectSpec.stop_after_s`; None: keeps it running) by holding it
  INACTIVE (the host stays up, so a short cut costs one activation). Once it is back in touch it
  keeps what it held down until it has caught up with the newest plan it can hear of: the fleet
  has replaced those copies meanwhile, and re-activating them from the stale plan would run two.
  An agent that starts with a plan placing other robots too is treated the same way (restarted
  into a running fleet: its plan is very likely stale); it launches no host until then.
- **the fleet side** (`held_components`): the allocator replaces an active copy on a robot it has
  lost only when that component's policy allows (`replace`) and `lost_after_s` has passed since the
  loss; until then the component keeps its placements as they are.
With the defaults (`stop_after` 0 s, `replace`, `lost_after` 0 s) a robot cut off stands its
actives down as soon as it sees it lost the fleet, the fleet replaces them as soon as it sees the
robot gone, and a heal finds one active copy of each. A fleet that loses its majority for good
(more than half of the robots dead at once) acts again once the dead are forgotten
(`GossipConfig.dead_reap_time`): no robot can tell a long partition from deaths.
"""

from __future__ import annotations

import math
from collections.abc import Collection, Mapping

from sdrpeer.plan import Plan
from sdrpeer.system.model import DisconnectSpec

__all__ = ["CutOff", "fleet_of", "has_quorum", "held_components"]


def fleet_of(
    me: str, members: Collection[str], plan: Plan | None, heard_of_others: bool
) -> frozenset[str]:
    """The fleet this robot counts: `members` (not left; dead ones until forgotten) and itself,
    plus the robots of its `plan` while it has heard of no other member since it started."""
    fleet = {me, *members}
    if not heard_of_others and plan is not None:
        fleet.update(p.robot for p in plan.placements)
    return frozenset(fleet)


def has_quorum(me: str, heard: Collection[str], fleet: Collection[str]) -> bool:
    """Whether `me`, hearing `heard`, is in touch with a majority of `fleet` (see above)."""
    up = {me, *heard}
    known = up | set(fleet)
    if 2 * len(up) != len(known):
        return 2 * len(up) > len(known)
    return min(known) in up


class CutOff:
    """This robot's side: since when it is cut off, and which actives it holds down."""

    def __init__(self) -> None:
        self.lost_at: float | None = None
        """When this robot lost the quorum (None: in touch)."""
        self.rejoining = False
        """Back in touch, not yet caught up with the fleet's newest plan."""
        self.lasted = 0.0
        """How long the last cut lasted (while rejoining)."""

    def restarted(self) -> None:
        """This agent starts with a plan that places robots other than itself: it is treated
        as back from a cut of unknown length (everything held down until it has caught up)."""
        self.lost_at = None
        self.rejoining = True
        self.lasted = math.inf

    @property
    def cut(self) -> bool:
        """Whether this robot is cut off from the fleet now."""
        return self.lost_at is not None

    def update(self, now: float, quorum: bool, caught_up: bool) -> bool:
        """Feed the quorum and whether the plan is caught up; True when the state changed."""
        if not quorum:
            if self.lost_at is None:
                self.lost_at = now
                self.rejoining = False
                return True
            return False
        changed = False
        if self.lost_at is not None:
            self.lasted = now - self.lost_at
            self.lost_at = None
            self.rejoining = True
            changed = True
        if self.rejoining and caught_up:
            self.rejoining = False
            changed = True
        return changed

    def holds_down(self, now: float, policy: DisconnectSpec) -> bool:
        """Whether an active copy under `policy` must be held INACTIVE now."""
        stop = policy.stop_after_s
        if stop is None:
            return False
        if self.lost_at is not None:
            return now - self.lost_at >= stop
        return self.rejoining and self.lasted >= stop

    def next_timer(self, policies: Collection[DisconnectSpec]) -> float:
        """When the next `stop_after` of `policies` runs out (inf: none pending)."""
        if self.lost_at is None:
            return math.inf
        due = [self.lost_at + p.stop_after_s for p in policies if p.stop_after_s is not None]
        return min(due, default=math.inf)


def held_components(
    plan: Plan,
    alive: Collection[str],
    lost_since: Mapping[str, float],
    now: float,
    degraded: Collection[str] = (),
) -> tuple[frozenset[str], float]:
    """The fleet's side: (components whose active sits on a lost robot and must not be replaced
    yet, the time the first of them may be). `lost_since`: robot -> when the allocator saw it go.
    A component the fleet never replaces (`replace: false`: tied to its robot) also stays on a
    robot that is alive but `degraded` (robot-wide recovery moves the rest off it)."""
    system = plan.system
    if system is None:
        return frozenset(), math.inf
    held: set[str] = set()
    due = math.inf
    for comp in system.components:
        active = plan.active_of(comp.name)
        policy = comp.disconnect
        if active is not None and active.robot in degraded and not policy.replace:
            held.add(comp.name)
            continue
        if active is None or active.robot in alive:
            continue
        if not policy.replace:
            held.add(comp.name)
            continue
        ready = lost_since.get(active.robot, now) + policy.lost_after_s
        if ready > now:
            held.add(comp.name)
            due = min(due, ready)
    return frozenset(held), due
