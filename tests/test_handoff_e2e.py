"""Recovery moves on real agents carry the component's state, and a component in ERROR moves to
its standby on another robot (Table III).

- sync: a hot standby on another robot receives the active instance's state every `sync`; when
  the active's robot is SIGKILLed, the standby goes on from the last state it received;
- final: with no sync at all, a planned move (the robot's signal fails) hands the old instance's
  last state to the new active instance before the old one stops;
- ERROR: a component that raises goes to ERROR, and its standby on the other robot takes over.
"""

from __future__ import annotations

import re
from pathlib import Path
from typing import Any

import pytest

from tests.realnet import Agent, RealCluster, http
from tests.test_recovery_e2e import deploy, status

pytestmark = pytest.mark.realnet

TALLY = """\
name: {name}
components:
  - name: Tally
    target: tests.components_fixture:Tally
    params: {{rate: 20}}
    standby: {{other_robots: 1, mode: hot{sync}}}
recovery:
  rules:
    - cause: communication_failure
      when: rssi <= -52.5dBm
      for: 1s
      clear: -50dBm
      actions: [standby_other_robot, launch_other_robot]
"""


def write(tmp_path: Path, text: str) -> Path:
    path = tmp_path / "system.yaml"
    path.write_text(text)
    return path


def counts(agent: Agent, instance: str, what: str) -> list[int]:
    """Every n the instance logged as `what n=...` (restored, active from)."""
    path = agent.data_dir / "instances" / f"{instance}.log"
    text = path.read_text(errors="replace") if path.exists() else ""
    return [int(n) for n in re.findall(rf"{what} n=(\d+)", text)]


def tally_on(robot: str) -> Any:
    def ok(doc: dict[str, Any]) -> bool:
        comps = doc["components"]
        return bool(comps) and comps[0]["robot"] == robot and comps[0]["state"] == "active"

    return ok


def test_a_standby_goes_on_from_the_last_synced_state_when_the_robot_dies(
    cluster: RealCluster, tmp_path: Path
) -> None:
    one, two, _ = cluster.start_many(3)  # two of three go on as the fleet (a majority)
    doc = deploy(cluster, one, write(tmp_path, TALLY.format(name="synced", sync=", sync: 300ms")))
    tally = doc["components"][0]
    assert (tally["robot"], tally["standbys"][0]["instance"]) == ("robot-1", "Tally-s1")
    synced = cluster.wait_until(
        lambda: counts(two, "Tally-s1", "restored"), lambda ns: len(ns) >= 3, "three syncs"
    )
    assert synced == sorted(synced)  # newer states, in order
    assert synced[-1] > synced[0]
    cluster.kill(one)
    cluster.wait_until(lambda: status(two), tally_on("robot-2"), "the standby active", 20)
    started = cluster.wait_until(
        lambda: counts(two, "Tally-s1", "active from"), bool, "the standby activated"
    )
    last = counts(two, "Tally-s1", "restored")[-1]
    assert started == [last]  # it counts on from the last state it received, not from 0
    assert last >= synced[-1] >= 3


@pytest.mark.parametrize("quorum", ["majority", "any"])
def test_of_two_robots_the_survivor_goes_on_only_with_quorum_any(
    cluster: RealCluster, tmp_path: Path, quorum: str
) -> None:
    """A fleet of two cannot tell robot-1's death from a cut: by default (majority) robot-2 alone
    is cut off and runs nothing; with `quorum: any` its standby takes over."""
    one, two = cluster.start_many(2)
    text = TALLY.format(name="two", sync="").replace(
        "components:", f"allocation: {{quorum: {quorum}}}\ncomponents:"
    )
    deploy(cluster, one, write(tmp_path, text))
    cluster.kill(one)
    if quorum == "any":
        cluster.wait_until(lambda: status(two), tally_on("robot-2"), "the standby active", 20)
        return
    doc = cluster.wait_until(lambda: status(two), lambda d: d["cut_off"], "robot-2 cut off", 20)
    assert doc["allocator"]["name"] is None
    rows = two.get("/v1/instances")
    assert [r["state"] for r in rows if r["name"] == "Tally-s1"] == ["INACTIVE"]


def test_a_planned_move_hands_over_the_final_state(cluster: RealCluster, tmp_path: Path) -> None:
    one, two = cluster.start_many(2)
    deploy(cluster, one, write(tmp_path, TALLY.format(name="moved", sync="")))
    cluster.wait_until(
        lambda: one.get("/v1/instances"),
        lambda rows: any(r["name"] == "Tally" and r["state"] == "ACTIVE" for r in rows),
        "Tally counting",
    )
    assert counts(two, "Tally-s1", "restored") == []  # no sync: the standby knows nothing yet
    code, _ = http("POST", one.api + "/v1/robot", {"rssi": "-56dBm"}, one.token)
    assert code == 200
    cluster.wait_until(lambda: status(two), tally_on("robot-2"), "moved to robot-2", 20)
    restored = cluster.wait_until(
        lambda: counts(two, "Tally-s1", "restored"), bool, "the final state restored"
    )
    assert restored[0] > 0
    sent = [e for e in one.events() if e["kind"] == "state.handoff"]
    assert [(e["detail"]["source"], e["detail"]["target"]) for e in sent] == [("Tally", "Tally-s1")]
    assert any(e["kind"] == "state.restored" for e in two.events())


FRAGILE = """\
name: fragile
components:
  - name: Fragile
    target: tests.components_fixture:Fragile
    params: {{trigger: '{trigger}'}}
    standby: {{other_robots: 1, mode: hot}}
recovery:
  rules:
    - cause: component_error
      actions: [standby_other_robot, launch_other_robot]
"""


def test_a_component_in_error_moves_to_its_standby_on_another_robot(
    cluster: RealCluster, tmp_path: Path
) -> None:
    one, two = cluster.start_many(2)
    trigger = tmp_path / "fail"
    deploy(cluster, one, write(tmp_path, FRAGILE.format(trigger=trigger)))
    trigger.write_text("Fragile\n")  # the active instance on robot-1 raises in on_execute
    doc = cluster.wait_until(lambda: status(two), tally_on("robot-2"), "the standby active", 20)
    assert doc["components"][0]["instance"] == "Fragile-s1"
    decisions = [e["detail"] for e in one.events() if e["kind"] == "recovery.decision"]
    assert decisions[0]["action"] == "standby_other_robot"
    assert decisions[0]["cause"] == "component_error"
