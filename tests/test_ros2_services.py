"""ROS 2 services and sdrpeer service ports bridged both ways, on a real 1-robot lab: an sdrpeer
component calls an unmodified rclpy node's /reset (std_srvs/Trigger) through a `ros2_service:`
end, and a ROS 2 client (the test's probe) calls /invert (std_srvs/SetBool), answered by an
sdrpeer component; a binding to a port of the wrong kind is refused at load time."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from std_srvs.srv import SetBool

from sdrpeer.client import AgentClient, post_when_elected
from sdrpeer.errors import ApiError, SystemFileError
from sdrpeer.lab.up import RunningLab, UpOptions, start_lab
from sdrpeer.system.loader import parse_system
from tests.ros2_probe import Probe
from tests.wait import until

pytestmark = pytest.mark.realnet
FX = "tests.ros2_services_fixture"
SYSTEM = f"""name: ros2-services
components:
  - {{name: Server, launcher: ros2, target: "{FX}:ResetServer"}}
  - {{name: Caller, target: "{FX}:ResetCaller"}}
  - {{name: Inverter, target: "{FX}:Inverter"}}
connections:
  - {{from: Caller.ros, to: {{ros2_service: /reset, type: std_srvs/srv/Trigger}}}}
  - {{from: {{ros2_service: /invert, type: std_srvs/srv/SetBool}}, to: Inverter.ros}}
"""
WITHIN = 60.0


@pytest.fixture
def lab(tmp_path: Path) -> Iterator[RunningLab]:
    running = start_lab(
        UpOptions(1, tmp_path / "lab", preset="lan", timeout=30, allow_launchers=("ros2",)),
        say=lambda _: None,
    )
    try:
        yield running
    finally:
        running.stop(grace=3)


def test_services_are_bridged_both_ways(lab: RunningLab) -> None:
    robot = lab.lab.robots[0]
    client = AgentClient(str(robot.api), robot.token, timeout=3)
    system = parse_system(SYSTEM, "services.yaml")
    assert {c.name for c in system.components} >= {"ros2-reset-client", "ros2-invert-server"}
    post_when_elected(client, "/v1/deploy", {"system": system.to_json()}, 30.0)

    def row(instance: str, port: str) -> dict[str, Any]:
        rows = client.get("/v1/ports")
        return next((r for r in rows if r["instance"] == instance and r["port"] == port), {})

    # sdrpeer -> ROS 2: every answer the caller got came from the rclpy node
    until(
        "answers from /reset",
        lambda: (row("Caller", "answers").get("counters") or {}).get("frames_out", 0),
        lambda n: n >= 3,
        within=WITHIN,
        retry=(ApiError,),
    )
    served = row("ros2-reset-client", "/reset")
    assert served["direction"] == "calls"
    assert served["type"] == "std_srvs/srv/Trigger"
    # ROS 2 -> sdrpeer: a ROS 2 client's request answered by the sdrpeer component
    probe = Probe()
    try:
        for data in (True, False):
            request = SetBool.Request(data=data)

            def ask(request: Any = request) -> Any:
                return probe.call("/invert", SetBool, request, 5.0)

            answer = until(
                "an answer from /invert",
                ask,
                lambda a: a is not None,
                within=WITHIN,
                retry=(AssertionError,),
            )
            assert answer.message == f"inverted {data}"
            assert answer.success is (not data)
    finally:
        probe.close()


def test_a_service_end_bound_to_a_data_port_is_refused() -> None:
    text = SYSTEM.replace("from: Caller.ros,", "from: Caller.answers,")
    with pytest.raises(SystemFileError) as info:
        parse_system(text, "services.yaml")
    assert "services.yaml:7: field 'connections[0].from': a ros2_service end binds a " in str(
        info.value
    )
