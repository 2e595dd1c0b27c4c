"""ROS 2 beside sdrpeer: rclpy nodes as components, a bridge between ports and topics, and
recordings in ROS 2's own format. Everything here is optional: modules that need rclpy import it
only when used (sdrpeer.ros2.env says whether it is there)."""
