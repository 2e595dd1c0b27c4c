"""What the agent hands the deployment side on every step: the alive robots and their records."""

from __future__ import annotations

from dataclasses import dataclass, field

from sdrpeer.record import RobotRecord


@dataclass
class ClusterState:
    """The alive robots (this one included) with their latest records."""

    alive: dict[str, RobotRecord]
    """Every alive robot (this one included) with its latest record."""
    order: list[str] = field(default_factory=list)
    """Robot names in the order first_fit tries them after the origin."""
