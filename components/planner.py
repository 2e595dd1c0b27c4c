"""A service pair: `PathPlanner` provides the `demo/Planner` interface, `PlanCaller` calls it.

How it works: `plan(start, goal, step)` is the pure rule: a straight path from `start` to `goal`
in steps of at most `step` metres (both ends included). `PathPlanner` provides `planner`
(methods `compute`, typed `Goal` -> `Path`, and `status`, untyped: how many paths it computed
and the instance that answered). `PlanCaller` runs periodically (`rate`, 5 Hz): each period it
calls `planner.compute` towards a goal that moves along a circle, with a timeout of one
period; a path that comes back is written on `path` (its waypoint count), a failed call is
counted by the SDK in the port's `failed` and logged (first of each kind). System file wiring:
a connection `from: PlanCaller.planner` `to: PathPlanner.planner`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

from sdrpeer.sdk import (
    Component,
    Interface,
    OutPort,
    Param,
    Periodic,
    ServiceCallError,
    ServiceConsumer,
    ServiceProvider,
    Stepped,
    message,
)

__all__ = ["PLANNER", "Goal", "Path", "PathPlanner", "PlanCaller", "plan"]


@message("demo/Goal")
@dataclass(frozen=True, slots=True)
class Goal:
    """Where to go from where."""

    x0: float
    y0: float
    x: float
    y: float


@message("demo/Path")
@dataclass(frozen=True, slots=True)
class Path:
    """The waypoints, `xs[i], ys[i]`, start and goal included."""

    xs: list[float]
    ys: list[float]


PLANNER = Interface.of("demo/Planner", "compute", "status", types={"compute": (Goal, Path)})
"""The planner's interface."""


def plan(start: tuple[float, float], goal: tuple[float, float], step: float) -> Path:
    """A straight path in steps of at most `step` metres (ValueError when `step` <= 0)."""
    if step <= 0:
        raise ValueError(f"step must be > 0, got {step}")
    dx, dy = goal[0] - start[0], goal[1] - start[1]
    n = max(1, math.ceil(math.hypot(dx, dy) / step))
    xs = [start[0] + dx * i / n for i in range(n + 1)]
    ys = [start[1] + dy * i / n for i in range(n + 1)]
    return Path(xs, ys)


class PathPlanner(Component):
    """Provides `demo/Planner`: straight paths in steps of `step` metres."""

    execution = Stepped()  # it only answers calls
    step = Param(float, 0.5, "longest step between waypoints, m")
    planner = ServiceProvider(PLANNER, "plans paths")

    def on_initialize(self) -> None:
        """No path computed yet."""
        self.computed = 0

    @planner.method
    def compute(self, goal: Goal) -> Path:
        """The path from (x0, y0) to (x, y)."""
        self.computed += 1
        return plan((goal.x0, goal.y0), (goal.x, goal.y), self.param_values()["step"])

    @planner.method
    def status(self, _: object) -> dict[str, object]:
        """How many paths this instance computed, and its name."""
        return {"computed": self.computed, "instance": self.instance_name}


class PlanCaller(Component):
    """Calls `demo/Planner.compute` every period and publishes each path's length."""

    execution = Periodic(param="rate")
    rate = Param(float, 5.0, "calls per second")
    planner = ServiceConsumer(PLANNER, "the planner it asks")
    path = OutPort("the waypoint count of each path received")

    def on_initialize(self) -> None:
        """Start at the origin."""
        self.n = 0
        self.errors: set[str] = set()

    async def on_execute(self) -> None:
        """Ask for a path to the next goal on a circle of radius 3 m."""
        self.n += 1
        angle = self.n * 0.1
        goal = Goal(0.0, 0.0, 3 * math.cos(angle), 3 * math.sin(angle))
        timeout = 1.0 / max(self.param_values()["rate"], 0.1)
        try:
            path = await self.planner.call("compute", goal, timeout=timeout)
        except ServiceCallError as exc:
            kind = type(exc).__name__
            if kind not in self.errors:
                self.errors.add(kind)
                self.log.warning("planner call failed: %s", exc)
            return
        self.path.write(len(path.xs))
