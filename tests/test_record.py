"""The gossip record: round trip, rounding, size, and refusal of anything malformed."""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import replace

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sdrpeer.errors import RecordError
from sdrpeer.launch.policy import LaunchPolicy
from sdrpeer.record.robot import (
    FORMAT,
    MAX_LISTED,
    ElectionInfo,
    InstanceInfo,
    LinkBounds,
    LinkStats,
    LinkSummary,
    Metrics,
    PlanInfo,
    RobotRecord,
    Vitals,
    apply_vitals,
    decode_record,
    decode_vitals,
    encode_record,
    encode_vitals,
    record_to_json,
    reference_record,
    vitals_of,
)
from sdrpeer.vocabulary import LifecycleState


def big_record() -> RobotRecord:
    """A robot with 10 measured peers (2 past the bounds) and 10 instances."""
    return reference_record()


def test_round_trip_rounds_to_the_grid() -> None:
    r = decode_record(encode_record(big_record()))
    m = r.metrics
    assert m.cpu_pct == 37.5
    assert m.mem_total == 4_000_000_000  # 3_906_250 KiB exactly
    assert m.mem_free == 1_205_633 * 1024  # nearest KiB
    assert m.battery_pct == 87.3  # 0.1 % grid
    assert m.rssi_dbm == -47.0
    assert m.pos == (12.35, -3.2)  # cm
    assert r.links.listed["robot-3"] == LinkStats(rtt_ms=66.17, jitter_ms=37.26, loss=0.0)
    assert r.links.listed["robot-2"].loss == 0.1
    assert r.links.typical == LinkStats(rtt_ms=3.17, jitter_ms=0.42, loss=0.01)
    assert (r.links.peers, r.links.bad) == (10, 2)
    assert r.links.bounds == LinkBounds(50.0, 10.0, 0.05)
    assert [i.name for i in r.instances][:3] == [
        "OmnidirectionalCameraRTC1",
        "AnomalyDetectionRTC2",
        "CameraRTC3",
    ]
    assert r.instances[1].state == LifecycleState.ACTIVE
    assert r.instances[9].role == "standby"
    assert r.instances[0].rss == round(512_000_000 / 1024) * 1024
    assert r.api == "http://192.168.10.11:8080"
    assert r.priority == 3
    # Once on the grid, a record survives unchanged.
    assert decode_record(encode_record(r)) == r


def test_size_does_not_grow_with_the_fleet() -> None:
    sizes = {n: len(encode_record(reference_record(peers=n))) for n in (10, 100, 1000)}
    print(f"record with 2 listed links + 10 instances: {sizes} bytes")
    assert max(sizes.values()) - min(sizes.values()) <= 2  # the number of peers: one integer
    assert sizes[10] < 400  # 361 when written; the paper's own names are long
    worst = reference_record(peers=1000, bad=1000)  # every link bad: still MAX_LISTED listed
    back = decode_record(encode_record(worst))
    assert len(back.links.listed) == MAX_LISTED
    assert back.links.bad == 1000
    assert len(encode_record(worst)) < 500


def test_minimal_record_and_unknown_names() -> None:
    r = RobotRecord(
        metrics=Metrics(0.0, 1024, 0, None, None, None),
        links=LinkSummary(),
        api=None,
        priority=-1,
        instances=(InstanceInfo("cam", "camera_driver", "weird-state", "observer", 0.0, 0),),
    )
    assert decode_record(encode_record(r)) == r
    assert len(encode_record(r)) == 72  # 30 of them are the three free-form strings
    refused = replace(r, instances=(replace(r.instances[0], out_refused=2),))
    assert decode_record(encode_record(refused)).instances[0].out_refused == 2  # format 5
    assert record_to_json(refused)["instances"][0]["out_refused"] == 2


def test_vitals_round_trip_and_overlay() -> None:
    r = decode_record(encode_record(big_record()))
    v = vitals_of(r)
    back = decode_vitals(encode_vitals(v))
    # What only a record changes is not carried: the capacity and the link bounds.
    assert back.metrics.mem_total == 0
    assert back.links.bounds == LinkBounds()
    assert apply_vitals(r, back) == r
    assert len(encode_vitals(v)) < len(encode_record(r))
    newer = Vitals(
        metrics=Metrics(80.0, 0, 1 << 30, 50.0, -60.0, None),
        links=LinkSummary(peers=3, typical=LinkStats(1.0, 0.5, 0.2)),
        loads=tuple((1.0, 1024 * (i + 1), 7, i) for i in range(len(r.instances))),
    )
    same = apply_vitals(r, newer)
    assert same.metrics == replace(newer.metrics, mem_total=r.metrics.mem_total)
    assert same.links == replace(newer.links, bounds=r.links.bounds)
    assert [i.rss for i in same.instances] == [1024 * (i + 1) for i in range(10)]
    assert [i.out_lost for i in same.instances] == list(range(10))
    assert decode_vitals(encode_vitals(newer)).loads == newer.loads  # out_lost travels
    assert same.instances[0].name == r.instances[0].name  # identity stays the record's
    # Vitals of a newer record than the one held: its instances may differ, only the
    # robot's own values apply.
    ahead = apply_vitals(r, newer, same_version=False)
    assert ahead.metrics.cpu_pct == 80.0
    assert ahead.instances == r.instances
    short = Vitals(newer.metrics, newer.links, newer.loads[:3])
    assert apply_vitals(r, short).instances == r.instances


def test_towards_a_peer() -> None:
    bounds = LinkBounds(rtt_ms=50.0, jitter_ms=None, loss=0.05)
    s = LinkSummary(
        peers=5,
        typical=LinkStats(80.0, 2.0, 0.01),  # most links slow, but none lossy
        bad=1,
        bounds=bounds,
        listed={"robot-9": LinkStats(120.0, 3.0, 0.3)},
    )
    assert s.towards("robot-9") == LinkStats(120.0, 3.0, 0.3)
    # Complete list: an unlisted link is inside every bound, just below it at worst.
    assert s.towards("robot-2") == LinkStats(49.99, 2.0, 0.01)
    partial = LinkSummary(peers=50, typical=LinkStats(80.0, 2.0, 0.2), bad=20, bounds=bounds)
    assert partial.towards("robot-2") == LinkStats(80.0, 2.0, 0.2)  # unknown: typical
    assert LinkSummary().towards("robot-2") is None


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
    assert d["links"]["robot-2"] == {"rtt_ms": 65.17, "jitter_ms": 24.84, "loss": 0.1}
    assert d["link_summary"]["typical"] == {"rtt_ms": 3.17, "jitter_ms": 0.42, "loss": 0.01}
    assert d["link_summary"]["peers"] == 10
    assert d["link_summary"]["bounds"] == {"rtt_ms": 50.0, "jitter_ms": 10.0, "loss": 0.05}
    assert d["instances"][0]["component"] == "OmnidirectionalCameraRTC"
    json.dumps(d)  # JSON-ready


def wire(**changes: object) -> bytes:
    """A valid wire array with some positions replaced."""
    base: list[object] = [
        FORMAT,
        [100, 4, 2, None, None, None],
        [3, 1, 1, 0, 1, [None, None, 500], ["p", 1, 1, 900]],
        None,
        0,
        ["C"],
        [[0, 1, "1", 2, 0, 0, 0, None, 0, 0, 0]],
        None,
        None,
        None,
    ]
    names = ["fmt", "metrics", "links", "api", "priority", "comps", "instances", "e", "p", "launch"]
    for k, v in changes.items():
        base[names.index(k)] = v
    data: bytes = msgpack.packb(base)
    return data


def test_a_launch_policy_travels_and_the_default_costs_one_byte() -> None:
    policy = LaunchPolicy(("python", "exec"), ("components.*", "mylab.*:Cam*"))
    r = replace(reference_record(peers=3), launch=policy)
    assert decode_record(encode_record(r)).launch == policy
    default = reference_record(peers=3)
    assert decode_record(encode_record(default)).launch == LaunchPolicy()
    assert decode_record(wire()).launch.is_default


def test_wire_helper_is_valid() -> None:
    r = decode_record(wire())
    assert r.instances[0].name == "C1"
    assert r.links.listed == {"p": LinkStats(0.01, 0.01, 0.9)}
    assert r.links.typical == LinkStats(0.01, 0.01, 0.0)


@pytest.mark.parametrize(
    ("changes", "detail"),
    [
        ({"fmt": 1}, "format 1"),
        ({"fmt": True}, "format True"),
        ({"metrics": [1, 2, 3]}, "metrics: expected a list of 6"),
        ({"metrics": [-1, 4, 2, None, None, None]}, "cpu_pct: -1 out of range"),
        ({"metrics": [1.5, 4, 2, None, None, None]}, "cpu_pct: expected an integer"),
        ({"metrics": [1, 4, 2, 1001, None, None]}, "battery_pct: 1001 out of range"),
        ({"metrics": [1, 4, 2, None, None, [1]]}, "metrics.pos: expected a list of 2"),
        ({"links": ["p", 1, 1]}, "links: expected a list of 7"),
        ({"links": [1, 1, 1, 0, 1, [None] * 3, ["p", 1, 1]]}, "expected at most 8 groups of 4"),
        ({"links": [1, 1, 1, 0, 1, [None] * 3, ["p", 1, 1, 1001]]}, "loss: 1001 out of range"),
        ({"links": [1, 1, 1, 0, 2, [None] * 3, ["p", 1, 1, 0] * 2]}, "peer 'p' twice"),
        ({"links": [1, 1, 1, 0, 1, [None] * 3, ["", 1, 1, 0]]}, "links.peer: expected a name"),
        ({"links": [1, 1, 1, 0, 0, [None] * 3, ["p", 1, 1, 0]]}, "links.bad: 0 out of range"),
        ({"links": [1, 1, 1, 0, 0, [None] * 2, []]}, "links.bounds: expected a list of 3"),
        ({"links": [1, -1, 1, 0, 0, [None] * 3, []]}, "rtt_ms: -1 out of range"),
        ({"links": [1, 1, 1, 0, 9, [None] * 3, ["p", 1, 1, 0] * 9]}, "at most 8 groups"),
        ({"api": 5}, "api: expected a name"),
        ({"priority": 2**40}, "priority"),
        ({"instances": [[1, 1, "1", 2, 0, 0, 0, None, 0, 0, 0]]}, "instance.component: 1 out of"),
        (
            {"instances": [[0, 2, "1", 2, 0, 0, 0, None, 0, 0, 0]]},
            "instance.prefix: 2 out of range",
        ),
        (
            {"instances": [[0, 1, "1", 99, 0, 0, 0, None, 0, 0, 0]]},
            "instance.state: 99 out of range",
        ),
        ({"instances": [[0, 0, "", 2, 0, 0, 0, None, 0, 0, 0]]}, "instance.name: expected a name"),
        ({"instances": [[0, 1, "1", 2, 0, 0, 0]]}, "instance: expected a list of 11"),
        ({"instances": [[0, 1, "1", 2, 0, 0, 0, None, 0, 0]]}, "instance: expected a list of 11"),
        ({"instances": [[0, 1, "1", 2, 0, 0, 0, None, 0, -1, 0]]}, "instance.out_lost: -1 out of"),
        (
            {"instances": [[0, 1, "1", 2, 0, 0, 0, None, 0, 0, -1]]},
            "instance.out_refused: -1 out of",
        ),
        ({"metrics": [1, 4, 2, None, None, [10**10, 0]]}, "pos.x: 10000000000 out of range"),
        ({"launch": [["python"]]}, "launch: expected a list of 2"),
        ({"launch": [["python", 5], []]}, "launch.launcher: expected a name"),
        ({"launch": [[], "*"]}, "launch.targets: expected a list"),
    ],
)
def test_malformed_fields_are_named(changes: dict[str, object], detail: str) -> None:
    with pytest.raises(RecordError) as info:
        decode_record(wire(**changes))
    assert info.value.reason == "malformed"
    assert detail in info.value.detail


@pytest.mark.parametrize(
    "data",
    [b"", b"\xc1", b"\x93\x01\x02", msgpack.packb({"a": 1}), msgpack.packb([1] * 9)],
)
def test_garbage_is_malformed(data: bytes) -> None:
    with pytest.raises(RecordError, match=r"^malformed"):
        decode_record(data)


@settings(max_examples=500)
@given(st.binary(max_size=300))
def test_random_bytes_never_raise_anything_but_wire_error(data: bytes) -> None:
    try:
        decode_record(data)
    except RecordError as e:
        reason = e.reason
    else:
        reason = "malformed"
    assert reason == "malformed"


def _mutations(data: bytes) -> st.SearchStrategy[bytes]:
    """Single-byte changes of a valid encoding: close to valid, so they reach the validators."""
    return st.tuples(st.integers(0, len(data) - 1), st.integers(0, 255)).map(
        lambda t: data[: t[0]] + bytes([t[1]]) + data[t[0] + 1 :]
    )


def _decodes_or_fails_cleanly(data: bytes, decode: Callable[[bytes], object]) -> None:
    """`decode(data)` raises only RecordError("malformed"), or returns what encodes back to it."""
    try:
        value = decode(data)
    except RecordError as e:
        assert e.reason == "malformed"  # noqa: PT017 - the reason is the point
        return
    encode = encode_record if isinstance(value, RobotRecord) else encode_vitals
    assert decode(encode(value)) == value  # type: ignore[arg-type]


@settings(max_examples=500)
@given(_mutations(encode_record(big_record())))
def test_mutated_records_decode_or_fail_cleanly(data: bytes) -> None:
    _decodes_or_fails_cleanly(data, decode_record)


@settings(max_examples=300)
@given(_mutations(encode_vitals(vitals_of(big_record()))))
def test_mutated_vitals_decode_or_fail_cleanly(data: bytes) -> None:
    _decodes_or_fails_cleanly(data, decode_vitals)


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


def test_first_format_is_refused_by_name() -> None:
    old = [1, [100, 4, 2, None, None, None], [], None, 0, [], [], 1.0]
    with pytest.raises(RecordError, match="format 1 not understood"):
        decode_record(msgpack.packb(old, use_bin_type=True))


@pytest.mark.parametrize(
    "election",
    [[1, "r"], [-1, "r", True], [1, 5, True], [1, "r", 1]],
)
def test_malformed_election_refused(election: list[object]) -> None:
    wire = msgpack.unpackb(encode_record(big_record()), raw=False)
    wire[7] = election
    with pytest.raises(RecordError, match="malformed"):
        decode_record(msgpack.packb(wire, use_bin_type=True))


_EXTREME = st.one_of(
    st.floats(allow_nan=True, allow_infinity=True),
    st.sampled_from([-1e308, 1e308, -1000.0, 50.0, 1e18]),
)


@settings(max_examples=300, deadline=None)
@given(
    cpu=_EXTREME,
    battery=st.none() | _EXTREME,
    rssi=st.none() | _EXTREME,
    x=_EXTREME,
    y=_EXTREME,
    mem=st.integers(-(2**70), 2**70),
    priority=st.integers(-(2**80), 2**80),
)
def test_any_metrics_encode_and_decode_on_every_peer(  # noqa: PLR0917 - hypothesis' arguments
    cpu: float,
    battery: float | None,
    rssi: float | None,
    x: float,
    y: float,
    mem: int,
    priority: int,
) -> None:
    """Whatever a robot file, the API or a measurement said, the record encodes, and every
    peer decodes it, inside sdrpeer.record.limits' ranges (the live-API bug: rssi=-1000dBm made
    robot-2's record unencodable and its /v1/members answer 500)."""
    m = Metrics(cpu, mem, mem, battery, rssi, (x, y))
    r = decode_record(encode_record(replace(big_record(), metrics=m, priority=priority)))
    assert 0 <= r.metrics.cpu_pct <= 10_000
    assert r.metrics.battery_pct is None or 0 <= r.metrics.battery_pct <= 100
    assert r.metrics.rssi_dbm is None or -150 <= r.metrics.rssi_dbm <= 0
    assert r.metrics.pos is not None
    assert all(abs(c) <= 10_000_000 for c in r.metrics.pos)
    assert -(2**31) <= r.priority < 2**31
    v = decode_vitals(encode_vitals(vitals_of(replace(big_record(), metrics=m))))
    assert v.metrics.rssi_dbm is None or -150 <= v.metrics.rssi_dbm <= 0
