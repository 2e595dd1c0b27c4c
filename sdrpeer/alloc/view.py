"""What the allocator knows of the cluster: one `RobotView` per alive robot.

How it works: the agent builds a `ClusterView` from its gossip table (members, their records:
metrics, link summaries, hosted instances, launch policies) just before it allocates; the allocation
core only reads it. A link between two robots is the worse of what each end's summary says of it:
exact when an end lists it (every link at or past the deployed system's bounds is listed, up to
`MAX_LISTED` per robot), else that end's typical link, kept just inside the bounds when its list is
complete (so a constraint no tighter than the bounds passes exactly when it should). Order matters:
`robots` is in the order robots are tried by `first_fit` after the robot that received the system
(`origin`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from sdrpeer.launch.policy import DEFAULT_POLICY, LaunchPolicy
from sdrpeer.record.robot import InstanceInfo, LinkStats, LinkSummary, Metrics


@dataclass(frozen=True, slots=True)
class RobotView:
    """One alive robot as the allocator sees it."""

    name: str
    metrics: Metrics
    links: LinkSummary = field(default_factory=LinkSummary)
    """This robot's summary of the links it measures (`sdrpeer.record.robot.LinkSummary`)."""
    instances: tuple[InstanceInfo, ...] = ()
    """Instances it hosts now (their measured RSS is already part of `metrics.mem_free`)."""
    launch: LaunchPolicy = DEFAULT_POLICY
    """What it lets hosts run: a component it would refuse is never placed there."""

    def link_to(self, other: RobotView) -> LinkStats | None:
        """The link between this robot and `other`: the worse of the two ends' estimates."""
        a = self.links.towards(other.name)
        b = other.links.towards(self.name)
        if a is None or b is None:
            return a or b
        return LinkStats(
            rtt_ms=max(a.rtt_ms, b.rtt_ms),
            jitter_ms=max(a.jitter_ms, b.jitter_ms),
            loss=max(a.loss, b.loss),
        )

    def distance_to(self, other: RobotView) -> float | None:
        """Euclidean distance in metres, or None when either position is unknown."""
        p, q = self.metrics.pos, other.metrics.pos
        if p is None or q is None:
            return None
        return math.hypot(p[0] - q[0], p[1] - q[1])


@dataclass(frozen=True, slots=True)
class ClusterView:
    """The alive robots, in first-fit order, and the robot that received the system."""

    robots: tuple[RobotView, ...]
    origin: str | None = None
    """The robot that first acquired the system (first_fit tries it first)."""

    def robot(self, name: str) -> RobotView | None:
        """The robot called `name`, or None."""
        for r in self.robots:
            if r.name == name:
                return r
        return None
