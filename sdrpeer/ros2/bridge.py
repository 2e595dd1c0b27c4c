"""Bridges between ROS 2 topics and sdrpeer ports: components that the `ros2` launcher hosts.

How it works: `FromRos<Type>` subscribes to a ROS 2 topic and writes each message to its OutPort
`out`; `ToRos<Type>` publishes every frame its InPort `input` receives on a ROS 2 topic. `<Type>` is
one of the standard robot types (`Pose`, `Velocity`, `Odometry`, `RangeScan`, `Image`,
`BatteryState`: typed ports, converted by sdrpeer.ros2.types); `FromRos`/`ToRos` carry any ROS
type given by `ros_type` (`std_msgs/msg/String`) as the untyped map of its fields. A system file
declares them with a `ros2:` end on a connection (sdrpeer.system.connections), and they are
placed, moved and recovered like any component.

The ROS side lives from initialize to finalize: a standby already has its subscription or
publisher matched with the topic's other ends, so a failover does not wait for DDS discovery; a
`FromRos` bridge writes to its port only while ACTIVE, a `ToRos` bridge publishes only what
arrives while ACTIVE. Received messages cross from rclpy's executor thread to the host's asyncio
loop in batches (one wake-up for all that arrived meanwhile); a `Pose`, `Velocity` or `Odometry`
bridge takes the serialized bytes and decodes them itself (sdrpeer.ros2.cdr), never building
rclpy's message objects. QoS comes from the params
`reliability` (reliable, best_effort), `depth` (keep last N) and `durability` (volatile,
transient_local); the system file derives them from the connection's policy (docs/ros2.md).
"""

from __future__ import annotations

import asyncio
import importlib
import logging
from collections import deque
from collections.abc import Callable
from typing import Any, ClassVar

from sdrpeer.ros2.cdr import decoder_for
from sdrpeer.ros2.endpoint import RosEndpoint
from sdrpeer.ros2.types import fill, mapping_for, message_to_map
from sdrpeer.sdk import InPort, OnInput, OutPort, Param, Periodic
from sdrpeer.sdk.errors import NoData
from sdrpeer.sdk.robot_types import BatteryState, Image, Odometry, Pose, RangeScan, Velocity

__all__ = [
    "FromRos",
    "FromRosBatteryState",
    "FromRosImage",
    "FromRosOdometry",
    "FromRosPose",
    "FromRosRangeScan",
    "FromRosVelocity",
    "ToRos",
    "ToRosBatteryState",
    "ToRosImage",
    "ToRosOdometry",
    "ToRosPose",
    "ToRosRangeScan",
    "ToRosVelocity",
    "bridge_class_name",
    "import_ros_type",
]

log = logging.getLogger("sdrpeer.ros2.bridge")
QUEUE_MAX = 4096
"""Messages a FromRos bridge holds for its loop at most (a flood the loop cannot keep up with
drops the oldest, as DDS's keep-last does, rather than growing without bound)."""
RELIABILITY = ("reliable", "best_effort")
DURABILITY = ("volatile", "transient_local")


def import_ros_type(name: str, kind: str = "msg") -> type:
    """The rclpy class of `pkg/msg/Name` (or `pkg/Name`; `kind="srv"`: a service type
    `pkg/srv/Name`); ValueError naming what is missing."""
    parts = name.split("/")
    if len(parts) == 2:
        parts = [parts[0], kind, parts[1]]
    if len(parts) != 3 or not all(p.isidentifier() for p in parts):
        raise ValueError(f"ROS type {name!r}: expected pkg/{kind}/Name")
    try:
        module = importlib.import_module(f"{parts[0]}.{parts[1]}")
    except ImportError:
        raise ValueError(f"ROS type {name!r}: package {parts[0]!r} is not installed") from None
    cls = getattr(module, parts[2], None)
    if not isinstance(cls, type):
        raise ValueError(f"ROS type {name!r}: {parts[0]}.{parts[1]} has no {parts[2]}")
    return cls


def bridge_class_name(direction: str, kind: str | None) -> str:
    """`FromRosOdometry` / `ToRos`: the bridge class for a direction (`from`: ROS -> port,
    `to`: port -> ROS) and a standard type's short name (None: any ROS type, untyped)."""
    return ("FromRos" if direction == "from" else "ToRos") + (kind or "")


class _Bridge(RosEndpoint):
    """What both directions share: the topic, the QoS, the executor."""

    topic = Param(str, "", "the ROS 2 topic (absolute, e.g. /odom)")
    ros_type = Param(str, "", "the ROS 2 type (pkg/msg/Name); default: the port type's mapping")
    reliability = Param(str, "reliable", "ROS 2 QoS reliability", choices=RELIABILITY)
    depth = Param(int, 10, "ROS 2 QoS history depth (keep last N)", min=1)
    durability = Param(str, "volatile", "ROS 2 QoS durability", choices=DURABILITY)
    kind: ClassVar[type | None] = None
    """The standard robot type of the port (None: untyped maps)."""

    def __init__(self, name: str | None = None, params: dict[str, Any] | None = None) -> None:
        super().__init__(name, params)
        self._mapping = None if self.kind is None else mapping_for(self.kind)
        self.frames = 0

    def _ros_class(self) -> type:
        p = self.param_values()
        name = p["ros_type"] or ("" if self._mapping is None else self._mapping.ros_type)
        if not name:
            raise ValueError(f"{self.instance_name}: an untyped bridge needs ros_type")
        return import_ros_type(name)

    def _qos(self) -> Any:
        from rclpy.qos import (  # noqa: PLC0415 - a ROS 2 host only
            DurabilityPolicy,
            HistoryPolicy,
            QoSProfile,
            ReliabilityPolicy,
        )

        p = self.param_values()
        return QoSProfile(
            history=HistoryPolicy.KEEP_LAST,
            depth=p["depth"],
            reliability=ReliabilityPolicy.RELIABLE
            if p["reliability"] == "reliable"
            else ReliabilityPolicy.BEST_EFFORT,
            durability=DurabilityPolicy.TRANSIENT_LOCAL
            if p["durability"] == "transient_local"
            else DurabilityPolicy.VOLATILE,
        )

    async def on_initialize(self) -> None:
        topic = self.param_values()["topic"]
        if not topic.startswith("/"):
            raise ValueError(f"{self.instance_name}: topic {topic!r} must be absolute (/name)")
        ros_class = self._ros_class()
        await self._start(lambda node: self._endpoint(node, ros_class))

    def _endpoint(self, node: Any, ros_class: type) -> None:
        raise NotImplementedError

    def endpoints(self) -> dict[str, list[str]]:
        """The bridged topic: name -> [direction, ROS type] (shown by `sdrpeer port list`)."""
        p = self.param_values()
        ros_type = p["ros_type"] or ("" if self._mapping is None else self._mapping.ros_type)
        return {p["topic"]: [self._direction, ros_type]}

    _direction: ClassVar[str] = ""

    def port_counters(self) -> dict[str, dict[str, int]]:
        out = super().port_counters()
        key = "in" if self._direction == "subscribes" else "out"
        counts = {f"frames_{key}": self.frames}
        counts.update({k: v for k, v in self._drops().items() if v})
        out[self.param_values()["topic"]] = counts
        return out

    def _drops(self) -> dict[str, int]:
        return {}


class _FromRos(_Bridge):
    """ROS 2 topic -> OutPort `out` (see the module's doc)."""

    execution = Periodic(hz=4.0)  # only watches the executor: frames are written as they come
    _direction = "subscribes"
    out = OutPort("frames from ROS (typed in each FromRos<Type>)")

    def __init__(self, name: str | None = None, params: dict[str, Any] | None = None) -> None:
        super().__init__(name, params)
        self._batch: deque[Any] = deque()
        self._loop: asyncio.AbstractEventLoop | None = None
        self._decode_raw: Callable[[bytes], Any] = bytes
        self.malformed = 0
        """Messages that did not decode (dropped)."""
        self.overflowed = 0
        """Messages dropped because `QUEUE_MAX` waited for the loop already."""
        self._active = False

    async def on_initialize(self) -> None:
        self._loop = asyncio.get_running_loop()
        await super().on_initialize()

    def _endpoint(self, node: Any, ros_class: type) -> None:
        topic, qos = self.param_values()["topic"], self._qos()
        raw = decoder_for(self.kind)
        if raw is None:
            node.create_subscription(ros_class, topic, self._heard, qos)
        else:  # the bytes DDS delivered, decoded here (sdrpeer.ros2.cdr): no rclpy message
            node.create_subscription(ros_class, topic, self._heard_raw, qos, raw=True)
            self._decode_raw = raw

    def _heard_raw(self, data: bytes) -> None:
        """In the executor thread: a raw message of a fixed-layout type (one that does not
        decode is dropped and counted: any participant of the domain may send it)."""
        if not self._active:
            return
        try:
            value = self._decode_raw(data)
        except ValueError as exc:
            self._malformed(exc)
            return
        self._queue(value)

    def _heard(self, msg: Any) -> None:
        """In the executor thread: queue the converted value; wake the loop once per batch."""
        if not self._active:
            return
        mapping = self._mapping
        try:
            value = message_to_map(msg) if mapping is None else mapping.from_ros(msg)
        except (ValueError, TypeError, AttributeError) as exc:
            self._malformed(exc)
            return
        self._queue(value)

    def _malformed(self, exc: Exception) -> None:
        self.malformed += 1
        if self.malformed in (1, 10, 100) or self.malformed % 1000 == 0:
            log.warning(
                "%s: %d malformed message(s) dropped: %s", self.instance_name, self.malformed, exc
            )

    def _queue(self, value: Any) -> None:
        """Hand a value to the loop; past `QUEUE_MAX` waiting the oldest is dropped (counted)."""
        batch = self._batch
        if len(batch) >= QUEUE_MAX:
            batch.popleft()
            self.overflowed += 1
        batch.append(value)
        if len(batch) == 1 and self._loop is not None:
            self._loop.call_soon_threadsafe(self._flush)

    def _flush(self) -> None:
        """On the loop: write everything that arrived (nothing once no longer ACTIVE)."""
        batch, out = self._batch, self.outport("out")
        try:
            while batch and self._active:
                out.write(batch.popleft())
                self.frames += 1
        finally:
            if batch and self._active and self._loop is not None:  # a write raised: go on later
                self._loop.call_soon(self._flush)

    def _drops(self) -> dict[str, int]:
        return {"malformed": self.malformed, "overflowed": self.overflowed}

    def on_activated(self) -> None:
        self._active = True

    def on_deactivated(self) -> None:
        self._active = False
        self._batch.clear()

    def on_aborting(self) -> None:
        self.on_deactivated()


class _ToRos(_Bridge):
    """InPort `input` -> ROS 2 topic (see the module's doc)."""

    execution = OnInput("input")
    _direction = "publishes"
    input = InPort("frames to ROS (typed in each ToRos<Type>)")

    def __init__(self, name: str | None = None, params: dict[str, Any] | None = None) -> None:
        super().__init__(name, params)
        self._pub: Any = None
        self._msg_class: type | None = None

    def _endpoint(self, node: Any, ros_class: type) -> None:
        self._msg_class = ros_class
        self._pub = node.create_publisher(ros_class, self.param_values()["topic"], self._qos())

    def on_execute(self) -> None:
        super().on_execute()
        port, pub, cls = self.inport("input"), self._pub, self._msg_class
        if pub is None or cls is None:
            return
        to_ros = None if self._mapping is None else self._mapping.to_ros
        while True:
            try:
                value = port.get_nowait()
            except NoData:
                return
            fields = to_ros(value) if to_ros is not None else value
            pub.publish(fill(cls(), fields))  # rcl_publish may be called from any thread
            self.frames += 1


def _from_ros(kind: type | None) -> type[_FromRos]:
    name = bridge_class_name("from", None if kind is None else kind.__name__)
    return type(name, (_FromRos,), {"kind": kind, "out": OutPort("frames from ROS", type=kind)})


def _to_ros(kind: type | None) -> type[_ToRos]:
    name = bridge_class_name("to", None if kind is None else kind.__name__)
    return type(name, (_ToRos,), {"kind": kind, "input": InPort("frames to ROS", type=kind)})


FromRos = _from_ros(None)
FromRosPose = _from_ros(Pose)
FromRosVelocity = _from_ros(Velocity)
FromRosOdometry = _from_ros(Odometry)
FromRosRangeScan = _from_ros(RangeScan)
FromRosImage = _from_ros(Image)
FromRosBatteryState = _from_ros(BatteryState)
ToRos = _to_ros(None)
ToRosPose = _to_ros(Pose)
ToRosVelocity = _to_ros(Velocity)
ToRosOdometry = _to_ros(Odometry)
ToRosRangeScan = _to_ros(RangeScan)
ToRosImage = _to_ros(Image)
ToRosBatteryState = _to_ros(BatteryState)
