"""`sdrpeer describe` on a real 5-robot lab with a scenario: robot-4's battery drains below the
allocation threshold (the low_battery rule moves what it ran, and it takes nothing more) and
robot-1, which runs every active, is SIGKILLed by the scenario's `agent: kill` step. Afterwards
every placement of the plan and every standby the plan lacks is explained: its robot, how it got
there, the robots ruled out and by what, the reason and plan that decided it; the missing standby
names every robot's refusal, and `describe` warns of it."""

from __future__ import annotations

import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.client import AgentClient
from sdrpeer.deploy.plan_change import EXCLUDED
from sdrpeer.errors import ApiError
from sdrpeer.lab.script import Conductor
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.monitor.scenario import Scenario
from sdrpeer.plan import HOW
from sdrpeer.system.loader import load_system
from tests.realnet import REPO
from tests.wait import until

pytestmark = [pytest.mark.realnet, pytest.mark.slow]

DRAIN_AT, KILL_AT = 55.0, 75.0
"""Lab times (s from the lab's start) of the scenario's drain and death: the lab and the deploy
must be done before (on a loaded machine they take ~20-30 s)."""

SYSTEM = """\
version: 1
name: fleet
components:
  - name: Cam
    target: tests.components_fixture:Counter
    params: {rate: 20}
    requires: {memory: 10MB}
    standby: {other_robots: 1, mode: hot}
  - name: Det
    target: tests.components_fixture:Recorder
    requires: {memory: 10MB}
    standby: {other_robots: 3, mode: hot}
  - name: Logger
    target: tests.components_fixture:Recorder
    requires: {memory: 10MB}
connections:
  - {from: Cam.out, to: Det.inp}
  - {from: Cam.out, to: Logger.inp}
allocation:
  strategy: first_fit
  constraints:
    battery_above: 30%
recovery:
  rules:
    - cause: low_battery
      when: battery <= 30%
      for: 1s
      clear: 40%
      actions: [standby_other_robot, launch_other_robot]
"""

SCENARIO = f"""\
description: robot-4's battery runs down, then robot-1 (every active) dies
steps:
  - {{at: {DRAIN_AT:g}s, robot: robot-4, set: {{drain: 60%/min}}}}
  - {{at: {KILL_AT:g}s, robot: robot-1, agent: kill}}
"""


def robot_files(where: Path) -> Path:
    where.mkdir(parents=True)
    for k in range(1, 6):
        battery = "40%" if k == 4 else "100%"
        (where / f"robot-{k}.yaml").write_text(
            f"name: robot-{k}\nmemory: 4GB\ncpus: 4\nbattery: {battery}\n"
            f"position: [{3 * k}, 0]\nrssi: -45dBm\n"
        )
    return where


def client(lab: RunningLab, robot: str) -> AgentClient:
    r = lab.lab.robot(robot)
    assert r is not None
    return AgentClient(str(r.api), r.token, timeout=10)


def describe(api: AgentClient, name: str) -> dict[str, Any]:
    doc: dict[str, Any] = api.get(f"/v1/describe/{name}")
    return doc


def explained(doc: dict[str, Any], alive: set[str]) -> None:
    """Every instance of a component's describe document is explained (module docstring)."""
    for inst in doc["instances"]:
        why = inst["why"]
        assert why is not None, (doc["component"], inst)
        assert why["robot"] == inst["robot"], inst
        assert why["how"] in HOW
        assert why["reason"], why
        assert why["decided_in"] != [0, 0], why
        assert why["checked"], why  # the constraints its robot passed
        assert why["checked"][0] == "launch"
        for robot, reason in why["ruled_out"]:
            assert robot != inst["robot"]
            assert reason
    for left in doc["standbys"]["left_out"]:
        refused = dict(left["ruled_out"])
        assert set(refused) >= alive, (left, alive)  # every robot in view said why not
        assert all(refused.values()), left
        assert left["reason"], left
    missing = doc["standbys"]["wanted"] - doc["standbys"]["placed"]
    assert len(doc["standbys"]["left_out"]) == missing, doc["standbys"]
    if missing:
        assert any(w.startswith("no standby:") for w in doc["warnings"]), doc["warnings"]


def test_every_placement_and_missing_standby_is_explained_after_a_drain_and_a_death(
    tmp_path: Path,
) -> None:
    scenario = tmp_path / "scenario.yaml"
    scenario.write_text(SCENARIO)
    (system_file := tmp_path / "system.yaml").write_text(SYSTEM)
    options = UpOptions(
        5,
        tmp_path / "lab",
        preset="lan",
        robot_files=robot_files(tmp_path / "robots"),
        scenario=scenario,
        timeout=90,
    )
    lab = start_lab(options, say=lambda _: None)
    try:
        two = client(lab, "robot-2")
        until(
            "an allocator",
            lambda: two.get("/v1/status")["allocator"]["name"],
            within=60,
            poll=0.2,
            retry=(ApiError,),
        )
        system = {"system": load_system(system_file).to_json()}
        until(  # 503 while a record has not reached the allocator yet
            "the deploy taken",
            lambda: client(lab, "robot-1").post("/v1/deploy", {**system, "origin": "robot-1"}),
            within=60,
            poll=0.5,
            retry=(ApiError,),
        )
        until(
            "all ACTIVE on robot-1",
            lambda: two.get("/v1/status"),
            lambda d: (
                bool(d["components"])
                and all(c["state"] == "active" and c["robot"] == "robot-1" for c in d["components"])
            ),
            within=60,
            poll=0.2,
            retry=(ApiError,),
        )
        for comp in ("Cam", "Det", "Logger"):  # at deploy: all placed, all explained
            doc = describe(two, comp)
            explained(doc, {f"robot-{k}" for k in range(1, 6)})
            assert {i["why"]["reason"] for i in doc["instances"]} == {"deploy"}
        elapsed = time.time() - lab.lab.created
        assert elapsed < DRAIN_AT, f"the lab and deploy took {elapsed:.0f} s: too slow to test"

        steps = Scenario.load(scenario).lab_steps()
        conductor = Conductor(lab, steps, say=lambda _: None)
        conductor.run_until(KILL_AT + 0.1)
        (kill,) = conductor.done
        assert kill[1].startswith("robot-1: agent kill (pid"), kill

        def settled(d: dict[str, Any]) -> bool:
            comps = d["components"]
            return all(c["state"] == "active" and c["robot"] != "robot-1" for c in comps)

        until("all ACTIVE off robot-1", lambda: two.get("/v1/status"), settled, within=60, poll=0.2)
        det = until(
            "Det short of a standby, and robot-4 left out",
            lambda: describe(two, "Det"),
            lambda d: (
                d["standbys"]["placed"] == 2
                and all(i["robot"] not in ("robot-1", "robot-4") for i in d["instances"])
            ),
            within=60,
            poll=0.5,
            retry=(ApiError,),
        )
        alive = {"robot-2", "robot-3", "robot-4", "robot-5"}
        for comp in ("Cam", "Det", "Logger"):
            explained(describe(two, comp), alive)
        (left,) = det["standbys"]["left_out"]
        refused = dict(left["ruled_out"])
        assert refused["robot-4"] == EXCLUDED, refused  # its low_battery condition holds
        assert {refused[r] for r in ("robot-2", "robot-3", "robot-5")} <= {
            f"already holds {i['instance']}" for i in det["instances"]
        }
        active = next(i for i in det["instances"] if i["role"] == "active")
        assert active["why"]["how"] in ("standby_promoted", "kept")

        robot4 = describe(two, "robot-4")
        assert {c["constraint"]: c["ok"] for c in robot4["checks"]} == {"battery": False}
        assert robot4["placed"] == []
        robot1 = describe(two, "robot-1")
        assert robot1["state"] in ("dead", None)
        assert any("robot-1 is" in w for w in robot1["warnings"])

        env = dict(os.environ)
        env["PYTHONPATH"] = os.pathsep.join(p for p in (str(REPO), env.get("PYTHONPATH")) if p)
        text = subprocess.run(
            [sys.executable, "-m", "sdrpeer", "describe", "Det", "--api", str(two.base)],
            capture_output=True,
            text=True,
            timeout=60,
            env=env,
            check=False,
        )
        assert text.returncode == 0, text.stderr
        assert f"{left['instance']}  left out" in text.stdout
        assert "refused by: robot-" in text.stdout
        assert "! no standby: the system asks for 3, the plan has 2" in text.stdout
    finally:
        lab.stop(grace=3)
