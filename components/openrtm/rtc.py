"""What the five RTC modules share, in OpenRTM-aist's own terms: the spec list, the memory
reserve the paper's components held while active, factory registration and a standalone main.

How it works: `spec(type_name, description, rate, conf)` is the usual OpenRTM spec list (the
`conf` map becomes `conf.default.*`, plus `reserve_mb`); `ReservingRTC` is a
`DataFlowComponentBase` that binds `reserve_mb` and holds that many MiB of touched memory
(components.base.MemoryReserve) from `onActivated` to `onDeactivated`/`onFinalize`; subclasses
call its `onInitialize`/`onActivated` first. `pose2d()` is a zero `RTC::TimedPose2D`.
`register(manager, spec, cls)` is what every `XxxInit(manager)` does; `main(init)` runs a module
under OpenRTM's own manager, as rtcd would.
"""

from __future__ import annotations

import sys
from collections.abc import Callable
from typing import Any

import OpenRTM_aist
import RTC

from components.base import MemoryReserve


def spec(type_name: str, description: str, rate: float, conf: dict[str, str]) -> list[str]:
    """An OpenRTM spec list for a periodic data-flow RTC of `type_name`."""
    items = [
        "implementation_id", type_name, "type_name", type_name, "description", description,
        "version", "1.0", "vendor", "sdrpeer", "category", "RED", "activity_type", "PERIODIC",
        "kind", "DataFlowComponent", "max_instance", "1", "language", "Python",
        "lang_type", "SCRIPT", "exec_cxt.periodic.rate", f"{rate:g}",
    ]  # fmt: skip
    for key, value in {**conf, "reserve_mb": "0"}.items():
        items += [f"conf.default.{key}", value]
    return [*items, ""]


def pose2d() -> Any:
    """A zero `RTC::TimedPose2D`, a DataPort's variable."""
    return RTC.TimedPose2D(RTC.Time(0, 0), RTC.Pose2D(RTC.Point2D(0.0, 0.0), 0.0))


class ReservingRTC(OpenRTM_aist.DataFlowComponentBase):  # type: ignore[misc]
    """An RTC that holds `reserve_mb` MiB of touched memory while active (the paper: 500)."""

    def __init__(self, manager: Any) -> None:
        OpenRTM_aist.DataFlowComponentBase.__init__(self, manager)
        self._reserve_mb = [0]
        self._reserve = MemoryReserve()

    def onInitialize(self) -> Any:
        self.bindParameter("reserve_mb", self._reserve_mb, "0")
        return RTC.RTC_OK

    def onActivated(self, ec_id: int) -> Any:
        self._reserve.allocate(self._reserve_mb[0])
        return RTC.RTC_OK

    def onDeactivated(self, ec_id: int) -> Any:
        self._reserve.release()
        return RTC.RTC_OK

    def onFinalize(self) -> Any:
        self._reserve.release()
        return RTC.RTC_OK


def register(manager: Any, spec_list: list[str], cls: type) -> None:
    """Register `cls`'s factory with OpenRTM's manager (the body of every `XxxInit`)."""
    profile = OpenRTM_aist.Properties(defaults_str=spec_list)
    manager.registerFactory(profile, cls, OpenRTM_aist.Delete)


def main(init: Callable[[Any], None]) -> None:
    """Run a module under OpenRTM's own manager (rtc.conf, naming service: as OpenRTM does)."""
    manager = OpenRTM_aist.Manager.init(sys.argv)
    manager.setModuleInitProc(init)
    manager.activateManager()
    manager.runManager()
