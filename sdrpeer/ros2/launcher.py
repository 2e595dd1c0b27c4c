"""The `ros2` launcher: hosts an rclpy node class, or an sdrpeer component that uses rclpy.

How it works: target `package.module:Class` or `path/to/file.py[:Class]` (as the `python` and
`script` launchers take), run by `python -m sdrpeer.ros2.host` (sdrpeer.ros2.host); params are the
node's ROS parameters (sdrpeer.ros2.node). The agent gives the host the fleet's ROS 2 discovery
settings (sdrpeer.ros2.env.Ros2Net). `available()` says why this robot cannot run it (ROS 2 not
installed): an agent offers only the launchers it can run, so the allocator places a ROS 2
component only on a robot that has ROS 2. Off until the agent's configuration names it
(`allow_launchers: [ros2]`), like every launcher but `python`; its targets are held to
`allow_targets` like `python`'s.
"""

from __future__ import annotations

from typing import Any

from sdrpeer.errors import LauncherError
from sdrpeer.launch.launchers import param_args
from sdrpeer.ros2 import env

__all__ = ["Ros2Launcher"]


class Ros2Launcher:
    """`python -m sdrpeer.ros2.host pkg.mod:Class` (or a file target)."""

    name = "ros2"

    def command(self, target: str | list[str], params: dict[str, Any], *, python: str) -> list[str]:
        """The host command for a node (or ROS-using component) class."""
        if not isinstance(target, str) or not target:
            raise LauncherError(
                "launcher 'ros2': target must be 'package.module:Class' or "
                f"'path/to/file.py[:Class]', got {target!r}"
            )
        return [python, "-m", "sdrpeer.ros2.host", target, *param_args(params)]

    def available(self) -> str | None:
        """None if ROS 2 is installed here, else why not."""
        return env.available()
