"""A wheel-odometry publisher: nav_msgs/Odometry on /odom at `rate_hz` (default 50), the robot
driving along x at `speed` m/s. Plain rclpy; `position.x / (speed / rate_hz)` counts the messages
since the node started, which lets a listener count the ones it missed."""

from __future__ import annotations

from nav_msgs.msg import Odometry
from rclpy.node import Node


class OdometryPublisher(Node):
    """Publishes /odom at rate_hz."""

    def __init__(self) -> None:
        super().__init__("odometry_publisher")
        self.declare_parameter("rate_hz", 50.0)
        self.declare_parameter("speed", 1.0)
        self.declare_parameter("topic", "/odom")
        self.rate = float(self.get_parameter("rate_hz").value)
        self.speed = float(self.get_parameter("speed").value)
        topic = str(self.get_parameter("topic").value)
        self.pub = self.create_publisher(Odometry, topic, 10)
        self.seq = 0
        self.timer = self.create_timer(1.0 / self.rate, self.tick)

    def tick(self) -> None:
        msg = Odometry()
        msg.header.stamp = self.get_clock().now().to_msg()
        msg.header.frame_id = "odom"
        msg.child_frame_id = "base_link"
        msg.pose.pose.position.x = self.seq * self.speed / self.rate
        msg.pose.pose.orientation.w = 1.0
        msg.twist.twist.linear.x = self.speed
        self.pub.publish(msg)
        self.seq += 1
