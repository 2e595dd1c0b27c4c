"""End to end on real agents: the paper's five components deployed over a 3-robot lab.

Robot capacities are chosen so that memory forces the split of the paper's Fig. 3 (Table V:
free memory must stay above 500MB after adding a 500MB component: two per robot at most), data
flows between robots, and a SIGKILLed allocator is replaced with the plan intact.
"""

from __future__ import annotations

from functools import partial
from pathlib import Path
from typing import Any

import pytest

from sdrpeer.cli.main import main as cli_main
from tests.realnet import Agent, RealCluster, http
from tests.wait import stays

pytestmark = pytest.mark.realnet

REPO = Path(__file__).resolve().parent.parent
COMPONENTS = {
    "OmnidirectionalCameraRTC": "components.camera:OmnidirectionalCamera",
    "AnomalyDetectionRTC": "components.anomaly_detection:AnomalyDetection",
    "CameraRTC": "components.camera:Camera",
    "REDControllerRTC": "components.red_controller:REDController",
    "PositionEstimationRTC": "components.position_estimation:PositionEstimation",
}
CONNECTIONS = """\
connections:
  - {from: OmnidirectionalCameraRTC.image, to: AnomalyDetectionRTC.image, policy: {push: new}}
  - {from: AnomalyDetectionRTC.alarm, to: REDControllerRTC.alarm, policy: {push: new}}
  - {from: REDControllerRTC.odometry, to: PositionEstimationRTC.odometry}
  - {from: PositionEstimationRTC.pose, to: REDControllerRTC.pose, policy: {push: new}}
allocation:
  strategy: first_fit
  constraints: {mem_free_above: 500MB}
"""


def system_file(tmp_path: Path, rate: int = 5) -> Path:
    lines = ["version: 1", "name: paper-fig3", "components:"]
    for name, target in COMPONENTS.items():
        lines += [
            f"  - name: {name}",
            f"    target: {target}",
            f"    params: {{reserve_mb: 0, rate: {rate}}}"
            if "Camera" in name
            else "    params: {}",
            "    requires: {cpu: 5%, memory: 500MB}",
        ]
        if name == "PositionEstimationRTC":
            lines.append("    standby: {other_robots: 1, mode: hot}")
    path = tmp_path / "system.yaml"
    path.write_text("\n".join(lines) + "\n" + CONNECTIONS)
    return path


def start_lab(cluster: RealCluster) -> list[Agent]:
    for i in (1, 2, 3):
        (cluster.root / f"robot-{i}.yaml").write_text(
            f"name: robot-{i}\nmemory: 1700MB\ncpus: 4\nbattery: 100%\n"
            f"position: [{3 * i}, 0]\nrssi: -45dBm\n"
        )
    return cluster.start_many(3)


def status(agent: Agent) -> dict[str, Any]:
    doc: dict[str, Any] = agent.get("/v1/status")
    return doc


def plan_digest(agent: Agent) -> str:
    return str(status(agent)["plan"]["digest"])


def placed(doc: dict[str, Any]) -> dict[str, tuple[str, str]]:
    return {c["component"]: (c.get("robot"), c.get("state")) for c in doc["components"]}


def test_paper_system_split_by_memory_flows_and_survives_allocator_kill(
    cluster: RealCluster, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    agents = start_lab(cluster)
    by_name = {a.name: a for a in agents}
    entry = by_name["robot-2"]
    doc = cluster.wait_until(
        lambda: status(entry), lambda d: d["allocator"]["name"] is not None, "an allocator"
    )
    first_epoch = doc["allocator"]["epoch"]
    path = system_file(tmp_path)
    code = cli_main(
        [
            "deploy",
            str(path),
            "--wait",
            "--timeout",
            "60",
            "--api",
            entry.api,
            "--token",
            entry.token,
        ]
    )
    out = capsys.readouterr().out
    assert code == 0, out
    assert "components ACTIVE after" in out
    doc = status(entry)
    where = placed(doc)
    assert set(where) == set(COMPONENTS)
    assert all(state == "active" for _, state in where.values())
    per_robot: dict[str, int] = {}
    for robot, _ in where.values():
        per_robot[robot] = per_robot.get(robot, 0) + 1
    # Table V with 1700MB robots: at most two 500MB components each -> 2 + 2 + 1 over 3 robots
    assert sorted(per_robot.values()) == [1, 2, 2], where
    # first_fit: the robot that received the system (robot-2) is filled first
    assert per_robot["robot-2"] == 2

    # port data crosses robots: the controller hears poses from position estimation
    ctl_robot = where["REDControllerRTC"][0]

    def pose_frames() -> int:
        rows = {i["name"]: i for i in by_name[ctl_robot].get("/v1/instances")}
        return int(rows["REDControllerRTC"]["ports"].get("pose", {}).get("frames_in", 0))

    n = cluster.wait_until(pose_frames, lambda v: v > 0, "poses reaching the controller")
    cluster.wait_until(pose_frames, lambda v: v > n, "more poses")

    # the hot standby runs INACTIVE on another robot
    (standby,) = next(c for c in doc["components"] if c["component"] == "PositionEstimationRTC")[
        "standbys"
    ]
    assert standby["robot"] != where["PositionEstimationRTC"][0]
    cluster.wait_until(
        lambda: status(entry)["components"][-1]["standbys"][0]["state"],
        lambda s: s == "inactive",
        "the hot standby INACTIVE",
    )

    # a changed system is applied with the smallest change: only the cameras' hosts restart
    def pids() -> dict[str, int]:
        return {i["name"]: i["pid"] for a in agents for i in a.get("/v1/instances")}

    before = pids()
    code = cli_main(
        [
            "deploy",
            str(system_file(tmp_path, rate=4)),
            "--wait",
            "--timeout",
            "60",
            "--api",
            entry.api,
            "--token",
            entry.token,
        ]
    )
    assert code == 0, capsys.readouterr().out
    doc = status(entry)
    assert placed(doc) == where
    after_change = cluster.wait_until(
        pids, lambda p: set(p) == set(before) and all(p.values()), "hosts after the change"
    )
    changed = {n for n in before if before[n] != after_change[n]}
    assert changed == {"OmnidirectionalCameraRTC", "CameraRTC"}

    # every agent sees the same plan
    for a in agents:
        cluster.wait_until(
            partial(plan_digest, a), lambda d: d == doc["plan"]["digest"], f"{a.name}'s plan"
        )

    # kill -9 the allocator's agent: another robot takes over with a higher epoch, same system
    allocator = doc["allocator"]["name"]
    cluster.kill(by_name[allocator])
    survivor = next(a for a in agents if a.name != allocator)

    def taken_over(d: dict[str, Any]) -> bool:
        return d["allocator"]["name"] not in (None, allocator) and d["plan"]["epoch"] > first_epoch

    after = cluster.wait_until(lambda: status(survivor), taken_over, "a new allocator", 20)
    stays(  # the dead robot's components do not fit elsewhere: no plan churn meanwhile
        "at most one plan version after the takeover",
        lambda: status(survivor)["plan"]["version"],
        lambda version: version - after["plan"]["version"] <= 1,
        window=1.5,
        poll=0.1,
    )
    assert after["allocator"]["epoch"] > doc["allocator"]["epoch"]
    assert after["plan"]["system"] == "paper-fig3"
    assert after["plan"]["digest"] == doc["plan"]["digest"]
    kept = {c: rs for c, rs in placed(after).items() if rs[0] != allocator}
    assert kept, after
    for comp, (robot, _) in kept.items():
        assert where[comp][0] == robot  # nothing that still runs was moved

    # undeploy stops everything the plan ran
    status_code, body = http("POST", survivor.api + "/v1/undeploy", {}, survivor.token)
    assert status_code == 200, body
    cluster.wait_until(
        lambda: [i for a in agents if a.name != allocator for i in a.get("/v1/instances")],
        lambda rows: rows == [],
        "all instances stopped",
    )


def test_malformed_system_deploys_nothing(
    cluster: RealCluster, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    agent = cluster.start("robot-1")
    bad = tmp_path / "bad.yaml"
    bad.write_text(
        "name: x\ncomponents:\n  - name: A\n    target: components.camera:Camera\n"
        "    requires: {memory: lots}\n"
    )
    code = cli_main(["deploy", str(bad), "--api", agent.api, "--token", agent.token])
    err = capsys.readouterr().err
    assert code == 2
    assert f"{bad}:5" in err
    assert status(agent)["plan"] is None


def test_infeasible_system_is_refused_with_reasons(
    cluster: RealCluster, tmp_path: Path, capsys: pytest.CaptureFixture[str]
) -> None:
    agent = cluster.start("robot-1")
    cluster.wait_until(
        lambda: status(agent), lambda d: d["allocator"]["name"] == "robot-1", "robot-1 elected"
    )
    big = tmp_path / "big.yaml"
    big.write_text(
        "name: big\ncomponents:\n  - name: A\n    target: components.camera:Camera\n"
        "    requires: {memory: 64GB}\n"
    )
    code = cli_main(["deploy", str(big), "--api", agent.api, "--token", agent.token])
    err = capsys.readouterr().err
    assert code == 1
    assert "cannot be placed" in err
    assert "robot-1" in err
    assert status(agent)["plan"] is None
