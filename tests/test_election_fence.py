"""Fencing, the ElectionState encoding, eligibility and health buckets, each by a table."""

from __future__ import annotations

import msgpack
import pytest

from sdrpeer.election import (
    ElectionState,
    Fence,
    decode_state,
    eligible,
    encode_state,
    health_bucket,
    state_from_wire,
    state_to_wire,
)
from sdrpeer.errors import RecordError
from sdrpeer.system.model import Thresholds


@pytest.mark.parametrize(
    ("held", "plan", "admitted"),
    [
        ((0, ""), (1, "a"), True),  # anything beats nothing
        ((5, "b"), (5, "b"), True),  # the current allocator, again and again
        ((5, "b"), (6, "a"), True),  # a newer epoch
        ((5, "b"), (4, "z"), False),  # strictly older: refused
        ((5, "b"), (5, "a"), False),  # same epoch, the claim that lost
        ((5, "b"), (5, "c"), True),  # same epoch, the claim that won
    ],
)
def test_fence_admits_only_what_is_not_older(
    held: tuple[int, str], plan: tuple[int, str], admitted: bool
) -> None:
    fence = Fence(held)
    assert fence.accepts(*plan) is admitted
    assert fence.admit(*plan) is admitted
    assert fence.highest == (plan if admitted else held)
    assert fence.refused == (0 if admitted else 1)


def test_fence_raise_to_never_lowers() -> None:
    fence = Fence()
    fence.raise_to(4, "b")
    fence.raise_to(3, "z")
    assert fence.highest == (4, "b")
    assert fence.epoch == 4
    assert not fence.admit(3, "z")
    assert fence.admit(4, "b")


@pytest.mark.parametrize(
    "state",
    [
        ElectionState(0, None, False),
        ElectionState(7, "r0003", True),
        ElectionState(2**62, "x", False),
    ],
)
def test_state_round_trips_in_the_record_layout(state: ElectionState) -> None:
    assert decode_state(encode_state(state)) == state
    assert state_from_wire(state_to_wire(state)) == state
    assert msgpack.unpackb(encode_state(state)) == [state.epoch, state.leader, state.claiming]


@pytest.mark.parametrize(
    "wire",
    [
        None,
        [1, "a"],
        [1, "a", True, 0],
        [-1, "a", True],
        [2**62 + 1, "a", True],
        [True, "a", True],
        [1.5, "a", True],
        [1, 7, True],
        [1, "a", 1],
    ],
)
def test_malformed_states_raise_wire_errors(wire: object) -> None:
    with pytest.raises(RecordError) as err:
        state_from_wire(wire)
    assert err.value.reason == "malformed"


def test_undecodable_bytes_raise_wire_errors() -> None:
    for data in (b"", b"\xc1", b"\x93\x01"):
        with pytest.raises(RecordError):
            decode_state(data)


PAPER = Thresholds(battery_above_pct=20.0, rssi_above_dbm=-52.5, loss_below=0.3)


@pytest.mark.parametrize(
    ("battery", "rssi", "loss", "leaving", "ok"),
    [
        (80.0, -40.0, 0.0, False, True),
        (20.0, -40.0, 0.0, False, False),  # battery at the threshold is not above it
        (80.0, -52.5, 0.0, False, False),
        (80.0, -40.0, 0.3, False, False),
        (80.0, -40.0, 0.0, True, False),  # a graceful leave
        (None, None, None, False, True),  # metrics it does not report are not checked
    ],
)
def test_eligibility_follows_the_allocation_thresholds(
    battery: float | None, rssi: float | None, loss: float | None, leaving: bool, ok: bool
) -> None:
    got = eligible(PAPER, battery_pct=battery, rssi_dbm=rssi, link_loss=loss, leaving=leaving)
    assert got is ok
    assert eligible(Thresholds(), battery_pct=1.0, rssi_dbm=-99.0, link_loss=1.0)


@pytest.mark.parametrize(
    ("battery", "rssi", "loss", "bucket"),
    [
        (None, None, None, 3),
        (100.0, -30.0, 0.0, 3),
        (74.9, -30.0, 0.0, 2),
        (76.0, -30.0, 0.0, 3),  # noise around 75 % moves a bucket only at the edge
        (90.0, -65.0, 0.0, 1),
        (90.0, -30.0, 0.03, 2),
        (10.0, -80.0, 0.5, 0),
    ],
)
def test_health_is_the_worst_coarse_level(
    battery: float | None, rssi: float | None, loss: float | None, bucket: int
) -> None:
    assert health_bucket(battery_pct=battery, rssi_dbm=rssi, link_loss=loss) == bucket
