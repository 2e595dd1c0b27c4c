"""Motion control of a RED robot (REDControllerRTC): drive, or stop on danger or off the area.

How it works: `decide(alarm, inside, speed, turn)` is the pure rule: drive at `(speed, turn)`
unless an alarm is up or the pose says the robot is outside the designated area, then stop
(`v = w = 0`) and say why (`"alarm"`, `"outside"` or `"alarm,outside"`). `integrate(odo, v, w,
dt, drift)` is pure dead reckoning (midpoint rule) of the commanded velocities, with a
systematic heading error of `drift` radians per metre travelled, standing in for the wheel
mismatch of a real base (it is what PositionEstimation's bias correction removes). The
component runs periodically (`rate`, 10 Hz), reads the newest `alarm` and `pose` (push policy
`new`; before the first one arrives it assumes no alarm and inside), measures the time since
its previous period on the monotonic clock (capped at five periods, so a stall does not teleport
the robot), integrates the command that was in force over that time, decides anew, and
publishes `cmd` `{"v", "w", "ts", "stopped", "reason"}` and `odometry` `{"x", "y", "theta",
"ts"}` every period. Migration: `on_snapshot` is `{"v": 1, "odometry": [x, y, theta], "stops"}`;
`on_restore` checks it whole and continues from it, also across the next activation (which
otherwise restarts at the origin), so a new instance's odometry goes on where the old one stopped.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass
from typing import Any

from components.base import RobotComponent
from sdrpeer.sdk import InPort, NoData, OutPort, Param, Periodic

__all__ = ["Command", "Odometry", "REDController", "decide", "integrate", "odometry_of"]


@dataclass(frozen=True, slots=True)
class Command:
    """One velocity command."""

    v: float
    """Forward speed, m/s."""
    w: float
    """Turn rate, rad/s (positive: left)."""
    reason: str | None
    """Why the robot stopped, or None while it drives."""

    @property
    def stopped(self) -> bool:
        """True when the command is a stop."""
        return self.reason is not None


@dataclass(frozen=True, slots=True)
class Odometry:
    """A dead-reckoned pose in the odometry frame (start: origin, facing +x)."""

    x: float = 0.0
    """Metres."""
    y: float = 0.0
    """Metres."""
    theta: float = 0.0
    """Heading in radians, wrapped to (-pi, pi]."""


def wrap_angle(a: float) -> float:
    """`a` wrapped to (-pi, pi]."""
    a = math.remainder(a, 2.0 * math.pi)
    return math.pi if a == -math.pi else a


def decide(alarm: bool, inside: bool, speed: float, turn: float) -> Command:
    """Drive at (speed, turn) unless alarmed or outside the area."""
    reasons = [r for r, hit in (("alarm", alarm), ("outside", not inside)) if hit]
    if reasons:
        return Command(0.0, 0.0, ",".join(reasons))
    return Command(speed, turn, None)


def integrate(odo: Odometry, v: float, w: float, dt: float, drift: float = 0.0) -> Odometry:
    """The pose after driving (v, w) for dt seconds, with `drift` rad/m of heading error."""
    d = v * dt
    dtheta = w * dt + drift * abs(d)
    mid = odo.theta + dtheta / 2.0
    return Odometry(
        odo.x + d * math.cos(mid), odo.y + d * math.sin(mid), wrap_angle(odo.theta + dtheta)
    )


def odometry_of(value: Any, what: str) -> Odometry:
    """An Odometry from `[x, y, theta]` (finite numbers); ValueError naming `what` otherwise."""
    ok = isinstance(value, list | tuple) and len(value) == 3
    if ok and all(isinstance(v, int | float) and not isinstance(v, bool) for v in value):
        x, y, theta = (float(v) for v in value)
        if all(map(math.isfinite, (x, y, theta))):
            return Odometry(x, y, theta)
    raise ValueError(f"{what}: expected [x, y, theta] finite numbers, got {value!r}")


class REDController(RobotComponent):
    """Drives the RED base in a steady arc; stops on an alarm or outside the area."""

    execution = Periodic(param="rate")
    rate = Param(float, 10.0, "control periods per second", min=0.0, max=1000.0)
    speed = Param(float, 0.2, "forward speed while driving, m/s")
    turn = Param(float, 0.3, "turn rate while driving, rad/s")
    drift = Param(float, 0.02, "odometry heading error, rad per metre (wheel mismatch)")
    alarm = InPort("{alarm, ts, where, source} from anomaly detection", policy={"push": "new"})
    pose = InPort("{x, y, theta, inside, ts} from position estimation", policy={"push": "new"})
    cmd = OutPort("{v, w, ts, stopped, reason} each period")
    odometry = OutPort("{x, y, theta, ts} each period")
    _restored: tuple[Odometry, int] | None = None  # odometry and stops the next activation keeps

    def on_activated(self) -> None:
        """Reserve memory; restart the dead reckoning at the origin (or where it was restored)."""
        super().on_activated()
        restored, self._restored = self._restored, None
        self.odo, self.stops = restored or (Odometry(), 0)
        self.last: Command | None = None
        self._prev: float | None = None

    def on_deactivated(self) -> None:
        """Free the reserve; a state restored while active is not carried to a later activation."""
        super().on_deactivated()
        self._restored = None

    def on_snapshot(self) -> dict[str, Any] | None:
        """The odometry and stop count (None before the first activation and restore)."""
        odo = getattr(self, "odo", None)
        if not isinstance(odo, Odometry):
            return None
        return {"v": 1, "odometry": [odo.x, odo.y, odo.theta], "stops": self.stops}

    def on_restore(self, state: Any) -> None:
        """Continue the odometry of an earlier instance (ValueError if the state is malformed)."""
        odo, stops = Odometry(), 0
        if state is not None:
            if not isinstance(state, dict) or state.get("v") != 1:
                raise ValueError("controller state: expected a map with v=1")
            odo = odometry_of(state.get("odometry"), "controller state 'odometry'")
            stops = state.get("stops", 0)
            if type(stops) is not int or stops < 0:
                raise ValueError(f"controller state 'stops': expected a count, got {stops!r}")
        self.odo, self.stops = odo, stops
        self._restored = (odo, stops)

    def _newest(self, port: str, key: str, default: bool) -> bool:
        try:
            value: dict[str, Any] = self.inport(port).read()
        except NoData:
            return default
        return bool(value.get(key, default))

    def on_execute(self) -> None:
        """Integrate the previous command into the odometry, decide, publish both."""
        now = time.monotonic()
        if self.last is not None and self._prev is not None:
            nominal = 1.0 / self.rate if self.rate > 0 else 0.1
            dt = min(now - self._prev, 5.0 * nominal)
            self.odo = integrate(self.odo, self.last.v, self.last.w, dt, self.drift)
        self._prev = now
        alarm = self._newest("alarm", "alarm", False)
        inside = self._newest("pose", "inside", True)
        command = decide(alarm, inside, self.speed, self.turn)
        if command.stopped and (self.last is None or not self.last.stopped):
            self.stops += 1
            self.log.info("stop: %s", command.reason)
        self.last = command
        ts = time.time()
        self.cmd.write(
            {
                "v": command.v,
                "w": command.w,
                "ts": ts,
                "stopped": command.stopped,
                "reason": command.reason,
            }
        )
        self.odometry.write({"x": self.odo.x, "y": self.odo.y, "theta": self.odo.theta, "ts": ts})
