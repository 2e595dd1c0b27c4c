"""`sdrpeer profile`: real hosts measured for 2 s; the rate arithmetic and input sources by hand."""

from __future__ import annotations

import datetime as dt
from pathlib import Path
from typing import Any

import msgpack
import pytest
import yaml

from sdrpeer.cli.main import main
from sdrpeer.profiling.measure import (
    ProfileError,
    ProfileRequest,
    make_source,
    port_rates,
    run_profile,
    write_profile,
)
from sdrpeer.units import parse_size

FRAME = 160 * 120
MIB = 1024 * 1024


def test_profile_a_camera_for_two_seconds(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    out = tmp_path / "profiles" / "camera.yaml"
    argv = ["profile", "components.camera:Camera", "--seconds", "2", "--out", str(out)]
    assert main([*argv, "--param", "rate=10", "--param", "reserve_mb=64"]) == 0
    profile: dict[str, Any] = yaml.safe_load(out.read_text())
    assert capsys.readouterr().out == out.read_text()
    assert profile["component"] == "Camera"
    assert profile["target"] == "components.camera:Camera"
    assert profile["params"]["rate"] == 10.0
    assert profile["params"]["reserve_mb"] == 64
    assert profile["seconds"] == 2.0
    cpu = profile["cpu"]
    assert 0.0 <= cpu["mean_pct"] <= cpu["peak_pct"] <= 100.0 * (profile["host"]["cpus"] or 1)
    assert cpu["samples"] >= 15  # every 0.1 s
    memory = profile["memory"]
    assert 64 * MIB < memory["peak_rss"] < 400 * MIB  # the reserve is resident while ACTIVE
    assert parse_size(memory["peak_rss_human"]) == pytest.approx(memory["peak_rss"], rel=1e-3)
    image = profile["ports"]["image"]
    assert image["direction"] == "out"
    assert image["frames_per_s"] == pytest.approx(10.0, abs=1.0)
    assert image["bytes_per_s"] == pytest.approx(FRAME * 10.0, rel=0.15)
    assert profile["inputs"] == {}
    measured = dt.datetime.fromisoformat(profile["measured_at"])
    assert abs((dt.datetime.now(dt.UTC) - measured).total_seconds()) < 60
    assert {"hostname", "platform", "python", "cpus", "memory_total"} <= profile["host"].keys()


async def test_profile_feeds_in_ports_from_a_recorded_file(tmp_path: Path) -> None:
    recorded = tmp_path / "frames.msgpack"
    frames = make_source("image", "image:80x60")[0]
    recorded.write_bytes(b"".join(msgpack.packb(frames(i, i / 10)) for i in range(1, 41)))
    req = ProfileRequest(
        "components.anomaly_detection:AnomalyDetection",
        seconds=2.0,
        inputs={"image": str(recorded)},
        input_rate=20.0,
    )
    profile = await run_profile(req)
    ports = profile["ports"]
    assert profile["inputs"] == {"image": str(recorded)}
    assert ports["image"]["direction"] == "in"
    assert ports["image"]["frames_per_s"] == pytest.approx(20.0, abs=2.0)
    assert ports["image"]["bytes_per_s"] == pytest.approx(80 * 60 * 20.0, rel=0.15)
    assert ports["alarm"]["frames_per_s"] == pytest.approx(20.0, abs=2.0)
    assert yaml.safe_load(write_profile(profile, None)) == profile


async def test_profile_reports_a_component_that_fails_to_initialize() -> None:
    req = ProfileRequest(
        "components.position_estimation:PositionEstimation", params={"area": "1,2"}
    )
    with pytest.raises(ProfileError, match=r"failed to initialize.*four numbers"):
        await run_profile(req)


async def test_profile_refuses_a_window_shorter_than_a_second() -> None:
    with pytest.raises(ProfileError, match="at least 1 s"):
        await run_profile(ProfileRequest("components.camera:Camera", seconds=0.5))


def test_port_rates_are_counter_differences_over_heartbeat_time() -> None:
    beats = [
        (
            100.0,
            {"out": {"frames_out": 10, "bytes_out": 1000}, "inp": {"frames_in": 3}},
            {"inp": 50},
        ),
        (
            100.5,
            {"out": {"frames_out": 15, "bytes_out": 1500}, "inp": {"frames_in": 5}},
            {"inp": 70},
        ),
        (
            102.0,
            {"out": {"frames_out": 30, "bytes_out": 3000}, "inp": {"frames_in": 11}},
            {"inp": 130},
        ),
    ]
    rates = port_rates(beats, {"out": "out", "inp": "in"})
    assert rates == {
        "out": {"direction": "out", "frames_per_s": 10.0, "bytes_per_s": 1000.0},
        "inp": {"direction": "in", "frames_per_s": 4.0, "bytes_per_s": 40.0},
    }
    with pytest.raises(ProfileError, match="only 1 heartbeat"):
        port_rates(beats[:1], {"out": "out"})


@pytest.mark.parametrize(
    ("port", "spec", "label", "keys"),
    [
        ("image", "", "image", {"w", "h", "seq", "ts", "pixels"}),
        ("frames", "image:32x16", "image:32x16", {"w", "h", "seq", "ts", "pixels"}),
        ("alarm", "", "alarm", {"alarm", "ts", "where", "source"}),
        ("pose", "", "pose", {"x", "y", "theta", "inside", "ts"}),
        ("odometry", "", "odometry", {"x", "y", "theta", "ts"}),
        ("whatever", "", "map", {"seq", "ts", "value"}),
    ],
)
def test_input_sources(port: str, spec: str, label: str, keys: set[str]) -> None:
    source, got = make_source(port, spec)
    assert got == label
    value = source(1, 0.0)
    assert set(value) == keys
    if "pixels" in value:
        assert len(value["pixels"]) == value["w"] * value["h"]


@pytest.mark.parametrize(
    ("spec", "message"),
    [("image:big", "image:WIDTHxHEIGHT"), ("nope", "no such generator"), ("", "no msgpack")],
)
def test_input_source_errors(tmp_path: Path, spec: str, message: str) -> None:
    empty = tmp_path / "empty.msgpack"
    empty.write_bytes(b"")
    with pytest.raises(ProfileError, match=message):
        make_source("p", spec or str(empty))
