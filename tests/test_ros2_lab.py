"""ROS 2 nodes in a fleet, end to end on a 3-robot loopback lab: examples/ros2/system.yaml
deployed by one request (an unmodified rclpy odometry publisher, a bridge, an sdrpeer component,
a bridge, an unmodified rclpy listener), a ROS 2 probe in the test process hearing the
component's output, the ROS 2 endpoints in `port list` and their traffic in `status`, then the
robot running the publisher killed: the publisher ACTIVE on another robot and the probe hearing
fresh poses again."""

from __future__ import annotations

import os
import signal
import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from geometry_msgs.msg import PoseStamped

from sdrpeer.client import AgentClient, post_when_elected
from sdrpeer.errors import ApiError
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.record.robot import state_to_wire
from sdrpeer.system.loader import load_system
from sdrpeer.vocabulary import LifecycleState
from tests.ros2_probe import Probe
from tests.wait import until

pytestmark = pytest.mark.realnet
SYSTEM = Path(__file__).resolve().parent.parent / "examples" / "ros2" / "system.yaml"
WITHIN = 60.0
ACTIVE = state_to_wire(LifecycleState.ACTIVE)


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[RunningLab]:
    running = start_lab(
        UpOptions(3, tmp_path / "lab", preset="lan", timeout=30, allow_launchers=("ros2",)),
        say=lambda _: None,
    )
    try:
        yield running
    finally:
        running.stop(grace=3)


@pytest.fixture
def probe() -> Iterator[Probe]:
    p = Probe()
    try:
        yield p
    finally:
        p.close()


def status_of(clients: dict[str, AgentClient]) -> dict[str, Any]:
    """The status as the first robot that answers gives it."""
    for c in clients.values():
        try:
            return dict(c.get("/v1/status"))
        except ApiError:
            continue
    raise ApiError("no agent answers")


def row(status: dict[str, Any], component: str) -> dict[str, Any]:
    return next((c for c in status["components"] if c["component"] == component), {})


def test_a_ros2_system_runs_across_the_fleet_and_survives_a_robot_death(
    lab: RunningLab, probe: Probe
) -> None:
    clients = {r.name: AgentClient(str(r.api), r.token, timeout=3) for r in lab.lab.robots}
    one = clients["robot-1"]
    probe.listen("/pose", PoseStamped)
    system = load_system(SYSTEM)
    post_when_elected(one, "/v1/deploy", {"system": system.to_json()}, 30.0)

    def status() -> dict[str, Any]:
        return status_of(clients)

    names = [c.name for c in system.components]
    until(
        "every component ACTIVE",
        status,
        lambda s: all(row(s, n).get("state") == ACTIVE for n in names),
        within=WITHIN,
        retry=(ApiError,),
    )
    # the sdrpeer component is in the path: its offset is on every pose the probe hears
    poses = until(
        "poses on /pose", lambda: probe.messages("/pose"), lambda m: len(m) >= 20, within=WITHIN
    )
    assert all(p.pose.position.x >= 100.0 for p in poses)
    assert all(p.header.frame_id == "odom" for p in poses)
    # the publisher's topic in `port list` (GET /v1/ports of its robot), its traffic in status
    robot = row(status(), "Odometry")["robot"]
    listing = until(
        "the node's endpoints listed",
        lambda: clients[robot].get("/v1/ports"),
        lambda rows: any(r["port"] == "/odom" and r["counters"].get("frames_out") for r in rows),
        within=WITHIN,
    )
    odom = next(r for r in listing if r["instance"] == row(status(), "Odometry")["instance"])
    assert (odom["port"], odom["direction"], odom["type"]) == (
        "/odom",
        "publishes",
        "nav_msgs/msg/Odometry",
    )
    until(
        "its traffic in status",
        lambda: row(status(), "Odometry").get("sends_bytes_per_s"),
        lambda b: (b or 0) > 1000,
        within=WITHIN,
        retry=(ApiError,),
    )

    # the robot running the publisher dies
    victim = next(r for r in lab.lab.robots if r.name == robot)
    assert victim.pid is not None
    os.kill(victim.pid, signal.SIGKILL)
    killed = time.time()
    alive = {n: c for n, c in clients.items() if n != robot}

    def survivors_status() -> dict[str, Any]:
        return status_of(alive)

    until(
        "the publisher ACTIVE on another robot",
        survivors_status,
        lambda s: (
            row(s, "Odometry").get("robot") not in (None, robot)
            and row(s, "Odometry").get("state") == ACTIVE
        ),
        within=WITHIN,
        retry=(ApiError,),
    )
    until(
        "fresh poses after the death",
        lambda: probe.messages("/pose", since=killed + 0.5),
        lambda m: len(m) >= 20,
        within=WITHIN,
    )
