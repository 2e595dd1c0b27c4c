"""Figs. 4-6 from a synthetic timeline shaped like the paper's run: valid, non-trivial PNGs."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.demo.figures import render_figures, summary_table

PNG_MAGIC = b"\x89PNG\r\n\x1a\n"
ROBOTS = ["robot-1", "robot-2", "robot-3"]
PLACED = {
    "robot-1": [
        ("OmnidirectionalCameraRTC-1", "OmnidirectionalCameraRTC"),
        ("AnomalyDetectionRTC-1", "AnomalyDetectionRTC"),
    ],
    "robot-2": [("CameraRTC-1", "CameraRTC"), ("REDControllerRTC-1", "REDControllerRTC")],
    "robot-3": [("PositionEstimationRTC-1", "PositionEstimationRTC")],
}


def paper_like_timeline() -> list[dict[str, Any]]:
    """Deploy at 27 s, all active by 43 s, robot-1's RSSI drops at 107 s, recovery to robot-3."""
    lines: list[dict[str, Any]] = [{"t": 0.0, "kind": "start", "robots": ROBOTS}]
    for k in range(0, 1400):
        t = k * 0.1
        for robot in ROBOTS:
            running = sum(1 for _ in PLACED[robot]) if t >= 28 else 0
            if robot == "robot-1" and t >= 113:
                running = 0
            if robot == "robot-3" and t >= 113:
                running += 2
            if robot == "robot-2" and 60 <= t < 63:
                continue  # the agent did not answer for 3 s: a gap in the curve
            rssi = -55.0 if robot == "robot-1" and t >= 107 else -47.0
            lines.append(
                {
                    "t": round(t, 3),
                    "kind": "sample",
                    "robot": robot,
                    "mem_free": int(2000e6 - 500e6 * running - 80e6),
                    "mem_total": int(2000e6),
                    "cpu": 10.0,
                    "battery": 90.0,
                    "rssi": None if robot == "robot-2" and t < 1 else rssi,
                }
            )
    lines.append({"t": 27.0, "kind": "mark", "what": "allocation", "label": "deploy"})
    lines.append({"t": 107.0, "kind": "mark", "what": "fault", "label": "RSSI drop"})
    lines.append({"t": 113.0, "kind": "mark", "what": "recovery", "label": "robot-1 weak signal"})
    lines.append({"t": 120.0, "kind": "mark", "what": "recovery", "label": "again"})
    lines.append(
        {
            "t": 112.9,
            "kind": "event",
            "robot": "robot-3",
            "event": "recovery.started",
            "detail": {"cause": "communication_failure", "robot": "robot-1"},
        }
    )
    n = 0
    for robot, placed in PLACED.items():
        for instance, component in placed:
            n += 1
            for t, state in ((28.0 + 3 * n, "inactive"), (29.0 + 3 * n, "active")):
                lines.append(_state(t, robot, instance, component, state, role="active"))
    for instance, component in PLACED["robot-1"]:
        lines.append(_state(113.0, "robot-1", instance, component, "gone", role="active"))
        moved = instance.replace("-1", "-3")
        lines.append(_state(114.0, "robot-3", moved, component, "inactive", role="standby"))
        lines.append(_state(116.0, "robot-3", moved, component, "active", role="standby"))
        lines.append(_state(118.0, "robot-3", moved, component, "active", role="active"))
    lines.append(_state(119.0, "robot-3", "X-1", "X", "error", role="active"))
    lines.append(_state(119.5, "robot-3", "X-1", "X", "starting", role="active"))
    lines.append({"t": 60.0, "kind": "agent", "robot": "robot-2", "status": "down", "error": "x"})
    return lines


def _state(t: float, robot: str, instance: str, component: str, state: str, *, role: str):
    return {
        "t": t,
        "kind": "state",
        "robot": robot,
        "instance": instance,
        "component": component,
        "role": role,
        "state": state,
    }


def _assert_png(path: Path) -> None:
    data = path.read_bytes()
    assert data[:8] == PNG_MAGIC, path
    assert len(data) > 10_000, f"{path} is only {len(data)} bytes"


def test_three_pngs_from_a_paper_like_timeline(tmp_path: Path) -> None:
    out = tmp_path / "figs"
    paths = render_figures(
        paper_like_timeline(), out, robots=ROBOTS, rssi_robot="robot-1", thresholds={"rssi": -52.5}
    )
    assert [p.name for p in paths] == ["fig4_free_memory.png", "fig5_rssi.png", "fig6_states.png"]
    for path in paths:
        assert path.parent == out
        _assert_png(path)


def test_an_empty_timeline_still_gives_three_figures(tmp_path: Path) -> None:
    paths = render_figures([], tmp_path, robots=[], thresholds={})
    for path in paths:
        assert path.read_bytes()[:8] == PNG_MAGIC


def test_unknown_threshold_is_refused(tmp_path: Path) -> None:
    with pytest.raises(ValueError, match="rssi_dbm"):
        render_figures([], tmp_path, robots=ROBOTS, thresholds={"rssi_dbm": -50.0})


def test_summary_table_tells_the_story_in_time_order() -> None:
    text = summary_table(paper_like_timeline())
    rows = text.splitlines()
    assert rows[0].split() == ["t", "[s]", "what"]
    assert "mark allocation: deploy" in rows[1]
    assert any("robot-3: recovery.started cause=communication_failure" in r for r in rows)
    assert any("robot-2: agent not answering (x)" in r for r in rows)
    assert not any("sample" in r for r in rows)
    times = [float(r.split()[0]) for r in rows[1:]]
    assert times == sorted(times)


def test_sdrpeer_does_not_import_matplotlib_until_figures_are_drawn() -> None:

    code = (
        "import sys, sdrpeer.cli.main, sdrpeer.demo.timeline, sdrpeer.demo.figures; "
        "print('matplotlib' in sys.modules)"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False"
