"""The soak's count of allocator elections and their causes, from literal event logs."""

from __future__ import annotations

from typing import Any

from sdrpeer.chaos.elections import elections

T0 = 1000.0


def ev(ts: float, kind: str, robot: str, **detail: Any) -> dict[str, Any]:
    return {"ts": T0 + ts, "kind": kind, "robot": robot, "detail": detail}


def test_each_election_is_explained_by_what_befell_the_allocator_before_it() -> None:
    logs = {
        "robot-2": [
            ev(1.0, "election.elected", "robot-1", epoch=1, previous=None),  # seen by robot-2
            ev(12.0, "member.dead", "robot-3"),  # robot-3 declared dead; nothing killed it
            ev(20.5, "election.stepped_down", "robot-2", epoch=4, reason="ineligible"),
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
    faults = [{"t": 5.0, "kind": "kill_agent", "robots": ["robot-1"]}]
    report = elections(logs, faults, T0)
    assert [(r["epoch"], r["winner"], r["why"]) for r in report["list"]] == [
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


def test_a_partition_explains_the_election_that_follows_it() -> None:
    logs = {
        "robot-1": [
            ev(1.0, "election.elected", "robot-1", epoch=1),
            ev(9.0, "election.elected", "robot-2", epoch=2),
        ]
    }
    faults = [{"t": 8.0, "kind": "partition", "robots": ["robot-1"]}]
    report = elections(logs, faults, T0)
    assert [r["why"] for r in report["list"]] == ["first", "partition"]
    assert report["churn"] == 0
