"""`sdrpeer system check` and `sdrpeer system schema`."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from sdrpeer.cli.main import main

REPO = Path(__file__).resolve().parent.parent


def test_check_summarises_the_paper_system(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["system", "check", str(REPO / "examples/paper/system.yaml")]) == 0
    out = capsys.readouterr().out
    assert "system 'paper-demo' is valid" in out
    assert "AnomalyDetectionRTC" in out
    assert "mem_free_above_bytes" in out


def test_check_shows_a_composites_context_and_members(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["system", "check", str(REPO / "examples/paper/system-composite.yaml")]) == 0
    out = capsys.readouterr().out
    members = "OmnidirectionalCameraRTC, CameraRTC, AnomalyDetectionRTC"
    assert f"composite, periodic 10 Hz: {members}" in out
    assert "VisionRTC.AnomalyDetectionRTC.alarm->REDControllerRTC.alarm" in out


def test_check_json_round_trips(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["system", "check", "--json", str(REPO / "examples/paper/system.yaml")]) == 0
    doc = json.loads(capsys.readouterr().out)
    assert len(doc["components"]) == 5


def test_check_reports_line_and_exits_2(tmp_path: Path, capsys: pytest.CaptureFixture[str]) -> None:
    bad = tmp_path / "s.yaml"
    bad.write_text(
        "name: s\ncomponents:\n  - name: A\n    target: components.camera:Camera\n"
        "    requires: {memory: -5MB}\n"
    )
    assert main(["system", "check", str(bad)]) == 2
    err = capsys.readouterr().err
    assert f"{bad}:5" in err


def test_schema_is_json(capsys: pytest.CaptureFixture[str]) -> None:
    assert main(["system", "schema"]) == 0
    schema = json.loads(capsys.readouterr().out)
    assert "components" in schema["properties"]
