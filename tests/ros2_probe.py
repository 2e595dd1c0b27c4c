"""A ROS 2 participant inside the test process: subscribes to topics and asks the graph, the way a
ROS 2 tool on the robot would, with its own rclpy context spun in a thread.

How it works: `Probe()` makes a context and a node (`sdrpeer_probe`) in the domain the test
process has (tests/conftest.py gives each test run its own ROS_DOMAIN_ID, discovery kept on the
machine); `listen(topic, type)` records `(arrival time, publisher GID, message)` of every message
(`messages` gives the messages, `heard` the triples; tools/bench_ros2.py tells node lives apart
by the GID);
`node_names()` and `call(service, type, request)` ask the graph and services. `close()` ends it.
Every wait in a test that uses it is bounded (tests.wait.until).
"""

from __future__ import annotations

import threading
import time
from typing import Any

import rclpy
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node


class Probe:
    """One rclpy context and node in the test process."""

    def __init__(self, name: str = "sdrpeer_probe") -> None:
        self.context = rclpy.Context()
        rclpy.init(context=self.context)
        self.node = Node(name, context=self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.node)
        self.got: dict[str, list[tuple[float, bytes, Any]]] = {}
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread = threading.Thread(target=self._spin, daemon=True)
        self._thread.start()

    def _spin(self) -> None:
        while not self._stop.is_set() and self.context.ok():
            self.executor.spin_once(timeout_sec=0.05)

    def listen(self, topic: str, msg_type: type, depth: int = 100) -> None:
        """Record every message on `topic` from now on."""
        self.got.setdefault(topic, [])

        def heard(msg: Any, info: Any) -> None:
            gid = bytes((info.get("publisher_gid") or {}).get("data", b""))
            with self._lock:
                self.got[topic].append((time.time(), gid, msg))

        done = threading.Event()

        def make() -> None:
            self.node.create_subscription(msg_type, topic, heard, depth)
            done.set()

        self.executor.create_task(make)
        assert done.wait(5.0), "the probe's executor did not make the subscription"

    def messages(self, topic: str, since: float = 0.0) -> list[Any]:
        """The messages heard on `topic` that arrived after `since` (unix seconds)."""
        return [m for _, _, m in self.heard(topic, since)]

    def heard(self, topic: str, since: float = 0.0) -> list[tuple[float, bytes, Any]]:
        """(arrival time, publisher GID, message) of what arrived on `topic` after `since`."""
        with self._lock:
            return [h for h in self.got.get(topic, []) if h[0] > since]

    def node_names(self) -> list[str]:
        """The nodes the graph knows now."""
        return list(self.node.get_node_names())

    def call(self, service: str, srv_type: type, request: Any, timeout: float = 5.0) -> Any:
        """Call a service once; its response (AssertionError when it does not answer)."""
        client: Any = self.node.create_client(srv_type, service)
        try:
            assert client.wait_for_service(timeout_sec=timeout), f"no service {service}"
            future = client.call_async(request)
            deadline = time.monotonic() + timeout
            while not future.done() and time.monotonic() < deadline:
                time.sleep(0.01)
            assert future.done(), f"{service} did not answer within {timeout} s"
            return future.result()
        finally:
            self.node.destroy_client(client)

    def close(self) -> None:
        """Stop spinning and shut the context down."""
        self._stop.set()
        self._thread.join(2.0)
        self.executor.shutdown(timeout_sec=1.0)
        self.node.destroy_node()
        if self.context.ok():
            rclpy.shutdown(context=self.context)
