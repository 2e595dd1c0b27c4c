"""OdomToPose: an sdrpeer component between two ROS 2 nodes in the ROS 2 example
(examples/ros2/system.yaml): takes `Odometry` from a bridged ROS 2 topic and sends the pose part,
offset by `offset_x` metres, as `Pose` (bridged back to ROS 2 as PoseStamped)."""

from __future__ import annotations

from dataclasses import replace

from sdrpeer.sdk import Component, InPort, NoData, OnInput, OutPort, Param
from sdrpeer.sdk.robot_types import Odometry, Pose


class OdomToPose(Component):
    """Odometry in, its pose out (one per input frame)."""

    execution = OnInput("odom")
    odom = InPort("the robot's odometry", type=Odometry)
    pose = OutPort("the pose, offset along x", type=Pose)
    offset_x = Param(float, 0.0, "metres added to x")

    def __init__(self, *args: object, **kwargs: object) -> None:
        super().__init__(*args, **kwargs)  # type: ignore[arg-type]
        self.handled = 0

    def on_execute(self) -> None:
        port = self.inport("odom")
        dx = float(self.param_values()["offset_x"])
        while True:
            try:
                o: Odometry = port.get_nowait()
            except NoData:
                return
            self.outport("pose").write(replace(o.pose, x=o.pose.x + dx))
            self.handled += 1
