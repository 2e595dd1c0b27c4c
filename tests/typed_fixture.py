"""Components with typed ports, for the typed-port tests (sdrpeer.sdk.typed)."""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any

from sdrpeer.sdk import Component, Image, InPort, OnInput, OutPort, Param, Periodic, Pose
from sdrpeer.sdk.robot_types import Odometry, Velocity
from sdrpeer.sdk.typed import MessageType, message, message_type

_ODOMETRY = message_type(Odometry)
assert _ODOMETRY is not None
ODOMETRY: MessageType = _ODOMETRY


class PosePub(Component):
    """Publishes a Pose at `rate` Hz, x counting up."""

    execution = Periodic(param="rate")
    rate = Param(float, 50.0, "poses per second")
    pose = OutPort("where we are", type=Pose)

    def on_initialize(self) -> None:
        """Start at the origin."""
        self.n = 0

    def on_execute(self) -> None:
        """The next pose."""
        self.n += 1
        self.pose.write(Pose(time.time(), "map", float(self.n), 0.0))


class PoseRec(Component):
    """Keeps the x of every Pose it takes."""

    execution = OnInput("pose")
    pose = InPort("poses", type=Pose)

    def on_initialize(self) -> None:
        """Nothing yet."""
        self.xs: list[float] = []

    def on_execute(self) -> None:
        """Take every pose waiting."""
        while self.pose.qsize():
            self.xs.append(self.pose.get_nowait().x)


class ImageRec(Component):
    """Takes images (a port of another type than PosePub's)."""

    execution = OnInput("image")
    image = InPort("images", type=Image)

    def on_execute(self) -> None:
        """Take every image waiting."""
        while self.image.qsize():
            self.image.get_nowait()


class OdomPub(Component):
    """Publishes an Odometry at `rate` Hz, its numbers counting up with `n` (x = n, y = 2n,
    vx = n / 10, wz = -n / 100), and keeps every value it sent (as its field arrays)."""

    execution = Periodic(param="rate")
    rate = Param(float, 50.0, "odometry messages per second")
    odom = OutPort("where we are and how we move", type=Odometry)

    def on_initialize(self) -> None:
        """Nothing sent yet."""
        self.n = 0
        self.sent: list[Any] = []

    def on_execute(self) -> None:
        """The next odometry."""
        self.n += 1
        n, now = float(self.n), time.time()
        pose = Pose(now, "odom", n, 2 * n, 0.0, 0.0, 0.0, 0.6, 0.8)
        value = Odometry(
            now, "odom", "base_link", pose, Velocity(now, "base_link", n / 10, wz=-n / 100)
        )
        self.odom.write(value)
        self.sent.append(ODOMETRY.flat(value))

    def on_snapshot(self) -> list[Any]:
        """Every value sent so far (field arrays)."""
        return self.sent


@message("lab/Detection")
@dataclass(slots=True)
class Detection:
    """A message type of a lab's own (no ROS 2 mapping)."""

    stamp: float
    label: str


class DetectionSource(Component):
    """Sends `Detection`s (a typed port whose type has no ROS 2 mapping)."""

    out = OutPort("detections", type=Detection)
