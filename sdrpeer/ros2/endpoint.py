"""`RosEndpoint`: a component with one rclpy node of its own, the base of the bridges
(sdrpeer.ros2.bridge, sdrpeer.ros2.services).

How it works: `_start(make)` initialises rclpy in a `Spinner` (sdrpeer.ros2.spin) and, in its
thread, makes a node named after the instance, puts the watch timer on it, lets `make(node)` add
the subscription, publisher, client or service, and spins it; `on_execute` turns a stopped or
stuck executor into an error (ERROR for recovery); `on_finalize` destroys the node and shuts
rclpy down. Subclasses choose the executor (`executor`: events or single).
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any, ClassVar

from sdrpeer.sdk import Component, Param

__all__ = ["RosEndpoint", "node_name"]


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

        spinner = self._spinner = Spinner(executor=self.executor)

        def made() -> None:
            node = Node(node_name(self.instance_name))
            self._node = node
            spinner.watch(node)
            make(node)
            spinner.executor.add_node(node)

        await spinner.call(made)

    def on_execute(self) -> None:
        if self._spinner is not None:
            self._spinner.check(float(self.param_values()["stuck_after"]))

    async def on_finalize(self) -> None:
        spinner, self._spinner = self._spinner, None
        if spinner is None:
            return
        node = self._node
        if spinner.alive and node is not None:
            await spinner.call(lambda: (spinner.executor.remove_node(node), node.destroy_node()))
        spinner.close()
