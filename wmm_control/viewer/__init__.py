"""The browser viewer's ROS-free parts: the robot scene from its URDF, the status panel, the goal drag."""
