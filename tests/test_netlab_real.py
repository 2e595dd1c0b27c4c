"""The network-namespace lab for real (root): three agents each in its own namespace, a partition
that kills and a heal that revives, packet loss the agents measure, a shaped link, and `lab down`
leaving nothing behind (no namespace, link or process) — also when the lab process itself died."""

from __future__ import annotations

import subprocess
import sys
from collections.abc import Iterator
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import pytest

from sdrpeer.client import AgentClient
from sdrpeer.errors import ApiError
from sdrpeer.lab.procs import processes_naming as lab_survivors
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.netlab import net
from tests.realnet import NETNS_ONLY
from tests.wait import until

pytestmark = [pytest.mark.realnet, NETNS_ONLY]
WITHIN, POLL = 20.0, 0.2
NOT_YET = (ApiError,)
"""An agent that is still starting answers with an API error: not yet."""


def states(lab: RunningLab, robot: str) -> dict[str, str]:
    api = lab.lab.robot(robot).api  # type: ignore[union-attr]
    return {m["name"]: m["state"] for m in AgentClient(str(api), timeout=2).members()}


def sdrpeer(*args: str) -> str:
    done = subprocess.run(
        [sys.executable, "-m", "sdrpeer", *args],
        capture_output=True,
        text=True,
        timeout=60,
        check=False,
    )
    assert done.returncode == 0, done.stderr
    return done.stdout


def output(argv: list[str]) -> str:
    """What a command printed (whatever its exit code)."""
    return subprocess.run(argv, capture_output=True, text=True, timeout=15, check=False).stdout


def text_of(path: Path) -> str:
    return path.read_text() if path.exists() else ""


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[RunningLab]:
    running = start_lab(
        UpOptions(3, tmp_path / "lab", preset="fast_test", netns=True, timeout=30),
        say=lambda _: None,
    )
    try:
        yield running
    finally:
        running.stop(grace=3)
        assert net.load(tmp_path / "lab") is None
        assert lab_survivors(tmp_path / "lab") == []


def test_robots_live_in_their_namespaces_and_faults_act_on_the_network(
    lab: RunningLab, tmp_path: Path
) -> None:
    plan = lab.net
    assert plan is not None
    lab_dir = str(tmp_path / "lab")
    for robot in lab.lab.robots:
        assert robot.api == f"http://{plan.address(robot.name)}:8080"
        assert robot.gossip == f"{plan.address(robot.name)}:7946"
    assert states(lab, "robot-1") == dict.fromkeys(plan.names(), "alive")

    sdrpeer("lab", "partition", "robot-1", "/", "robot-2,robot-3", "--dir", lab_dir)
    until(
        "cut",
        lambda: states(lab, "robot-1"),
        lambda s: s["robot-2"] == s["robot-3"] == "dead",
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    until(
        "cut, other side",
        lambda: states(lab, "robot-2"),
        lambda s: s["robot-1"] == "dead",
        within=WITHIN,
        poll=POLL,
        retry=NOT_YET,
    )
    assert states(lab, "robot-2")["robot-3"] == "alive"  # inside a side nothing changes

    sdrpeer("lab", "heal", "--dir", lab_dir)
    for name in plan.names():
        until(
            f"healed, as {name} sees it",
            lambda name=name: states(lab, name),  # type: ignore[misc]
            lambda s: set(s.values()) == {"alive"},
            within=WITHIN,
            poll=POLL,
            retry=NOT_YET,
        )

    out = sdrpeer("lab", "fault", "robot-2", "loss", "60%", "--dir", lab_dir)
    assert "60% of arriving packets dropped" in out
    rules = output(plan.in_ns("robot-2", "iptables", "-S", "SDRPEER-FAULT"))
    assert "--probability 0.6" in rules

    def loss_seen() -> float:
        api = lab.lab.robot("robot-1").api  # type: ignore[union-attr]
        members = {m["name"]: m for m in AgentClient(str(api), timeout=2).members()}
        return float(members["robot-1"]["links"].get("robot-2", {}).get("loss") or 0)

    until(
        "robot-1 measuring loss to robot-2",
        loss_seen,
        lambda x: x >= 0.2,
        within=30,
        poll=POLL,
        retry=NOT_YET,
    )
    sdrpeer("lab", "fault", "robot-2", "bandwidth", "1mbit", "--dir", lab_dir)
    qdisc = output(["tc", "qdisc", "show", "dev", plan.veth("robot-2")])
    assert "tbf" in qdisc
    assert "rate 1Mbit" in qdisc
    sdrpeer("lab", "fault", "robot-2", "clear", "--dir", lab_dir)
    rules = output(plan.in_ns("robot-2", "iptables", "-S", "SDRPEER-FAULT"))
    assert "DROP" not in rules
    assert "tbf" not in output(["tc", "qdisc", "show", "dev", plan.veth("robot-2")])


def test_lab_down_removes_everything_after_the_lab_process_died(tmp_path: Path) -> None:
    lab_dir = tmp_path / "lab"
    up = subprocess.Popen(  # a foreground lab, killed as a crash would
        [sys.executable, "-m", "sdrpeer", "lab", "up", "--netns", "--robots", "2",
         "--dir", str(lab_dir), "--seconds", "60"],
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )  # fmt: skip
    try:
        until(
            "netns.json",
            lambda: net.load(lab_dir),
            lambda p: p is not None,
            within=WITHIN,
            poll=POLL,
            retry=NOT_YET,
        )
        until(
            "agents",
            lambda: text_of(lab_dir / "lab.json"),
            lambda t: '"api": "http' in t,
            within=WITHIN,
            poll=POLL,
            retry=NOT_YET,
        )
    except BaseException:
        up.kill()
        net.destroy(lab_dir)  # a failure here must not leave namespaces behind either
        raise
    up.kill()
    up.wait(10)
    plan = net.load(lab_dir)
    assert plan is not None
    namespaces = output(["ip", "netns", "list"])
    assert plan.namespace("robot-1") in namespaces  # the crash left the network behind
    out = sdrpeer("lab", "down", "--dir", str(lab_dir))
    assert "network removed" in out
    namespaces = output(["ip", "netns", "list"])
    assert f"sdrlab{plan.lab_id}-" not in namespaces
    links = output(["ip", "link", "show"])
    assert plan.bridge not in links
    assert plan.veth("robot-1") not in links
    assert lab_survivors(lab_dir) == [], out  # and no process: every agent, however far it got


def test_labs_built_at_once_claim_different_ids(tmp_path: Path) -> None:
    """Four networks built side by side (two `lab up --netns` at once, or tests in parallel):
    each claims its own id by making its bridge, and each is whole."""
    dirs = [tmp_path / f"lab{k}" for k in range(4)]
    with ThreadPoolExecutor(len(dirs)) as pool:
        plans = list(pool.map(lambda d: net.create(d, 2), dirs))
    try:
        assert len({p.lab_id for p in plans}) == len(plans)
        for plan in plans:
            for robot in plan.names():
                shown = output(["ip", "-n", plan.namespace(robot), "-o", "addr", "show", "eth0"])
                assert f"{plan.address(robot)}/24" in shown
    finally:
        left = [x for d in dirs for x in net.destroy(d)]
    assert left == []
