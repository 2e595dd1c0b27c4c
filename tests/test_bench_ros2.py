"""The ROS 2 benchmark, small: every phase once with tiny settings (a plain rclpy pair and the
FromRosPose bridge, a failover and a planned move of the ROS 2 node on 3-robot labs, a short
ROS 2-format recording), every figure written."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = [pytest.mark.realnet, pytest.mark.slow]


def test_every_phase_runs_small_and_writes_its_figures(tmp_path: Path) -> None:
    out = tmp_path / "ros2.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "bench_ros2.py"),
            *("--rounds", "1", "--seconds", "1", "--latency-seconds", "1"),
            *("--failovers", "1", "--moves", "1", "--record-seconds", "2"),
            *("--keep", str(tmp_path / "run"), "--json", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=420,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    doc = json.loads(out.read_text())
    t = doc["throughput"]
    assert t["direct_per_s"] > 0
    assert t["bridge_per_s"] > 0
    assert t["message_bytes"] >= 100
    lat = doc["latency"]["rounds"][0]
    assert lat["direct_n"] > 50
    assert lat["bridge_n"] > 50
    assert 0 < doc["latency"]["bridge_p50_ms"] < 1000
    f = doc["failover"]["rounds"][0]
    assert f["to"] != f["victim"]
    assert 0 < f["active_s"] <= f["fresh_pose_s"] < 60
    m = doc["move"]["rounds"][0]
    assert (m["to"] != m["from"], m["odom_lives"]) == (True, 2)
    assert m["silent_s"] > 0
    r = doc["record"]
    assert r["recorded"] > 0
    assert (r["decoded"], r["failed"]) == (r["recorded"], 0)
    assert sorted(r["per_channel"]) == ["/OdomToPose/pose", "/ros2_odom_sub/out"]
    for title in ("throughput:", "latency:", "failover:", "move:", "record:"):
        assert title in done.stdout
