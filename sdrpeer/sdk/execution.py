"""Execution contexts: when a component's `on_execute` runs (OpenRTM's ExecutionContext).

How it works: a Component class names one with `execution = Periodic(hz=10.0)`,
`Periodic(param="rate")` (the rate read from a numeric Param before every period, so it can be
changed live, `on_rate_changed` told; a rate <= 0 pauses execution), `OnInput("port")` (once per
frame accepted by that InPort) or `Stepped()` (only when the caller advances it:
`ComponentRunner.step(n)`, the host's `step` command, `POST /v1/instances/NAME/step`; OpenRTM's
ExtTrig, for simulators and deterministic tests). These are plain frozen descriptions, checked
against the class when it is created; `ComponentRunner` (sdrpeer.sdk.runner) runs them, calling
`on_execute` only while ACTIVE and `on_error` instead while in ERROR.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ["ExecutionContext", "OnInput", "Periodic", "Stepped"]


@dataclass(frozen=True, slots=True)
class Periodic:
    """Run `on_execute` periodically at a fixed rate or at the rate held by a Param."""

    hz: float | None = None
    """Fixed rate in executions per second (> 0)."""
    param: str | None = None
    """Name of an int/float Param holding the rate in Hz instead (changeable while running)."""

    def __post_init__(self) -> None:
        if (self.hz is None) == (self.param is None):
            raise ValueError("Periodic: give exactly one of hz=... or param=...")
        if self.hz is not None and not (math.isfinite(self.hz) and self.hz > 0):
            raise ValueError(f"Periodic: hz must be a positive number, not {self.hz!r}")


@dataclass(frozen=True, slots=True)
class OnInput:
    """Run `on_execute` once for each frame accepted by the named InPort."""

    port: str
    """The InPort's name (its attribute name on the class)."""


@dataclass(frozen=True, slots=True)
class Stepped:
    """Run `on_execute` only when the caller steps the context (no clock, no input trigger)."""


ExecutionContext = Periodic | OnInput | Stepped
