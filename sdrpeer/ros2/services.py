"""Service bridges: an sdrpeer service port calling a ROS 2 service, a ROS 2 client calling an
sdrpeer service port, through the one interface `ROS2_SERVICE`.

How it works: `ROS2_SERVICE` (`ros2/Service`, one method `call`) carries a ROS 2 request as the
map of its fields and answers with the response's map. An sdrpeer component that calls ROS 2
services declares `ServiceConsumer(ROS2_SERVICE)` and binds it (`from: Comp.port`) to a
`{ros2_service: /name, type: pkg/srv/Name}` end: the bridge `ToRosService` provides the interface,
fills the request message, calls the ROS 2 service (`timeout` seconds) and answers with the
response's fields. A component that serves ROS 2 clients provides `ServiceProvider(ROS2_SERVICE)`
with a `call(request) -> response` handler and is bound from a `ros2_service:` end: the bridge
`FromRosService` offers the ROS 2 service while ACTIVE (a standby offers nothing, so ROS 2 clients
never reach two servers) and hands each request to the component (the answer fills the response;
a failure is logged and answers the response's defaults, since ROS 2 services have no error
reply). Both are `ros2`-launcher components like the topic bridges (sdrpeer.ros2.bridge).
"""

from __future__ import annotations

import asyncio
import concurrent.futures
import logging
from typing import Any

from sdrpeer.ros2.bridge import import_ros_type
from sdrpeer.ros2.endpoint import TEARDOWN, RosEndpoint
from sdrpeer.ros2.types import fill, message_to_map
from sdrpeer.sdk import Param, Periodic
from sdrpeer.sdk.services import Interface, ServiceCallError, ServiceConsumer, ServiceProvider

__all__ = ["ROS2_SERVICE", "FromRosService", "ToRosService"]

log = logging.getLogger("sdrpeer.ros2.services")
ROS2_SERVICE = Interface.of("ros2/Service", "call")
"""A ROS 2 service call: the request's fields in, the response's fields out."""


class _ServiceBridge(RosEndpoint):
    execution = Periodic(hz=4.0)  # only watches rclpy's executor
    executor = "single"
    service = Param(str, "", "the ROS 2 service (absolute, e.g. /reset)")
    srv_type = Param(str, "", "the ROS 2 service type (pkg/srv/Name)")
    timeout = Param(float, 5.0, "seconds a call may take", min=0.01)
    _direction = ""

    def __init__(self, name: str | None = None, params: dict[str, Any] | None = None) -> None:
        super().__init__(name, params)
        self.calls = 0

    async def on_initialize(self) -> None:
        p = self.param_values()
        if not p["service"].startswith("/"):
            raise ValueError(f"{self.instance_name}: service {p['service']!r} must be absolute")
        srv = import_ros_type(p["srv_type"], kind="srv")
        await self._start(lambda node: self._endpoint(node, srv))

    def _endpoint(self, node: Any, srv: type) -> None:
        raise NotImplementedError

    def endpoints(self) -> dict[str, list[str]]:
        """The bridged service: name -> [direction, ROS type] (shown by `sdrpeer port list`)."""
        p = self.param_values()
        return {p["service"]: [self._direction, p["srv_type"]]}

    def port_counters(self) -> dict[str, dict[str, int]]:
        out = super().port_counters()
        out[self.param_values()["service"]] = {"calls": self.calls}
        return out


class ToRosService(_ServiceBridge):
    """Provides `ROS2_SERVICE`; each call is a call of the ROS 2 service."""

    ros = ServiceProvider(ROS2_SERVICE, "calls of the ROS 2 service")
    _direction = "calls"

    def _endpoint(self, node: Any, srv: type) -> None:
        self._srv = srv
        self._client = node.create_client(srv, self.param_values()["service"])

    @ros.method
    async def call(self, request: Any) -> Any:
        """Fill the request, call, answer with the response's fields."""
        p = self.param_values()
        client, srv = self._client, self._srv
        msg = fill(srv.Request(), request or {})  # type: ignore[attr-defined]
        self.calls += 1
        if not client.service_is_ready():
            raise RuntimeError(f"ROS 2 service {p['service']} is not available")
        future = await self._spinner.call(lambda: client.call_async(msg))
        done = asyncio.get_running_loop().create_future()

        def settled(f: Any) -> None:
            loop = done.get_loop()
            loop.call_soon_threadsafe(_settle, done, f)

        future.add_done_callback(settled)
        try:
            async with asyncio.timeout(float(p["timeout"])):
                response = await done
        except TimeoutError:
            client.remove_pending_request(future)  # its answer, if it comes, goes nowhere
            raise
        return message_to_map(response)


def _settle(done: asyncio.Future[Any], f: Any) -> None:
    if done.done():
        return
    exc = f.exception()
    if exc is not None:
        done.set_exception(exc)
    else:
        done.set_result(f.result())


class FromRosService(_ServiceBridge):
    """Offers the ROS 2 service; each request is a call of the bound `ROS2_SERVICE` provider."""

    ros = ServiceConsumer(ROS2_SERVICE, "the component that answers the ROS 2 service")
    _direction = "serves"

    def __init__(self, name: str | None = None, params: dict[str, Any] | None = None) -> None:
        super().__init__(name, params)
        self._server: Any = None
        self._srv: type | None = None

    async def on_initialize(self) -> None:
        self._loop = asyncio.get_running_loop()
        await super().on_initialize()

    def _endpoint(self, node: Any, srv: type) -> None:
        self._srv = srv  # the service itself exists only while ACTIVE: a standby answers nobody

    async def on_activated(self) -> None:
        node, srv, service = self._node, self._srv, self.param_values()["service"]
        self._server = await self._spinner.call(
            lambda: node.create_service(srv, service, self._serve)
        )

    async def on_deactivated(self) -> None:
        server, self._server = self._server, None
        spinner = self._spinner
        if server is not None and spinner is not None and spinner.usable:
            await spinner.call(lambda: self._node.destroy_service(server), TEARDOWN)

    async def on_aborting(self) -> None:
        await self.on_deactivated()

    def stuck_limit(self) -> float:
        """A request waits up to `timeout` (+1 s) for the component in rclpy's thread: that is
        not a stuck executor."""
        p = self.param_values()
        return max(float(p["stuck_after"]), float(p["timeout"]) + 2.0)

    def _serve(self, request: Any, response: Any) -> Any:
        """In rclpy's executor thread: ask the component, wait for its answer (bounded). A
        request it cannot answer is answered with the response's defaults (ROS 2 services have
        no error reply) and logged; nothing raised here reaches rclpy's thread."""
        self.calls += 1
        timeout = float(self.param_values()["timeout"])
        try:
            caller = self.consumer("ros")
            job = asyncio.run_coroutine_threadsafe(
                caller.call("call", message_to_map(request), timeout=timeout), self._loop
            )
            answer = job.result(timeout + 1.0)
            if isinstance(answer, dict):
                fill(response, answer)
        except (ServiceCallError, concurrent.futures.TimeoutError) as exc:
            log.warning("%s: the component did not answer: %s", self.instance_name, exc)
        except Exception as exc:  # a wrong answer (a field the response lacks), a closed loop
            log.warning(
                "%s: answered with defaults: %s: %s", self.instance_name, type(exc).__name__, exc
            )
        return response
