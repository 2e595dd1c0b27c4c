"""A composite deployed on real agents: one placement, one host process, its members' ports
carrying data inside it (Src.out -> Dbl.inp) and to a component on another robot; a member's
failure puts the whole composite in ERROR and Table III replaces it as one."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.realnet import Agent, RealCluster
from tests.test_recovery_e2e import deploy, status

pytestmark = pytest.mark.realnet

SYSTEM = """\
name: composite-e2e
components:
  - {name: Rec, target: tests.components_fixture:Recorder, pin: robot-2}
composites:
  - name: Pipe
    execution: {periodic: 20}
    pin: robot-1
    members:
      - {name: Src, target: tests.composite_fixture:Source}
      - {name: Dbl, target: tests.composite_fixture:Doubler, params: {gain: 3}}
connections:
  - {from: Src.out, to: Dbl.inp, policy: {push: fifo}}
  - {from: Dbl.out, to: Rec.inp}
"""


def rows(agent: Agent) -> dict[str, dict[str, Any]]:
    return {r["name"]: r for r in agent.get("/v1/instances")}


def test_a_composite_is_placed_as_one_and_its_members_ports_carry_data(
    cluster: RealCluster, tmp_path: Path
) -> None:
    one, two = cluster.start_many(2)
    path = tmp_path / "system.yaml"
    path.write_text(SYSTEM)
    doc = deploy(cluster, one, path)
    placed = {c["component"]: c["robot"] for c in doc["components"]}
    assert placed == {"Pipe": "robot-1", "Rec": "robot-2"}
    pipe = cluster.wait_until(  # inside the composite: Src's frames reach Dbl
        lambda: rows(one).get("Pipe", {}),
        lambda r: r.get("ports", {}).get("Dbl.inp", {}).get("frames_in", 0) > 10,
        "Src.out -> Dbl.inp frames",
    )
    assert set(pipe["ports"]) == {"Src.out", "Dbl.inp", "Dbl.out"}
    assert pipe["ports"]["Dbl.inp"]["lost"] == 0
    assert list(rows(one)) == ["Pipe"]  # one host process for both members
    members = [(m["name"], m["state"]) for m in pipe["members"]]
    assert members == [("Src", "ACTIVE"), ("Dbl", "ACTIVE")]  # listed under it, in order
    assert pipe["pid"] > 0
    cluster.wait_until(  # and out of it: Dbl.out reaches Rec on the other robot
        lambda: rows(two).get("Rec", {}).get("ports", {}).get("inp", {}),
        lambda c: c.get("frames_in", 0) > 10,
        "Dbl.out -> Rec.inp frames",
    )


TRIPPY = """\
name: composite-recovery
components:
  - {{name: Rec, target: tests.components_fixture:Recorder}}
composites:
  - name: Pipe
    execution: {{periodic: 20}}
    standby: {{same_robot: 1, mode: hot}}
    members:
      - {{name: Src, target: tests.composite_fixture:Source}}
      - {{name: Trip, target: tests.composite_fixture:Tripwire, params: {{trigger: "{trigger}"}}}}
connections:
  - {{from: Src.out, to: Rec.inp}}
recovery:
  rules:
    - cause: component_error
      actions: [standby_same_robot, restart, standby_other_robot, launch_other_robot]
"""


def test_a_members_failure_is_the_composites_and_its_standby_takes_over_whole(
    cluster: RealCluster, tmp_path: Path
) -> None:
    one = cluster.start("robot-1")
    trigger = tmp_path / "trip"
    path = tmp_path / "trippy.yaml"
    path.write_text(TRIPPY.format(trigger=trigger))

    def ready(d: dict[str, Any]) -> bool:
        comps = d["components"]
        return bool(comps) and all(
            c["state"] == "active" and all(s["state"] == "inactive" for s in c["standbys"])
            for c in comps
        )

    deploy(cluster, one, path)
    cluster.wait_until(lambda: status(one), ready, "the composite's standby ready")
    trigger.write_text("trip")  # the active composite's Trip member raises in on_execute

    def replaced(d: dict[str, Any]) -> bool:
        pipe = next(c for c in d["components"] if c["component"] == "Pipe")
        return bool(pipe["instance"] == "Pipe-s1" and pipe["state"] == "active")

    cluster.wait_until(lambda: status(one), replaced, "the standby composite active")
    decisions = [e for e in one.events() if e["kind"] == "recovery.decision"]
    assert decisions[0]["detail"]["action"] == "standby_same_robot"
    assert any("member Trip: on_execute: RuntimeError: tripped" in str(e) for e in one.events())

    def received() -> int:
        return int(rows(one)["Rec"]["ports"].get("inp", {}).get("frames_in", 0))

    n = received()
    cluster.wait_until(received, lambda v: v > n, "frames from the new composite's Src")
