"""A managed (lifecycle) node: std_msgs/String on /chatter at 10 Hz, only while active. Its
publisher and timer are made in on_configure and dropped in on_cleanup, as ROS 2's lifecycle
demos do. Plain rclpy."""

from __future__ import annotations

from typing import Any

from rclpy.lifecycle import LifecycleNode, LifecycleState, TransitionCallbackReturn
from std_msgs.msg import String


class LifecycleTalker(LifecycleNode):
    """Talks on /chatter while active."""

    def __init__(self) -> None:
        super().__init__("lifecycle_talker")
        self.pub: Any = None
        self.timer: Any = None
        self.count = 0
        self.transitions: list[str] = []

    def on_configure(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.transitions.append("configure")
        self.pub = self.create_lifecycle_publisher(String, "/chatter", 10)
        self.timer = self.create_timer(0.1, self.talk)
        return TransitionCallbackReturn.SUCCESS

    def on_activate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.transitions.append("activate")
        return super().on_activate(state)

    def on_deactivate(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.transitions.append("deactivate")
        return super().on_deactivate(state)

    def on_cleanup(self, state: LifecycleState) -> TransitionCallbackReturn:
        self.transitions.append("cleanup")
        self.destroy_timer(self.timer)
        self.destroy_lifecycle_publisher(self.pub)
        return TransitionCallbackReturn.SUCCESS

    def talk(self) -> None:
        if self.pub is not None and self.pub.is_activated:
            self.count += 1
            self.pub.publish(String(data=f"hello {self.count}"))
