"""The lab-down benchmark: labs whose `lab up` is killed at random moments, taken down, and
nothing of them left running."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.realnet


def test_two_killed_labs_are_taken_down_and_every_figure_written(tmp_path: Path) -> None:
    out = tmp_path / "down.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "bench_lab_down.py"),
            "--runs",
            "2",
            "--robots",
            "2",
            "--kill-within",
            "2",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=300,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    doc = json.loads(out.read_text())
    assert (doc["runs"], doc["robots"], doc["survivors"]) == (2, 2, 0)
    assert [sorted(r) for r in doc["per_run"]] == [
        ["delay_s", "down_rc", "down_s", "recorded", "survivors", "unrecorded"]
    ] * 2
    assert all(0 <= r["delay_s"] <= 2 and r["survivors"] == [] for r in doc["per_run"])
    assert 0 < doc["down_median_s"] <= doc["down_max_s"]
