"""What the agent hands the deployment side on every step: the alive robots and their records,
and the members the fleet is counted in."""

from __future__ import annotations

from dataclasses import dataclass, field

from sdrpeer.record.robot import RobotRecord


@dataclass
class ClusterState:
    """The alive robots (this one included) with their latest records."""

    alive: dict[str, RobotRecord]
    """Every alive robot (this one included) with its latest record."""
    order: list[str] = field(default_factory=list)
    """Robot names in the order first_fit tries them after the origin."""
    members: frozenset[str] = frozenset()
    """Every member the membership table holds that has not left (dead ones until they are
    forgotten), this robot included: the fleet a quorum is counted in (`deploy.disconnect`)."""
    heard: frozenset[str] = frozenset()
    """The members alive or suspect (this robot included), with a record yet or not."""
    heard_of_others: bool = True
    """Whether the table holds any other robot (in any state) since this agent started."""
