"""The gossip record: round trip, rounding, size, and refusal of anything malformed."""

from __future__ import annotations

import json
from dataclasses import replace

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sdrpeer.errors import WireError
from sdrpeer.record import (
    ElectionInfo,
    InstanceInfo,
    LinkStats,
    Metrics,
    PlanInfo,
    RobotRecord,
    decode_record,
    encode_record,
    record_to_json,
    reference_record,
)


def big_record() -> RobotRecord:
    """A robot with 10 measured peers and 10 instances: a realistic upper bound."""
    return reference_record(ts=1_732_240_000.123)


def test_round_trip_rounds_to_the_grid() -> None:
    r = decode_record(encode_record(big_record()))
    m = r.metrics
    assert m.cpu_pct == 37.5
    assert m.mem_total == 4_000_000_000  # 3_906_250 KiB exactly
    assert m.mem_free == 1_205_633 * 1024  # nearest KiB
    assert m.battery_pct == 87.3  # 0.1 % grid
    assert m.rssi_dbm == -47.0
    assert m.pos == (12.35, -3.2)  # cm
    assert r.links["robot-3"] == LinkStats(rtt_ms=6.17, jitter_ms=1.26, loss=0.0)
    assert r.links["robot-4"].loss == 0.05
    assert [i.name for i in r.instances][:3] == [
        "OmnidirectionalCameraRTC1",
        "AnomalyDetectionRTC2",
        "CameraRTC3",
    ]
    assert r.instances[1].state == "active"
    assert r.instances[9].role == "standby"
    assert r.instances[0].rss == round(512_000_000 / 1024) * 1024
    assert r.api == "http://192.168.10.11:8080"
    assert r.priority == 3
    assert r.ts == 1_732_240_000.123
    # Once on the grid, a record survives unchanged.
    assert decode_record(encode_record(r)) == r


def test_size_of_ten_peers_and_ten_instances() -> None:
    size = len(encode_record(big_record()))
    print(f"record with 10 links + 10 instances: {size} bytes")
    assert size < 500  # 449 when written; the paper's own names are long


def test_minimal_record_and_unknown_names() -> None:
    r = RobotRecord(
        metrics=Metrics(0.0, 1024, 0, None, None, None),
        links={},
        api=None,
        priority=-1,
        instances=(InstanceInfo("cam", "camera_driver", "weird-state", "observer", 0.0, 0),),
        ts=0.0,
    )
    assert decode_record(encode_record(r)) == r
    assert len(encode_record(r)) == 68  # 30 of them are the three free-form strings


def test_record_to_json() -> None:
    d = record_to_json(decode_record(encode_record(big_record())))
    assert d["metrics"] == {
        "cpu_pct": 37.5,
        "mem_total": 4_000_000_000,
        "mem_free": 1_234_568_192,
        "battery_pct": 87.3,
        "rssi_dbm": -47.0,
        "pos": [12.35, -3.2],
    }
    assert d["links"]["robot-2"] == {"rtt_ms": 5.17, "jitter_ms": 0.84, "loss": 0.1}
    assert d["instances"][0]["component"] == "OmnidirectionalCameraRTC"
    json.dumps(d)  # JSON-ready


def wire(**changes: object) -> bytes:
    """A valid wire array with some positions replaced."""
    base: list[object] = [
        1,
        [100, 4, 2, None, None, None],
        ["p", 1, 1, 0],
        None,
        0,
        ["C"],
        [[0, 1, "1", 2, 0, 0, 0]],
        1.0,
    ]
    names = ["fmt", "metrics", "links", "api", "priority", "comps", "instances", "ts"]
    for k, v in changes.items():
        base[names.index(k)] = v
    data: bytes = msgpack.packb(base)
    return data


def test_wire_helper_is_valid() -> None:
    r = decode_record(wire())
    assert r.instances[0].name == "C1"
    assert r.links == {"p": LinkStats(0.01, 0.01, 0.0)}


@pytest.mark.parametrize(
    ("changes", "detail"),
    [
        ({"fmt": 2}, "format 2"),
        ({"fmt": True}, "format True"),
        ({"metrics": [1, 2, 3]}, "metrics: expected a list of 6"),
        ({"metrics": [-1, 4, 2, None, None, None]}, "cpu_pct: -1 out of range"),
        ({"metrics": [1.5, 4, 2, None, None, None]}, "cpu_pct: expected an integer"),
        ({"metrics": [1, 4, 2, 1001, None, None]}, "battery_pct: 1001 out of range"),
        ({"metrics": [1, 4, 2, None, None, [1]]}, "metrics.pos: expected a list of 2"),
        ({"links": ["p", 1, 1]}, "links: expected groups of 4"),
        ({"links": ["p", 1, 1, 1001]}, "loss: 1001 out of range"),
        ({"links": ["p", 1, 1, 0, "p", 1, 1, 0]}, "peer 'p' twice"),
        ({"links": ["", 1, 1, 0]}, "links.peer: expected a name"),
        ({"api": 5}, "api: expected a name"),
        ({"priority": 2**40}, "priority"),
        ({"instances": [[1, 1, "1", 2, 0, 0, 0]]}, "instance.component: 1 out of range"),
        ({"instances": [[0, 2, "1", 2, 0, 0, 0]]}, "instance.prefix: 2 out of range"),
        ({"instances": [[0, 1, "1", 99, 0, 0, 0]]}, "instance.state: 99 out of range"),
        ({"instances": [[0, 0, "", 2, 0, 0, 0]]}, "instance.name: expected a name"),
        ({"ts": 1}, "ts: expected a finite float"),
        ({"ts": float("nan")}, "ts: expected a finite float"),
    ],
)
def test_malformed_fields_are_named(changes: dict[str, object], detail: str) -> None:
    with pytest.raises(WireError) as info:
        decode_record(wire(**changes))
    assert info.value.reason == "malformed"
    assert detail in info.value.detail


@pytest.mark.parametrize(
    "data",
    [b"", b"\xc1", b"\x93\x01\x02", msgpack.packb({"a": 1}), msgpack.packb([1] * 9)],
)
def test_garbage_is_malformed(data: bytes) -> None:
    with pytest.raises(WireError, match=r"^malformed"):
        decode_record(data)


@settings(max_examples=500)
@given(st.binary(max_size=300))
def test_random_bytes_never_raise_anything_but_wire_error(data: bytes) -> None:
    try:
        decode_record(data)
    except WireError as e:
        reason = e.reason
    else:
        reason = "malformed"
    assert reason == "malformed"


def _mutations(data: bytes) -> st.SearchStrategy[bytes]:
    """Single-byte changes of a valid encoding: close to valid, so they reach the validators."""
    return st.tuples(st.integers(0, len(data) - 1), st.integers(0, 255)).map(
        lambda t: data[: t[0]] + bytes([t[1]]) + data[t[0] + 1 :]
    )


@settings(max_examples=500)
@given(_mutations(encode_record(big_record())))
def test_mutated_records_decode_or_fail_cleanly(data: bytes) -> None:
    try:
        r = decode_record(data)
    except WireError as e:
        reason = e.reason
    else:
        assert decode_record(encode_record(r)) == r
        reason = "malformed"
    assert reason == "malformed"


def test_election_plan_and_data_address_round_trip() -> None:
    base = big_record()
    inst = replace(base.instances[0], data="tcp://10.0.0.7:40123")
    r = replace(
        base,
        instances=(inst, *base.instances[1:]),
        election=ElectionInfo(epoch=7, leader="robot-2", claiming=False),
        plan=PlanInfo(epoch=7, version=3, digest="ab12cd34ef56ab78", allocator="robot-2"),
    )
    back = decode_record(encode_record(r))
    assert back.election == ElectionInfo(7, "robot-2", False)
    assert back.plan == PlanInfo(7, 3, "ab12cd34ef56ab78", "robot-2")
    assert back.instances[0].data == "tcp://10.0.0.7:40123"
    assert back.instances[1].data is None


def test_first_layout_still_accepted() -> None:
    wire = msgpack.unpackb(encode_record(big_record()), raw=False)
    old = wire[:8]
    old[6] = [item[:7] for item in old[6]]
    back = decode_record(msgpack.packb(old, use_bin_type=True))
    assert back.election is None
    assert back.plan is None
    assert all(i.data is None for i in back.instances)


@pytest.mark.parametrize(
    "election",
    [[1, "r"], [-1, "r", True], [1, 5, True], [1, "r", 1]],
)
def test_malformed_election_refused(election: list[object]) -> None:
    wire = msgpack.unpackb(encode_record(big_record()), raw=False)
    wire[8] = election
    with pytest.raises(WireError, match="malformed"):
        decode_record(msgpack.packb(wire, use_bin_type=True))
