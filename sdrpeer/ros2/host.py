"""`python -m sdrpeer.ros2.host TARGET [--param k=v ...]`: a component host with ROS 2 in it.

How it works: the same host as `python -m sdrpeer.host` (sdrpeer.host.main: control channel, data
plane, lifecycle), with two differences. First, the process gets the environment of
`sdrpeer.ros2.env.process_env` (the ROS wheels' libraries on `LD_LIBRARY_PATH`, which only an
`exec` can give a running interpreter, so the host re-executes itself once when they are missing;
the fleet's ROS_* discovery settings come from the agent). Second, the target may name an rclpy
node class (`rclpy.node.Node` or `rclpy.lifecycle.LifecycleNode`, unmodified) as well as an
sdrpeer Component class (one that uses rclpy itself, like the bridge: sdrpeer.ros2.bridge): a
node class is hosted by `Ros2Node.hosting(cls)` (sdrpeer.ros2.node).
"""

from __future__ import annotations

import os
import sys

from sdrpeer.errors import LoadError
from sdrpeer.host.config import HostConfig
from sdrpeer.host.loader import load_component_class
from sdrpeer.host.main import main as host_main
from sdrpeer.ros2.env import BOOTSTRAP_DONE, process_env

__all__ = ["load_ros2_class", "main"]


def load_ros2_class(config: HostConfig) -> type:
    """The Component class for the target: itself, or a node class wrapped in `Ros2Node`
    (LoadError when ROS 2 is not installed here)."""
    try:
        from rclpy.node import Node  # noqa: PLC0415 - after the environment is right
    except ImportError as exc:
        raise LoadError(f"{config.target}: ROS 2 cannot be loaded here ({exc})") from None

    from sdrpeer.ros2.node import Ros2Node  # noqa: PLC0415
    from sdrpeer.sdk import Component  # noqa: PLC0415

    cls = load_component_class(config.target, (Component, Node))
    if issubclass(cls, Node):
        return Ros2Node.hosting(cls)
    return cls


def _missing_libraries(current: dict[str, str], wanted: dict[str, str]) -> bool:
    have = set(current.get("LD_LIBRARY_PATH", "").split(os.pathsep))
    return not set(wanted["LD_LIBRARY_PATH"].split(os.pathsep)) <= have


def main() -> int:
    """Fix the environment (re-executing once if the libraries are missing), then host."""
    env = process_env(os.environ)
    if _missing_libraries(dict(os.environ), env) and os.environ.get("SDRPEER_ROS2_EXEC") != "1":
        env["SDRPEER_ROS2_EXEC"] = "1"  # once: never loop if the libraries are not there
        os.execve(sys.executable, [sys.executable, "-m", "sdrpeer.ros2.host", *sys.argv[1:]], env)
    os.environ[BOOTSTRAP_DONE] = "1"
    os.environ["AMENT_PREFIX_PATH"] = env["AMENT_PREFIX_PATH"]
    return host_main(load=load_ros2_class)


if __name__ == "__main__":
    raise SystemExit(main())
