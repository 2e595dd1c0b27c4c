"""The standard robot types (sdrpeer.sdk.robot_types) as ROS 2 messages, both ways (pure).

How it works: each mapped type has a ROS 2 type name and two functions: `to_ros(value)` gives the
ROS message as nested dicts of its fields (what mcap-ros2-support encodes to CDR, and what
`fill` copies into an rclpy message object), `from_ros(type, msg)` reads a ROS message (an rclpy
object, a decoded MCAP message or the dicts) back into the sdrpeer value. The mapping:

- `Pose` <-> `geometry_msgs/msg/PoseStamped` (stamp and frame in the header);
- `Velocity` <-> `geometry_msgs/msg/TwistStamped` (v* linear, w* angular);
- `Odometry` <-> `nav_msgs/msg/Odometry` (velocity in child_frame; covariances zero);
- `RangeScan` <-> `sensor_msgs/msg/LaserScan` (angle_max from the count; no intensities);
- `Image` <-> `sensor_msgs/msg/Image` (little-endian; the encoding as is);
- `BatteryState` <-> `sensor_msgs/msg/BatteryState` (percentage 0..100 here, 0..1 there;
  charging <-> power_supply_status CHARGING, FULL counts as charging).

Stamps are unix seconds here and `builtin_interfaces/Time` (sec, nanosec) there. A value of any
other type has no mapping (`ros_type_of` is None); the bridge then carries a ROS message as the
map of its fields (`message_to_map`/`fill`), untyped on the sdrpeer side.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from typing import Any, Final

from sdrpeer.sdk.robot_types import BatteryState, Image, Odometry, Pose, RangeScan, Velocity

__all__ = [
    "MAPPED",
    "RosMapping",
    "fill",
    "from_ros",
    "mapping_for",
    "message_to_map",
    "ros_type_of",
    "stamp_from",
    "stamp_to",
    "to_ros",
]

_CHARGING: Final = 1
_DISCHARGING: Final = 2
_BATTERY_STATUS_CHARGING: Final = (1, 4)  # CHARGING, FULL (on its charger)


def _get(msg: Any, name: str) -> Any:
    """Field `name` of a message object or of its dict form."""
    if isinstance(msg, Mapping):
        return msg[name]
    return getattr(msg, name)


def stamp_to(stamp: float) -> dict[str, int]:
    """Unix seconds as `builtin_interfaces/Time` (non-negative; nanoseconds rounded)."""
    total = max(0, round(stamp * 1e9))
    return {"sec": total // 1_000_000_000, "nanosec": total % 1_000_000_000}


def stamp_from(time: Any) -> float:
    """`builtin_interfaces/Time` as unix seconds."""
    return int(_get(time, "sec")) + int(_get(time, "nanosec")) * 1e-9


def _header(stamp: float, frame: str) -> dict[str, Any]:
    return {"stamp": stamp_to(stamp), "frame_id": frame}


def _xyz(x: float, y: float, z: float) -> dict[str, float]:
    return {"x": float(x), "y": float(y), "z": float(z)}


def _pose_body(p: Pose) -> dict[str, Any]:
    return {
        "position": _xyz(p.x, p.y, p.z),
        "orientation": {"x": float(p.qx), "y": float(p.qy), "z": float(p.qz), "w": float(p.qw)},
    }


def _twist_body(v: Velocity) -> dict[str, Any]:
    return {"linear": _xyz(v.vx, v.vy, v.vz), "angular": _xyz(v.wx, v.wy, v.wz)}


def _pose_from(stamp: float, frame: str, body: Any) -> Pose:
    pos, q = _get(body, "position"), _get(body, "orientation")
    return Pose(
        stamp,
        frame,
        _get(pos, "x"),
        _get(pos, "y"),
        _get(pos, "z"),
        _get(q, "x"),
        _get(q, "y"),
        _get(q, "z"),
        _get(q, "w"),
    )


def _velocity_from(stamp: float, frame: str, body: Any) -> Velocity:
    lin, ang = _get(body, "linear"), _get(body, "angular")
    return Velocity(
        stamp,
        frame,
        _get(lin, "x"),
        _get(lin, "y"),
        _get(lin, "z"),
        _get(ang, "x"),
        _get(ang, "y"),
        _get(ang, "z"),
    )


def _head(msg: Any) -> tuple[float, str]:
    h = _get(msg, "header")
    return stamp_from(_get(h, "stamp")), str(_get(h, "frame_id"))


# -- one pair of functions per type ---------------------------------------------------------------


def _pose_to(p: Pose) -> dict[str, Any]:
    return {"header": _header(p.stamp, p.frame), "pose": _pose_body(p)}


def _pose_back(msg: Any) -> Pose:
    stamp, frame = _head(msg)
    return _pose_from(stamp, frame, _get(msg, "pose"))


def _velocity_to(v: Velocity) -> dict[str, Any]:
    return {"header": _header(v.stamp, v.frame), "twist": _twist_body(v)}


def _velocity_back(msg: Any) -> Velocity:
    stamp, frame = _head(msg)
    return _velocity_from(stamp, frame, _get(msg, "twist"))


def _odometry_to(o: Odometry) -> dict[str, Any]:
    zeros = [0.0] * 36
    return {
        "header": _header(o.stamp, o.frame),
        "child_frame_id": o.child_frame,
        "pose": {"pose": _pose_body(o.pose), "covariance": zeros},
        "twist": {"twist": _twist_body(o.velocity), "covariance": zeros},
    }


def _odometry_back(msg: Any) -> Odometry:
    stamp, frame = _head(msg)
    child = str(_get(msg, "child_frame_id"))
    return Odometry(
        stamp,
        frame,
        child,
        _pose_from(stamp, frame, _get(_get(msg, "pose"), "pose")),
        _velocity_from(stamp, child, _get(_get(msg, "twist"), "twist")),
    )


def _scan_to(s: RangeScan) -> dict[str, Any]:
    n = len(s.ranges)
    return {
        "header": _header(s.stamp, s.frame),
        "angle_min": float(s.angle_min),
        "angle_max": float(s.angle_min + max(0, n - 1) * s.angle_increment),
        "angle_increment": float(s.angle_increment),
        "time_increment": 0.0,
        "scan_time": 0.0,
        "range_min": float(s.range_min),
        "range_max": float(s.range_max),
        "ranges": [float(r) for r in s.ranges],
        "intensities": [],
    }


def _scan_back(msg: Any) -> RangeScan:
    stamp, frame = _head(msg)
    return RangeScan(
        stamp,
        frame,
        float(_get(msg, "angle_min")),
        float(_get(msg, "angle_increment")),
        float(_get(msg, "range_min")),
        float(_get(msg, "range_max")),
        [float(r) for r in _get(msg, "ranges")],
    )


def _image_to(i: Image) -> dict[str, Any]:
    return {
        "header": _header(i.stamp, i.frame),
        "height": int(i.height),
        "width": int(i.width),
        "encoding": i.encoding,
        "is_bigendian": 0,
        "step": int(i.step),
        "data": bytes(i.data),
    }


def _image_back(msg: Any) -> Image:
    stamp, frame = _head(msg)
    return Image(
        stamp,
        frame,
        int(_get(msg, "width")),
        int(_get(msg, "height")),
        str(_get(msg, "encoding")),
        int(_get(msg, "step")),
        bytes(_get(msg, "data")),
    )


def _battery_to(b: BatteryState) -> dict[str, Any]:
    nan = math.nan
    return {
        "header": _header(b.stamp, ""),
        "voltage": float(b.voltage),
        "temperature": nan,
        "current": float(b.current),
        "charge": nan,
        "capacity": nan,
        "design_capacity": nan,
        "percentage": float(b.percentage) / 100.0,
        "power_supply_status": _CHARGING if b.charging else _DISCHARGING,
        "power_supply_health": 0,
        "power_supply_technology": 0,
        "present": True,
        "cell_voltage": [],
        "cell_temperature": [],
        "location": "",
        "serial_number": "",
    }


def _battery_back(msg: Any) -> BatteryState:
    stamp, _frame = _head(msg)
    return BatteryState(
        stamp,
        float(_get(msg, "voltage")),
        float(_get(msg, "current")),
        float(_get(msg, "percentage")) * 100.0,
        int(_get(msg, "power_supply_status")) in _BATTERY_STATUS_CHARGING,
    )


@dataclass(frozen=True, slots=True)
class RosMapping:
    """How one sdrpeer type travels as one ROS 2 type."""

    cls: type
    ros_type: str
    """`pkg/msg/Name`."""
    to_ros: Callable[[Any], dict[str, Any]]
    from_ros: Callable[[Any], Any]


MAPPED: Final[dict[type, RosMapping]] = {
    m.cls: m
    for m in (
        RosMapping(Pose, "geometry_msgs/msg/PoseStamped", _pose_to, _pose_back),
        RosMapping(Velocity, "geometry_msgs/msg/TwistStamped", _velocity_to, _velocity_back),
        RosMapping(Odometry, "nav_msgs/msg/Odometry", _odometry_to, _odometry_back),
        RosMapping(RangeScan, "sensor_msgs/msg/LaserScan", _scan_to, _scan_back),
        RosMapping(Image, "sensor_msgs/msg/Image", _image_to, _image_back),
        RosMapping(BatteryState, "sensor_msgs/msg/BatteryState", _battery_to, _battery_back),
    )
}
"""sdrpeer type -> its mapping."""
_BY_NAME: Final = {m.cls.__name__: m for m in MAPPED.values()}
_BY_ROS: Final = {m.ros_type: m for m in MAPPED.values()}


def mapping_for(kind: type | str) -> RosMapping | None:
    """The mapping of an sdrpeer type (the class, its short name `Pose`, or its ROS 2 type
    name `geometry_msgs/msg/PoseStamped`), None if it has none."""
    if isinstance(kind, str):
        return _BY_NAME.get(kind) or _BY_ROS.get(kind) or _BY_ROS.get(_long(kind))
    return MAPPED.get(kind)


def _long(ros_type: str) -> str:
    """`pkg/Name` as `pkg/msg/Name` (the form rosbag2 and rclpy print)."""
    pkg, sep, name = ros_type.partition("/")
    return f"{pkg}/msg/{name}" if sep and "/" not in name else ros_type


def ros_type_of(cls: type) -> str | None:
    """The ROS 2 type a typed port's values travel as, None if unmapped."""
    m = MAPPED.get(cls)
    return None if m is None else m.ros_type


def to_ros(value: Any) -> dict[str, Any]:
    """A value of a mapped type as its ROS 2 message's nested dicts; TypeError if unmapped."""
    m = MAPPED.get(type(value))
    if m is None:
        raise TypeError(f"{type(value).__name__} has no ROS 2 mapping (mapped: {_names()})")
    return m.to_ros(value)


def from_ros(kind: type, msg: Any) -> Any:
    """A ROS 2 message (object or dicts) as the sdrpeer value of type `kind`."""
    m = MAPPED.get(kind)
    if m is None:
        raise TypeError(f"{kind.__name__} has no ROS 2 mapping (mapped: {_names()})")
    return m.from_ros(msg)


def _names() -> str:
    return ", ".join(_BY_NAME)


def fill(msg: Any, fields: Mapping[str, Any]) -> Any:
    """Copy nested dicts into an rclpy message object (nested messages filled in place); the
    message. A field the message lacks is an AttributeError naming it."""
    for name, value in fields.items():
        if isinstance(value, Mapping):
            fill(getattr(msg, name), value)
        else:
            setattr(msg, name, value)
    return msg


def message_to_map(msg: Any) -> Any:
    """An rclpy message object as plain dicts, lists and scalars (what an untyped port carries);
    `bytes` stay bytes."""
    fields = getattr(msg, "get_fields_and_field_types", None)
    if fields is None:
        if isinstance(msg, list | tuple):
            return [message_to_map(v) for v in msg]
        if hasattr(msg, "tolist"):  # array.array / numpy arrays of numeric fields
            return msg.tolist()
        return msg
    return {name: message_to_map(getattr(msg, name)) for name in fields()}
