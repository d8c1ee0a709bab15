"""``redundancy_resolver``: whole-body redundancy resolution as a node (Sorour §II–III).

Publish an end-effector goal on ``/goal_pose`` and the robot goes there.

Subscribes:
  ``/goal_pose`` (``geometry_msgs/PoseStamped``, frame ``world_frame``): the set-point;
  ``/ee_reference`` (``trajectory_msgs/MultiDOFJointTrajectory``, frame ``world_frame``): a
  trajectory point, its first point's ``transforms[0]`` (pose), ``velocities[0]`` and
  ``accelerations[0]`` (linear, angular, world axes); the latest of a goal and a reference
  is the target. A reference older than ``state_timeout`` is held as a set-point;
  ``/joint_states`` (``sensor_msgs/JointState``): arm joints by name; each message runs one
  control cycle;
  ``/odom`` (``nav_msgs/Odometry``): base pose and twist (wheel odometry on a real robot);
  ``/ee_pose`` (``geometry_msgs/PoseStamped``): measured end-effector pose, used only when
  ``ee_feedback`` is ``ground_truth`` (otherwise forward kinematics from odometry and joints);
  ``/base/feasible_twist`` (``geometry_msgs/TwistStamped``): the base controller's answer to
  this cycle's base reference (Sorour eq 15), for the arm compensation of eq (14);
  ``/obstacles`` (``visualization_msgs/MarkerArray``, frame ``world_frame``): obstacles added
  and removed live, beside those of the ``obstacles`` file (:mod:`wmm_control.nodes.obstacle_topic`);
  the safety stage keeps the robot off them.
Publishes, every cycle:
  ``/base/reference`` (``geometry_msgs/TwistStamped``, frame ``base_frame``): the base twist,
  stamped with the joint state the cycle answers;
  ``/arm_controller/commands`` (``std_msgs/Float64MultiArray``): arm joint velocities in the
  robot YAML's order;
  ``/diagnostics`` (``diagnostic_msgs/DiagnosticArray``) every ``diagnostics_period``, stamped
  with the joint state of the cycle it reports: method, mode, ψ, errors, limit scales, σ_min,
  compensation, cycle time, the commands sent, goal status;
  ``~/markers`` (``visualization_msgs/MarkerArray``, frame ``world_frame``) every
  ``markers_period`` of steady time: goal, reference, end-effector trail, base footprint
  (:mod:`wmm_control.nodes.markers`).

The exchange, one per period: on the joint state stamped S the resolver publishes the base
reference stamped S, waits (steady clock, at most ``compensation_timeout``) for the feasible
twist stamped S, then publishes the arm command with the compensation. When the answer does
not come in time the arm command goes out without it (counted, logged). Methods without
compensation publish both at once.

Safety: zero commands when there is no goal, after a rejected goal, and while the joint
states, the odometry or (with ground-truth feedback) the end-effector pose are older than
``state_timeout`` (steady clock, at receipt); a watchdog publishes zeros when the joint
states stop. A goal (or ``/ee_reference`` point) in another frame, with NaN/inf or a zero
quaternion, beyond ``max_goal_distance`` from the world origin, below the floor, above the
highest the end effector can reach, inside the base's body at its current pose or inside an
obstacle (:class:`~wmm_control.kinematics.workspace.Workspace`) is rejected with a logged reason; a
non-unit quaternion is normalised with a warning. Odometry with NaN/inf, a zero quaternion
or a twist beyond ten times the base limits, and joint states lacking an arm joint or naming
one twice, with non-finite values, rates beyond ten times the limits or positions beyond
the limits, are rejected. A joint state whose stamp is not after the last cycle's, or jumps
more than ``state_timeout`` ahead, runs no cycle (a second publisher, a replayed message).
A goal that stops making progress is logged once. Every command stays within the robot's limits
(:mod:`wmm_control.resolvers.limits`); a goal out of reach is pursued as far as they allow
and reported on ``/diagnostics``.
"""

import dataclasses
import math

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.orientation import matrix_from_quaternion, yaw_from_quaternion
from wmm_control.kinematics.workspace import Workspace
from wmm_control.nodes.markers import MarkerSet
from wmm_control.nodes.obstacle_topic import OBSTACLE_PARAM_HELP, ObstacleSet, describe
from wmm_control.nodes.common import (
    COMMAND_QOS, DIAGNOSTICS_QOS, Freshness, JointSelector, JointStateWatchdog, Param, STATE_SUB_QOS,
    declare_parameters, diagnostic_array, float_array, guard_clock, node_status, robot_method, robot_param,
    robot_period, run_node, stamp_key, twist_stamped)
from wmm_control.resolvers import METHODS, PoseTarget, RobotState, make_resolver, method_parameters
from wmm_control.resolvers.pose_servo import ORIENTATION_ERRORS
from wmm_control.resolvers.progress import GoalProgress
from wmm_control.viewer.scene import Trail

__all__ = ['RedundancyResolverNode', 'main']

_SPECS = (
    robot_param(),
    Param('method', 'Redundancy resolution method; default: the robot YAML\'s method.', choices=tuple(sorted(METHODS)),
          read_only=True, default_from=robot_method),
    Param('period', 'Control period [s]: the acceleration limits act per period; default: the robot YAML\'s '
          'period.', lo=1e-3, hi=1.0, read_only=True, default_from=robot_period),
    Param('lambda_p', 'Gain λ_p of the pose controller, eq (12) [1/s].', lo=1e-3, hi=100.0, read_only=True),
    Param('rho', 'Damping ρ of the pseudo-inverse [-].', lo=1e-9, hi=10.0, read_only=True),
    Param('r_fm', 'Fine manipulation range r_fm [m] (task_sharing).', lo=1e-4, hi=100.0, read_only=True),
    Param('r_mm', 'Mobile manipulation range r_mm [m] (task_sharing).', lo=1e-4, hi=100.0, read_only=True),
    Param('lambda_dex', 'Gain λ_dex of the pull to the dexterous posture [1/s] (task_sharing).',
          lo=0.0, hi=100.0, read_only=True),
    Param('compensation', 'Arm compensation of the base velocity error, eq (14) (task_sharing).',
          read_only=True),
    Param('psi_rate', 'Largest change of ψ per second [1/s]; 0: ψ jumps as in eq (11).', lo=0.0, hi=1000.0,
          read_only=True),
    Param('orientation_error', 'rpy (the paper) or log (SO(3) log map).', choices=ORIENTATION_ERRORS,
          read_only=True),
    Param('rotate_angular_error', 'Rotate the RPY error by the base yaw, as eq (12) is printed.',
          read_only=True),
    Param('singular_region', 'σ_min below which the damping grows [-].', lo=1e-6, hi=10.0, read_only=True),
    Param('max_damping', 'Damping at an exact singularity [-].', lo=0.0, hi=10.0, read_only=True),
    Param('hold_joint_limits', 'Hold an arm joint the task would drive past its braking bound there and share '
          'its part of the task among the others (pinv, task_sharing; not in the paper).', read_only=True),
    Param('arm_takeover', 'Where the base acceleration limit holds back the base share of the task, the arm '
          'takes it over instead of slowing the whole body (pinv, task_sharing; not in the paper).', read_only=True),
    Param('rows', 'Task rows of amp/traditional: position (r = 3) or full (r = 6).', choices=('position', 'full'),
          read_only=True),
    Param('kp', 'K_p of the PD law, eq (23), position rows [1/s²] (amp, traditional).', lo=0.0, hi=1e4,
          read_only=True),
    Param('kd', 'K_d of eq (23), position rows [1/s] (amp, traditional).', lo=0.0, hi=1e3, read_only=True),
    Param('kp_rot', 'K_p of eq (23), orientation rows [1/s²] (amp, traditional).', lo=0.0, hi=1e4, read_only=True),
    Param('kd_rot', 'K_d of eq (23), orientation rows [1/s] (amp, traditional).', lo=0.0, hi=1e3, read_only=True),
    Param('gamma1', 'γ1 of the manipulability objective, eqs (12)-(13) (amp, traditional).', lo=0.0, hi=1e3,
          read_only=True),
    Param('gamma2', 'γ2 of eq (13) (amp, traditional).', lo=0.0, hi=1e3, read_only=True),
    Param('manipulability', 'Run the manipulability objective (amp, traditional).', read_only=True),
    Param('collision_avoidance', 'Pass every arm command through the safety stage (velocity dampers that keep '
          'the arm off the body, itself and the floor).', read_only=True),
    Param('collision_influence', 'Distance d_i [m] under which a pair is constrained.', lo=1e-3, hi=1.0,
          read_only=True),
    Param('collision_safety', 'Distance d_s [m] the dampers keep; below it a pair must separate.', lo=1e-4,
          hi=1.0, read_only=True),
    Param('collision_gain', 'Approach speed ξ [m/s] allowed at the influence distance.', lo=1e-3, hi=10.0,
          read_only=True),
    Param('collision_lookahead', 'Distance d_b [m] under which a pair approaches no faster than braking at '
          'collision_braking can stop.', lo=1e-3, hi=2.0, read_only=True),
    Param('collision_braking', 'Deceleration a_b [m/s²] of a distance that braking counts on.', lo=1e-3, hi=100.0,
          read_only=True),
    Param('sigma_min', 'σ_m,min: the base is activated below it (amp).', lo=0.0, hi=10.0, read_only=True),
    Param('singularity_avoidance', 'Activate the base near a singularity (amp).', read_only=True),
    Param('sigma_rows', 'Rows of J_m for σ_m: task (the task rows) or position (amp).', choices=('task', 'position'),
          read_only=True),
    Param('sigma_lookahead', 'Anticipation of the singularity test: σ_m + τ·min(σ̇_m, 0) [s] (amp).', lo=0.0,
          hi=10.0, read_only=True),
    Param('setpoint_speed', 'Peak speed of the trajectory a goal becomes [m/s] (amp, traditional).', lo=1e-3,
          hi=10.0, read_only=True),
    Param('setpoint_accel', 'Peak acceleration of that trajectory [m/s²] (amp, traditional).', lo=1e-3, hi=100.0,
          read_only=True),
    Param('setpoint_angular_speed', 'Peak angular speed of that trajectory [rad/s].', lo=1e-3, hi=10.0,
          read_only=True),
    Param('setpoint_angular_accel', 'Peak angular acceleration of that trajectory [rad/s²].', lo=1e-3, hi=100.0,
          read_only=True),
    Param('ee_feedback', 'End-effector pose from odometry + forward kinematics, or from /ee_pose.',
          choices=('odometry', 'ground_truth'), read_only=True),
    Param('obstacles', OBSTACLE_PARAM_HELP, read_only=True),
    Param('world_frame', 'Frame of /goal_pose, /ee_pose and /obstacles.', read_only=True),
    Param('base_frame', 'Frame of /base/reference and /base/feasible_twist.', read_only=True),
    Param('state_timeout', 'Age [s] of joint states, odometry, EE pose or trajectory reference (steady clock, '
          'at receipt) after which commands are zero.', lo=1e-3, hi=60.0),
    Param('compensation_timeout', 'Steady time [s] to wait for the feasible twist of this cycle.',
          lo=0.0, hi=1.0, read_only=True),
    Param('max_goal_distance', 'Goals farther than this from the world origin are rejected [m].',
          lo=1.0, hi=1e6),
    Param('goal_tolerance', 'Position [m] and orientation [rad] errors under which the goal is reached.',
          lo=1e-6, hi=10.0, size=(2,)),
    Param('stall_time', 'Time [s] without progress after which an unreached goal is reported as stalled.',
          lo=0.1, hi=600.0),
    Param('min_progress_ratio', 'Fraction [-] of its best value by which an error must fall within stall_time '
          'to count as progress (at least 1 mm / 1 mrad).', lo=0.0, hi=0.9),
    Param('diagnostics_period', 'Time [s] between /diagnostics messages; 0 = none.', lo=0.0, hi=3600.0),
    Param('markers_period', 'Steady time [s] between ~/markers messages (goal, reference, end-effector trail, '
          'base footprint for rviz); 0 = none.', lo=0.0, hi=60.0, read_only=True),
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
PARAMS = tuple(dataclasses.replace(spec, default_from=lambda _values, d=_METHOD_DEFAULTS[spec.name]: d)
               if spec.name in _METHOD_DEFAULTS else spec for spec in _SPECS)


REFERENCE = 'ee_reference'


def _twist_values(twist):
    return np.array([twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y,
                     twist.angular.z])


def _unit_quaternion(quat, topic, logger):
    """``quat`` (x, y, z, w, finite) normalised, or None when it is zero; a norm off 1 is logged.
    The norm does not overflow for entries near the largest double (``np.hypot``)."""
    norm = float(np.hypot.reduce(quat))
    if norm < 1e-6:
        return None
    if abs(norm - 1.0) > 1e-3:
        logger.warn(f'{topic} quaternion has norm {norm:.6g}: normalised', throttle_duration_sec=1.0)
    return quat / norm


class RedundancyResolverNode(Node):
    """Wraps one :class:`~wmm_control.resolvers.Resolver`; the maths lives there."""

    def __init__(self, **kwargs):
        super().__init__('redundancy_resolver', **kwargs)
        guard_clock(self)
        p = self.p = declare_parameters(self, 'redundancy_resolver.yaml', PARAMS, on_change={
            'state_timeout': self._set_state_timeout,
            'goal_tolerance': lambda v: setattr(self.progress, 'tolerance', self._tolerance(v)),
            'stall_time': lambda v: setattr(self.progress, 'stall_time', float(v)),
            'min_progress_ratio': lambda v: setattr(self.progress, 'min_progress_ratio', float(v))})
        self.model = KinematicModel(p.robot)
        names = [n for n in method_parameters(p.method) if n != 'dt' and hasattr(p, n)]
        self.resolver = make_resolver(p.method, self.model, dt=p.period, **{n: getattr(p, n) for n in names})
        arm = self.model.config.arm
        self.arm_joints = arm.joints
        self.arm = JointSelector(arm.joints, velocity_limits=arm.velocity,
                                 position_limits=(arm.position_lower, arm.position_upper))
        self.workspace = Workspace(self.model)
        self.obstacles = ObstacleSet(p.obstacles, p.world_frame)
        self.resolver.set_obstacles(self.obstacles.obstacles)
        # /odom and /base/feasible_twist beyond this are glitches
        self._plausible_twist = JointSelector.PLAUSIBLE_FACTOR * self.model.config.base.velocity
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.fresh = {k: Freshness(p.state_timeout) for k in ('odom', 'ee_pose', 'reference')}
        self._tracking = False        # the target is a trajectory point of /ee_reference
        self._odom = None
        self._ee = None
        self.target = None
        self._goal_key = None
        self._pending = None
        self._wait = None
        self._last = None
        self.progress = GoalProgress(self._tolerance(p.goal_tolerance), p.stall_time, p.period,
                                     min_progress_ratio=p.min_progress_ratio)
        self._stall_logged = False
        self._reached_logged = False
        self._goal_cycles = 0
        self._next_diag = 0.0
        self.counters = {'cycles': 0, 'goals': 0, 'goals_rejected': 0, 'compensation_dropped': 0,
                         'stale_cycles': 0}
        self.pub_arm = self.create_publisher(Float64MultiArray, 'arm_controller/commands', COMMAND_QOS)
        self.pub_base = self.create_publisher(TwistStamped, 'base/reference', COMMAND_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.create_subscription(PoseStamped, 'goal_pose', self._on_goal, COMMAND_QOS)
        self.create_subscription(MultiDOFJointTrajectory, 'ee_reference', self._on_reference, COMMAND_QOS)
        self.create_subscription(JointState, 'joint_states', self._on_joint_states, STATE_SUB_QOS)
        self.create_subscription(Odometry, 'odom', self._on_odom, STATE_SUB_QOS)
        self.create_subscription(MarkerArray, '/obstacles', self._on_obstacles, COMMAND_QOS)
        if p.ee_feedback == 'ground_truth':
            self.create_subscription(PoseStamped, 'ee_pose', self._on_ee_pose, STATE_SUB_QOS)
        if self.resolver.uses_compensation:
            self.create_subscription(TwistStamped, 'base/feasible_twist', self._on_feasible, COMMAND_QOS)
            self._wait = (self.create_timer(p.compensation_timeout, self._compensation_timeout, clock=self._steady,
                                            autostart=False) if p.compensation_timeout > 0 else None)
        self._last_state = None
        if p.markers_period > 0:
            self._markers = MarkerSet(p.world_frame, self.workspace.footprint(), self.workspace.floor_z)
            self._marker_model = KinematicModel(p.robot)     # the trail's FK, apart from the resolver's model
            self._trail = Trail(max_points=2000, min_step=0.005)
            self.pub_markers = self.create_publisher(MarkerArray, '~/markers', COMMAND_QOS)
            self.create_timer(p.markers_period, self._publish_markers, clock=self._steady)
        self.watchdog = JointStateWatchdog(self, p.state_timeout, p.period, self._steady, self._stop, 'zero commands')
        self.get_logger().info(
            f'{p.method} on robot {self.model.config.name}: t_s {p.period} s, EE feedback {p.ee_feedback}, '
            f'compensation {"on" if self.resolver.uses_compensation else "off"}, {describe(self.obstacles.obstacles)}; '
            f'waiting for /goal_pose (frame {p.world_frame!r})')

    def _tolerance(self, goal_tolerance):
        """(position, orientation) tolerance of a goal; a method that tracks the position alone
        (``rows: position``) leaves the orientation free, so only the position counts."""
        position_only = getattr(self.resolver.params, 'rows', 'full') == 'position'
        return (float(goal_tolerance[0]), math.inf if position_only else float(goal_tolerance[1]))

    def _set_state_timeout(self, timeout):
        for fresh in self.fresh.values():
            fresh.timeout = timeout
        self.watchdog.set_timeout(timeout)

    # ------------------------------------------------------------------ time
    def _now(self):
        return self._steady.now().nanoseconds * 1e-9

    # ------------------------------------------------------------------ inputs
    def _reject_goal(self, reason, topic='goal_pose'):
        self.counters['goals_rejected'] += 1
        self.get_logger().warn(f'rejected {topic}: {reason}; holding still', throttle_duration_sec=1.0)
        self.target = None
        self._goal_key = None
        self._tracking = False

    def _on_goal(self, msg):
        pos = msg.pose.position
        q = msg.pose.orientation
        values = np.array([pos.x, pos.y, pos.z, q.x, q.y, q.z, q.w])
        if msg.header.frame_id != self.p.world_frame:
            return self._reject_goal(f'frame {msg.header.frame_id!r}, expected {self.p.world_frame!r}')
        if not np.all(np.isfinite(values)):
            return self._reject_goal(f'non-finite values {values.tolist()}')
        if float(np.max(np.abs(values[:3]))) > self.p.max_goal_distance:
            return self._reject_goal(f'position {values[:3].tolist()} is beyond max_goal_distance '
                                     f'{self.p.max_goal_distance} m')
        impossible = self._impossible(values[:3])
        if impossible:
            return self._reject_goal(f'position {values[:3].tolist()}: {impossible}')
        quat = _unit_quaternion(values[3:], '/goal_pose', self.get_logger())
        if quat is None:
            return self._reject_goal('zero quaternion')
        key = tuple(np.round(np.concatenate((values[:3], quat)), 9))
        if key == self._goal_key:
            return None      # the same goal again (a sequencer re-publishing it)
        rot = matrix_from_quaternion(quat)
        self.target = PoseTarget(values[:3], rot)
        self._goal_key = key
        self._tracking = False
        self._start_goal()
        self.counters['goals'] += 1
        self.get_logger().info(f'new goal: position {np.round(values[:3], 4).tolist()}, '
                               f'quaternion (x, y, z, w) {np.round(quat, 4).tolist()}')
        return None

    def _on_reference(self, msg):
        if msg.header.frame_id != self.p.world_frame:
            return self._reject_goal(f'frame {msg.header.frame_id!r}, expected {self.p.world_frame!r}', REFERENCE)
        point = msg.points[0] if msg.points else None
        if point is None or not point.transforms:
            return self._reject_goal('no point or no transform', REFERENCE)
        tf = point.transforms[0]
        vel = _twist_values(point.velocities[0]) if point.velocities else np.zeros(6)
        acc = _twist_values(point.accelerations[0]) if point.accelerations else np.zeros(6)
        pose = np.array([tf.translation.x, tf.translation.y, tf.translation.z, tf.rotation.x, tf.rotation.y,
                         tf.rotation.z, tf.rotation.w])
        if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(acc))):
            return self._reject_goal('non-finite values', REFERENCE)
        if float(np.max(np.abs(pose[:3]))) > self.p.max_goal_distance or \
                float(np.max(np.abs(np.concatenate((vel, acc))))) > 1e3:
            return self._reject_goal('beyond max_goal_distance, or a twist or acceleration beyond 1e3', REFERENCE)
        impossible = self._impossible(pose[:3])
        if impossible:
            return self._reject_goal(f'position {pose[:3].tolist()}: {impossible}', REFERENCE)
        quat = _unit_quaternion(pose[3:], '/' + REFERENCE, self.get_logger())
        if quat is None:
            return self._reject_goal('zero quaternion', REFERENCE)
        if not self._tracking:
            self.get_logger().info('tracking /ee_reference')
            self._start_goal()
        self.target = PoseTarget(pose[:3], matrix_from_quaternion(quat), velocity=vel, acceleration=acc)
        self._goal_key = None
        self._tracking = True
        self.fresh['reference'].mark(self._now())
        return None

    def _impossible(self, position):
        """'' or why no motion reaches an end-effector goal at the world ``position``."""
        fresh = self._odom is not None and self.fresh['odom'].fresh(self._now())
        return self.workspace.impossible(position, self._odom[0] if fresh else None, self.obstacles.obstacles)

    def _on_obstacles(self, msg):
        if self.obstacles.take(msg, self.get_logger()):
            self.resolver.set_obstacles(self.obstacles.obstacles)

    def _on_odom(self, msg):
        p, q, t = msg.pose.pose.position, msg.pose.pose.orientation, msg.twist.twist
        quat = np.array([q.x, q.y, q.z, q.w])
        twist = np.array([t.linear.x, t.linear.y, t.angular.z])
        values = np.concatenate(([p.x, p.y], quat, twist))
        logger = self.get_logger()
        if not np.all(np.isfinite(values)):
            logger.warn(f'rejected /odom with non-finite values {values.tolist()}', throttle_duration_sec=1.0)
            return
        if max(abs(p.x), abs(p.y)) > self.p.max_goal_distance:
            logger.warn(f'rejected /odom at ({p.x:.6g}, {p.y:.6g}): beyond max_goal_distance '
                        f'{self.p.max_goal_distance} m from the origin', throttle_duration_sec=1.0)
            return
        if np.any(np.abs(twist) > self._plausible_twist):
            logger.warn(f'rejected /odom with twist {twist.tolist()} beyond {JointSelector.PLAUSIBLE_FACTOR:g} times '
                        'the base velocity limits', throttle_duration_sec=1.0)
            return
        quat = _unit_quaternion(quat, '/odom', logger)
        if quat is None:
            logger.warn('rejected /odom with a zero quaternion', throttle_duration_sec=1.0)
            return
        yaw = yaw_from_quaternion(quat)
        self._odom = (np.array([p.x, p.y, yaw]), twist)
        self.fresh['odom'].mark(self._now())

    def _on_ee_pose(self, msg):
        if msg.header.frame_id != self.p.world_frame:
            self.get_logger().warn(f'rejected /ee_pose in frame {msg.header.frame_id!r}', throttle_duration_sec=1.0)
            return
        p, q = msg.pose.position, msg.pose.orientation
        values = np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w])
        quat = _unit_quaternion(values[3:], '/ee_pose', self.get_logger()) if np.all(np.isfinite(values)) else None
        if quat is None:
            self.get_logger().warn('rejected /ee_pose with non-finite values or a zero quaternion',
                                   throttle_duration_sec=1.0)
            return
        self._ee = (values[:3], matrix_from_quaternion(quat))
        self.fresh['ee_pose'].mark(self._now())

    def _arm_state(self, msg):
        q, dq, reason = self.arm.read(msg)
        if q is None:
            self.get_logger().warn(f'rejected /joint_states {reason}: no cycle (the watchdog stops the robot '
                                   'when no valid one comes within state_timeout)', throttle_duration_sec=1.0)
            return None
        return q, dq

    # ------------------------------------------------------------------ cycle
    def _state(self, arm):
        """The RobotState of this cycle, or (None, reason) when some input is missing or stale."""
        now = self._now()
        if self._odom is None or not self.fresh['odom'].fresh(now):
            return None, 'no fresh /odom'
        ee = None
        if self.p.ee_feedback == 'ground_truth':
            if self._ee is None or not self.fresh['ee_pose'].fresh(now):
                return None, 'no fresh /ee_pose'
            ee = self._ee
        pose, twist = self._odom
        q, dq = arm
        self._last_state = (pose, q, ee)
        return RobotState(pose, twist, q, dq, ee_position=None if ee is None else ee[0],
                          ee_rotation=None if ee is None else ee[1]), ''

    def _on_joint_states(self, msg):
        arm = self._arm_state(msg)
        if arm is None or not self.watchdog.admit(msg.header.stamp):
            return
        if self._pending is not None:        # the last cycle's feasible twist never came
            self._finish(None)
        stamp = msg.header.stamp
        state, reason = self._state(arm)
        if state is None or self.target is None:
            if state is None:
                self.counters['stale_cycles'] += 1
                self.get_logger().warn(f'{reason}: zero commands', throttle_duration_sec=2.0)
            self._publish_zero(stamp)
            return
        if self.watchdog.resync(self.pub_arm):
            self.resolver.reset()
        self.counters['cycles'] += 1
        if self._tracking and not self.fresh['reference'].fresh(self._now()):
            self.get_logger().warn('/ee_reference stopped: holding its last pose', throttle_duration_sec=5.0)
            self.target = PoseTarget(self.target.position, self.target.rotation)
            self._tracking = False
        command = self.resolver.step(state, self.target)
        # Judged now, against the target the command was computed for: a new goal may come in
        # before the arm command goes out (it waits for the feasible twist).
        self.progress.update(command.diagnostics)
        self._log_goal_status(command.diagnostics)
        self._publish_base(stamp, command.base_twist)
        if not self.resolver.uses_compensation:
            self._publish_arm(command, stamp)
            return
        self._pending = (stamp_key(stamp), command, stamp)
        if self._wait is None:
            self._finish(None)
        else:
            self._wait.reset()

    def _on_feasible(self, msg):
        if self._pending is None or stamp_key(msg.header.stamp) != self._pending[0]:
            return
        twist = np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z])
        if not np.all(np.isfinite(twist)) or np.any(np.abs(twist) > self._plausible_twist):
            self.get_logger().warn(f'rejected /base/feasible_twist {twist.tolist()}: non-finite or beyond '
                                   f'{JointSelector.PLAUSIBLE_FACTOR:g} times the base velocity limits',
                                   throttle_duration_sec=1.0)
            return
        self._finish(twist)

    def _compensation_timeout(self):
        if self._pending is not None:
            self._finish(None)

    def _finish(self, feasible):
        """Publish the pending arm command, compensated when ``feasible`` is given."""
        if self._wait is not None:
            self._wait.cancel()
        _, command, stamp = self._pending
        self._pending = None
        if feasible is None:
            self.counters['compensation_dropped'] += 1
            self.get_logger().warn('no /base/feasible_twist for this cycle in time: arm command without '
                                   'compensation', throttle_duration_sec=1.0)
            self._publish_arm(command, stamp)
        else:
            self._publish_arm(self.resolver.compensate(command, feasible), stamp)

    # ------------------------------------------------------------------ outputs
    def _publish_base(self, stamp, twist):
        self.pub_base.publish(twist_stamped(stamp, self.p.base_frame, twist))

    def _publish_arm(self, command, stamp):
        """Publish the arm command of the cycle stamped ``stamp`` (and, when due, its diagnostics)."""
        self.pub_arm.publish(float_array(command.arm_velocity))
        self._last = command
        now = self._now()
        if self.p.diagnostics_period > 0 and now >= self._next_diag:
            self._next_diag = now + self.p.diagnostics_period
            self.pub_diag.publish(self._diagnostics(stamp))

    def _publish_zero(self, stamp):
        self._publish_base(stamp, np.zeros(3))
        self.pub_arm.publish(float_array(np.zeros(len(self.arm_joints))))
        self.resolver.reset()

    def _stop(self):
        """Joint states stopped: zero commands every period (the watchdog's timeout action)."""
        self._pending = None
        self._publish_zero(self.get_clock().now().to_msg())

    # ------------------------------------------------------------------ markers
    def _publish_markers(self) -> None:
        """~/markers: the goal, the tracked reference, the end-effector trail, the base footprint."""
        base = None
        if self._last_state is not None:
            base, q_arm, ee = self._last_state
            if ee is None:
                self._marker_model.update(base, q_arm)
                ee = self._marker_model.ee_placement_world()
            self._trail.add(ee[0])
        target = None if self.target is None else (self.target.position, self.target.rotation)
        stamp = self.get_clock().now().to_msg()
        self.pub_markers.publish(self._markers.build(stamp, None if self._tracking else target,
                                                     target if self._tracking else None, self._trail.points, base))

    # ------------------------------------------------------------------ status
    def _start_goal(self) -> None:
        """A new goal or trajectory: progress judged afresh, its reach and stall logged anew."""
        self.progress.start()
        self._stall_logged = False
        self._reached_logged = False
        self._goal_cycles = 0

    def _log_goal_status(self, diag) -> None:
        """Log once when a goal of /goal_pose is reached, and warn once when a goal stalls (again
        after it made progress)."""
        self._goal_cycles += 1
        if self.progress.reached and not self._reached_logged and not self._tracking:
            self.get_logger().info(f'goal reached: {diag.position_error:.4f} m, {diag.orientation_error:.4f} rad '
                                   f'away after {self._goal_cycles * self.p.period:.2f} s '
                                   f'({self._goal_cycles} cycles)')
            self._reached_logged = True
        if not self.progress.stalled:
            self._stall_logged = False
        elif not self._stall_logged:
            self.get_logger().warn(f'goal not reached: {diag.position_error:.3f} m, {diag.orientation_error:.3f} rad '
                                   f'away, {self._no_progress()} (out of reach, or held by a limit?)')
            self._stall_logged = True

    def _no_progress(self):
        floor = self.progress.min_progress
        return (f'no progress in {self.p.stall_time} s (best error down by less than '
                f'{100 * self.p.min_progress_ratio:g} %, {1e3 * floor[0]:g} mm, {1e3 * floor[1]:g} mrad)')

    def _diagnostics(self, stamp):
        """Status of the cycle stamped ``stamp`` (the joint state it answers)."""
        values = dict(self.counters, joint_states_skipped=self.watchdog.skipped,
                      measured_period_s=self.watchdog.stamps.measured_period,
                      obstacles=len(self.obstacles.obstacles))
        level, message = 'ok', 'no goal'
        if self._last is not None and self.target is not None:
            d = self._last.diagnostics
            reached, stalled = self.progress.reached, self.progress.stalled
            values.update({
                'method': d.method, 'mode': d.mode, 'psi': d.psi, 'position_error_m': d.position_error,
                'orientation_error_rad': d.orientation_error, 'limit_scale': d.limit_scale,
                'accel_scale': d.accel_scale, 'null_scale': d.null_scale,
                'compensation_scale': d.compensation_scale, 'compensated': d.compensated,
                'limited': list(d.limited), 'sigma_min': d.sigma_min, 'cycle_time_us': d.cycle_time_s * 1e6,
                'reference_time_left_s': d.reference_time_left,
                'clearance_m': d.clearance, 'closest_pair': d.closest_pair,
                'collision_constraints': d.collision_constraints, 'collision_changed': d.collision_changed,
                'goal_reached': reached, 'goal_stalled': stalled,
                'arm_command': self._last.arm_velocity, 'base_reference': self._last.base_twist})
            if stalled:
                level, message = 'warn', (f'goal not reached: {d.position_error:.3f} m, {d.orientation_error:.3f} '
                                          f'rad; {self._no_progress()} (out of reach?)')
            else:
                message = 'goal reached' if reached else d.mode
        return diagnostic_array(stamp, [node_status(self, '', self.model.config.name,
                                            level, message, values)])


def main(args=None):
    return run_node(RedundancyResolverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
