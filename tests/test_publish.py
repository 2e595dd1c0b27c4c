"""The publishing deadband."""

from __future__ import annotations

from dataclasses import replace

import pytest

from sdrpeer.monitor.publish import worth_publishing
from sdrpeer.record import InstanceInfo, LinkStats, Metrics, RobotRecord

GB = 1 << 30
BASE = RobotRecord(
    Metrics(10.0, 4 * GB, 3 * GB, 80.0, -47.0, (1.0, 2.0)),
    {"robot-2": LinkStats(0.5, 0.1, 0.0)},
    "http://127.0.0.1:1",
    0,
    (),
    1000.0,
)


def metrics(**changes: object) -> RobotRecord:
    return replace(BASE, metrics=replace(BASE.metrics, **changes))  # type: ignore[arg-type]


def link(**changes: object) -> RobotRecord:
    return replace(BASE, links={"robot-2": replace(BASE.links["robot-2"], **changes)})  # type: ignore[arg-type]


@pytest.mark.parametrize(
    ("new", "expected"),
    [
        (replace(BASE, ts=2000.0), False),  # only the timestamp
        (metrics(cpu_pct=14.9), False),
        (metrics(cpu_pct=15.0), True),
        (metrics(mem_free=3 * GB - 20 * 2**20), False),  # 20 MiB < 1 % of 4 GB
        (metrics(mem_free=3 * GB - 50 * 2**20), True),
        (metrics(battery_pct=79.5), False),
        (metrics(battery_pct=79.0), True),
        (metrics(rssi_dbm=-48.9), False),
        (metrics(rssi_dbm=-55.0), True),
        (metrics(rssi_dbm=None), True),
        (metrics(pos=(1.0, 2.5)), True),
        (link(rtt_ms=1.4), False),  # 0.9 ms < 1 ms
        (link(rtt_ms=1.6), True),
        (link(loss=0.04), False),
        (link(loss=0.3), True),
        (link(jitter_ms=0.9), False),
        (replace(BASE, links={}), True),
        (replace(BASE, priority=5), True),
    ],
)
def test_deadband(new: RobotRecord, expected: bool) -> None:
    assert worth_publishing(BASE, new) is expected


def test_first_record_is_always_published() -> None:
    assert worth_publishing(None, BASE) is True


def test_noise_around_a_value_does_not_flap() -> None:
    # RTT hovering around 0.5 ms: bucketed rounding would flip 0 <-> 1 ms every sample.
    assert not any(worth_publishing(BASE, link(rtt_ms=r)) for r in (0.45, 0.55, 0.49, 0.51, 0.6))


def test_instances_compare_by_identity_and_state_with_bands_for_load() -> None:
    cam = InstanceInfo("CameraRTC2", "Camera", "active", "active", 12.0, 100 << 20)
    last = replace(BASE, instances=(cam,))
    assert not worth_publishing(last, replace(BASE, instances=(replace(cam, cpu_pct=14.0),)))
    assert not worth_publishing(last, replace(BASE, instances=(replace(cam, rss=110 << 20),)))
    assert worth_publishing(last, replace(BASE, instances=(replace(cam, cpu_pct=20.0),)))
    assert worth_publishing(last, replace(BASE, instances=(replace(cam, rss=600 << 20),)))
    assert worth_publishing(last, replace(BASE, instances=(replace(cam, state="error"),)))
    assert worth_publishing(last, replace(BASE, instances=()))
