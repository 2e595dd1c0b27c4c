"""REDControllerRTC as an OpenRTM-aist RT-Component: drives in a steady arc, stops while `alarm`
(`RTC::TimedBoolean`) is up or `inside` (`RTC::TimedBoolean`) is false, writes the command on
`cmd` (`RTC::TimedVelocity2D`) and dead-reckoned odometry on `odometry` (`RTC::TimedPose2D`)
every period (components.red_controller's `decide` and `integrate`); `pose`
(`RTC::TimedPose2D`) takes the estimator's pose, newest kept."""

from __future__ import annotations

import time
from typing import Any

import OpenRTM_aist
import RTC

from components.openrtm import rtc
from components.red_controller import Command, Odometry, decide, integrate

redcontroller_spec = rtc.spec(
    "REDController",
    "RED base: drive, stop on alarm or outside the area",
    10,
    {"speed": "0.2", "turn": "0.3", "drift": "0.02"},
)


class REDController(rtc.ReservingRTC):
    """Drives the RED base; stops on an alarm or outside the area."""

    def __init__(self, manager: Any) -> None:
        rtc.ReservingRTC.__init__(self, manager)
        self._d_alarm = RTC.TimedBoolean(RTC.Time(0, 0), False)
        self._alarmIn = OpenRTM_aist.InPort("alarm", self._d_alarm)
        self._d_inside = RTC.TimedBoolean(RTC.Time(0, 0), True)
        self._insideIn = OpenRTM_aist.InPort("inside", self._d_inside)
        self._d_pose = rtc.pose2d()
        self._poseIn = OpenRTM_aist.InPort("pose", self._d_pose)
        self._d_cmd = RTC.TimedVelocity2D(RTC.Time(0, 0), RTC.Velocity2D(0.0, 0.0, 0.0))
        self._cmdOut = OpenRTM_aist.OutPort("cmd", self._d_cmd)
        self._d_odometry = rtc.pose2d()
        self._odometryOut = OpenRTM_aist.OutPort("odometry", self._d_odometry)
        self._speed, self._turn, self._drift = [0.2], [0.3], [0.02]

    def onInitialize(self) -> Any:
        rtc.ReservingRTC.onInitialize(self)
        self.bindParameter("speed", self._speed, "0.2")
        self.bindParameter("turn", self._turn, "0.3")
        self.bindParameter("drift", self._drift, "0.02")
        self.addInPort("alarm", self._alarmIn)
        self.addInPort("inside", self._insideIn)
        self.addInPort("pose", self._poseIn)
        self.addOutPort("cmd", self._cmdOut)
        self.addOutPort("odometry", self._odometryOut)
        return RTC.RTC_OK

    def onActivated(self, ec_id: int) -> Any:
        rtc.ReservingRTC.onActivated(self, ec_id)
        self._odo = Odometry()
        self._alarm, self._inside = False, True
        self._last: Command | None = None
        self._prev: float | None = None
        return RTC.RTC_OK

    def onExecute(self, ec_id: int) -> Any:
        now = time.monotonic()
        if self._last is not None and self._prev is not None:
            dt = min(now - self._prev, 5.0 / self.get_context(ec_id).get_rate())
            self._odo = integrate(self._odo, self._last.v, self._last.w, dt, self._drift[0])
        self._prev = now
        while self._alarmIn.isNew():
            self._alarm = bool(self._alarmIn.read().data)
        while self._insideIn.isNew():
            self._inside = bool(self._insideIn.read().data)
        while self._poseIn.isNew():
            self._poseIn.read()
        self._last = decide(self._alarm, self._inside, self._speed[0], self._turn[0])
        self._d_cmd.data = RTC.Velocity2D(self._last.v, 0.0, self._last.w)
        OpenRTM_aist.setTimestamp(self._d_cmd)
        self._cmdOut.write()
        odo = self._odo
        self._d_odometry.data = RTC.Pose2D(RTC.Point2D(odo.x, odo.y), odo.theta)
        OpenRTM_aist.setTimestamp(self._d_odometry)
        self._odometryOut.write()
        return RTC.RTC_OK


def REDControllerInit(manager: Any) -> None:
    rtc.register(manager, redcontroller_spec, REDController)


def MyModuleInit(manager: Any) -> None:
    REDControllerInit(manager)
    manager.createComponent("REDController")


if __name__ == "__main__":
    rtc.main(MyModuleInit)
