"""Anomaly detection (AnomalyDetectionRTC): find the dangerous object in camera frames.

How it works: `find_hazard` is pure. It thresholds the frame in one C-level pass
(`bytes.translate` with a 256-entry table: 1 for levels >= `threshold`, else 0), then walks only
the bright pixels (`find` jumps over the dark ones) and grows each 4-connected bright region with
a stack, recording its area, bounding box and centroid. A region is the dangerous object when
its area lies in [min_area, max_area] and its shape is a disc: the bounding box nearly square
(aspect 0.75..1.33) and filled to about pi/4 (fill 0.6..0.92). Bright bars and dim round
objects of the scene (components.scene) are therefore rejected. With `wrap` (the panorama of
the omnidirectional camera) the left and right edges are neighbours, so an object cut in two by
the seam is one region (its columns are tracked unwrapped from where the walk started); the
param `wrap=auto` wraps frames at least twice as wide as high. At 160x120 a frame takes about a
millisecond. `AnomalyDetection` runs `find_hazard` once per received frame (`OnInput("image")`,
push policy `new`: a late detector skips to the newest frame), publishes
`{"alarm": bool, "ts", "where": [x, y] | None, "source": frame seq}` on `alarm` for every frame,
and logs each raise and clear of the alarm.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Any, Final

from components.base import RobotComponent
from sdrpeer.sdk import InPort, OnInput, OutPort, Param

__all__ = ["AnomalyDetection", "Blob", "find_blobs", "find_hazard", "is_hazard"]

ASPECT: Final = (0.75, 1.33)
WRAP: Final = ("auto", "yes", "no")
FILL: Final = (0.6, 0.92)
_TABLES: dict[int, bytes] = {}


@dataclass(frozen=True, slots=True)
class Blob:
    """One 4-connected bright region."""

    area: int
    """Pixels in the region."""
    x: float
    """Centroid column."""
    y: float
    """Centroid row."""
    width: int
    """Bounding box width."""
    height: int
    """Bounding box height."""

    @property
    def fill(self) -> float:
        """Area over bounding-box area (a disc: about 0.785)."""
        return self.area / (self.width * self.height)

    @property
    def aspect(self) -> float:
        """Bounding box width over height."""
        return self.width / self.height


def _table(threshold: int) -> bytes:
    table = _TABLES.get(threshold)
    if table is None:
        table = _TABLES[threshold] = bytes(1 if v >= threshold else 0 for v in range(256))
    return table


def find_blobs(pixels: bytes, w: int, h: int, threshold: int, *, wrap: bool = False) -> list[Blob]:
    """Every 4-connected region of levels >= `threshold`; `wrap`: columns 0 and w-1 touch."""
    if len(pixels) != w * h:
        raise ValueError(f"frame of {len(pixels)} bytes is not {w}x{h}")
    mask = bytearray(pixels.translate(_table(threshold)))
    blobs: list[Blob] = []
    start = mask.find(1)
    while start >= 0:
        mask[start] = 0
        stack = [(start, start % w)]  # (index, column unwrapped relative to the seed)
        area = sx = sy = 0
        x0 = y0 = 1 << 30
        x1 = y1 = -(1 << 30)
        while stack:
            i, ux = stack.pop()
            y, x = divmod(i, w)
            area += 1
            sx += ux
            sy += y
            x0, x1, y0, y1 = min(x0, ux), max(x1, ux), min(y0, y), max(y1, y)
            for j, vx in (
                (i - 1 if x > 0 else (i + w - 1 if wrap else -1), ux - 1),
                (i + 1 if x < w - 1 else (i - w + 1 if wrap else -1), ux + 1),
                (i - w if y > 0 else -1, ux),
                (i + w if y < h - 1 else -1, ux),
            ):
                if j >= 0 and mask[j]:
                    mask[j] = 0
                    stack.append((j, vx))
        blobs.append(Blob(area, (sx / area) % w, sy / area, x1 - x0 + 1, y1 - y0 + 1))
        start = mask.find(1, start + 1)
    return blobs


def is_hazard(blob: Blob, min_area: int, max_area: int) -> bool:
    """Whether `blob` has the size and the round shape of the dangerous object."""
    return (
        min_area <= blob.area <= max_area
        and ASPECT[0] <= blob.aspect <= ASPECT[1]
        and FILL[0] <= blob.fill <= FILL[1]
    )


def find_hazard(
    pixels: bytes,
    w: int,
    h: int,
    *,
    threshold: int = 230,
    min_area: int = 20,
    max_area: int = 5000,
    wrap: bool = False,
) -> Blob | None:
    """The largest region that passes `is_hazard`, or None."""
    blobs = find_blobs(pixels, w, h, threshold, wrap=wrap)
    found = [b for b in blobs if is_hazard(b, min_area, max_area)]
    return max(found, key=lambda b: b.area, default=None)


class AnomalyDetection(RobotComponent):
    """Raises an alarm while the dangerous object is in the camera's view."""

    execution = OnInput("image")
    threshold = Param(int, 230, "grey level from which a pixel counts as bright", min=1, max=255)
    min_area = Param(int, 20, "smallest hazard in pixels", min=1)
    max_area = Param(int, 5000, "largest hazard in pixels", min=1)
    wrap = Param(str, "auto", "edges touch: yes, no, auto (a 2:1 panorama)", choices=WRAP)
    image = InPort("camera frames {w, h, seq, ts, pixels}", policy={"push": "new", "buffer": 1})
    alarm = OutPort("{alarm, ts, where, source} for every frame")

    def on_activated(self) -> None:
        """Reserve memory; count from zero."""
        super().on_activated()
        self.frames = 0
        self.alarms = 0
        self.raised = False

    def on_execute(self) -> None:
        """Scan the newest frame and publish the verdict."""
        if not self.image.is_new():
            return
        frame: dict[str, Any] = self.image.read()
        w, h = frame["w"], frame["h"]
        blob = find_hazard(
            frame["pixels"],
            w,
            h,
            threshold=self.threshold,
            min_area=self.min_area,
            max_area=self.max_area,
            wrap=self.wrap == "yes" or (self.wrap == "auto" and w >= 2 * h),
        )
        self.frames += 1
        self.alarms += blob is not None
        where = [round(blob.x, 1), round(blob.y, 1)] if blob is not None else None
        if (blob is not None) != self.raised:
            self.raised = blob is not None
            self.log.info(
                "alarm %s (frame %s, at %s)", "raised" if blob else "cleared", frame["seq"], where
            )
        self.alarm.write(
            {"alarm": blob is not None, "ts": time.time(), "where": where, "source": frame["seq"]}
        )
