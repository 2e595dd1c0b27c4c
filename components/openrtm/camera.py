"""CameraRTC and OmnidirectionalCameraRTC as OpenRTM-aist RT-Components: synthetic grayscale
frames (components.scene) on the OutPort `image` as `RTC::CameraImage`, at the execution
context's rate (10 Hz)."""

from __future__ import annotations

from typing import Any

import OpenRTM_aist
import RTC

from components.openrtm import rtc
from components.scene import Scene

_SCENE = {"objects": "4", "hazard_period": "8.0", "hazard_on": "4.0"}
camera_spec = rtc.spec(
    "Camera", "synthetic camera", 10, {"width": "160", "height": "120", "seed": "1", **_SCENE}
)
omnidirectionalcamera_spec = rtc.spec(
    "OmnidirectionalCamera",
    "synthetic fisheye camera, a 2:1 panorama",
    10,
    {"width": "320", "height": "160", "seed": "2", **_SCENE},
)


class Camera(rtc.ReservingRTC):
    """A perspective camera: a dangerous object comes into view now and then."""

    wrap = False

    def __init__(self, manager: Any) -> None:
        rtc.ReservingRTC.__init__(self, manager)
        self._d_image = RTC.CameraImage(RTC.Time(0, 0), 0, 0, 8, "mono8", 1.0, b"")
        self._imageOut = OpenRTM_aist.OutPort("image", self._d_image)
        self._width, self._height, self._seed = [0], [0], [0]
        self._objects, self._hazard_period, self._hazard_on = [4], [8.0], [4.0]

    def onInitialize(self) -> Any:
        rtc.ReservingRTC.onInitialize(self)
        self.bindParameter("width", self._width, "160")
        self.bindParameter("height", self._height, "120")
        self.bindParameter("seed", self._seed, "1")
        self.bindParameter("objects", self._objects, "4")
        self.bindParameter("hazard_period", self._hazard_period, "8.0")
        self.bindParameter("hazard_on", self._hazard_on, "4.0")
        self.addOutPort("image", self._imageOut)
        return RTC.RTC_OK

    def onActivated(self, ec_id: int) -> Any:
        rtc.ReservingRTC.onActivated(self, ec_id)
        self._scene = Scene(
            self._seed[0],
            self._width[0],
            self._height[0],
            wrap=self.wrap,
            objects=self._objects[0],
            period=self._hazard_period[0],
            on_time=self._hazard_on[0],
        )
        self._t = 0.0
        return RTC.RTC_OK

    def onExecute(self, ec_id: int) -> Any:
        self._d_image.width, self._d_image.height = self._width[0], self._height[0]
        self._d_image.pixels = self._scene.render(self._t)
        OpenRTM_aist.setTimestamp(self._d_image)
        self._imageOut.write()
        self._t += 1.0 / self.get_context(ec_id).get_rate()
        return RTC.RTC_OK


class OmnidirectionalCamera(Camera):
    """A fisheye camera unrolled to a 2:1 panorama: objects wrap around horizontally."""

    wrap = True


def CameraInit(manager: Any) -> None:
    rtc.register(manager, camera_spec, Camera)


def OmnidirectionalCameraInit(manager: Any) -> None:
    rtc.register(manager, omnidirectionalcamera_spec, OmnidirectionalCamera)


def MyModuleInit(manager: Any) -> None:
    CameraInit(manager)
    OmnidirectionalCameraInit(manager)
    manager.createComponent("Camera")
    manager.createComponent("OmnidirectionalCamera")


if __name__ == "__main__":
    rtc.main(MyModuleInit)
