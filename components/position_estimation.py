"""Position estimation (PositionEstimationRTC): a corrected pose and "inside the area?".

How it works: `Estimator` is pure. It re-integrates the odometry stream increment by increment:
for each new sample it takes the distance travelled `d` (signed by whether the motion was along
the old heading) and the heading change, removes the known heading bias (`bias` rad per metre,
the wheel mismatch calibrated for this robot), and advances its own pose with the midpoint rule.
A step longer than `max_step` metres (a glitch, or the controller restarted its odometry) is not
integrated: the estimator re-anchors on the new sample and keeps its pose. `Area` is the
designated area `xmin,ymin,xmax,ymax` (a string param, since params are scalars) with
`contains`. The component runs once per odometry frame (`OnInput("odometry")`, push `new`) and
publishes `{"x", "y", "theta", "inside", "ts"}` on `pose`; it logs when the robot leaves or
re-enters the area. Migration: `on_snapshot` is the estimator's state (`Estimator.state`: the pose,
the last odometry sample, the glitch count); `on_restore` checks a state whole and takes it over,
also across the next activation (which otherwise starts afresh), so a new instance continues the
estimate where the old one stopped (a controller that restarted its odometry is one glitch).
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any, Final

from components.base import RobotComponent
from components.red_controller import Odometry, odometry_of, wrap_angle
from sdrpeer.sdk import InPort, OnInput, OutPort, Param

__all__ = ["Area", "Estimator", "PositionEstimation"]

STATE_VERSION: Final = 1
"""Version of the snapshot state (`Estimator.state`)."""


@dataclass(frozen=True, slots=True)
class Area:
    """An axis-aligned rectangle in metres."""

    xmin: float
    """Left edge."""
    ymin: float
    """Bottom edge."""
    xmax: float
    """Right edge."""
    ymax: float
    """Top edge."""

    @classmethod
    def parse(cls, text: str) -> Area:
        """`"xmin,ymin,xmax,ymax"` (or a JSON-style list); ValueError naming what is wrong."""
        parts = [p for p in text.strip().strip("[]").replace(" ", ",").split(",") if p]
        try:
            xmin, ymin, xmax, ymax = (float(p) for p in parts)
        except ValueError:
            raise ValueError(f"area {text!r}: expected four numbers xmin,ymin,xmax,ymax") from None
        if not (xmin < xmax and ymin < ymax):
            raise ValueError(f"area {text!r}: needs xmin < xmax and ymin < ymax")
        return cls(xmin, ymin, xmax, ymax)

    def contains(self, x: float, y: float) -> bool:
        """Whether (x, y) is inside (edges included)."""
        return self.xmin <= x <= self.xmax and self.ymin <= y <= self.ymax


class Estimator:
    """Dead reckoning over odometry samples, with heading-bias correction and glitch rejection."""

    def __init__(self, bias: float = 0.0, max_step: float = 0.5) -> None:
        self.bias = bias
        self.max_step = max_step
        self.pose = Odometry()
        """The current estimate."""
        self.glitches = 0
        """Samples not integrated because they jumped too far."""
        self._prev: Odometry | None = None

    def update(self, odo: Odometry) -> Odometry:
        """Take one odometry sample; return the new estimate."""
        prev, self._prev = self._prev, odo
        if prev is None:
            self.pose = odo
            return odo
        dx, dy = odo.x - prev.x, odo.y - prev.y
        d = math.hypot(dx, dy)
        if d > self.max_step:
            self.glitches += 1
            return self.pose
        if dx * math.cos(prev.theta) + dy * math.sin(prev.theta) < 0:
            d = -d
        dtheta = wrap_angle(odo.theta - prev.theta) - self.bias * abs(d)
        p = self.pose
        mid = p.theta + dtheta / 2.0
        self.pose = Odometry(
            p.x + d * math.cos(mid), p.y + d * math.sin(mid), wrap_angle(p.theta + dtheta)
        )
        return self.pose

    def state(self) -> dict[str, Any]:
        """What a successor needs to continue: pose, last sample, glitch count (msgpack-able)."""
        prev = self._prev
        return {
            "v": STATE_VERSION,
            "pose": [self.pose.x, self.pose.y, self.pose.theta],
            "prev": None if prev is None else [prev.x, prev.y, prev.theta],
            "glitches": self.glitches,
        }

    def load(self, state: Any) -> None:
        """Take over `state` (from `state()`); ValueError, changing nothing, if it is malformed."""
        if not isinstance(state, dict) or state.get("v") != STATE_VERSION:
            raise ValueError(f"estimator state: expected a map with v={STATE_VERSION}")
        pose = odometry_of(state.get("pose"), "estimator state 'pose'")
        raw_prev = state.get("prev")
        prev = None if raw_prev is None else odometry_of(raw_prev, "estimator state 'prev'")
        glitches = state.get("glitches", 0)
        if type(glitches) is not int or glitches < 0:
            raise ValueError(f"estimator state 'glitches': expected a count, got {glitches!r}")
        self.pose, self._prev, self.glitches = pose, prev, glitches


class PositionEstimation(RobotComponent):
    """Estimates the robot's pose from odometry and flags leaving the designated area."""

    execution = OnInput("odometry")
    area = Param(
        str, "-1,-1,1,1", "designated area xmin,ymin,xmax,ymax in metres", on_change="_set_area"
    )
    bias = Param(float, 0.02, "odometry heading bias to remove, rad per metre")
    max_step = Param(float, 0.5, "odometry steps longer than this (m) are glitches", min=0.0)
    odometry = InPort("{x, y, theta, ts} from the controller", policy={"push": "new"})
    pose = OutPort("{x, y, theta, inside, ts} per odometry sample")
    _restored: Estimator | None = None  # a restored estimate the next activation continues

    def on_initialize(self) -> None:
        """Check the area."""
        self._region = Area.parse(self.area)

    def _set_area(self, value: str) -> None:
        self._region = Area.parse(value)

    def on_activated(self) -> None:
        """Reserve memory; start a fresh estimate (or continue a restored one)."""
        super().on_activated()
        restored, self._restored = self._restored, None
        self.estimator = restored or Estimator(self.bias, self.max_step)
        self.inside: bool | None = None

    def on_deactivated(self) -> None:
        """Free the reserve; a state restored while active is not carried to a later activation."""
        super().on_deactivated()
        self._restored = None

    def on_snapshot(self) -> dict[str, Any] | None:
        """The estimator's state (None before the first activation and restore)."""
        est = getattr(self, "estimator", None)
        return est.state() if isinstance(est, Estimator) else None

    def on_restore(self, state: Any) -> None:
        """Continue from an earlier instance's estimate (ValueError if malformed)."""
        est = Estimator(self.bias, self.max_step)
        if state is not None:
            est.load(state)
        self.estimator = self._restored = est
        self.log.info("restored pose (%.2f, %.2f, %.2f)", est.pose.x, est.pose.y, est.pose.theta)

    def on_params_changed(self, changed: dict[str, Any]) -> None:
        """Apply a new bias or step limit to the running estimator."""
        if hasattr(self, "estimator"):
            self.estimator.bias = self.bias
            self.estimator.max_step = self.max_step

    def on_execute(self) -> None:
        """Update the estimate from the newest odometry sample and publish it."""
        if not self.odometry.is_new():
            return
        sample: dict[str, Any] = self.odometry.read()
        odo = Odometry(float(sample["x"]), float(sample["y"]), float(sample["theta"]))
        p = self.estimator.update(odo)
        inside = self._region.contains(p.x, p.y)
        if inside != self.inside and self.inside is not None:
            self.log.info("%s the area at (%.2f, %.2f)", "entered" if inside else "left", p.x, p.y)
        self.inside = inside
        self.pose.write({"x": p.x, "y": p.y, "theta": p.theta, "inside": inside, "ts": time.time()})
