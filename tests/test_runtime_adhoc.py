"""Run-time connections beside the desired set (sdrpeer.runtime.adhoc): merged into the sender's
spec, a plan's own connection of the same id winning, pruned with either end, remote receivers
addressed afresh (pending while unknown)."""

from __future__ import annotations

import pytest

from sdrpeer.runtime.adhoc import AdHoc
from sdrpeer.runtime.spec import ConnectionSpec, InstanceSpec


def spec(name: str, *conns: ConnectionSpec) -> InstanceSpec:
    return InstanceSpec(name, name, "python", "m:C", connections=conns)


PLAN = ConnectionSpec("plan", "out", "B", "inp")
EXTRA = ConnectionSpec("x", "out", "B", "other")
DESIRED = {"A": spec("A", PLAN), "B": spec("B")}


def test_merged_adds_to_the_sender_and_leaves_the_desired_set_alone():
    adhoc = AdHoc()
    adhoc.add("A", EXTRA)
    merged = adhoc.merged(DESIRED)
    assert merged["A"].connections == (PLAN, EXTRA)
    assert merged["B"] == DESIRED["B"]
    assert DESIRED["A"].connections == (PLAN,)


def test_a_plan_connection_of_the_same_id_wins():
    adhoc = AdHoc()
    adhoc.add("A", ConnectionSpec("plan", "out", "B", "other"))
    assert adhoc.merged(DESIRED)["A"].connections == (PLAN,)


def test_ids_are_unique_and_removal_says_whether_one_was_there():
    adhoc = AdHoc()
    adhoc.add("A", EXTRA)
    with pytest.raises(ValueError, match="exists already"):
        adhoc.add("A", EXTRA)
    assert adhoc.remove("x") is True
    assert adhoc.remove("x") is False
    assert adhoc.items() == []


@pytest.mark.parametrize(
    ("desired", "kept"),
    [
        (DESIRED, ["x", "tap", "far"]),
        ({"A": spec("A")}, ["tap", "far"]),  # the local receiver B stopped
        ({"B": spec("B")}, []),  # the sender stopped: all of its go
    ],
)
def test_prune_drops_what_lost_an_end(desired, kept):
    adhoc = AdHoc()
    adhoc.add("A", EXTRA)
    adhoc.add("A", ConnectionSpec("tap", "out", "sdrpeer-tap", "t0", to_addr="unix:///t.sock"))
    adhoc.add("A", ConnectionSpec("far", "out", "Far", "inp"), remote=True)
    adhoc.prune(desired)
    assert [c.id for _, c in adhoc.items()] == sorted(kept)


def test_a_remote_receiver_is_addressed_now_or_pending():
    adhoc = AdHoc()
    adhoc.add("A", ConnectionSpec("far", "out", "Far", "inp"), remote=True)
    addresses = {"Far": "tcp://10.0.0.2:4000"}
    [_, far] = adhoc.merged(DESIRED, addresses.get)["A"].connections
    assert (far.to_addr, far.pending) == ("tcp://10.0.0.2:4000", False)
    [_, far] = adhoc.merged(DESIRED, lambda instance: None)["A"].connections
    assert (far.to_addr, far.pending) == (None, True)
    # the receiver moved to this robot: resolved here, not pending for ever on another's record
    here = {**DESIRED, "Far": spec("Far")}
    [_, far] = adhoc.merged(here, addresses.get)["A"].connections
    assert (far.to_addr, far.pending) == (None, False)
