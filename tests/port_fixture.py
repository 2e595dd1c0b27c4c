"""Components the port tool tests feed: they keep what they take and hand it over as their
state (`on_snapshot`), so a test reads exactly what arrived, in order; and a typed camera."""

from __future__ import annotations

import time
from typing import Any

from sdrpeer.sdk import Component, Image, InPort, OnInput, OutPort, Periodic, Pose


class Keeper(Component):
    """Keeps every value arriving on `inp`, in order."""

    execution = OnInput("inp")
    inp = InPort("anything", {"buffer": 4096})

    def on_initialize(self) -> None:
        """Nothing yet."""
        self.values: list[Any] = []

    def on_execute(self) -> None:
        """Take every value waiting."""
        while self.inp.qsize():
            self.values.append(self.inp.get_nowait())

    def on_snapshot(self) -> list[Any]:
        """Everything taken so far."""
        return self.values


class PoseKeeper(Component):
    """Keeps (frame, x, y) of every Pose arriving on `pose`."""

    execution = OnInput("pose")
    pose = InPort("poses", {"buffer": 1024}, type=Pose)

    def on_initialize(self) -> None:
        """Nothing yet."""
        self.poses: list[list[Any]] = []

    def on_execute(self) -> None:
        """Take every pose waiting."""
        while self.pose.qsize():
            p = self.pose.get_nowait()
            self.poses.append([p.frame, p.x, p.y])

    def on_snapshot(self) -> list[list[Any]]:
        """Everything taken so far."""
        return self.poses


class SlowKeeper(Component):
    """Takes one value from `inp` per period (100 Hz) with the default policy (a buffer of 8
    that overwrites): a consumer slower than what is fed to it."""

    execution = Periodic(hz=100.0)
    inp = InPort("anything")

    def on_initialize(self) -> None:
        """Nothing yet."""
        self.values: list[Any] = []

    def on_execute(self) -> None:
        """Take the oldest value waiting, if any."""
        if self.inp.qsize():
            self.values.append(self.inp.get_nowait())

    def on_snapshot(self) -> list[Any]:
        """Everything taken so far."""
        return self.values


class MonoCamera(Component):
    """Publishes a 320x240 mono8 `Image` (76,800 bytes: sent as a blob) at 50 Hz, its first
    row's bytes the frame's number."""

    execution = Periodic(hz=50.0)
    image = OutPort("frames", type=Image)

    def on_initialize(self) -> None:
        """Nothing sent yet."""
        self.n = 0

    def on_execute(self) -> None:
        """The next frame."""
        self.n += 1
        data = bytes([self.n % 256]) * 320 + bytes(320 * 239)
        self.image.write(Image(time.time(), "cam", 320, 240, "mono8", 320, data))


class ImageKeeper(Component):
    """Keeps (stamp, the first row's first byte, len(data)) of every Image on `image`."""

    execution = OnInput("image")
    image = InPort("frames", {"buffer": 1024}, type=Image)

    def on_initialize(self) -> None:
        """Nothing yet."""
        self.images: list[list[Any]] = []

    def on_execute(self) -> None:
        """Take every image waiting."""
        while self.image.qsize():
            i = self.image.get_nowait()
            self.images.append([i.stamp, i.data[0], len(i.data)])

    def on_snapshot(self) -> list[list[Any]]:
        """Everything taken so far."""
        return self.images
