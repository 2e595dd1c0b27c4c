"""The election shell: candidates made of gossip records, and another robot's claim taken at
its word (every robot names the same allocator while their views of its health differ)."""

from __future__ import annotations

from sdrpeer.deploy.election_shell import ElectionShell
from sdrpeer.election.config import lan
from sdrpeer.election.events import Elected, LeaderChanged, SteppedDown
from sdrpeer.record.robot import ElectionInfo, LinkSummary, Metrics, RobotRecord
from sdrpeer.system.model import Thresholds

GB = 1000**3
NEEDS_BATTERY = Thresholds(battery_above_pct=20.0)


def record(battery: float, election: ElectionInfo | None = None) -> RobotRecord:
    metrics = Metrics(5.0, 4 * GB, 2 * GB, battery, -45.0, (0.0, 0.0))
    return RobotRecord(metrics, LinkSummary(), "http://x", 0, (), election=election)


def test_a_claim_stands_in_every_view_while_the_claimer_itself_holds_it():
    shell = ElectionShell("robot-1", lan(), known_epoch=3)
    claim = ElectionInfo(4, "robot-2", True)
    alive = {"robot-1": record(90.0), "robot-2": record(10.0, claim)}
    # robot-2's battery is below the threshold in our view, and our health shell has it degraded:
    # it still holds the role until it abdicates itself
    shell.update(100.0, alive, NEEDS_BATTERY, degraded={"robot-2"})
    assert shell.info().leader == "robot-2"
    assert not shell.is_allocator()
    # it abdicates (its own judgement): the role is vacant and robot-1, eligible, claims it
    alive["robot-2"] = record(10.0, ElectionInfo(4, "robot-2", False))
    shell.update(101.0, alive, NEEDS_BATTERY, degraded={"robot-2"})
    shell.update(110.0, alive, NEEDS_BATTERY, degraded={"robot-2"})
    assert shell.is_allocator()
    assert shell.info().epoch == 5


def test_this_robot_still_judges_itself():
    shell = ElectionShell("robot-1", lan())
    alive = {"robot-1": record(10.0)}
    for t in (100.0, 105.0, 110.0):
        shell.update(t, alive, NEEDS_BATTERY)
    assert not shell.is_allocator()  # below the battery threshold: never claims
    alive = {"robot-1": record(90.0)}
    shell.update(111.0, alive, NEEDS_BATTERY)
    shell.update(115.0, alive, NEEDS_BATTERY)
    assert shell.is_allocator()
    shell.update(116.0, alive, NEEDS_BATTERY, degraded={"robot-1"})
    assert not shell.is_allocator()  # its own recovery condition: it abdicates


def test_the_cores_events_are_passed_on_as_they_happen():
    """What the election core reports reaches the shell's caller (the coordinator logs it):
    a leader seen, this robot's claim, its stepping down; nothing twice."""
    shell = ElectionShell("robot-1", lan(), known_epoch=3)
    claim = ElectionInfo(4, "robot-2", True)
    alive = {"robot-1": record(90.0), "robot-2": record(90.0, claim)}
    shell.update(100.0, alive, NEEDS_BATTERY)
    assert shell.drain() == [LeaderChanged(4, "robot-2", None, 100.0)]
    assert shell.drain() == []
    alive = {"robot-1": record(90.0)}  # robot-2 is gone: the role is vacant, robot-1 claims it
    for t in (101.0, 105.0, 110.0):
        shell.update(t, alive, NEEDS_BATTERY)
    events = shell.drain()
    assert [type(e) for e in events] == [LeaderChanged, Elected, LeaderChanged]
    vacant, elected, leader = events
    assert isinstance(vacant, LeaderChanged)
    assert vacant.leader is None
    assert elected.epoch == 5
    assert isinstance(leader, LeaderChanged)
    assert leader.leader == "robot-1"
    shell.update(111.0, alive, NEEDS_BATTERY, degraded={"robot-1"})
    assert [type(e) for e in shell.drain()] == [SteppedDown, LeaderChanged]
