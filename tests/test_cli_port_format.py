"""`sdrpeer port list`'s table: a service port shows its role, interface and calls; a ROS 2 node's
topics their direction, ROS 2 type and frames."""

from __future__ import annotations

from typing import Any

from sdrpeer.cli.port import format_ports


def test_service_ports_show_role_interface_and_calls() -> None:
    rows: list[dict[str, Any]] = [
        {
            "robot": "robot-1",
            "instance": "Caller",
            "port": "planner",
            "direction": "requires",
            "type": "demo/Planner#5692b540",
            "counters": {"calls": 61, "frames_in": 0},
            "connections": [{"id": "b", "to": "Planner.planner", "adhoc": False}],
        },
        {
            "robot": "robot-1",
            "instance": "Cam",
            "port": "image",
            "direction": "out",
            "type": None,
            "counters": {"frames_out": 7},
            "rates": {"frames_out_per_s": 2.5},
            "connections": [{"id": "c", "to": "Det.image", "adhoc": True}],
        },
    ]
    lines = format_ports(rows).splitlines()
    assert lines[1].split() == [
        "robot-1", "Caller.planner", "requires", "demo/Planner#5692b540", "61", "-",
        "Planner.planner",
    ]  # fmt: skip
    assert lines[2].split() == ["robot-1", "Cam.image", "out", "-", "7", "2.5", "+Det.image"]
    assert lines[-1] == "(+ run-time connection)"


def test_a_ros2_nodes_topics_show_their_direction_type_and_frames() -> None:
    rows: list[dict[str, Any]] = [
        {
            "robot": "robot-2",
            "instance": "Odometry",
            "port": "/odom",
            "direction": "publishes",
            "type": "nav_msgs/msg/Odometry",
            "counters": {"frames_out": 500, "bytes_out": 36000},
            "rates": {"frames_out_per_s": 50.0},
            "connections": [],
            "ros2": True,
        },
        {
            "robot": "robot-2",
            "instance": "Listener",
            "port": "/pose",
            "direction": "subscribes",
            "type": "geometry_msgs/msg/PoseStamped",
            "counters": {"frames_in": 498},
            "connections": [],
            "ros2": True,
        },
    ]
    lines = format_ports(rows).splitlines()
    assert lines[1].split() == [
        "robot-2", "Odometry", "/odom", "publishes", "nav_msgs/msg/Odometry", "500", "50", "-",
    ]  # fmt: skip
    assert lines[2].split() == [
        "robot-2", "Listener", "/pose", "subscribes", "geometry_msgs/msg/PoseStamped", "498", "-",
        "-",
    ]  # fmt: skip
