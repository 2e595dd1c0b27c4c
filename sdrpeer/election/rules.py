"""The election's roles and the moves between them, as a table; an illegal move raises.

How it works: a robot is a FOLLOWER (it believes in the allocator of the highest valid claim, or in
none), WAITING (the role is vacant, or it may preempt, and it gives each robot ranked above it a
grace period to claim first) or LEADER (it claims the role). `Election` (core.py) decides which
trigger applies and asks `next_role` for the new role:

    role      trigger      -> role      when
    FOLLOWER  vacancy      -> WAITING   no valid claim in the view (or preempt and we outrank the
                                        allocator), and we are alive, eligible and not leaving
    WAITING   claim        -> LEADER    our grace ran out: k * grace after the vacancy began, k the
                                        alive eligible robots ranked above us (and startup grace)
    WAITING   settled      -> FOLLOWER  a valid claim appeared, or we may no longer claim
    LEADER    outranked    -> FOLLOWER  a valid claim with a higher (epoch, name) than ours
    LEADER    ineligible   -> FOLLOWER  we left the allocation thresholds (abdication)
    LEADER    left         -> FOLLOWER  we are leaving the cluster (abdication)
    LEADER    newer_epoch  -> LEADER    a robot that follows us knows an epoch above our claim's
                                        (its fence would refuse our plans) and no claim beats ours:
                                        we claim again at max epoch + 1

A claim is valid when its robot is alive (ALIVE or SUSPECT: a suspect allocator is not replaced
before it is confirmed dead), eligible and publishes claiming=True. A new claim always takes the
highest epoch this robot has ever seen + 1.
"""

from __future__ import annotations

from enum import Enum

from sdrpeer.errors import ElectionError


class Role(Enum):
    """What a robot is in the election."""

    FOLLOWER = "follower"
    WAITING = "waiting"
    LEADER = "leader"


TRANSITIONS: dict[tuple[Role, str], Role] = {
    (Role.FOLLOWER, "vacancy"): Role.WAITING,
    (Role.WAITING, "claim"): Role.LEADER,
    (Role.WAITING, "settled"): Role.FOLLOWER,
    (Role.LEADER, "outranked"): Role.FOLLOWER,
    (Role.LEADER, "ineligible"): Role.FOLLOWER,
    (Role.LEADER, "left"): Role.FOLLOWER,
    (Role.LEADER, "newer_epoch"): Role.LEADER,
}
"""(role, trigger) -> role: every move the election may make."""


def next_role(role: Role, trigger: str) -> Role:
    """The role after `trigger` in `role`; raises ElectionError if the table has no such move."""
    try:
        return TRANSITIONS[role, trigger]
    except KeyError:
        raise ElectionError(f"no election move {trigger!r} from {role.value}") from None
