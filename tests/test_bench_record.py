"""The recording benchmark, small: a real camera recorded to MCAP through a real agent, read
back, replayed into a consumer; every figure written, every frame identical."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parent.parent

pytestmark = pytest.mark.realnet


def test_a_small_recording_replays_identical_and_writes_every_figure(tmp_path: Path) -> None:
    out = tmp_path / "record.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "bench_record.py"),
            *("--frames", "20", "--rate", "50", "--size", "32x24"),
            *("--keep", str(tmp_path / "run"), "--json", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    doc = json.loads(out.read_text())
    counts = [doc[k] for k in ("frames_recorded", "frames_read", "frames_replayed")]
    assert counts == [20, 20, 20]
    assert (doc["frames_identical"], doc["identical_in_order"]) == (20, True)
    assert doc["frames_missing_in_recording"] == 0
    assert (doc["topics"], doc["schemas"]) == (["Cam.image"], ["sdrpeer/any (jsonschema)"])
    assert doc["record_fps"] > 0
    assert doc["record_mb_s"] > 0
