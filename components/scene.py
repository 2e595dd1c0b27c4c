"""A synthetic camera scene: textured background, moving objects, and a dangerous object.

How it works: `Scene(seed, w, h)` draws everything from `random.Random(seed)` once: a background
texture (row gradient plus noise, levels 25..115), `objects` ordinary movers (discs and boxes at
levels 120..180), one decoy (a bright elongated bar, level 245, always there) and the hazard: a
bright disc (level 250) with a dark one-pixel rim, which is visible only while
`(t + phase) % period < on_time`. `render(t)` is a pure function of the time `t` in seconds:
every mover bounces between the image edges (or, with `wrap=True`, as in a panoramic image,
wraps around horizontally) and is drawn row by row with slice assignments, so a 160x120 frame
costs well under a millisecond. `hazard_at(t)` is the ground truth the detector tests use.
Only the hazard is both bright (>= 230) and round: the decoy is bright but a bar, the others
are round but dim, so a detector has to test brightness *and* shape.
"""

from __future__ import annotations

import math
import random
from dataclasses import dataclass
from typing import Final, Literal

__all__ = ["DECOY_LEVEL", "HAZARD_LEVEL", "Mover", "Scene"]

HAZARD_LEVEL: Final = 250
DECOY_LEVEL: Final = 245
RIM_LEVEL: Final = 10

Shape = Literal["disc", "box", "bar"]


@dataclass(frozen=True, slots=True)
class Mover:
    """One moving object; positions and speeds are fractions of the image size."""

    shape: Shape
    """disc, box (square) or bar (4:1 rectangle)."""
    level: int
    """Grey level, 0..255."""
    size: float
    """Radius (disc) or half-height (box, bar), as a fraction of the image height."""
    x0: float
    """Start position of the centre, fraction of the width."""
    y0: float
    """Start position of the centre, fraction of the height."""
    vx: float
    """Horizontal speed, widths per second."""
    vy: float
    """Vertical speed, heights per second."""


def _bounce(p: float) -> float:
    """A triangle wave over [0, 1]: p moving forever, folded back at both ends."""
    p %= 2.0
    return 2.0 - p if p > 1.0 else p


class Scene:
    """A deterministic scene; `render(t)` gives the grayscale pixels at time `t`."""

    def __init__(
        self,
        seed: int,
        w: int,
        h: int,
        *,
        wrap: bool = False,
        objects: int = 4,
        period: float = 8.0,
        on_time: float = 4.0,
    ) -> None:
        self.w = w
        self.h = h
        self.wrap = wrap
        self.period = period
        self.on_time = on_time
        rng = random.Random(seed)
        self.background = self._texture(rng)
        self.movers: list[Mover] = [
            self._mover(rng, rng.choice(("disc", "box"))) for _ in range(objects)
        ]
        self.decoy = self._mover(rng, "bar", level=DECOY_LEVEL, size=0.04)
        self.hazard = self._mover(rng, "disc", level=HAZARD_LEVEL, size=0.08)
        self.phase = rng.uniform(0.0, period)

    def _texture(self, rng: random.Random) -> bytes:
        w, h = self.w, self.h
        rows = []
        for y in range(h):
            base = 40 + 60 * y // max(1, h - 1)
            table = bytes(min(255, base - 15 + n * 30 // 255) for n in range(256))
            rows.append(rng.randbytes(w).translate(table))
        return b"".join(rows)

    @staticmethod
    def _mover(
        rng: random.Random, shape: Shape, *, level: int | None = None, size: float | None = None
    ) -> Mover:
        speed = rng.uniform(0.05, 0.2)
        angle = rng.uniform(0.0, 2.0 * math.pi)
        return Mover(
            shape=shape,
            level=level if level is not None else rng.randint(120, 180),
            size=size if size is not None else rng.uniform(0.05, 0.1),
            x0=rng.random(),
            y0=rng.random(),
            vx=speed * math.cos(angle),
            vy=speed * math.sin(angle),
        )

    def hazard_visible(self, t: float) -> bool:
        """Whether the dangerous object is in the picture at time `t`."""
        return (t + self.phase) % self.period < self.on_time

    def position(self, m: Mover, t: float) -> tuple[int, int, int, int]:
        """Centre (x, y) and half-extents (rx, ry) of `m` at time `t`, in pixels."""
        ry = max(2, round(m.size * self.h))
        rx = 4 * ry if m.shape == "bar" else ry
        if self.wrap:
            x = round(((m.x0 + m.vx * t) % 1.0) * self.w)
        else:
            x = rx + round(_bounce(m.x0 + m.vx * t) * max(0, self.w - 1 - 2 * rx))
        y = ry + 1 + round(_bounce(m.y0 + m.vy * t) * max(0, self.h - 3 - 2 * ry))
        return x, y, rx, ry

    def hazard_at(self, t: float) -> tuple[int, int] | None:
        """The hazard's centre in pixels at time `t`, or None while it is hidden."""
        if not self.hazard_visible(t):
            return None
        x, y, _, _ = self.position(self.hazard, t)
        return x % self.w, y

    def render(self, t: float, *, hazard: bool | None = None) -> bytes:
        """The frame at time `t` (w*h bytes, row-major); `hazard` overrides the schedule."""
        buf = bytearray(self.background)
        for m in (*self.movers, self.decoy):
            self._draw(buf, m, t, 0)
        if hazard if hazard is not None else self.hazard_visible(t):
            self._draw(buf, self.hazard, t, 1, RIM_LEVEL)
            self._draw(buf, self.hazard, t, 0)
        return bytes(buf)

    def _draw(
        self, buf: bytearray, m: Mover, t: float, grow: int, level: int | None = None
    ) -> None:
        cx, cy, rx, ry = self.position(m, t)
        rx += grow
        ry += grow
        w, h = self.w, self.h
        fill = level if level is not None else m.level
        for dy in range(-ry, ry + 1):
            y = cy + dy
            if not 0 <= y < h:
                continue
            half = math.isqrt(ry * ry - dy * dy) if m.shape == "disc" else rx
            self._span(buf, y * w, cx - half, cx + half + 1, fill)

    def _span(self, buf: bytearray, row: int, x0: int, x1: int, level: int) -> None:
        w = self.w
        if self.wrap:
            n = min(x1 - x0, w)
            x0 %= w
            x1 = x0 + n
            if x1 > w:
                buf[row + x0 : row + w] = bytes((level,)) * (w - x0)
                buf[row : row + x1 - w] = bytes((level,)) * (x1 - w)
                return
        x0, x1 = max(0, x0), min(w, x1)
        if x1 > x0:
            buf[row + x0 : row + x1] = bytes((level,)) * (x1 - x0)
