"""Standard robot message types for typed ports, each with a timestamp (sdrpeer.sdk.typed).

How it works: plain dataclasses declared with `@message`, named `sdrpeer/<Name>`; a port
declared `OutPort(type=Pose)` sends them as msgpack arrays of their fields in the order below,
and an `InPort(type=Pose)` gives them back as `Pose` objects. `stamp` is when the data was true
(unix seconds), `frame` the coordinate frame it is expressed in (ROS's `frame_id`). Units are SI:
metres, radians, seconds, volts, amperes. The layouts follow ROS 2's geometry_msgs, nav_msgs and
sensor_msgs where a robot developer will look for them, flattened: no nested headers.
"""

from __future__ import annotations

from dataclasses import dataclass, field

from sdrpeer.sdk.typed import message

__all__ = ["BatteryState", "Image", "Odometry", "Pose", "RangeScan", "Velocity"]


@message("sdrpeer/Pose")
@dataclass(slots=True)
class Pose:
    """A position and an orientation (a unit quaternion) in `frame`."""

    stamp: float
    frame: str
    x: float
    y: float
    z: float = 0.0
    qx: float = 0.0
    qy: float = 0.0
    qz: float = 0.0
    qw: float = 1.0


@message("sdrpeer/Velocity")
@dataclass(slots=True)
class Velocity:
    """Linear (m/s) and angular (rad/s) velocity in `frame` (ROS's Twist)."""

    stamp: float
    frame: str
    vx: float
    vy: float = 0.0
    vz: float = 0.0
    wx: float = 0.0
    wy: float = 0.0
    wz: float = 0.0


@message("sdrpeer/Odometry")
@dataclass(slots=True)
class Odometry:
    """Where the robot believes it is (`pose`, in `frame`) and how it moves (`velocity`, in
    `child_frame`, the robot's own)."""

    stamp: float
    frame: str
    child_frame: str
    pose: Pose
    velocity: Velocity


@message("sdrpeer/RangeScan")
@dataclass(slots=True)
class RangeScan:
    """A planar range scan (ROS's LaserScan): `ranges[i]` at angle_min + i * angle_increment;
    a range outside [range_min, range_max] is no return."""

    stamp: float
    frame: str
    angle_min: float
    angle_increment: float
    range_min: float
    range_max: float
    ranges: list[float] = field(default_factory=list)


@message("sdrpeer/Image")
@dataclass(slots=True)
class Image:
    """A camera image: `height` rows of `step` bytes each in `data`, pixels as `encoding` says
    (`rgb8`, `bgr8`, `mono8`, `mono16`, `jpeg`, ...). A big `data` is sent without a copy."""

    stamp: float
    frame: str
    width: int
    height: int
    encoding: str
    step: int
    data: bytes


@message("sdrpeer/BatteryState")
@dataclass(slots=True)
class BatteryState:
    """A battery: `percentage` of charge 0..100, voltage (V), current (A, negative when
    discharging), and whether it is charging."""

    stamp: float
    voltage: float
    current: float
    percentage: float
    charging: bool = False
