"""AnomalyDetectionRTC as an OpenRTM-aist RT-Component: scans the newest `RTC::CameraImage` on
`image` for the dangerous object (components.anomaly_detection.find_hazard) and writes
`RTC::TimedBoolean` on `alarm` for every frame."""

from __future__ import annotations

from typing import Any

import OpenRTM_aist
import RTC

from components.anomaly_detection import find_hazard
from components.openrtm import rtc

anomalydetection_spec = rtc.spec(
    "AnomalyDetection",
    "alarm while the dangerous object is in view",
    20,
    {"threshold": "230", "min_area": "20", "max_area": "5000"},
)


class AnomalyDetection(rtc.ReservingRTC):
    """Raises an alarm while the dangerous object is in a camera's view."""

    def __init__(self, manager: Any) -> None:
        rtc.ReservingRTC.__init__(self, manager)
        self._d_image = RTC.CameraImage(RTC.Time(0, 0), 0, 0, 8, "mono8", 1.0, b"")
        self._imageIn = OpenRTM_aist.InPort("image", self._d_image)
        self._d_alarm = RTC.TimedBoolean(RTC.Time(0, 0), False)
        self._alarmOut = OpenRTM_aist.OutPort("alarm", self._d_alarm)
        self._threshold, self._min_area, self._max_area = [230], [20], [5000]

    def onInitialize(self) -> Any:
        rtc.ReservingRTC.onInitialize(self)
        self.bindParameter("threshold", self._threshold, "230")
        self.bindParameter("min_area", self._min_area, "20")
        self.bindParameter("max_area", self._max_area, "5000")
        self.addInPort("image", self._imageIn)
        self.addOutPort("alarm", self._alarmOut)
        return RTC.RTC_OK

    def onExecute(self, ec_id: int) -> Any:
        frame = None
        while self._imageIn.isNew():  # the newest frame only
            frame = self._imageIn.read()
        if frame is None or not frame.width:
            return RTC.RTC_OK
        blob = find_hazard(
            frame.pixels,
            frame.width,
            frame.height,
            threshold=self._threshold[0],
            min_area=self._min_area[0],
            max_area=self._max_area[0],
            wrap=frame.width >= 2 * frame.height,
        )
        self._d_alarm.data = blob is not None
        OpenRTM_aist.setTimestamp(self._d_alarm)
        self._alarmOut.write()
        return RTC.RTC_OK


def AnomalyDetectionInit(manager: Any) -> None:
    rtc.register(manager, anomalydetection_spec, AnomalyDetection)


def MyModuleInit(manager: Any) -> None:
    AnomalyDetectionInit(manager)
    manager.createComponent("AnomalyDetection")


if __name__ == "__main__":
    rtc.main(MyModuleInit)
