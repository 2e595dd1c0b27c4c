"""The two cameras of the paper's RED robots, as synthetic image sources.

How it works: `Camera` (the perspective camera, CameraRTC) renders a `components.scene.Scene`
at `rate` Hz (`Periodic(param="rate")`) and writes each frame to its OutPort `image` as
`{"w", "h", "seq", "ts", "pixels"}`: `pixels` is `w*h` grayscale bytes, row-major, `seq` counts
frames from 1, `ts` is the wall-clock time of the frame. Scene time advances by `1 / rate` per
frame, so the picture sequence depends only on `seed`, size and the hazard schedule, never on
timing jitter. `OmnidirectionalCamera` (the fisheye camera, OmnidirectionalCameraRTC) produces
a 2:1 panoramic image (320x160 by default) in which objects wrap around horizontally. Changing
the size, seed or schedule while running rebuilds the scene.
"""

from __future__ import annotations

import time
from typing import Any, ClassVar

from components.base import RobotComponent
from components.scene import Scene
from sdrpeer.sdk import OutPort, Param, Periodic

__all__ = ["Camera", "OmnidirectionalCamera"]

_SCENE_PARAMS = frozenset({"width", "height", "seed", "objects", "hazard_period", "hazard_on"})


class Camera(RobotComponent):
    """A perspective camera: synthetic grayscale frames with a dangerous object now and then."""

    wrap: ClassVar[bool] = False
    execution = Periodic(param="rate")
    rate = Param(float, 10.0, "frames per second (0 pauses)", min=0.0, max=1000.0)
    width = Param(int, 160, "image width in pixels", min=16, max=4096)
    height = Param(int, 120, "image height in pixels", min=16, max=4096)
    seed = Param(int, 1, "scene seed: same seed, same pictures")
    objects = Param(int, 4, "ordinary moving objects", min=0, max=64)
    hazard_period = Param(
        float, 8.0, "seconds between appearances of the dangerous object", min=0.1
    )
    hazard_on = Param(float, 4.0, "seconds the dangerous object stays in view", min=0.0)
    image = OutPort("grayscale frame {w, h, seq, ts, pixels}")

    def on_initialize(self) -> None:
        """Build the scene."""
        self._build()
        self.seq = 0
        self.scene_time = 0.0

    def _build(self) -> None:
        self.scene = Scene(
            self.seed,
            self.width,
            self.height,
            wrap=self.wrap,
            objects=self.objects,
            period=self.hazard_period,
            on_time=self.hazard_on,
        )

    def on_execute(self) -> None:
        """Render and publish the next frame."""
        self.seq += 1
        pixels = self.scene.render(self.scene_time)
        self.image.write(
            {
                "w": self.width,
                "h": self.height,
                "seq": self.seq,
                "ts": time.time(),
                "pixels": pixels,
            }
        )
        self.scene_time += 1.0 / self.rate if self.rate > 0 else 0.0

    def on_params_changed(self, changed: dict[str, Any]) -> None:
        """Rebuild the scene when its size, seed or schedule changed."""
        if _SCENE_PARAMS & changed.keys():
            self._build()


class OmnidirectionalCamera(Camera):
    """A fisheye camera unrolled to a 2:1 panorama: objects wrap around horizontally."""

    wrap: ClassVar[bool] = True
    width = Param(int, 320, "panorama width in pixels (2 x height)", min=16, max=4096)
    height = Param(int, 160, "panorama height in pixels", min=16, max=4096)
    seed = Param(int, 2, "scene seed: same seed, same pictures")
