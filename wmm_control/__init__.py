"""wmm_control: whole-body motion control of wheeled mobile manipulators.

The core (kinematics, base controllers, resolvers) is ROS-free; the rclpy nodes live in
``wmm_control.nodes`` and the simulator in the sibling package ``sim_bridge``.
"""

from wmm_control.errors import ConfigError, NonFiniteError, ShapeError, UnknownFrameError, WmmError
from wmm_control.robot_config import RobotConfig, load_robot

__all__ = [
    'ConfigError',
    'NonFiniteError',
    'ShapeError',
    'UnknownFrameError',
    'WmmError',
    'RobotConfig',
    'load_robot',
]
