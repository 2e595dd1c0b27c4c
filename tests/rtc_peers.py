"""sdrpeer components that talk to the test RTC (tests/rtc_fixture.py) through typed ports."""

from __future__ import annotations

import time
from typing import Any

from sdrpeer.sdk import Component, InPort, OutPort, Periodic, Pose


class PosePub(Component):
    """Publishes a Pose with x = 1, 2, 3, ... at 20 Hz."""

    execution = Periodic(hz=20.0)
    out = OutPort("poses", type=Pose)

    def on_initialize(self) -> None:
        """Start from zero."""
        self.n = 0

    def on_execute(self) -> None:
        """The next pose, a quarter turn."""
        self.n += 1
        self.out.write(
            Pose(stamp=time.time(), frame="map", x=float(self.n), y=1.0, qz=0.7071068, qw=0.7071068)
        )


class PoseCheck(Component):
    """Takes echoed poses; ERROR on one whose x is odd or whose heading is not a quarter turn."""

    execution = Periodic(hz=20.0)
    inp = InPort("echoed poses", type=Pose)

    def on_execute(self) -> None:
        """Check what arrived."""
        while self.inp.qsize():
            pose: Any = self.inp.get_nowait()
            if pose.x % 2 != 0 or abs(pose.qz - 0.7071068) > 1e-4 or pose.y != 1.0:
                raise ValueError(f"pose not echoed as the RTC should: {pose}")
