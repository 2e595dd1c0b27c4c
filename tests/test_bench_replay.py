"""The replay benchmark, small: 10 datagrams captured on their way to robot-2 of a real lab,
replayed to every robot, then 10 more to robot-2's new life after a restart; every figure
written, none accepted by another robot or by the new life."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import pytest

from tests.capture import ROOT_ONLY

ROOT = Path(__file__).resolve().parent.parent

pytestmark = [pytest.mark.realnet, ROOT_ONLY]


def test_a_small_replay_run_refuses_every_datagram_at_another_robot(tmp_path: Path) -> None:
    out = tmp_path / "replay.json"
    done = subprocess.run(
        [
            sys.executable,
            str(ROOT / "tools" / "bench_replay.py"),
            *("--datagrams", "10", "--preset", "fast_test", "--no-stale", "--json", str(out)),
        ],
        capture_output=True,
        text=True,
        timeout=180,
        check=False,
    )
    assert done.returncode == 0, done.stdout + done.stderr
    doc = json.loads(out.read_text())
    assert doc["accepted_by_other_robots"] == 0
    replay = doc["replay"]
    assert sorted(replay) == ["robot-1", "robot-2", "robot-3"]
    for name, figures in replay.items():
        reason = "replayed" if name == "robot-2" else "wrong_receiver"
        assert figures["replayed"] == 10, name
        assert figures["accepted"] == 0, (name, figures)
        assert figures["refused"] == {reason: 10}, (name, figures)
        assert figures["core"] == {"misdirected": 0, "self_loop": 0}, (name, figures)
    assert "stale" not in doc
    restart = doc["restart"]
    assert (restart["replayed"], restart["accepted"]) == (10, 0), restart
    assert restart["refused"] == {"stale": 10}, restart
    assert "accepted by robots other than robot-2: 0" in done.stdout
