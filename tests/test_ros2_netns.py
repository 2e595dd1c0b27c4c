"""ROS 2 across robots that are separate machines: a 2-robot namespace lab (each robot its own
network stack and address), an rclpy publisher pinned to robot-1 and an rclpy listener pinned to
robot-2. DDS discovery is kept on each robot's own machine (LOCALHOST) and the agent names the
fleet's other robots as static peers, so the listener hears the publisher across the lab's
network; the listener's ROS 2 host was given robot-1's address and the fleet's domain."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import psutil
import pytest

from sdrpeer.client import AgentClient, post_when_elected
from sdrpeer.errors import ApiError
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.netlab import net
from sdrpeer.system.loader import parse_system
from tests.realnet import NETNS_ONLY
from tests.wait import until

pytestmark = pytest.mark.realnet
SYSTEM = """name: ros2-across
components:
  - {name: Pub, launcher: ros2, target: "components.ros2.odometry:OdometryPublisher",
     params: {rate_hz: 20.0}, pin: robot-1}
  - {name: Sub, launcher: ros2, target: "components.ros2.odometry:OdometryListener",
     pin: robot-2}
"""
WITHIN = 60.0


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[RunningLab]:
    running = start_lab(
        UpOptions(
            2, tmp_path / "lab", preset="lan", netns=True, timeout=30, allow_launchers=("ros2",)
        ),
        say=lambda _: None,
    )
    try:
        yield running
    finally:
        running.stop(grace=3)
        assert net.load(tmp_path / "lab") is None


@NETNS_ONLY
def test_nodes_on_two_robots_find_each_other_through_the_fleets_static_peers(
    lab: RunningLab,
) -> None:
    clients = {r.name: AgentClient(str(r.api), r.token, timeout=3) for r in lab.lab.robots}
    system = parse_system(SYSTEM, "across.yaml")
    post_when_elected(clients["robot-1"], "/v1/deploy", {"system": system.to_json()}, 30.0)

    def heard() -> int:
        rows: list[dict[str, Any]] = clients["robot-2"].get("/v1/ports")
        row = next((r for r in rows if r["instance"] == "Sub" and r["port"] == "/odom"), {})
        return int((row.get("counters") or {}).get("frames_in", 0))

    until(
        "robot-2's listener hearing robot-1's publisher",
        heard,
        lambda n: n >= 20,
        within=WITHIN,
        retry=(ApiError,),
    )
    instances = clients["robot-2"].get("/v1/instances")
    pid = next(i["pid"] for i in instances if i["name"] == "Sub")
    environ = psutil.Process(pid).environ()
    robot1_host = str(lab.lab.robot("robot-1").gossip).rsplit(":", 1)[0]  # type: ignore[union-attr]
    assert environ["ROS_STATIC_PEERS"].split(";") == [robot1_host]
    assert environ["ROS_AUTOMATIC_DISCOVERY_RANGE"] == "LOCALHOST"
    assert environ["ROS_DOMAIN_ID"] == str(int(environ["ROS_DOMAIN_ID"]))
