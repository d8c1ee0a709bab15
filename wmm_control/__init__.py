"""wmm_control: whole-body motion control of wheeled mobile manipulators.

The core (kinematics, base controllers, resolvers) is ROS-free; the rclpy nodes live in
``wmm_control.nodes`` and the simulator in the sibling package ``sim_bridge``.

``RobotConfig`` and ``load_robot`` are imported when first asked for: importing a submodule
(a command-line tool's ``--help``, say) loads no kinematics library.
"""

from typing import Any

from wmm_control.errors import ConfigError, NonFiniteError, ShapeError, UnknownFrameError, WmmError

__all__ = [
    'ConfigError',
    'NonFiniteError',
    'ShapeError',
    'UnknownFrameError',
    'WmmError',
    'RobotConfig',
    'load_robot',
]


def __getattr__(name: str) -> Any:
    if name in ('RobotConfig', 'load_robot'):
        from wmm_control import robot_config

        return getattr(robot_config, name)
    raise AttributeError(f'module {__name__!r} has no attribute {name!r}')
