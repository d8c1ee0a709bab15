"""The parameters of the base controller nodes (:mod:`wmm_control.nodes.base_controller`): the
same for every base family, with the steerable controller's gains besides; their defaults in
``config/<executable>.yaml``, the robot's geometry and limits in its description."""

from wmm_control.base.period import NODE_NAMES
from wmm_control.nodes.parameters import Param, max_state_wait_param, robot_param, robot_period

__all__ = ['NODE_NAMES', 'GAINS', 'STEERABLE_PARAMS', 'WHEEL_PARAMS']

#: The steerable controller's gains (Sorour Table I), its only parameters of its own.
GAINS = (
    Param('kp', 'Gain K_p of the twist controller [1/s].', lo=1e-3, hi=40.0, read_only=True),
    Param('icr_gain', 'Gain λ of the ICR P-controller [1/s].', lo=1e-3, hi=40.0, read_only=True),
)


def _params(robot_help, gains=()):
    return (
        robot_param(robot_help),
        Param(
            'period',
            'Control period t_s [s]; default: the robot YAML\'s period.',
            lo=1e-3,
            hi=1.0,
            read_only=True,
            default_from=robot_period,
        ),
        *gains,
        Param('base_frame', 'Frame of the reference and feasible twists.', read_only=True),
        Param(
            'reference_timeout',
            'Reference age [s] (this node\'s clock at receipt; in lockstep the simulation\'s time) after which '
            'the base brakes to rest.',
            lo=1e-3,
            hi=60.0,
        ),
        Param(
            'reference_wait',
            'Steady time [s] a joint state waits for its reference; in lockstep, while the references come, as '
            'long as the simulator waits for the commands (its lockstep_timeout).',
            lo=0.0,
            hi=1.0,
            read_only=True,
        ),
        Param(
            'joint_state_timeout',
            'Joint-state age [s] (steady clock) after which zero rates are commanded; in lockstep the '
            'simulator\'s lockstep_timeout is added.',
            lo=1e-3,
            hi=60.0,
        ),
        max_state_wait_param(),
        Param(
            'applied_rate_tolerance',
            'Largest difference [rad/s] between the rates of a joint state and the '
            'last command under which that command counts as applied; beyond it the controller restarts from '
            'the measured state. 0: never.',
            lo=0.0,
            hi=100.0,
            read_only=True,
        ),
        Param('diagnostics_period', 'Time [s] between /diagnostics messages; 0 = none.', lo=0.0, hi=3600.0),
    )


STEERABLE_PARAMS = _params(
    'A robot with a steerable base (A, Sorour). Geometry, joints and limits come from its YAML.', GAINS
)
WHEEL_PARAMS = _params('A robot with a Mecanum or differential base. Geometry and limits come from its description.')
