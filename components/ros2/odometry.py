"""A wheel-odometry publisher: nav_msgs/Odometry on /odom at `rate_hz` (default 50), the robot
driving along x at `speed` m/s, and a listener that counts what it hears. Plain rclpy;
`position.x / (speed / rate_hz)` counts the messages since the publisher's node started, which
lets a listener count the ones it missed."""

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


class OdometryListener(Node):
    """Subscribes to /odom (parameter `topic`) and logs once a second how many it received."""

    def __init__(self) -> None:
        super().__init__("odometry_listener")
        self.declare_parameter("topic", "/odom")
        self.received = 0
        topic = str(self.get_parameter("topic").value)
        self.sub = self.create_subscription(Odometry, topic, self.heard, 10)
        self.timer = self.create_timer(1.0, self.report)

    def heard(self, msg: Odometry) -> None:
        self.received += 1

    def report(self) -> None:
        self.get_logger().info(f"{self.received} odometry messages")
