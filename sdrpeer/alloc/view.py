"""What the allocator knows of the cluster: one `RobotView` per alive robot.

How it works: the agent builds a `ClusterView` from its gossip table (members, their records:
metrics, measured links, hosted instances) just before it allocates; the allocation core only
reads it. Order matters: `robots` is in the order robots are tried by `first_fit` after the
robot that received the system (`origin`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

from sdrpeer.record import InstanceInfo, LinkStats, Metrics


@dataclass(frozen=True, slots=True)
class RobotView:
    """One alive robot as the allocator sees it."""

    name: str
    metrics: Metrics
    links: dict[str, LinkStats] = field(default_factory=dict)
    """Measured by this robot towards each peer (rtt, jitter, loss)."""
    instances: tuple[InstanceInfo, ...] = ()
    """Instances it hosts now (their measured RSS is already part of `metrics.mem_free`)."""

    def link_to(self, other: RobotView) -> LinkStats | None:
        """The link between this robot and `other`: the worse of the two directions measured."""
        a = self.links.get(other.name)
        b = other.links.get(self.name)
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
