"""`lab up` with real processes: real agents on loopback, and a stand-in agent for failures."""

from __future__ import annotations

import contextlib
import functools
import os
import signal
import subprocess
import sys
from pathlib import Path
from typing import Any

import psutil
import pytest

from sdrpeer.cli.main import main
from sdrpeer.client import AgentClient
from sdrpeer.errors import ApiError, SdrpeerError
from sdrpeer.lab.files import lab_path, read_lab
from sdrpeer.lab.procs import processes_naming as lab_survivors
from sdrpeer.lab.up import UpOptions, start_lab
from sdrpeer.netlab import net
from tests.realnet import NETNS_ONLY, http
from tests.wait import until

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


# `lab up` dying the moment after it spawned robot-2, before lab.json names it: the write that
# would record robot-2's pid ends the process instead (as a SIGKILL at that moment would).
DIES_UNRECORDED = """
import os, sys
from pathlib import Path
import sdrpeer.lab.up as up

def write_lab(lab_dir, lab):
    if lab.robots[1].pid is not None:
        os._exit(9)
    real_write_lab(lab_dir, lab)

real_write_lab, up.write_lab = up.write_lab, write_lab
up.start_lab(up.UpOptions(2, Path(sys.argv[1]), netns=sys.argv[2] == "netns", timeout=60))
"""


@pytest.mark.parametrize("where", ["loopback", pytest.param("netns", marks=NETNS_ONLY)])
def test_lab_down_stops_an_agent_spawned_but_not_recorded_nor_ready(
    tmp_path: Path, where: str
) -> None:
    lab_dir = tmp_path / "lab"
    env = dict(os.environ, PYTHONPATH=str(FAKE_AGENT), FAKE_AGENT_HANG="robot-2")
    up = subprocess.run(
        [sys.executable, "-c", DIES_UNRECORDED, str(lab_dir), where],
        env=env,
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    try:
        assert up.returncode == 9, up.stderr
        lab = read_lab(lab_dir)
        assert lab is not None
        assert lab.robots[1].pid is None  # robot-2 runs, and lab.json does not know it
        until(
            "robot-2's agent running (still starting)",
            lambda: lab_survivors(lab_dir / "robot-2"),
            bool,
            within=15,
            poll=0.1,
        )
        down = subprocess.run(
            [sys.executable, "-m", "sdrpeer", "lab", "down", "--dir", str(lab_dir)],
            capture_output=True,
            text=True,
            timeout=60,
            check=False,
        )
        assert down.returncode == 0, down.stderr
        assert lab_survivors(lab_dir) == [], down.stdout
    finally:
        for line in lab_survivors(lab_dir):  # never leave one behind, whatever failed
            with contextlib.suppress(ProcessLookupError):
                os.kill(int(line.split(":")[0]), signal.SIGKILL)
        if where == "netns":
            net.destroy(lab_dir)


def launchers_seen(api: str) -> dict[str, Any]:
    """Each member's allowed launchers, as the agent at `api` sees them."""
    members = AgentClient(api).members()
    return {m["name"]: (m.get("launch") or {}).get("launchers") for m in members}


def sdrpeer(*args: str) -> subprocess.CompletedProcess[str]:
    """Run `python -m sdrpeer ARGS` (a detached lab's agents outlive the command)."""
    command = [sys.executable, "-m", "sdrpeer", *args]
    return subprocess.run(command, capture_output=True, text=True, timeout=120, check=False)


FOREIGN = {
    "instances": [
        {
            "name": "Foreign",
            "launcher": "exec",
            "target": [sys.executable, str(Path(__file__).with_name("fake_host.py"))],
        }
    ]
}
"""An instance whose host is no Python SDK host: the control channel spoken by a script."""


def instance_states(api: str) -> dict[str, str]:
    """Instance name -> state on the agent at `api`."""
    return {i["name"]: i["state"] for i in AgentClient(api).get("/v1/instances")}


def test_lab_up_allow_launcher_reaches_every_agent(tmp_path: Path) -> None:
    """`lab up --allow-launcher exec` turns exec on in every agent of the lab (as `sdrpeer agent
    --allow-launcher` does), so a foreign host (tests/fake_host.py speaks the control channel
    without the SDK) runs there; without it they allow python only and refuse it (403); an
    unknown name starts nothing."""
    lab_dir = str(tmp_path / "lab")
    up = ["lab", "up", "--robots", "2", "--detach", "--preset", "fast_test", "--dir", lab_dir]
    refused = sdrpeer(*up, "--allow-launcher", "warp")
    assert refused.returncode == 1
    assert "--allow-launcher 'warp': unknown launcher (known: " in refused.stderr
    assert read_lab(tmp_path / "lab") is None
    for flags, launchers in (([], ["python"]), (["--allow-launcher", "exec"], ["python", "exec"])):
        started = sdrpeer(*up, *flags)
        try:
            assert started.returncode == 0, started.stderr
            lab = read_lab(tmp_path / "lab")
            assert lab is not None
            expected = dict.fromkeys(["robot-1", "robot-2"], launchers)
            until(
                "every robot's launch policy, as robot-1 sees it",
                functools.partial(launchers_seen, str(lab.robots[0].api)),
                expected.__eq__,
                within=15,
                poll=0.1,
                retry=(ApiError,),
            )
            robot = lab.robots[0]
            status, doc = http("POST", f"{robot.api}/v1/instances", FOREIGN, token=robot.token)
            if "exec" not in launchers:
                assert status == 403, doc
                assert "launcher 'exec' is off on this robot" in doc["error"]
                continue
            assert status == 200, doc
            until(
                "the foreign host ACTIVE on robot-1",
                functools.partial(instance_states, str(robot.api)),
                lambda states: states.get("Foreign") == "ACTIVE",
                within=30,
                poll=0.1,
                retry=(ApiError,),
            )
        finally:
            assert sdrpeer("lab", "down", "--dir", lab_dir).returncode == 0
        assert lab_survivors(tmp_path / "lab") == []
