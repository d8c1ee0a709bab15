"""Thin rclpy nodes around the ROS-free core. Each wraps one core object."""
