"""Inputs for `sdrpeer profile`: synthetic frames per port, or frames recorded to a file.

How it works: a *source* is a function (seq from 1, time in seconds) -> the value to send. An InPort
named like a generator (`image`, `alarm`, `pose`, `odometry`, ...) gets that generator, any other
port a generic map; `--input port=image:WxH` sizes the images and `--input port=FILE` replays a
file of msgpack values in a loop.
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import msgpack

from sdrpeer.errors import ProfileError

Source = Callable[[int, float], Any]
"""An input source: (seq from 1, time in seconds) -> the value to send."""


def image_source(w: int = 160, h: int = 120) -> Source:
    """Grayscale frames: a scrolling gradient, and a bright disc for 2 s of every 4."""
    ramp = bytes(40 + (x * 70 // w) for x in range(w)) * 2
    r = max(2, h // 12)

    def frame(seq: int, t: float) -> dict[str, Any]:
        off = seq % w
        buf = bytearray(ramp[off : off + w] * h)
        if t % 4.0 < 2.0:
            cx, cy = int(w / 2 + w / 4 * math.sin(t)), h // 2
            for dy in range(-r, r + 1):
                half = math.isqrt(r * r - dy * dy)
                row = (cy + dy) * w
                buf[row + cx - half : row + cx + half + 1] = b"\xfa" * (2 * half + 1)
        return {"w": w, "h": h, "seq": seq, "ts": time.time(), "pixels": bytes(buf)}

    return frame


def file_source(path: Path) -> Source:
    """The msgpack values recorded in `path`, replayed in a loop."""
    with path.open("rb") as f:
        values = list(msgpack.Unpacker(f, raw=False))
    if not values:
        raise ProfileError(f"{path}: no msgpack values in the file")
    return lambda seq, t: values[(seq - 1) % len(values)]


GENERATORS: dict[str, Callable[[], Source]] = {
    "image": image_source,
    "alarm": lambda: (
        lambda seq, t: {"alarm": t % 5.0 < 1.0, "ts": time.time(), "where": None, "source": seq}
    ),
    "pose": lambda: (
        lambda seq, t: {
            "x": 0.1 * math.cos(t),
            "y": 0.1 * math.sin(t),
            "theta": t,
            "inside": True,
            "ts": time.time(),
        }
    ),
    "odometry": lambda: (
        lambda seq, t: {
            "x": 0.5 * math.sin(0.3 * t),
            "y": 0.5 - 0.5 * math.cos(0.3 * t),
            "theta": 0.3 * t,
            "ts": time.time(),
        }
    ),
    "map": lambda: lambda seq, t: {"seq": seq, "ts": time.time(), "value": math.sin(t)},
}
"""Input generators by name; an InPort without `--input` uses the one named like it, or `map`."""


def make_source(port: str, spec: str = "") -> tuple[Source, str]:
    """The source for `port` from `--input port=SPEC` (empty: by port name) and its label."""
    name = spec or (port if port in GENERATORS else "map")
    if name.startswith("image:"):
        try:
            w, h = (int(v) for v in name[6:].lower().split("x"))
        except ValueError:
            raise ProfileError(f"--input {port}={spec}: expected image:WIDTHxHEIGHT") from None
        return image_source(w, h), name
    factory = GENERATORS.get(name)
    if factory is not None:
        return factory(), name
    path = Path(name)
    if not path.is_file():
        known = ", ".join(GENERATORS)
        raise ProfileError(f"--input {port}={spec}: no such generator ({known}) or file")
    return file_source(path), str(path)
