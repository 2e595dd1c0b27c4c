"""A pose listener: subscribes to geometry_msgs/PoseStamped on /pose (parameter `topic`) and
logs once a second how many it received. Plain rclpy."""

from __future__ import annotations

from geometry_msgs.msg import PoseStamped
from rclpy.node import Node


class PoseListener(Node):
    """Counts PoseStamped messages."""

    def __init__(self) -> None:
        super().__init__("pose_listener")
        self.declare_parameter("topic", "/pose")
        topic = str(self.get_parameter("topic").value)
        self.received = 0
        self.last: PoseStamped | None = None
        self.sub = self.create_subscription(PoseStamped, topic, self.heard, 10)
        self.timer = self.create_timer(1.0, self.report)

    def heard(self, msg: PoseStamped) -> None:
        self.received += 1
        self.last = msg

    def report(self) -> None:
        if self.last is not None:
            x = self.last.pose.position.x
            self.get_logger().info(f"{self.received} poses, last x={x:.2f}")
