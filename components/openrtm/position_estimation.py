"""PositionEstimationRTC as an OpenRTM-aist RT-Component: re-integrates the controller's
`odometry` (`RTC::TimedPose2D`) with the heading bias removed (components.position_estimation's
`Estimator`), writes the estimate on `pose` (`RTC::TimedPose2D`) and whether it is inside the
designated area on `inside` (`RTC::TimedBoolean`)."""

from __future__ import annotations

from typing import Any

import OpenRTM_aist
import RTC

from components.openrtm import rtc
from components.position_estimation import Area, Estimator
from components.red_controller import Odometry

positionestimation_spec = rtc.spec(
    "PositionEstimation",
    "corrected pose, inside the designated area or not",
    20,
    {"area": "-1,-1,1,1", "bias": "0.02", "max_step": "0.5"},
)


class PositionEstimation(rtc.ReservingRTC):
    """Estimates the robot's pose from odometry and flags leaving the designated area."""

    def __init__(self, manager: Any) -> None:
        rtc.ReservingRTC.__init__(self, manager)
        self._d_odometry = rtc.pose2d()
        self._odometryIn = OpenRTM_aist.InPort("odometry", self._d_odometry)
        self._d_pose = rtc.pose2d()
        self._poseOut = OpenRTM_aist.OutPort("pose", self._d_pose)
        self._d_inside = RTC.TimedBoolean(RTC.Time(0, 0), True)
        self._insideOut = OpenRTM_aist.OutPort("inside", self._d_inside)
        self._area, self._bias, self._max_step = ["-1,-1,1,1"], [0.02], [0.5]

    def onInitialize(self) -> Any:
        rtc.ReservingRTC.onInitialize(self)
        self.bindParameter("area", self._area, "-1,-1,1,1")
        self.bindParameter("bias", self._bias, "0.02")
        self.bindParameter("max_step", self._max_step, "0.5")
        self.addInPort("odometry", self._odometryIn)
        self.addOutPort("pose", self._poseOut)
        self.addOutPort("inside", self._insideOut)
        return RTC.RTC_OK

    def onActivated(self, ec_id: int) -> Any:
        try:
            self._region = Area.parse(self._area[0])
        except ValueError:
            return RTC.RTC_ERROR
        rtc.ReservingRTC.onActivated(self, ec_id)
        self._estimator = Estimator(self._bias[0], self._max_step[0])
        return RTC.RTC_OK

    def onExecute(self, ec_id: int) -> Any:
        while self._odometryIn.isNew():
            sample = self._odometryIn.read().data
            odo = Odometry(sample.position.x, sample.position.y, sample.heading)
            p = self._estimator.update(odo)
            self._d_pose.data = RTC.Pose2D(RTC.Point2D(p.x, p.y), p.theta)
            OpenRTM_aist.setTimestamp(self._d_pose)
            self._poseOut.write()
            self._d_inside.data = self._region.contains(p.x, p.y)
            OpenRTM_aist.setTimestamp(self._d_inside)
            self._insideOut.write()
        return RTC.RTC_OK


def PositionEstimationInit(manager: Any) -> None:
    rtc.register(manager, positionestimation_spec, PositionEstimation)


def MyModuleInit(manager: Any) -> None:
    PositionEstimationInit(manager)
    manager.createComponent("PositionEstimation")


if __name__ == "__main__":
    rtc.main(MyModuleInit)
