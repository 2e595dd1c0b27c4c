"""Components with typed ports, for the typed-port tests (sdrpeer.sdk.typed)."""

from __future__ import annotations

import time

from sdrpeer.sdk import Component, Image, InPort, OnInput, OutPort, Param, Periodic, Pose


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
