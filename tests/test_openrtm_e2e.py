"""An unmodified OpenRTM-aist RTC (tests/rtc_fixture.py) hosted by the `openrtm` launcher on
real agents: ACTIVE, its DataPorts connected to sdrpeer components' ports both ways, its host
killed and replaced, its onExecute's RTC_ERROR an sdrpeer ERROR that recovery acts on, moved to
another robot; the paper's five RTCs (components/openrtm/) wired together."""

from __future__ import annotations

import os
import signal
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.launch.openrtm import available
from tests.realnet import Agent, RealCluster, http
from tests.test_recovery_e2e import deploy, status

pytestmark = [
    pytest.mark.realnet,
    pytest.mark.skipif(available() is not None, reason=f"{available()}"),
]

RTC = "tests.rtc_fixture:Relay"
FLAGS = ("--allow-launcher", "openrtm")

SYSTEM = f"""\
name: openrtm-e2e
components:
  - {{name: Pub, target: tests.rtc_peers:PosePub}}
  - {{name: Relay, launcher: openrtm, target: "{RTC}"}}
  - {{name: Counts, target: tests.components_fixture:Recorder}}
  - {{name: Check, target: tests.rtc_peers:PoseCheck}}
connections:
  - {{from: Pub.out, to: Relay.pose}}
  - {{from: Relay.count, to: Counts.inp}}
  - {{from: Relay.echo, to: Check.inp}}
"""


def rows(agent: Agent) -> dict[str, dict[str, Any]]:
    return {r["name"]: r for r in agent.get("/v1/instances")}


def frames_in(agent: Agent, instance: str, port: str) -> int:
    return int(rows(agent).get(instance, {}).get("ports", {}).get(port, {}).get("frames_in", 0))


def test_an_rtc_goes_active_and_its_dataports_connect_both_ways(
    cluster: RealCluster, tmp_path: Path
) -> None:
    one = cluster.start("robot-1", flags=FLAGS)
    path = tmp_path / "system.yaml"
    path.write_text(SYSTEM)
    doc = deploy(cluster, one, path)
    assert {c["component"]: c["state"] for c in doc["components"]}["Relay"] == "active"
    relay = cluster.wait_until(lambda: rows(one)["Relay"], lambda r: r["ports"], "port counters")
    assert relay["state"] == "ACTIVE"
    assert set(relay["ports"]) == {"pose", "count", "echo"}
    # the RTC's OutPort (TimedLong) reaches an sdrpeer InPort
    cluster.wait_until(lambda: frames_in(one, "Counts", "inp"), lambda n: n > 10, "RTC counts")
    # sdrpeer's Poses reach the RTC's InPort (TimedPose2D) and come back from its OutPort as Poses
    cluster.wait_until(lambda: frames_in(one, "Check", "inp"), lambda n: n > 10, "echoed poses")
    assert frames_in(one, "Relay", "pose") > 0  # counted on the RTC host side too
    assert rows(one)["Check"]["state"] == "ACTIVE"  # every echo held x*2, y, heading


CRASHY = f"""\
name: openrtm-crash
components:
  - name: Relay
    launcher: openrtm
    target: "{RTC}"
    params: {{trigger: "{{trigger}}"}}
    standby: {{{{same_robot: 1, mode: hot}}}}
  - {{name: Counts, target: tests.components_fixture:Recorder}}
connections:
  - {{from: Relay.count, to: Counts.inp}}
recovery:
  rules:
    - cause: component_error
      actions: [standby_same_robot, restart, standby_other_robot, launch_other_robot]
"""


def _ready(d: dict[str, Any]) -> bool:
    comps = d["components"]
    return bool(comps) and all(
        c["state"] == "active" and all(s["state"] == "inactive" for s in c["standbys"])
        for c in comps
    )


def _deploy_with_standby(
    cluster: RealCluster, tmp_path: Path, template: str = "", key: str = "trigger"
) -> tuple[Agent, Path]:
    """One robot running `template` (CRASHY) with its `{key}` a file path; the standby ready."""
    one = cluster.start("robot-1", flags=FLAGS)
    file = tmp_path / key
    path = tmp_path / "system.yaml"
    text = (template or CRASHY).replace("{" + key + "}", str(file))
    path.write_text(text.replace("{{", "{").replace("}}", "}"))
    deploy(cluster, one, path)
    cluster.wait_until(lambda: status(one), _ready, "the RTC's standby ready")
    return one, file


def test_killing_an_rtcs_host_brings_its_standby_up(cluster: RealCluster, tmp_path: Path) -> None:
    one, _ = _deploy_with_standby(cluster, tmp_path)
    os.kill(rows(one)["Relay"]["pid"], signal.SIGKILL)
    doc = cluster.wait_until(
        lambda: status(one),
        lambda d: (
            next(c for c in d["components"] if c["component"] == "Relay")["instance"] == "Relay-s1"
            and _ready(d)
        ),
        "the RTC's standby active",
    )
    assert doc is not None
    decisions = [e for e in one.events() if e["kind"] == "recovery.decision"]
    assert decisions[0]["detail"]["action"] == "standby_same_robot"
    n = frames_in(one, "Counts", "inp")
    cluster.wait_until(lambda: frames_in(one, "Counts", "inp"), lambda v: v > n, "counts again")


def test_an_rtc_returning_rtc_error_is_in_error_and_recovered(
    cluster: RealCluster, tmp_path: Path
) -> None:
    one, trigger = _deploy_with_standby(cluster, tmp_path)
    trigger.write_text("trip")  # every Relay's onExecute now returns RTC_ERROR
    cluster.wait_until(
        lambda: [e for e in one.events() if e["kind"] == "recovery.decision"],
        bool,
        "a recovery decision",
    )
    errors = [e for e in one.events() if "onExecute returned RTC_ERROR" in str(e)]
    assert errors, "the RTC's RTC_ERROR is reported as sdrpeer ERROR"
    decisions = [e for e in one.events() if e["kind"] == "recovery.decision"]
    assert decisions[0]["detail"]["action"] == "standby_same_robot"
    assert decisions[0]["detail"].get("cause", "component_error") == "component_error"


PAPER = """\
name: paper-rtcs
components:
  - {name: OmniCam, launcher: openrtm, target: components.openrtm.camera:OmnidirectionalCamera}
  - {name: Cam, launcher: openrtm, target: components.openrtm.camera:Camera}
  - {name: Detector, launcher: openrtm, target: components.openrtm.anomaly_detection}
  - {name: Ctl, launcher: openrtm, target: components.openrtm.red_controller}
  - {name: Est, launcher: openrtm, target: components.openrtm.position_estimation}
  - {name: Cmds, target: tests.components_fixture:Recorder}
connections:
  - {from: OmniCam.image, to: Detector.image, policy: {push: new, buffer: 1}}
  - {from: Cam.image, to: Detector.image, policy: {push: new, buffer: 1}}
  - {from: Detector.alarm, to: Ctl.alarm, policy: {push: new}}
  - {from: Ctl.odometry, to: Est.odometry}
  - {from: Est.pose, to: Ctl.pose, policy: {push: new}}
  - {from: Est.inside, to: Ctl.inside, policy: {push: new}}
  - {from: Ctl.cmd, to: Cmds.inp}
"""


def test_the_papers_five_rtcs_run_unmodified_and_talk(cluster: RealCluster, tmp_path: Path) -> None:
    one = cluster.start("robot-1", flags=FLAGS)
    path = tmp_path / "paper.yaml"
    path.write_text(PAPER)
    deploy(cluster, one, path)
    wired = (("Detector", "image"), ("Ctl", "alarm"), ("Est", "odometry"), ("Ctl", "inside"))
    for instance, port in (*wired, ("Ctl", "pose"), ("Cmds", "inp")):

        def count(i: str = instance, p: str = port) -> int:
            return frames_in(one, i, p)

        cluster.wait_until(count, lambda n: n > 5, f"{instance}.{port}")
    assert all(r["state"] == "ACTIVE" for r in rows(one).values())


def test_a_planned_move_takes_an_rtc_to_another_robot_and_its_streams_with_it(
    cluster: RealCluster, tmp_path: Path
) -> None:
    one, two = cluster.start_many(2, flags=FLAGS)
    path = tmp_path / "system.yaml"
    path.write_text(SYSTEM)
    doc = deploy(cluster, one, path)
    origin = next(c["robot"] for c in doc["components"] if c["component"] == "Relay")
    to = "robot-2" if origin == "robot-1" else "robot-1"
    code, answer = http("POST", one.api + "/v1/move", {"component": "Relay", "to": to}, one.token)
    assert code == 200, answer

    def relay_on(d: dict[str, Any]) -> bool:
        relay = next(c for c in d["components"] if c["component"] == "Relay")
        return bool(relay["robot"] == to and relay["state"] == "active")

    cluster.wait_until(lambda: status(one), relay_on, f"Relay ACTIVE on {to}")
    agent = one if to == "robot-1" else two

    def poses_in() -> int:
        rows = [r for r in agent.get("/v1/instances") if r["component"] == "Relay"]
        return sum(int(r.get("ports", {}).get("pose", {}).get("frames_in", 0)) for r in rows)

    cluster.wait_until(poses_in, lambda n: n > 5, "poses into the moved RTC")
    checks = {a.name: a for a in (one, two)}
    check_robot = next(c["robot"] for c in status(one)["components"] if c["component"] == "Check")
    n = frames_in(checks[check_robot], "Check", "inp")
    cluster.wait_until(
        lambda: frames_in(checks[check_robot], "Check", "inp"), lambda v: v > n + 5, "echoes"
    )
    assert rows(checks[check_robot])["Check"]["state"] == "ACTIVE"


HANGS = f"""\
name: openrtm-hangs
components:
  - name: Relay
    launcher: openrtm
    target: "{RTC}"
    params: {{{{hang: "{{hang}}"}}}}
    standby: {{{{same_robot: 1, mode: hot}}}}
    watchdog: 3s
recovery:
  rules:
    - cause: component_error
      actions: [standby_same_robot, restart, standby_other_robot, launch_other_robot]
"""


def test_an_rtc_stuck_in_onexecute_is_killed_by_the_watchdog_and_replaced(
    cluster: RealCluster, tmp_path: Path
) -> None:
    one, hang = _deploy_with_standby(cluster, tmp_path, HANGS, "hang")
    pid = rows(one)["Relay"]["pid"]
    hang.write_text(f"{pid}\n")  # that host's onExecute never returns from now on

    def replaced(d: dict[str, Any]) -> bool:
        relay = d["components"][0]
        return bool(relay["instance"] == "Relay-s1" and relay["state"] == "active")

    cluster.wait_until(lambda: status(one), replaced, "the standby active")
    faults = [e["detail"] for e in one.events() if e["kind"] == "instance.fault"]
    assert any(f["instance"] == "Relay" and f["detail"].startswith("hung: ") for f in faults)
