"""The paper's five demonstration components written against OpenRTM-aist's own API, as the
paper's were (`OpenRTM_aist.DataFlowComponentBase`, `onExecute`, `OpenRTM_aist.OutPort`).

How it works: each module is an ordinary OpenRTM-aist-Python RTC module: a spec list, a
`DataFlowComponentBase` subclass, `XxxInit(manager)` registering its factory, `MyModuleInit`
and a `main()` that runs it under OpenRTM's own manager (`python camera.py` with an rtc.conf, as
any RTC). Nothing in them knows about sdrpeer; sdrpeer runs them unmodified with the `openrtm`
launcher (`launcher: openrtm`, `target: components.openrtm.camera:Camera`; docs/openrtm.md),
examples/paper/system-openrtm.yaml is the paper's system made of them, and `sdrpeer demo
--openrtm` runs the paper's demonstration with them. The algorithms are the SDK components'
pure functions (scene rendering, blob detection, dead reckoning), so both versions behave alike;
only the component model differs. Data types are OpenRTM's: `RTC::CameraImage` frames,
`RTC::TimedBoolean` alarms and inside-the-area flags, `RTC::TimedPose2D` odometry and poses,
`RTC::TimedVelocity2D` commands. Their state is not handed over (OpenRTM has no such call): a
standby or moved instance starts afresh. This package imports nothing of OpenRTM itself.
"""
