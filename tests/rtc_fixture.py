"""An RT-Component written against OpenRTM-aist's own API, as any OpenRTM user writes one: for
the openrtm launcher's tests (tests/test_openrtm_e2e.py). Nothing in it knows about sdrpeer.

`Relay` counts on `count` (TimedLong) every period, echoes each pose arriving on `pose`
(TimedPose2D) on `echo` with x doubled, returns RTC_ERROR from onExecute once the file its
`trigger` configuration parameter names exists ("none": never), and never returns from onExecute
once the file its `hang` parameter names holds its process id (a call stuck for good).
"""

import os
import time

import OpenRTM_aist
import RTC

relay_spec = [
    "implementation_id", "Relay", "type_name", "Relay", "description", "test relay",
    "version", "1.0", "vendor", "sdrpeer-tests", "category", "test",
    "activity_type", "PERIODIC", "kind", "DataFlowComponent", "max_instance", "1",
    "language", "Python", "lang_type", "SCRIPT", "exec_cxt.periodic.rate", "20",
    "conf.default.trigger", "none", "conf.default.hang", "none", "",
]  # fmt: skip


class Relay(OpenRTM_aist.DataFlowComponentBase):  # type: ignore[misc]
    """Counts, echoes poses, fails on a trigger file."""

    def __init__(self, manager):
        OpenRTM_aist.DataFlowComponentBase.__init__(self, manager)
        self._d_count = RTC.TimedLong(RTC.Time(0, 0), 0)
        self._countOut = OpenRTM_aist.OutPort("count", self._d_count)
        self._d_pose = RTC.TimedPose2D(RTC.Time(0, 0), RTC.Pose2D(RTC.Point2D(0.0, 0.0), 0.0))
        self._poseIn = OpenRTM_aist.InPort("pose", self._d_pose)
        self._d_echo = RTC.TimedPose2D(RTC.Time(0, 0), RTC.Pose2D(RTC.Point2D(0.0, 0.0), 0.0))
        self._echoOut = OpenRTM_aist.OutPort("echo", self._d_echo)
        self._trigger = ["none"]
        self._hang = ["none"]
        self._n = 0

    def onInitialize(self):
        self.bindParameter("trigger", self._trigger, "none")
        self.bindParameter("hang", self._hang, "none")
        self.addInPort("pose", self._poseIn)
        self.addOutPort("count", self._countOut)
        self.addOutPort("echo", self._echoOut)
        return RTC.RTC_OK

    def onExecute(self, ec_id):
        if self._trigger[0] != "none" and os.path.exists(self._trigger[0]):
            return RTC.RTC_ERROR
        if self._hang[0] != "none" and os.path.exists(self._hang[0]):
            with open(self._hang[0]) as f:
                if str(os.getpid()) in f.read().split():
                    while True:
                        time.sleep(1.0)
        self._n += 1
        self._d_count.data = self._n
        OpenRTM_aist.setTimestamp(self._d_count)
        self._countOut.write()
        while self._poseIn.isNew():
            pose = self._poseIn.read()
            self._d_echo.data = RTC.Pose2D(
                RTC.Point2D(pose.data.position.x * 2, pose.data.position.y), pose.data.heading
            )
            OpenRTM_aist.setTimestamp(self._d_echo)
            self._echoOut.write()
        return RTC.RTC_OK


def RelayInit(manager):
    profile = OpenRTM_aist.Properties(defaults_str=relay_spec)
    manager.registerFactory(profile, Relay, OpenRTM_aist.Delete)


def MyModuleInit(manager):
    RelayInit(manager)
    manager.createComponent("Relay")
