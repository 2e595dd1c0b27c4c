"""What the agent hands the deployment side on every step: the alive robots and their records,
and the members the fleet is counted in.

How it works: the agent builds a `ClusterState` from its gossip view for every step; the
deployment core asks it three questions, `plan_offers()`, `claims()` and `hosted()`, computed
from the records on each call (a caller that knows its records never change, such as the
simulator's snapshots shared by a thousand robots, may answer them once)."""

from __future__ import annotations

from dataclasses import dataclass, field

from sdrpeer.record.robot import InstanceInfo, RobotRecord

PlanKey = tuple[int, str, int]
"""(epoch, allocator, version): the order of plans (`sdrpeer.plan.Plan.key`)."""


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

    def plan_offers(self) -> list[tuple[PlanKey, str]]:
        """(plan key, robot) of every alive robot that gossips a plan, newest plan first."""
        offers = [
            ((p.epoch, p.allocator, p.version), robot)
            for robot, rec in self.alive.items()
            if (p := rec.plan) is not None
        ]
        offers.sort(reverse=True)
        return offers

    def hosted(self) -> list[tuple[str, InstanceInfo]]:
        """(robot, instance) of every instance an alive robot gossips."""
        return [(robot, inst) for robot, rec in self.alive.items() for inst in rec.instances]

    def claims(self) -> list[tuple[int, str]]:
        """(epoch, robot) of every alive robot's published claim to the allocator role."""
        return [
            (e.epoch, e.leader)
            for rec in self.alive.values()
            if (e := rec.election) is not None and e.claiming and e.leader is not None
        ]
