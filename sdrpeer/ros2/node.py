"""`Ros2Node`: an unmodified rclpy node class hosted as an sdrpeer component.

How it works: `Ros2Node.hosting(cls)` builds a Component subclass around one rclpy node class
(`rclpy.node.Node` or `rclpy.lifecycle.LifecycleNode`); `sdrpeer.ros2.host` runs it like any
component, so placement, the watchdog, Table III recovery and planned moves treat it as one. The
RTC lifecycle drives the node:

| sdrpeer                  | plain `Node`                 | `LifecycleNode`                       |
|--------------------------|------------------------------|---------------------------------------|
| initialize (INACTIVE)    | rclpy up, class imported (*) | node made, `configure`d: inactive     |
| activate                 | node made and spun           | `activate`                            |
| deactivate / aborting    | node destroyed               | `deactivate`                          |
| finalize                 | context shut down            | `cleanup`, `shutdown`, destroyed      |

(*) with a hidden node, `_sdrpeer_<instance>`, that holds the DDS participant (rmw_fastrtps makes
it with the first node), so the fleet has discovered a standby before it activates. So a standby
is a warm interpreter with rclpy loaded and its participant known (a plain node) or a
configured, inactive lifecycle node, and activating it takes milliseconds. A lifecycle
transition that returns FAILURE or ERROR, a node whose constructor raises, an executor that
stopped (a callback raised) and one stuck in a callback for `stuck_after` seconds all put the
component in ERROR, which the agent's recovery handles. The component's params other than its
own (`executor`, `stuck_after`) are the node's ROS parameters: given at start as parameter
overrides (`--ros-args -p name:=value`) and set on the running node when they change.

Traffic: every publisher's `publish` and every subscription's callback the node made (ROS 2's
own `/rosout`, `/parameter_events` and parameter/lifecycle services left out) is counted;
`endpoints()` lists them (name -> direction, ROS type) and `port_counters` adds their counters
(`frames_out`/`bytes_out` for a publisher, `frames_in`/`bytes_in` for a subscription; bytes from
the serialized size of one message in `SAMPLE`), so `sdrpeer port list` and `status` show them.
"""

from __future__ import annotations

import json
import logging
from collections.abc import Mapping
from typing import Any, ClassVar, Final

from sdrpeer.sdk import Component, Param, Periodic

__all__ = ["HIDDEN_SERVICES", "HIDDEN_TOPICS", "Ros2Node", "ros_type_name"]

log = logging.getLogger("sdrpeer.ros2.node")
TEARDOWN: Final = 3.0
"""Seconds a deactivation or teardown step waits for rclpy's executor."""
RESCAN: Final = 1.0
"""Seconds between looks for endpoints the node made after it was constructed."""
SAMPLE: Final = 32
"""One message in this many is serialized to learn the size of its topic's messages."""
HIDDEN_TOPICS: Final = frozenset({"/rosout", "/parameter_events"})
HIDDEN_SERVICES: Final = (
    "/describe_parameters",
    "/get_parameter_types",
    "/get_parameters",
    "/get_type_description",
    "/list_parameters",
    "/set_parameters",
    "/set_parameters_atomically",
    "/change_state",
    "/get_state",
    "/get_available_states",
    "/get_available_transitions",
    "/get_transition_graph",
)


def ros_type_name(cls: type) -> str:
    """`geometry_msgs/msg/PoseStamped` for the rclpy class of that message (or service)."""
    parts = cls.__module__.split(".")
    return f"{parts[0]}/{parts[1] if len(parts) > 1 else 'msg'}/{cls.__name__}"


def _ros_value(text: Any) -> Any:
    """A param as the node's ROS parameter: strings that read as JSON numbers, booleans or lists
    become them (the host passes params as text), anything else stays as it is."""
    if not isinstance(text, str):
        return text
    lowered = text.strip().lower()
    if lowered in ("true", "false"):
        return lowered == "true"
    try:
        value = json.loads(text)
    except ValueError:
        return text
    return value if isinstance(value, int | float | list) else text


class _Counted:
    """Counters of one endpoint."""

    __slots__ = ("bytes", "direction", "frames", "size", "type")

    def __init__(self, direction: str, type_name: str) -> None:
        self.direction = direction
        self.type = type_name
        self.frames = 0
        self.bytes = 0
        self.size = 0

    def count(self, msg: Any) -> None:
        if self.frames % SAMPLE == 0:
            try:
                from rclpy.serialization import serialize_message  # noqa: PLC0415 - rclpy is up

                self.size = len(serialize_message(msg))
            except Exception:  # a raw (bytes) or foreign message: count frames only
                self.size = len(msg) if isinstance(msg, bytes | bytearray) else 0
        self.frames += 1
        self.bytes += self.size


class Ros2Node(Component):
    """Hosts one rclpy node class (see the module's doc); made per class by `hosting`."""

    execution = Periodic(hz=10.0)
    executor = Param(
        str,
        "single",
        "the rclpy executor: single (rclpy.spin's) or events (EventsExecutor)",
        choices=("single", "events"),
    )
    stuck_after = Param(
        float, 2.0, "seconds the executor may sit in one callback before ERROR", min=0.1
    )
    node_class: ClassVar[type] = object
    lifecycle: ClassVar[bool] = False

    @classmethod
    def hosting(cls, node_class: type) -> type[Ros2Node]:
        """The component class that hosts `node_class`."""
        from rclpy.lifecycle import LifecycleNode  # noqa: PLC0415 - only in a ROS 2 host

        return type(
            node_class.__name__,
            (cls,),
            {
                "node_class": node_class,
                "lifecycle": issubclass(node_class, LifecycleNode),
                "__module__": cls.__module__,
                "__qualname__": node_class.__name__,
            },
        )

    def __init__(self, name: str | None = None, params: Mapping[str, Any] | None = None) -> None:
        self.ros_params: dict[str, Any] = {}
        """The node's ROS parameters (every param that is not the component's own)."""
        super().__init__(name, params)
        self.node: Any = None
        self._spinner: Any = None
        self._timer: Any = None
        self._endpoints: dict[str, _Counted] = {}
        self._keeper: Any = None

    def convert_params(self, values: Mapping[str, Any]) -> dict[str, Any]:
        """Own params converted as usual; the rest kept as ROS parameters (see the doc)."""
        own = {k: v for k, v in values.items() if k in type(self)._sdk_params}
        for k, v in values.items():
            if k not in own:
                self.ros_params[k] = _ros_value(v)
        return super().convert_params(own)

    # -- lifecycle ------------------------------------------------------------------------

    async def on_initialize(self) -> None:
        from sdrpeer.ros2.spin import Spinner  # noqa: PLC0415 - loads rclpy

        if self._spinner is not None:  # a reset after a failed initialize: rclpy again
            await self._close()
        args: list[str] = []
        for k, v in sorted(self.ros_params.items()):
            args += ["-p", f"{k}:={json.dumps(v) if not isinstance(v, str) else v}"]
        self._spinner = Spinner(
            args=["--ros-args", *args] if args else (), executor=self.param_values()["executor"]
        )
        try:
            if self.lifecycle:
                await self._spinner.call(self._make)
                await self._transition("configure")
            else:
                await self._spinner.call(self._keep)
        except BaseException:
            await self._close()
            raise

    async def on_activated(self) -> None:
        if self.lifecycle:
            await self._transition("activate")
        else:
            await self._spinner.call(self._make)

    async def on_deactivated(self) -> None:
        await self._stop()

    async def on_aborting(self) -> None:
        await self._stop()

    async def on_reset(self) -> None:
        """ERROR -> INACTIVE: a stopped or stuck executor cannot be reset (the error stays and
        recovery restarts the host); a lifecycle node is made and configured afresh (after a
        transition that returned ERROR, rclpy leaves it unconfigured or finalized)."""
        spinner = self._spinner
        if spinner is None:
            return
        spinner.check(float(self.param_values()["stuck_after"]))
        if self.lifecycle:
            await spinner.call(self._destroy, TEARDOWN)
            await spinner.call(self._make)
            await self._transition("configure")

    async def on_finalize(self) -> None:
        await self._close()

    async def _close(self) -> None:
        """The node and the hidden one destroyed (when the executor can still do it), rclpy
        shut down."""
        spinner = self._spinner
        if spinner is None:
            return
        try:
            if self.node is not None and spinner.usable:
                if self.lifecycle:
                    for name in ("deactivate", "cleanup", "shutdown"):
                        await spinner.call(lambda n=name: self._trigger(n, strict=False), TEARDOWN)
                await spinner.call(self._destroy, TEARDOWN)
            keeper, self._keeper = self._keeper, None
            if keeper is not None and spinner.usable:
                await spinner.call(keeper.destroy_node, TEARDOWN)
        finally:
            self._spinner = None
            spinner.close()

    def on_execute(self) -> None:
        if self._spinner is not None and self.node is not None:
            self._spinner.check(float(self.param_values()["stuck_after"]))

    def on_params_changed(self, changed: dict[str, Any]) -> Any:
        ros = {k: _ros_value(v) for k, v in changed.items() if k not in type(self)._sdk_params}
        self.ros_params.update(ros)
        if ros and self.node is not None and self._spinner is not None:
            return self._spinner.call(lambda: self._set_ros_params(ros))
        return None

    # -- in the executor's thread ---------------------------------------------------------

    def _make(self) -> None:
        """Construct the node, count its endpoints, spin it."""
        node = self.node_class()
        self.node = node
        self._count()
        self._timer = self._spinner.watch(node)
        node.create_timer(RESCAN, self._count)  # endpoints made later (on_configure, ...)
        self._spinner.executor.add_node(node)

    def _keep(self) -> None:
        """A hidden node (`_sdrpeer_<instance>`) from initialize to finalize, for a plain node's
        host: rmw_fastrtps makes the context's DDS participant with its first node, so without
        it a standby's participant is born when it activates and the fleet's other participants
        discover it only then (a failover's or a move's first messages go unheard meanwhile)."""
        from rclpy.node import Node  # noqa: PLC0415

        name = "".join(c if c.isalnum() else "_" for c in self.instance_name)
        self._keeper = Node(f"_sdrpeer_{name}")

    def _destroy(self) -> None:
        node, self.node = self.node, None
        if node is None:
            return
        self._spinner.executor.remove_node(node)
        node.destroy_node()
        self._endpoints.clear()

    async def _stop(self) -> None:
        """Deactivate or destroy the node; nothing when the executor sits in a callback (it
        would wait behind it: the component is in ERROR and its host restarted by recovery)."""
        spinner = self._spinner
        if spinner is None or not spinner.usable or self.node is None:
            return
        if self.lifecycle:
            await spinner.call(lambda: self._trigger("deactivate", strict=False), TEARDOWN)
        else:
            await spinner.call(self._destroy, TEARDOWN)

    async def _transition(self, name: str) -> None:
        await self._spinner.call(lambda: self._trigger(name, strict=True))

    def _trigger(self, name: str, *, strict: bool) -> None:
        from rclpy.lifecycle import TransitionCallbackReturn  # noqa: PLC0415

        try:
            result = getattr(self.node, f"trigger_{name}")()
        except Exception as exc:  # rclpy refuses a transition the state does not allow
            if strict:
                raise RuntimeError(f"lifecycle {name}: {exc}") from exc
            return
        self._count()
        if strict and result != TransitionCallbackReturn.SUCCESS:
            raise RuntimeError(f"lifecycle {name} returned {getattr(result, 'name', result)}")

    def _set_ros_params(self, values: dict[str, Any]) -> None:
        from rclpy.parameter import Parameter  # noqa: PLC0415

        node = self.node
        if node is None:
            return
        params = [Parameter(k, value=v) for k, v in values.items() if node.has_parameter(k)]
        for result in node.set_parameters(params):
            if not result.successful:
                log.warning("%s: parameter refused: %s", self.instance_name, result.reason)

    def _count(self) -> None:
        """Wrap the node's publishers and subscription callbacks not yet counted."""
        node = self.node
        if node is None:
            return
        for pub in list(node.publishers):
            if pub.topic_name in HIDDEN_TOPICS or not self._new(pub):
                continue
            c = self._endpoints.setdefault(
                pub.topic_name, _Counted("publishes", ros_type_name(pub.msg_type))
            )
            pub.publish = _counting_publish(pub.publish, c)
        for sub in list(node.subscriptions):
            if sub.topic_name in HIDDEN_TOPICS or not self._new(sub):
                continue
            c = self._endpoints.setdefault(
                sub.topic_name, _Counted("subscribes", ros_type_name(sub.msg_type))
            )
            sub.callback = _counting_callback(sub.callback, c)
        for srv in list(node.services):
            if srv.srv_name.endswith(HIDDEN_SERVICES) or not self._new(srv):
                continue
            c = self._endpoints.setdefault(
                srv.srv_name, _Counted("serves", ros_type_name(srv.srv_type))
            )
            srv.callback = _counting_callback(srv.callback, c, sized=False)

    def _new(self, endpoint: Any) -> bool:
        """True the first time an endpoint is seen (it is then counted); the mark is on the
        endpoint itself (an id could be reused by a later one)."""
        if getattr(endpoint, "_sdrpeer_counted", False):
            return False
        endpoint._sdrpeer_counted = True
        return True

    # -- what the agent sees --------------------------------------------------------------

    def endpoints(self) -> dict[str, list[str]]:
        """Topic or service name -> [direction, ROS type] of the running node."""
        return {n: [c.direction, c.type] for n, c in sorted(self._endpoints.items())}

    def port_counters(self) -> dict[str, dict[str, int]]:
        out = super().port_counters()
        for name, c in list(self._endpoints.items()):
            key = "out" if c.direction == "publishes" else "in"
            out[name] = {f"frames_{key}": c.frames, f"bytes_{key}": c.bytes}
        return out


def _counting_publish(publish: Any, c: _Counted) -> Any:
    def counted(msg: Any) -> None:
        c.count(msg)
        publish(msg)

    return counted


def _counting_callback(callback: Any, c: _Counted, *, sized: bool = True) -> Any:
    def counted(*args: Any) -> Any:
        if sized and args:
            c.count(args[0])
        else:
            c.frames += 1
        return callback(*args)

    return counted
