"""`sdrpeer demo --fast` end to end (both runs), and its timeline checked."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sdrpeer.cli.main import main
from sdrpeer.demo.query import Timeline
from sdrpeer.demo.timeline import load_timeline

pytestmark = [pytest.mark.realnet, pytest.mark.slow]

FIG3 = {
    "OmnidirectionalCameraRTC": "robot-1",
    "AnomalyDetectionRTC": "robot-1",
    "CameraRTC": "robot-2",
    "REDControllerRTC": "robot-2",
    "PositionEstimationRTC": "robot-3",
}


def test_fast_demo_reproduces_the_papers_experiment(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    assert main(["demo", "--fast", "--out", str(tmp_path)]) == 0
    out = capsys.readouterr().out
    assert "condition met -> moved ACTIVE" in out
    summary = json.loads((tmp_path / "summary.json").read_text())
    assert len(summary) == 2
    for name, run in summary.items():
        assert run["placement"] == FIG3, name  # memory splits the five as in Fig. 3
        assert "robot-1" not in run["placement_after"].values()
        assert run["allocator_after"] != "robot-1"
        # the 2 s rule fires after 2 s of weak signal, not before
        assert run["fault_to_condition_s"] >= 1.9
        assert run["condition_to_active_s"] is not None
    first, second = summary.values()
    assert first["allocator_first"] == "robot-2"
    assert second["allocator_first"] == "robot-1"  # the allocator moved off the failing robot

    run_dir = tmp_path / "run-second"
    for fig in ("fig4_free_memory.png", "fig5_rssi.png", "fig6_states.png"):
        assert (run_dir / fig).read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    lines = load_timeline(run_dir / "timeline.jsonl")
    tl = Timeline(lines)
    assert {ln["robot"] for ln in tl.of("sample")} == {"robot-1", "robot-2", "robot-3"}
    drop = tl.first("event", event="scenario", robot="robot-1")  # robot-1's own clock
    allocator = summary["second (alloc robot-1)"]["allocator_after"]
    condition = tl.first("event", event="recovery.condition", robot=allocator)
    move = tl.first("event", event="recovery.move")
    assert drop is not None
    assert condition is not None
    assert move is not None
    assert drop["t"] <= condition["t"] <= move["t"]
    assert tl.rssi_crossing("robot-1", -52.5) is not None  # Fig. 5's drop is in the samples
    assert tl.when_all_active(list(FIG3), after=move["t"], exclude={"robot-1"}) is not None
    assert tl.marks("allocation")
    assert tl.marks("recovery")
