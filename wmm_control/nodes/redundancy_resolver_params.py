"""The parameters of ``redundancy_resolver`` (:mod:`wmm_control.nodes.redundancy_resolver`):
the node's own, with their defaults in ``config/redundancy_resolver.yaml``, and the method's
gains and options, with their defaults in the resolver parameter classes."""

import dataclasses

from wmm_control.nodes.parameters import (
    Param,
    defaults_elsewhere,
    max_state_wait_param,
    robot_method,
    robot_param,
    robot_period,
)
from wmm_control.nodes.obstacle_topic import obstacle_params
from wmm_control.resolvers import METHODS
from wmm_control.resolvers.pose_servo import ORIENTATION_ERRORS

__all__ = ['PARAMS']

_SPECS = (
    robot_param(),
    Param(
        'method',
        'Redundancy resolution method; default: the robot YAML\'s method.',
        choices=tuple(sorted(METHODS)),
        read_only=True,
        default_from=robot_method,
    ),
    Param(
        'period',
        'Control period [s]: the acceleration limits act per period; default: the robot YAML\'s period.',
        lo=1e-3,
        hi=1.0,
        read_only=True,
        default_from=robot_period,
    ),
    Param('lambda_p', 'Gain λ_p of the pose controller, eq (12) [1/s].', lo=1e-3, hi=100.0, read_only=True),
    Param('rho', 'Damping ρ of the pseudo-inverse [-].', lo=1e-9, hi=10.0, read_only=True),
    Param('r_fm', 'Fine manipulation range r_fm [m] (task_sharing).', lo=1e-4, hi=100.0, read_only=True),
    Param('r_mm', 'Mobile manipulation range r_mm [m] (task_sharing).', lo=1e-4, hi=100.0, read_only=True),
    Param(
        'lambda_dex',
        'Gain λ_dex of the pull to the dexterous posture [1/s] (task_sharing).',
        lo=0.0,
        hi=100.0,
        read_only=True,
    ),
    Param('compensation', 'Arm compensation of the base velocity error, eq (14) (task_sharing).', read_only=True),
    Param(
        'psi_rate', 'Largest change of ψ per second [1/s]; 0: ψ jumps as in eq (11).', lo=0.0, hi=1000.0, read_only=True
    ),
    Param('orientation_error', 'rpy (the paper) or log (SO(3) log map).', choices=ORIENTATION_ERRORS, read_only=True),
    Param('rotate_angular_error', 'Rotate the RPY error by the base yaw, as eq (12) is printed.', read_only=True),
    Param('singular_region', 'σ_min below which the damping grows [-].', lo=1e-6, hi=10.0, read_only=True),
    Param('max_damping', 'Damping at an exact singularity [-].', lo=0.0, hi=10.0, read_only=True),
    Param(
        'hold_joint_limits',
        'Hold an arm joint the task would drive past its braking bound there and share '
        'its part of the task among the others (pinv, task_sharing; not in the paper).',
        read_only=True,
    ),
    Param(
        'arm_takeover',
        'Where the base acceleration limit holds back the base share of the task, the arm '
        'takes it over instead of slowing the whole body (pinv, task_sharing; not in the paper).',
        read_only=True,
    ),
    Param(
        'rows',
        'Task rows of amp/traditional: position (r = 3) or full (r = 6).',
        choices=('position', 'full'),
        read_only=True,
    ),
    Param('kp', 'K_p of the PD law, eq (23), position rows [1/s²] (amp, traditional).', lo=0.0, hi=1e4, read_only=True),
    Param('kd', 'K_d of eq (23), position rows [1/s] (amp, traditional).', lo=0.0, hi=1e3, read_only=True),
    Param('kp_rot', 'K_p of eq (23), orientation rows [1/s²] (amp, traditional).', lo=0.0, hi=1e4, read_only=True),
    Param('kd_rot', 'K_d of eq (23), orientation rows [1/s] (amp, traditional).', lo=0.0, hi=1e3, read_only=True),
    Param(
        'gamma1',
        'γ1 of the manipulability objective, eqs (12)-(13) (amp, traditional).',
        lo=0.0,
        hi=1e3,
        read_only=True,
    ),
    Param('gamma2', 'γ2 of eq (13) (amp, traditional).', lo=0.0, hi=1e3, read_only=True),
    Param('manipulability', 'Run the manipulability objective (amp, traditional).', read_only=True),
    Param(
        'collision_avoidance',
        'Pass every arm command through the safety stage (velocity dampers that keep '
        'the arm off the body, itself and the floor).',
        read_only=True,
    ),
    Param(
        'collision_influence', 'Distance d_i [m] under which a pair is constrained.', lo=1e-3, hi=1.0, read_only=True
    ),
    Param(
        'collision_safety',
        'Distance d_s [m] the dampers keep; below it a pair must separate.',
        lo=1e-4,
        hi=1.0,
        read_only=True,
    ),
    Param(
        'collision_gain', 'Approach speed ξ [m/s] allowed at the influence distance.', lo=1e-3, hi=10.0, read_only=True
    ),
    Param(
        'collision_lookahead',
        'Distance d_b [m] under which a pair approaches no faster than braking at collision_braking can stop.',
        lo=1e-3,
        hi=2.0,
        read_only=True,
    ),
    Param(
        'collision_braking',
        'Deceleration a_b [m/s²] of a distance that braking counts on.',
        lo=1e-3,
        hi=100.0,
        read_only=True,
    ),
    Param(
        'collision_lag_margin',
        "Room [m] a lagging (steerable) base's chassis and wheels keep from obstacles beyond "
        'collision_safety, for the sweep of its re-steering.',
        lo=0.0,
        hi=1.0,
        read_only=True,
    ),
    Param(
        'steering_damping',
        "Damping ratio ζ [-] of a differential base's sideways offset from a followed plan's line, "
        'steered out as it drives (Kanayama k_y = k_θ² / (4 ζ² v_max²)); larger: gentler.',
        lo=1e-3,
        hi=100.0,
        read_only=True,
    ),
    Param('sigma_min', 'σ_m,min: the base is activated below it (amp).', lo=0.0, hi=10.0, read_only=True),
    Param('singularity_avoidance', 'Activate the base near a singularity (amp).', read_only=True),
    Param(
        'sigma_rows',
        'Rows of J_m for σ_m: task (the task rows) or position (amp).',
        choices=('task', 'position'),
        read_only=True,
    ),
    Param(
        'sigma_lookahead',
        'Anticipation of the singularity test: σ_m + τ·min(σ̇_m, 0) [s] (amp).',
        lo=0.0,
        hi=10.0,
        read_only=True,
    ),
    Param(
        'setpoint_speed',
        'Peak speed of the trajectory a goal becomes [m/s] (amp, traditional).',
        lo=1e-3,
        hi=10.0,
        read_only=True,
    ),
    Param(
        'setpoint_accel',
        'Peak acceleration of that trajectory [m/s²] (amp, traditional).',
        lo=1e-3,
        hi=100.0,
        read_only=True,
    ),
    Param('setpoint_angular_speed', 'Peak angular speed of that trajectory [rad/s].', lo=1e-3, hi=10.0, read_only=True),
    Param(
        'setpoint_angular_accel',
        'Peak angular acceleration of that trajectory [rad/s²].',
        lo=1e-3,
        hi=100.0,
        read_only=True,
    ),
    Param(
        'ee_feedback',
        'End-effector pose from odometry + forward kinematics, or from /ee_pose.',
        choices=('odometry', 'ground_truth'),
        read_only=True,
    ),
    *obstacle_params(),
    Param('world_frame', 'Frame of /goal_pose, /ee_pose and /obstacles.', read_only=True),
    Param('base_frame', 'Frame of /base/reference and /base/feasible_twist.', read_only=True),
    Param(
        'state_timeout',
        'Age [s] of joint states, odometry, EE pose or trajectory reference (steady clock, '
        'at receipt; in lockstep the simulation\'s time, and the joint states\' watchdog adds the '
        'simulator\'s lockstep_timeout) after which commands are zero.',
        lo=1e-3,
        hi=60.0,
    ),
    max_state_wait_param(),
    Param(
        'compensation_timeout',
        'Steady time [s] to wait for the feasible twist of this cycle; in lockstep, while the feasible '
        'twists come, as long as the simulator waits for the commands (its lockstep_timeout).',
        lo=0.0,
        hi=1.0,
        read_only=True,
    ),
    Param('max_goal_distance', 'Goals farther than this from the world origin are rejected [m].', lo=1.0, hi=1e6),
    Param(
        'goal_tolerance',
        'Position [m] and orientation [rad] errors under which the goal is reached.',
        lo=1e-6,
        hi=10.0,
        size=(2,),
    ),
    Param(
        'stall_time',
        'Time [s] without progress after which an unreached goal is reported as stalled.',
        lo=0.1,
        hi=600.0,
    ),
    Param(
        'min_progress_ratio',
        'Fraction [-] of its best value by which an error must fall within stall_time '
        'to count as progress (at least 1 mm / 1 mrad).',
        lo=0.0,
        hi=0.9,
    ),
    Param('diagnostics_period', 'Time [s] between /diagnostics messages; 0 = none.', lo=0.0, hi=3600.0),
    Param(
        'markers_period',
        'Steady time [s] between ~/markers messages (goal, reference, end-effector trail, '
        'base footprint for rviz); 0 = none.',
        lo=0.0,
        hi=60.0,
        read_only=True,
    ),
)


def _method_defaults():
    """The default of every method parameter: its field's default in the resolver parameter
    classes (:mod:`wmm_control.resolvers`), their one home. A name several classes share has
    one default in all of them (checked here)."""
    out = {}
    for _, params_cls in METHODS.values():
        for field in dataclasses.fields(params_cls):
            if out.setdefault(field.name, field.default) != field.default:
                raise AssertionError(f'method parameter {field.name} has two defaults')
    return out


_METHOD_DEFAULTS = _method_defaults()
#: The node's parameters. The method's own (gains, thresholds, options) take their defaults
#: from the resolver parameter classes; config/redundancy_resolver.yaml holds the node's.
PARAMS = defaults_elsewhere(_SPECS, _METHOD_DEFAULTS, 'resolver class')
