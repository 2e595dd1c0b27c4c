"""Components on both sides of the ROS 2 service bridges (sdrpeer.ros2.services), for
tests/test_ros2_services.py: an rclpy node offering /reset (std_srvs/Trigger), an sdrpeer
component calling it, and an sdrpeer component answering /invert (std_srvs/SetBool) for ROS 2
clients."""

from __future__ import annotations

from typing import Any

from rclpy.node import Node
from std_srvs.srv import Trigger

from sdrpeer.ros2.services import ROS2_SERVICE
from sdrpeer.sdk import Component, OutPort, Periodic, ServiceConsumer, ServiceProvider
from sdrpeer.sdk.services import ServiceCallError


class ResetServer(Node):
    """An unmodified rclpy node: /reset answers `reset N`."""

    def __init__(self) -> None:
        super().__init__("reset_server")
        self.count = 0
        self.srv = self.create_service(Trigger, "/reset", self.reset)

    def reset(self, request: Any, response: Any) -> Any:
        self.count += 1
        response.success = True
        response.message = f"reset {self.count}"
        return response


class ResetCaller(Component):
    """Calls /reset through its `ros` port at 5 Hz; each answer's message goes out on `answers`."""

    execution = Periodic(hz=5.0)
    ros = ServiceConsumer(ROS2_SERVICE, "the ROS 2 /reset service")
    answers = OutPort("the message of each answer")

    async def on_execute(self) -> None:
        try:
            answer = await self.ros.call("call", {}, timeout=2.0)
        except ServiceCallError as exc:
            self.log.info("call failed: %s", exc)
            return
        if answer.get("success"):
            self.answers.write(answer["message"])


class Inverter(Component):
    """Answers /invert (std_srvs/SetBool) for ROS 2 clients: success = not data."""

    ros = ServiceProvider(ROS2_SERVICE, "serves /invert")

    @ros.method
    def call(self, request: dict[str, Any]) -> dict[str, Any]:
        return {"success": not request["data"], "message": f"inverted {request['data']}"}
