"""The paper's demonstration components (section III): two RED robots' worth of RT-Components.

How it works: each module holds one component, run by `python -m sdrpeer.host MODULE:CLASS`:
`camera` (`Camera`, `OmnidirectionalCamera`: synthetic frames of `scene`), `anomaly_detection`
(`AnomalyDetection`: alarm while the dangerous object is in view), `red_controller`
(`REDController`: drive, stop on alarm or outside the area, odometry) and `position_estimation`
(`PositionEstimation`: corrected pose, inside/outside the area). All derive from
`base.RobotComponent`, which holds `reserve_mb` MiB of touched memory while ACTIVE, as the
paper's components held 500 MB. Wiring: cameras `image` -> detector `image`; detector `alarm`
-> controller `alarm`; controller `odometry` -> estimator `odometry`; estimator `pose` ->
controller `pose`. Measured costs: `profiles/*.yaml` (`sdrpeer profile`).
"""
