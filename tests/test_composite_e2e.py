"""A composite deployed on real agents: one placement, one host process, its members' ports
carrying data inside it (Src.out -> Dbl.inp) and to a component on another robot."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.realnet import Agent, RealCluster
from tests.test_recovery_e2e import deploy

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
