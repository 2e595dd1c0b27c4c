"""Traps: hysteresis (one trap per crossing), default rules, and the validated wire form."""

from __future__ import annotations

import msgpack
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from sdrpeer.errors import RecordError
from sdrpeer.monitor.traps import (
    Trap,
    TrapDetector,
    TrapRule,
    decode_trap,
    default_rules,
    encode_trap,
)
from sdrpeer.record.robot import Metrics

MB = 1_000_000


def metrics(
    cpu: float = 10.0,
    free: int = 2000 * MB,
    battery: float | None = 80.0,
    rssi: float | None = -45.0,
) -> Metrics:
    return Metrics(cpu, 4000 * MB, free, battery, rssi, (0.0, 0.0))


def test_rssi_hysteresis_fires_once_per_crossing() -> None:
    d = TrapDetector([TrapRule("rssi_dbm", "<=", -52.5, -50.0)])
    seq = [-47.0, -52.4, -52.5, -55.0, -51.0, -53.0, -50.0, -50.1, -49.9, -49.0, -53.0]
    fired = [
        (t, [(x.state, x.value) for x in d.feed(metrics(rssi=v), float(t))])
        for t, v in enumerate(seq)
    ]
    assert [(t, f) for t, f in fired if f] == [
        (2, [("raised", -52.5)]),  # "-52.5 dBm or less"
        (8, [("cleared", -49.9)]),  # only once above -50; -51, -53, -50 stay raised
        (10, [("raised", -53.0)]),
    ]


def test_memory_and_cpu_defaults() -> None:
    d = TrapDetector()
    assert d.feed(metrics(), 0.0) == []
    assert d.feed(metrics(free=200 * MB), 1.0) == [
        Trap("mem_free", 200_000_000.0, 200_000_000, "raised", 1.0, broadcast=False)
    ]
    assert d.feed(metrics(free=240 * MB), 2.0) == []
    assert d.feed(metrics(free=250 * MB), 3.0) == []  # at 250MB still "250MB or less"
    assert [t.state for t in d.feed(metrics(free=251 * MB), 4.0)] == ["cleared"]
    assert [(t.metric, t.state) for t in d.feed(metrics(cpu=95.0), 5.0)] == [("cpu_pct", "raised")]
    assert d.feed(metrics(cpu=85.0), 6.0) == []
    assert [t.state for t in d.feed(metrics(cpu=79.0), 7.0)] == ["cleared"]


def test_battery_default_and_missing_metrics() -> None:
    d = TrapDetector()
    assert [t.metric for t in d.feed(metrics(battery=19.9), 0.0)] == ["battery_pct"]
    assert [r.metric for r in d.raised()] == ["battery_pct"]
    assert d.feed(metrics(battery=None, rssi=None), 1.0) == []  # unknown: no change
    assert d.feed(metrics(battery=24.0), 2.0) == []
    assert [t.state for t in d.feed(metrics(battery=25.0), 3.0)] == ["cleared"]
    assert d.raised() == []


def test_first_sample_already_bad_raises() -> None:
    d = TrapDetector()
    traps = d.feed(metrics(rssi=-60.0, free=100 * MB), 0.0)
    assert sorted(t.metric for t in traps) == ["mem_free", "rssi_dbm"]


def test_default_rules_match_the_paper() -> None:
    rules = {r.metric: r for r in default_rules()}
    assert rules["mem_free"] == TrapRule("mem_free", "<=", 200 * MB, 250 * MB, broadcast=False)
    assert rules["rssi_dbm"] == TrapRule("rssi_dbm", "<=", -52.5, -50.0)
    assert rules["battery_pct"] == TrapRule("battery_pct", "<", 20.0, 25.0)
    assert rules["cpu_pct"] == TrapRule("cpu_pct", ">", 90.0, 80.0, broadcast=False)
    # Other robots act on battery and RSSI; memory and CPU are the robot's own agent's.
    assert [r.metric for r in default_rules() if r.broadcast] == ["battery_pct", "rssi_dbm"]


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (("jitter", "<", 1.0, 1.0), "unknown metric 'jitter'"),
        (("cpu_pct", "=", 1.0, 1.0), "op must be one of <, <=, >, >="),
        (("rssi_dbm", "<", -52.5, -60.0), "rssi_dbm: clear level must be at or above"),
        (("cpu_pct", ">", 90.0, 95.0), "cpu_pct: clear level must be at or below"),
    ],
)
def test_bad_rules(args: tuple[str, str, float, float], message: str) -> None:
    with pytest.raises(ValueError, match=message):
        TrapRule(*args)


def test_trap_round_trip() -> None:
    t = Trap("rssi_dbm", -55.0, -52.5, "raised", 107.25)
    data = encode_trap(t)
    assert decode_trap(data) == t
    assert len(data) < 40
    c = Trap("mem_free", 300_000_000.0, 200_000_000.0, "cleared", 1.0)
    assert decode_trap(encode_trap(c)) == c


@pytest.mark.parametrize(
    ("wire", "detail"),
    [
        ([2, "cpu_pct", 1.0, 1.0, 0, 1.0], "format 2"),
        ([1, "cpu_pct", 1.0, 1.0, 0], "expected a list of 6"),
        ([1, "CPU PCT", 1.0, 1.0, 0, 1.0], "metric"),
        ([1, "cpu_pct", "x", 1.0, 0, 1.0], "value"),
        ([1, "cpu_pct", 1.0, float("inf"), 0, 1.0], "threshold"),
        ([1, "cpu_pct", 1.0, 1.0, 2, 1.0], "state"),
        ([1, "cpu_pct", 1.0, 1.0, 0.0, 1.0], "state"),
        ([1, "cpu_pct", 1.0, 1.0, True, 1.0], "state"),
        ([1, "cpu_pct", 1.0, 1.0, 0, None], "ts"),
        ({"a": 1}, "expected a list of 6"),
    ],
)
def test_malformed_traps(wire: object, detail: str) -> None:
    with pytest.raises(RecordError) as info:
        decode_trap(msgpack.packb(wire))
    assert info.value.reason == "malformed"
    assert detail in info.value.detail


@settings(max_examples=300)
@given(st.binary(max_size=64))
def test_random_bytes_only_wire_error(data: bytes) -> None:
    try:
        decode_trap(data)
    except RecordError as e:
        reason = e.reason
    else:
        reason = "malformed"
    assert reason == "malformed"
