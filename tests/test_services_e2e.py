"""A service binding on real agents: the caller keeps calling while its provider moves to
another robot, and its calls succeed again once the agent has re-pointed the binding."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.realnet import Agent, RealCluster, http
from tests.test_recovery_e2e import deploy, status

pytestmark = pytest.mark.realnet

SYSTEM = """\
name: planning
components:
  - name: Planner
    target: components.planner:PathPlanner
    prefer: [robot-1]
    standby: {other_robots: 1, mode: hot}
  - name: Caller
    target: components.planner:PlanCaller
    params: {rate: 10}
    pin: robot-2
connections:
  - {from: Caller.planner, to: Planner.planner}
recovery:
  rules:
    - cause: communication_failure
      when: rssi <= -52.5dBm
      for: 1s
      clear: -50dBm
      actions: [standby_other_robot, launch_other_robot]
"""


def caller_row(agent: Agent) -> dict[str, Any]:
    """The caller's instance row on robot-2 (its ports' counters and its connections)."""
    rows = {r["name"]: r for r in agent.get("/v1/instances")}
    row: dict[str, Any] = rows.get("Caller", {})
    return row


def paths(row: dict[str, Any]) -> int:
    """Paths the caller received (each one written on its `path` port)."""
    return int(row.get("ports", {}).get("path", {}).get("frames_out", 0))


def planner_on(robot: str) -> Any:
    def ok(doc: dict[str, Any]) -> bool:
        rows = {c["component"]: c for c in doc["components"]}
        planner = rows.get("Planner", {})
        return bool(planner.get("robot") == robot and planner.get("state") == "active")

    return ok


def test_calls_succeed_again_after_the_provider_moves(cluster: RealCluster, tmp_path: Path) -> None:
    one, two = cluster.start_many(2)
    path = tmp_path / "system.yaml"
    path.write_text(SYSTEM)
    deploy(cluster, one, path)
    cluster.wait_until(lambda: status(two), planner_on("robot-1"), "the planner on robot-1")
    row = cluster.wait_until(lambda: caller_row(two), lambda r: paths(r) >= 10, "10 paths")
    before = row["connections"][0]
    assert before["in"] == "planner"
    assert row["services"]["planner"]["role"] == "requires"  # from the host's hello
    code, _ = http("POST", one.api + "/v1/robot", {"rssi": "-56dBm"}, one.token)
    assert code == 200
    cluster.wait_until(lambda: status(two), planner_on("robot-2"), "the planner moved", 20)
    moved = cluster.wait_until(
        lambda: caller_row(two),
        lambda r: r["connections"] and r["connections"][0]["addr"] != before["addr"],
        "the binding re-pointed",
    )
    assert moved["connections"][0]["id"] == before["id"]  # the same binding, re-pointed
    assert moved["connections"][0]["to"] == "Planner-s1"
    count = paths(moved)
    after = cluster.wait_until(
        lambda: caller_row(two), lambda r: paths(r) >= count + 10, "10 paths from the new planner"
    )
    counters = after["ports"]["planner"]  # every call is a path or a failure (one may be running)
    assert 0 <= counters["calls"] - counters["failed"] - paths(after) <= 1

    def served(agent: Agent) -> int:  # calls the moved planner answered (its heartbeats lag)
        rows = {r["name"]: r for r in agent.get("/v1/instances")}
        return int(rows["Planner-s1"]["ports"]["planner"]["calls"])

    cluster.wait_until(lambda: served(two), lambda n: n >= 10, "10 calls served by Planner-s1")
