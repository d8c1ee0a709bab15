"""The parameters of ``wmm_sim`` (:mod:`sim_bridge.node`), with their defaults in
``config/wmm_sim.yaml`` and, for the period and the start state, the robot YAML; and the
world they describe."""

import math

from sim_bridge.slip import SlipParams
from sim_bridge.world import BASE_MODES, SimWorld
from wmm_control.nodes.obstacle_topic import obstacle_params
from wmm_control.nodes.parameters import Param, robot_param, robot_period
from wmm_control.robot_config import load_robot

__all__ = ['PARAMS', 'make_world']


def _robot_start(field):
    """Default of a start-state parameter: the robot YAML's ``start:`` entry (its one home)."""
    return lambda values: [float(v) for v in getattr(load_robot(values.robot).start, field)]


PARAMS = (
    robot_param('The robot to simulate.'),
    Param(
        'base_mode',
        'kinematic: rolling model + seeded slip; physics: PyBullet wheel contact.',
        choices=BASE_MODES,
        read_only=True,
    ),
    Param(
        'timing',
        'realtime: wall-clock steps; lockstep: step when the commands answer the state.',
        choices=('realtime', 'lockstep'),
        read_only=True,
    ),
    Param(
        'period',
        'Control period [s]; default: the robot YAML\'s period.',
        lo=1e-4,
        hi=1.0,
        read_only=True,
        default_from=robot_period,
    ),
    Param('substeps', 'Physics steps per period [-].', lo=1, hi=1000, read_only=True),
    Param('command_timeout', 'Command age [s] (receiver clock) after which a group is zeroed.', lo=1e-3, hi=10.0),
    Param('lockstep_groups', 'Comma-separated command groups lockstep waits for, or "all".'),
    Param(
        'lockstep_timeout',
        'Wall time [s] lockstep waits for commands before stepping anyway; published on sim/lockstep_timeout '
        '(latched; 0 in realtime) so that the other nodes know they run in lockstep.',
        lo=1e-3,
        hi=60.0,
    ),
    Param(
        'publish_clock',
        'Publish the sim time on clock (relative: /clock in the root namespace, '
        '<namespace>/clock in one) in realtime mode too; lockstep always does.',
        read_only=True,
    ),
    Param('diagnostics_period', 'Simulated time [s] between /diagnostics messages; 0 = none.', lo=0.0, hi=3600.0),
    Param('slip_gain', 'Slip fraction per unit rim speed [1/(m/s)], kinematic mode.', lo=0.0, hi=10.0, read_only=True),
    Param(
        'slip_drift',
        'Base-frame twist bias (vx, vy, ω) [m/s, m/s, rad/s] while moving.',
        lo=-10.0,
        hi=10.0,
        size=(3,),
        read_only=True,
    ),
    Param(
        'slip_noise',
        'Std of the base twist noise (vx, vy, ω) [m/s, m/s, rad/s].',
        lo=0.0,
        hi=10.0,
        size=(3,),
        read_only=True,
    ),
    Param('seed', 'Seed of the slip noise.', lo=0, hi=2**31 - 1, read_only=True),
    Param(
        'start_base_pose',
        'Start base pose (x, y, θ) [m, m, rad]; default: the robot YAML\'s start.',
        lo=-1e4,
        hi=1e4,
        size=(3,),
        read_only=True,
        default_from=_robot_start('base_pose'),
    ),
    Param(
        'start_arm',
        'Start arm joints [rad or m] (one per arm joint); default: the robot YAML\'s start.',
        lo=-2 * math.pi,
        hi=2 * math.pi,
        read_only=True,
        default_from=_robot_start('arm'),
    ),
    Param('publish_tf', 'Publish /tf and /tf_static (needs tf2_msgs, which has no PyPI wheel).', read_only=True),
    Param(
        'frame_prefix', 'Prefix of the robot\'s frames in TF and odometry (e.g. r1/); world has none.', read_only=True
    ),
    Param('gui', 'Open the PyBullet GUI.', read_only=True),
    *obstacle_params(),
)


def make_world(p, obstacles) -> SimWorld:
    """The :class:`~sim_bridge.world.SimWorld` of the parameter values ``p`` (as
    :func:`~wmm_control.nodes.parameters.declare_parameters` returns them), with ``obstacles``."""
    slip = SlipParams(gain=p.slip_gain, drift=tuple(p.slip_drift), noise_std=tuple(p.slip_noise))
    return SimWorld(
        robot=p.robot,
        base_mode=p.base_mode,
        dt=p.period,
        substeps=p.substeps,
        slip=slip,
        seed=p.seed,
        gui=p.gui,
        start_base_pose=p.start_base_pose,
        start_arm=p.start_arm,
        obstacles=obstacles,
    )
