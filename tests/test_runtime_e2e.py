"""End to end: a real agent runs two real hosts (Counter -> Recorder) posted through its API;
both reach ACTIVE, frames flow, the gossip record lists them, the CLI shows them, and the hosts
die with the agent even when it is SIGKILLed."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

import psutil
import pytest

from sdrpeer.cli.main import main as cli_main
from tests.realnet import Agent, RealCluster, http

pytestmark = pytest.mark.realnet

SYSTEM = """\
name: two
components:
  - {name: Pub, target: "tests.components_fixture:Counter", params: {rate: 200}}
  - {name: Rec, target: "tests.components_fixture:Recorder"}
connections:
  - {from: Pub.out, to: Rec.inp, policy: {buffer: 16}}
"""


def instances(agent: Agent) -> dict[str, dict[str, Any]]:
    return {i["name"]: i for i in agent.get("/v1/instances")}


def frames_in(agent: Agent) -> int:
    ports = instances(agent)["Rec"]["ports"]
    return int((ports.get("inp") or {}).get("frames_in", 0))


def test_two_real_instances_connected_reach_active_and_frames_flow(
    cluster: RealCluster, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    agent = cluster.start("robot-1")
    pub = {
        "name": "Pub",
        "target": "tests.components_fixture:Counter",
        "params": {"rate": 200},
        "connections": [{"out": "out", "to": "Rec", "in": "inp"}],
    }
    rec = {"name": "Rec", "target": "tests.components_fixture:Recorder"}
    status, body = http("POST", agent.api + "/v1/instances", {"instances": [pub, rec]}, agent.token)
    assert status == 200, body
    cluster.wait_until(
        lambda: {n: i["state"] for n, i in instances(agent).items()},
        lambda s: s == {"Pub": "ACTIVE", "Rec": "ACTIVE"},
        "both instances ACTIVE",
    )
    first = cluster.wait_until(lambda: frames_in(agent), lambda n: n > 0, "frames at Rec")
    cluster.wait_until(lambda: frames_in(agent), lambda n: n > first, "more frames at Rec")
    listing = instances(agent)
    assert listing["Pub"]["connections"][0]["addr"].startswith("unix://")
    assert listing["Pub"]["start_latency_s"] < 10
    cluster.wait_until(
        lambda: agent.member("robot-1")["instances"],
        lambda items: {i["name"]: i["state"] for i in items} == {"Pub": "active", "Rec": "active"},
        "instances in the gossip record",
    )
    cluster.wait_until(
        lambda: agent.member("robot-1")["instances"],
        lambda items: all(i["rss"] > 1_000_000 for i in items),
        "host RSS in the gossip record",
    )

    assert cli_main(["instances", "--api", agent.api]) == 0
    table = capsys.readouterr().out
    assert table.splitlines()[0].split() == [
        "NAME", "COMPONENT", "STATE", "ROLE", "PID", "CPU", "RSS", "RESTARTS", "SINCE",
    ]  # fmt: skip
    assert "Counter" in table
    assert "Recorder" in table

    # the same system from a file replaces the desired set on the named robot
    system = tmp_path / "system.yaml"
    system.write_text(SYSTEM)
    argv = ["run", str(system), "--robot", "robot-1", "--api", agent.api, f"--token={agent.token}"]
    assert cli_main(argv) == 0
    cluster.wait_until(
        lambda: instances(agent)["Pub"]["connections"],
        lambda c: [(x["id"], x["policy"]) for x in c] == [("Pub.out->Rec.inp", {"buffer": 16})],
        "the connection from the system file",
    )

    # hosts die with the agent, even on SIGKILL (parent-death signal)
    pids = [i["pid"] for i in instances(agent).values()]
    assert all(psutil.pid_exists(p) for p in pids)
    os.kill(agent.pid, signal.SIGKILL)
    agent.stopped = True
    agent.proc.wait(timeout=5)
    procs = [psutil.Process(p) for p in pids if psutil.pid_exists(p)]
    _, alive = psutil.wait_procs(procs, timeout=5)
    assert alive == [], f"hosts outlived the agent: {alive}"


def test_agent_stop_stops_hosts_gracefully(cluster: RealCluster) -> None:
    agent = cluster.start("robot-1")
    spec = {"name": "Rec", "target": "tests.components_fixture:Recorder"}
    status, body = http("POST", agent.api + "/v1/instances", {"instances": [spec]}, agent.token)
    assert status == 200, body
    pid = cluster.wait_until(
        lambda: instances(agent)["Rec"],
        lambda i: i["state"] == "ACTIVE",
        "Rec ACTIVE",
    )["pid"]
    assert cluster.terminate(agent, timeout=10) == 0
    assert not psutil.pid_exists(pid) or psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    log = agent.log.read_text()
    assert "SIGTERM" not in log  # the host left on the exit command
    assert "SIGKILL" not in log
