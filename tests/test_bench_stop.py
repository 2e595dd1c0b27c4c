"""The stop benchmark: one lab of real agents stopped together, every agent timed and counted."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.realnet


def test_one_lab_stopped_together_writes_every_figure(tmp_path: Path) -> None:
    out = tmp_path / "stop.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "bench_stop.py"),
            "--labs",
            "1",
            "--limit",
            "10",
            "--json",
            str(out),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    doc = json.loads(out.read_text())
    assert doc["agents"] == 3
    assert doc["not_exited_within_limit"] == 0, doc["late"]
    assert doc["overdue_exit_1"] == 0  # an idle agent stops well inside its own deadline
    assert 0 < doc["median_s"] <= doc["max_s"] < 10
