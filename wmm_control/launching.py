"""What the launch files in ``launch/`` start: one robot's system, in a namespace or not.

A robot's system is ``wmm_sim``, the base controller of its base family (``swmr_controller``
for a steerable base, ``mecanum_controller``, ``differential_controller``), the
``redundancy_resolver``, with ``planner:=true`` ``goal_planner`` (the resolver's ``goal_pose``
then remapped to ``goal_planner/goal``: the user's goals go to the planner) and, with
``viewer:=true``, ``wmm_viewer``. Every node gets the robot
as its ``robot`` parameter (the robot YAML's path) and ``use_sim_time``. In a namespace
(``/r1``), the nodes remap ``/clock`` to the simulator's ``/r1/clock`` and the simulator
prefixes its TF frames with ``r1/``.

Needs ``launch`` and ``launch_ros`` (a ROS 2 install, or the ``ros2`` command line put into the
venv); the rest of the package does not import this module.
"""

from __future__ import annotations

# launch has no type information, so mypy takes the repository's launch/ folder (launch files, no
# __init__.py) for it, as a namespace package without these names.
from launch import LaunchContext, LaunchDescription  # type: ignore[attr-defined]
from launch.actions import DeclareLaunchArgument, OpaqueFunction
from launch.substitutions import LaunchConfiguration
from launch_ros.actions import Node

from wmm_control.base.period import NODE_NAMES
from wmm_control.errors import ConfigError
from wmm_control.kinematics.obstacles import load_obstacles, obstacle_file
from wmm_control.robot_config import load_robot

__all__ = [
    'robot_nodes',
    'robot_launch_description',
    'two_robots_launch_description',
    'common_arguments',
]


def _flag(context: LaunchContext, name: str) -> bool:
    value = LaunchConfiguration(name).perform(context).strip().lower()
    if value not in ('true', 'false'):
        raise ConfigError(f'launch argument {name}:={value!r}: expected true or false')
    return value == 'true'


def common_arguments() -> list[DeclareLaunchArgument]:
    """``use_sim_time``, ``viewer``, ``obstacles`` and ``planner``, the arguments of every launch file."""
    return [
        DeclareLaunchArgument(
            'use_sim_time', default_value='false', description='Every node on the simulator\'s clock (true or false).'
        ),
        DeclareLaunchArgument(
            'viewer', default_value='false', description='Also start wmm_viewer, the browser view (true or false).'
        ),
        DeclareLaunchArgument(
            'obstacles',
            default_value='',
            description=(
                'Obstacle file for the simulator and the resolver: a name in config/obstacles (table_pillar, '
                'table_reach) or a YAML path; empty for none.'
            ),
        ),
        DeclareLaunchArgument(
            'planner',
            default_value='false',
            description=(
                'Also start goal_planner between /goal_pose and the resolver: goals beyond the obstacles are '
                'reached by a planned way round them (true or false).'
            ),
        ),
    ]


def robot_nodes(
    robot: str, namespace: str, use_sim_time: bool, viewer: bool, obstacles: str = '', planner: bool = False
) -> list[Node]:
    """The nodes of one robot's system.

    Args:
        robot: a shipped robot's name or a robot YAML path (:func:`~wmm_control.robot_config.load_robot`).
        namespace: '' or a namespace such as ``r1`` (no slashes).
        use_sim_time: every node on the simulator's clock.
        viewer: start ``wmm_viewer`` too.
        obstacles: an obstacle file (name or path; '' for none) for the simulator, the resolver and
            the planner.
        planner: start ``goal_planner`` too, and remap the resolver's ``goal_pose`` to it.

    Raises:
        ConfigError: the robot or the obstacle file cannot be loaded.
    """
    config = load_robot(robot)
    if obstacles:
        load_obstacles(obstacles)  # a bad file fails here, not in two nodes
        obstacles = str(obstacle_file(obstacles).resolve())
    common = {'robot': str(config.yaml_path), 'use_sim_time': use_sim_time}
    remap = [('/clock', f'/{namespace}/clock')] if namespace else []
    # the resolver takes its goals from the planner when it runs (relative: goal_planner/goal in a namespace)
    resolver_remap = [('goal_pose', 'goal_planner/goal')] if planner else []
    executables = [
        ('wmm_sim', {'frame_prefix': f'{namespace}/' if namespace else '', 'obstacles': obstacles}, []),
        (NODE_NAMES[config.base.family], {}, []),
        ('redundancy_resolver', {'obstacles': obstacles}, resolver_remap),
    ]
    if planner:
        executables.append(('goal_planner', {'obstacles': obstacles}, []))
    if viewer:
        executables.append(('wmm_viewer', {'obstacles': obstacles}, []))
    return [
        Node(
            package='wmm_control',
            executable=exe,
            namespace=namespace or None,
            output='screen',
            parameters=[dict(common, **extra)],
            remappings=remap + own,
        )
        for exe, extra, own in executables
    ]


def robot_launch_description(robot: str | None = None) -> LaunchDescription:
    """One robot's system: ``robot`` fixed, or (None) taken from the ``robot:=`` argument."""
    arguments = common_arguments()
    if robot is None:
        arguments.insert(
            0,
            DeclareLaunchArgument(
                'robot',
                default_value='steerable',
                description=(
                    'A shipped robot (steerable, mecanum, ur_mecanum, panda_diff; A, B) or a robot YAML path.'
                ),
            ),
        )

    def nodes(context: LaunchContext) -> list[Node]:
        name = robot if robot is not None else LaunchConfiguration('robot').perform(context)
        return robot_nodes(
            name,
            '',
            _flag(context, 'use_sim_time'),
            _flag(context, 'viewer'),
            LaunchConfiguration('obstacles').perform(context).strip(),
            _flag(context, 'planner'),
        )

    return LaunchDescription([*arguments, OpaqueFunction(function=nodes)])


def two_robots_launch_description() -> LaunchDescription:
    """Two robots in namespaces ``/r1`` and ``/r2`` (``robot1:=``, ``robot2:=``); the viewer
    (``viewer:=true``) shows ``/r1``."""
    arguments = [
        DeclareLaunchArgument('robot1', default_value='steerable', description='The robot in /r1.'),
        DeclareLaunchArgument('robot2', default_value='mecanum', description='The robot in /r2.'),
        *common_arguments(),
    ]

    def nodes(context: LaunchContext) -> list[Node]:
        sim_time, viewer = _flag(context, 'use_sim_time'), _flag(context, 'viewer')
        obstacles = LaunchConfiguration('obstacles').perform(context).strip()
        planner = _flag(context, 'planner')
        return [
            *robot_nodes(LaunchConfiguration('robot1').perform(context), 'r1', sim_time, viewer, obstacles, planner),
            *robot_nodes(LaunchConfiguration('robot2').perform(context), 'r2', sim_time, False, obstacles, planner),
        ]

    return LaunchDescription([*arguments, OpaqueFunction(function=nodes)])
