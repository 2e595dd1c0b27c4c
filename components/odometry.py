"""A wheel-odometry source: a robot driving a circle, as a typed `Odometry` stream.

How it works: `OdometrySource` writes an `sdrpeer.sdk.robot_types.Odometry` to its OutPort
`odom` at `rate` Hz (`Periodic(param="rate")`): the robot drives a circle of `radius` metres at
`speed` m/s in frame `odom` (child frame `base_link`), its pose and velocity computed from the
number of the message (`n / rate` seconds of driving), so the values depend only on the
parameters, never on timing jitter; `stamp` is the wall-clock time of the message. A standard
typed source for the port tools (a ROS 2-format recording of it is `nav_msgs/msg/Odometry`).
"""

from __future__ import annotations

import math
import time

from sdrpeer.sdk import Component, OutPort, Param, Periodic
from sdrpeer.sdk.robot_types import Odometry, Pose, Velocity

__all__ = ["OdometrySource"]


class OdometrySource(Component):
    """Odometry of a robot driving a circle."""

    execution = Periodic(param="rate")
    rate = Param(float, 50.0, "messages per second")
    radius = Param(float, 2.0, "the circle's radius (m)")
    speed = Param(float, 0.5, "forward speed (m/s)")
    odom = OutPort("where the robot is and how it moves", type=Odometry)

    def on_initialize(self) -> None:
        """Nothing sent yet."""
        self.n = 0

    def on_execute(self) -> None:
        """The next message."""
        self.n += 1
        turn = self.speed / self.radius  # rad/s
        heading = turn * self.n / self.rate
        now = time.time()
        x, y = self.radius * math.sin(heading), self.radius * (1 - math.cos(heading))
        qz, qw = math.sin(heading / 2), math.cos(heading / 2)
        pose = Pose(now, "odom", x, y, 0.0, 0.0, 0.0, qz, qw)
        velocity = Velocity(now, "base_link", self.speed, wz=turn)
        self.odom.write(Odometry(now, "odom", "base_link", pose, velocity))
