"""The ROS 2-format recording benchmark, small: a typed Odometry stream of a real agent's host
recorded in ROS 2 format through the agent's tap; every message decodes with rclpy."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.realnet


def test_a_short_ros2_recording_decodes_message_by_message(tmp_path: Path) -> None:
    out = tmp_path / "record.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "bench_record_ros2.py"),
            *("--seconds", "2", "--rate", "50"),
            *("--keep", str(tmp_path / "run"), "--json", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    doc = json.loads(out.read_text())
    assert doc["recorded"] > 50  # about 100 in 2 s
    assert (doc["decoded"], doc["failed"], doc["missing"]) == (doc["recorded"], 0, 0)
    assert doc["stamps_in_order"]
    assert doc["channels"] == ["/Odom/odom (cdr)"]
    assert doc["schemas"] == ["nav_msgs/msg/Odometry (ros2msg)"]
