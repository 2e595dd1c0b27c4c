"""`RosEndpoint`: a component with one rclpy node of its own, the base of the bridges
(sdrpeer.ros2.bridge, sdrpeer.ros2.services).

How it works: `_start(make)` initialises rclpy in a `Spinner` (sdrpeer.ros2.spin) and, in its
thread, makes a node named after the instance, puts the watch timer on it, lets `make(node)` add
the subscription, publisher, client or service, and spins it; `on_execute` turns a stopped or stuck
executor into an error (ERROR for recovery), and `on_reset` refuses to clear it (the host is
restarted instead); `on_finalize` destroys the node (unless the executor sits in a callback) and
shuts rclpy down. A callback of a subclass must not raise: rclpy would end the executor's thread.
Subclasses choose the executor (`executor`: events or single).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

from sdrpeer.sdk import Component, Param

__all__ = ["TEARDOWN", "RosEndpoint", "node_name"]

TEARDOWN = 3.0
"""Seconds a teardown step waits for rclpy's executor (it skips rclpy when stuck)."""


def node_name(instance: str) -> str:
    """A valid ROS 2 node name for an instance (letters, digits and underscores)."""
    name = "".join(c if c.isalnum() else "_" for c in instance)
    return name if name[:1].isalpha() else f"n_{name}"


class RosEndpoint(Component):
    """One rclpy node, made at initialize and destroyed at finalize (see the module's doc)."""

    stuck_after = Param(float, 2.0, "seconds rclpy's executor may sit in a callback", min=0.1)
    executor: ClassVar[str] = "events"

    def __init__(self, name: str | None = None, params: dict[str, Any] | None = None) -> None:
        super().__init__(name, params)
        self._spinner: Any = None
        self._node: Any = None

    async def _start(self, make: Callable[[Any], None]) -> None:
        """rclpy up, the node made and `make(node)` run in the executor's thread, then spun."""
        from rclpy.node import Node  # noqa: PLC0415 - a ROS 2 host only

        from sdrpeer.ros2.spin import Spinner  # noqa: PLC0415 - loads rclpy

        if self._spinner is not None:  # a reset after a failed initialize: rclpy again
            await self.on_finalize()
        spinner = self._spinner = Spinner(executor=self.executor)

        def made() -> None:
            node = Node(node_name(self.instance_name))
            self._node = node
            spinner.watch(node)
            make(node)
            spinner.executor.add_node(node)

        try:
            await spinner.call(made)
        except BaseException:
            await self.on_finalize()
            raise

    def stuck_limit(self) -> float:
        """Seconds the executor may sit in one callback before the component is in ERROR."""
        return float(self.param_values()["stuck_after"])

    def on_execute(self) -> None:
        if self._spinner is not None:
            self._spinner.check(self.stuck_limit())

    def on_reset(self) -> None:
        """A stopped or stuck executor cannot be reset: the error stays (recovery restarts the
        host)."""
        if self._spinner is not None:
            self._spinner.check(self.stuck_limit())

    async def on_finalize(self) -> None:
        spinner, self._spinner = self._spinner, None
        if spinner is None:
            return
        node, self._node = self._node, None
        try:
            if spinner.usable and node is not None:
                await spinner.call(
                    lambda: (spinner.executor.remove_node(node), node.destroy_node()), TEARDOWN
                )
        finally:
            spinner.close()
