"""`lab up` with real processes: real agents on loopback, and a stand-in agent for failures."""

from __future__ import annotations

from pathlib import Path

import psutil
import pytest

from sdrpeer.cli.main import main
from sdrpeer.client import AgentClient
from sdrpeer.errors import SdrpeerError
from sdrpeer.lab.files import lab_path, read_lab
from sdrpeer.lab.up import UpOptions, start_lab

FAKE_AGENT = Path(__file__).parent / "fake_agent"

pytestmark = pytest.mark.realnet


def test_lab_of_real_agents_converges_and_stops(
    tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    running = start_lab(UpOptions(robots=3, lab_dir=tmp_path), say=lambda _: None)
    try:
        lab = read_lab(tmp_path)
        assert lab is not None
        assert [r.name for r in lab.robots] == ["robot-1", "robot-2", "robot-3"]
        assert all(r.api and r.gossip and r.pid for r in lab.robots)
        members = AgentClient(str(lab.robots[2].api)).members()
        assert {m["name"]: m["state"] for m in members} == {
            "robot-1": "alive",
            "robot-2": "alive",
            "robot-3": "alive",
        }
        assert main(["robot", "set", "robot-2", "battery=30%", "--lab-dir", str(tmp_path)]) == 0
        assert "robot-2: set battery=30%" in capsys.readouterr().out
        assert main(["robot", "set", "robot-2", "battery=300%", "--lab-dir", str(tmp_path)]) == 1
        assert "answered 400" in capsys.readouterr().err
        pids = [r.pid for r in lab.robots]
    finally:
        report = running.stop()
    assert report == [f"robot-{i}: pid {pid} stopped" for i, pid in enumerate(pids, 1)]
    assert not lab_path(tmp_path).exists()
    assert not any(psutil.pid_exists(pid) for pid in pids if pid)


def test_agent_that_exits_is_reported_with_its_log(
    tmp_path: Path, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("PYTHONPATH", str(FAKE_AGENT))
    monkeypatch.setenv("FAKE_AGENT_FAIL", "robot-2")
    with pytest.raises(SdrpeerError) as info:
        start_lab(UpOptions(robots=2, lab_dir=tmp_path), say=lambda _: None)
    log = tmp_path.resolve() / "robot-2" / "agent.log"
    assert str(info.value) == (
        f"robot-2: agent exited with code 3 while starting; last lines of {log}:\n"
        "    | robot-2: failing on purpose"
    )
    assert not lab_path(tmp_path).exists()  # robot-1 was stopped again


def test_start_timeout_names_the_robot(tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setenv("PYTHONPATH", str(FAKE_AGENT))
    with pytest.raises(SdrpeerError, match=r"^robot-1: no .*agent\.json within the start timeout"):
        start_lab(UpOptions(robots=2, lab_dir=tmp_path, timeout=0.0), say=lambda _: None)
    assert not lab_path(tmp_path).exists()


def test_lab_up_refuses_a_running_lab(tmp_path: Path) -> None:
    running = start_lab(UpOptions(robots=1, lab_dir=tmp_path), say=lambda _: None)
    try:
        with pytest.raises(SdrpeerError, match=r"a lab is already running .* \(robot-1\)"):
            start_lab(UpOptions(robots=1, lab_dir=tmp_path), say=lambda _: None)
    finally:
        running.stop()
