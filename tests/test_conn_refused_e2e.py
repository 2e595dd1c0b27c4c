"""End to end: a real agent runs a sender whose receiver refuses its stream (it names an
in-port the receiver does not have); the refusal's reason reaches the agent's event log
(`conn.refused`), the instance's status (under its connection), `sdrpeer instances` and the
robot's gossip record (`out_refused`, which `sdrpeer status` shows) (issue 30 item 5). The
sender's host then exits cleanly when the agent stops it."""

from __future__ import annotations

from typing import Any

import pytest

from sdrpeer.cli.main import main as cli_main
from tests.realnet import Agent, RealCluster, http

pytestmark = pytest.mark.realnet


def instances(agent: Agent) -> dict[str, dict[str, Any]]:
    return {i["name"]: i for i in agent.get("/v1/instances")}


def refused_events(agent: Agent) -> list[dict[str, Any]]:
    return [e for e in agent.events() if e["kind"] == "conn.refused"]


def test_a_refused_connection_says_why_in_events_status_and_the_cli(
    cluster: RealCluster, capsys: pytest.CaptureFixture[str]
) -> None:
    agent = cluster.start("robot-1")
    pub = {
        "name": "Pub",
        "target": "components.ledger:Sequencer",
        "connections": [{"out": "out", "to": "Rec", "in": "nope", "policy": {"full": "block"}}],
    }
    rec = {"name": "Rec", "target": "tests.components_fixture:Recorder"}
    status, body = http("POST", agent.api + "/v1/instances", {"instances": [pub, rec]}, agent.token)
    assert status == 200, body
    (event,) = cluster.wait_until(lambda: refused_events(agent), bool, "a conn.refused event")
    detail = event["detail"]
    assert event["robot"] == "robot-1"
    assert detail["instance"] == "Pub"
    assert detail["sender"] == "Pub.out"
    assert detail["port"] == "nope"
    assert detail["error"] == "unknown in-port 'nope'"
    conns = cluster.wait_until(
        lambda: instances(agent)["Pub"]["connections"],
        lambda cs: bool(cs) and cs[0].get("refused") is not None,
        "the refusal in Pub's status",
    )
    assert conns[0]["refused"]["error"] == "unknown in-port 'nope'"
    assert conns[0]["refused"]["count"] >= 1
    assert cli_main(["instances", "--api", agent.api]) == 0
    out = capsys.readouterr().out
    assert "Pub: connection" in out
    assert "refused by its receiver" in out
    assert "unknown in-port 'nope'" in out
    # fleet-wide: the robot's gossip record counts Pub's connections refused now (what
    # `sdrpeer status` shows under its connections)
    cluster.wait_until(
        lambda: {i["name"]: i.get("out_refused") for i in agent.member("robot-1")["instances"]},
        lambda counts: counts.get("Pub") == 1 and counts.get("Rec") == 0,
        "out_refused in the gossip record",
    )
    assert len(refused_events(agent)) == 1  # rate-limited: the sender keeps redialing
    # the sender's component waits in send() (full: block, nothing drains): removing it stops
    # its host at once and cleanly, not after the finalize deadline
    status, body = http("DELETE", agent.api + "/v1/instances/Pub", None, agent.token)
    assert status == 200, body
    cluster.wait_until(lambda: set(instances(agent)), lambda n: n == {"Rec"}, "Pub gone")
    assert "finalize did not finish" not in (agent.data_dir / "instances" / "Pub.log").read_text(
        errors="replace"
    )
