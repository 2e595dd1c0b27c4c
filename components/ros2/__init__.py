"""Unmodified ROS 2 (rclpy) nodes, as a robot's existing software would be: sdrpeer hosts them
with the `ros2` launcher (sdrpeer.ros2). Nothing here imports sdrpeer."""
