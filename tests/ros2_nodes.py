"""rclpy node classes that misbehave, for the ROS 2 host's tests (hosted by sdrpeer.ros2.host)."""

from __future__ import annotations

import time

from rclpy.node import Node
from std_msgs.msg import String


class Raising(Node):
    """Its timer callback raises on the third tick."""

    def __init__(self) -> None:
        super().__init__("raising")
        self.ticks = 0
        self.pub = self.create_publisher(String, "/raising", 10)
        self.timer = self.create_timer(0.05, self.tick)

    def tick(self) -> None:
        self.ticks += 1
        if self.ticks == 3:
            raise RuntimeError("sensor driver lost")
        self.pub.publish(String(data=str(self.ticks)))


class Blocking(Node):
    """Its timer callback blocks for 30 s on the second tick (a driver stuck in a read)."""

    def __init__(self) -> None:
        super().__init__("blocking")
        self.ticks = 0
        self.timer = self.create_timer(0.05, self.tick)

    def tick(self) -> None:
        self.ticks += 1
        if self.ticks == 2:
            time.sleep(30.0)


class Failing(Node):
    """Its constructor raises (a missing device at start)."""

    def __init__(self) -> None:
        super().__init__("failing")
        raise OSError("no such device: /dev/ttyUSB0")
