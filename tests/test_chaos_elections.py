"""The soak's count of allocator elections and their causes, from literal event logs."""

from __future__ import annotations

from typing import Any

from sdrpeer.chaos.elections import elections

T0 = 1000.0


def ev(ts: float, kind: str, robot: str, **detail: Any) -> dict[str, Any]:
    return {"ts": T0 + ts, "kind": kind, "robot": robot, "detail": detail}


def fault(t: float, kind: str, robot: str, until: float | None = None) -> dict[str, Any]:
    return {"t": t, "kind": kind, "robots": [robot], "until": until}


def whys(report: dict[str, Any]) -> list[tuple[int, str, str]]:
    return [(r["epoch"], r["winner"], r["why"]) for r in report["list"]]


def test_each_election_is_explained_by_what_befell_the_allocator_before_it() -> None:
    logs = {
        "robot-2": [
            ev(1.0, "election.elected", "robot-1", epoch=1, previous=None),  # seen by robot-2
            ev(12.0, "member.dead", "robot-3"),  # robot-3 declared dead; nothing killed it
            ev(21.1, "election.stepped_down", "robot-2", epoch=4, reason="ineligible"),
        ],
        "robot-1": [ev(1.0, "election.elected", "robot-1", epoch=1, previous=None)],
        # robot-3's own log was lost with it: robot-5 learnt of its win
        "robot-5": [ev(6.1, "election", "robot-5", epoch=2, leader="robot-3", previous=None)],
        "robot-4": [
            ev(13.0, "election.elected", "robot-4", epoch=3, previous=None),
            ev(14.0, "election.elected", "robot-2", epoch=4, previous="robot-4"),
            ev(20.8, "election.elected", "robot-4", epoch=5, previous=None),
            ev(30.0, "election.elected", "robot-5", epoch=6, previous=None),
        ],
    }
    report = elections(logs, [fault(5.0, "kill_agent", "robot-1", 9.0)], T0)
    assert whys(report) == [
        (1, "robot-1", "first"),
        (2, "robot-3", "allocator killed"),  # as robot-5 heard of it
        (3, "robot-4", "declared dead while alive"),
        (4, "robot-2", "other"),  # robot-4 lost the role and nothing in the logs says why
        (5, "robot-4", "stepped down: ineligible"),  # logged 0.3 s after the next win
        (6, "robot-5", "other"),
    ]
    assert report["total"] == 6
    assert report["churn"] == 4  # all but the first and the killed allocator's
    assert report["by_reason"]["allocator killed"] == 1


def test_faults_on_while_the_role_changed_explain_it_before_a_step_down() -> None:
    logs = {
        "robot-1": [
            ev(1.0, "election.elected", "robot-1", epoch=1),
            ev(8.5, "election.stepped_down", "robot-1", epoch=1, reason="ineligible"),
            ev(9.0, "election.elected", "robot-2", epoch=2),  # robot-1 cut off (8-15 s)
            ev(13.0, "election.elected", "robot-4", epoch=3),  # the partition still on
            ev(21.0, "election.stepped_down", "robot-4", epoch=3, reason="ineligible"),
            ev(21.2, "election.elected", "robot-3", epoch=4),  # robot-4's RSSI pushed down
        ]
    }
    faults = [fault(8.0, "partition", "robot-1", 15.0), fault(20.0, "rssi", "robot-4", 27.0)]
    report = elections(logs, faults, T0)
    assert [why for _, _, why in whys(report)] == [
        "first",
        "partition",
        "partition",
        "fault on the allocator's robot",
    ]
    assert report["churn"] == 0


def test_two_claims_of_one_epoch_are_settled_as_the_election_settles_them() -> None:
    # robot-5 heard robot-2's claim first; robot-3 won the epoch (the higher name) and was
    # then killed: the next election is explained by robot-3's kill, not robot-2's history.
    logs = {
        "robot-5": [
            ev(1.0, "election", "robot-5", epoch=1, leader="robot-2"),
            ev(1.1, "election", "robot-5", epoch=1, leader="robot-3"),
            ev(9.0, "election", "robot-5", epoch=2, leader="robot-4"),
        ],
    }
    report = elections(logs, [fault(5.0, "kill_agent", "robot-3", 9.0)], T0)
    assert whys(report) == [(1, "robot-3", "first"), (2, "robot-4", "allocator killed")]
