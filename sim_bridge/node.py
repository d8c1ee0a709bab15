"""``wmm_sim``: the PyBullet simulator node standing in for the robot hardware.

Subscribes (``std_msgs/Float64MultiArray``, ros2_control JointGroupVelocityController style,
joint order = the robot YAML's):
  ``/arm_controller/commands`` (7); robot A ``/steer_controller/commands`` and
  ``/drive_controller/commands`` (4 each); robot B ``/wheel_controller/commands`` (4);
  ``/obstacles`` (``visualization_msgs/MarkerArray``, frame ``world``): obstacles added and
  removed live, beside those of the ``obstacles`` file (:mod:`wmm_control.nodes.obstacle_topic`):
  static bodies of the simulated world.
Publishes, every period:
  ``/joint_states`` (``sensor_msgs/JointState``: every simulated joint, position and velocity),
  ``/ee_pose`` (``geometry_msgs/PoseStamped``, ground-truth end effector, frame ``world``),
  ``/odom`` (``nav_msgs/Odometry``: wheel odometry, dead reckoning through the nominal
  model, frame ``odom`` = ``world`` at the start, child ``base_link``; pose and twist
  covariances are the mean squared errors the slip model gives,
  :class:`~sim_bridge.slip.OdometryCovariance`),
  ``/ground_truth/odom`` (``nav_msgs/Odometry``: true base pose and twist, frame ``world``),
  ``/tf`` (world → odom → base_link and the moving joints) where ``tf2_msgs`` can be imported,
  ``clock`` (``rosgraph_msgs/Clock``, sim time; always in lockstep, in realtime with
  ``publish_clock``), and ``/diagnostics`` every ``diagnostics_period``: the command
  counters, the simulation's pace and, with obstacles, the robot's true clearance from them
  (status ``obstacles``: ``clearance_m``, the closest link and obstacle, ``contact_periods``
  and ``deepest_contact_m``; level ERROR while in contact, which is also logged).

The clock topic is relative: ``/clock`` in the root namespace, ``/r1/clock`` for a simulator in
``/r1``, so that two simulators in one domain never both publish ``/clock``. The nodes of a
robot in a namespace that run on its sim time remap their clock to it
(``--ros-args -r /clock:=/r1/clock``; the launch files do).

Once, transient local: ``robot_description`` (``std_msgs/String``, the URDF text) and, where
``tf2_msgs`` can be imported, ``/tf_static`` (the fixed joints); else one log line says why TF
is not published (:mod:`wmm_control.nodes.robot_frames`). Every frame but ``world`` carries
``frame_prefix``.

Timing: ``realtime`` steps on a wall-clock timer. ``lockstep`` publishes the state at t,
waits (event-driven) until every group of ``lockstep_groups`` has sent a command, or
``lockstep_timeout`` wall seconds pass, then steps one period and publishes the state at
t + period. Both run their timers on the steady clock, so ``use_sim_time:=true`` works. The
simulator is the time source in lockstep, and in realtime under ``use_sim_time`` with
``publish_clock``: its stamps and ``/clock`` are then the simulated time (from 0).
Otherwise (realtime, wall time) they are the ROS clock.

Safety: a group's command older than ``command_timeout``, judged by this node's clock at
receipt (the simulated time when it is the time source), is replaced by zero velocity; NaN/inf or wrong-length
commands are rejected with a throttled warning and never applied; values beyond the URDF
velocity limits are clamped, counted and reported on ``/diagnostics``.
"""

import math
import time

import numpy as np

from builtin_interfaces.msg import Time
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from diagnostic_msgs.msg import DiagnosticArray
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from sim_bridge.slip import VARIANCE_FLOOR, OdometryCovariance, SlipParams
from sim_bridge.world import BASE_MODES, SimWorld
from wmm_control.nodes.conversions import parse_command, set_planar_pose, set_planar_twist, set_pose
from wmm_control.nodes.obstacle_topic import OBSTACLE_PARAM_HELP, ObstacleSet, describe
from wmm_control.nodes.robot_frames import RobotFrames, valid_frame_prefix
from wmm_control.robot_config import load_robot
from wmm_control.errors import ConfigError
from wmm_control.checks import Freshness
from wmm_control.nodes.diagnostics import diagnostic_array, node_status
from wmm_control.nodes.parameters import Param, declare_parameters, robot_param, robot_period
from wmm_control.nodes.qos import CLOCK_QOS, COMMAND_QOS, DIAGNOSTICS_QOS, STATE_PUB_QOS
from wmm_control.nodes.runner import guard_clock, run_node

__all__ = ['SimNode', 'main', 'wait_groups']


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
    Param('lockstep_timeout', 'Wall time [s] lockstep waits for commands before stepping anyway.', lo=1e-3, hi=60.0),
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
    Param('obstacles', OBSTACLE_PARAM_HELP, read_only=True),
)


def _poll_period(lockstep_timeout):
    """Wall-clock poll period [s] of lockstep (start-up, and stepping after ``lockstep_timeout``)."""
    return min(0.01, lockstep_timeout / 4)


def wait_groups(text, groups):
    """The command groups of ``lockstep_groups`` text, and '' or the reason it is invalid."""
    if text.strip() == 'all':
        return frozenset(groups), ''
    chosen = frozenset(g.strip() for g in text.split(',') if g.strip())
    unknown = sorted(chosen - set(groups))
    if unknown or not chosen:
        return chosen, f'lockstep_groups: unknown groups {unknown}; this robot has {sorted(groups)}'
    return chosen, ''


def _stamp(seconds):
    sec = math.floor(seconds)
    return Time(sec=int(sec), nanosec=min(int(round((seconds - sec) * 1e9)), 999_999_999))


class SimNode(Node):
    """Wraps one :class:`sim_bridge.world.SimWorld`; all physics and kinematics live there."""

    def __init__(self, **kwargs):
        super().__init__('wmm_sim', **kwargs)
        guard_clock(self)
        self.world = None
        self.p = declare_parameters(
            self,
            'wmm_sim.yaml',
            PARAMS,
            on_change={
                'command_timeout': self._set_command_timeout,
                'lockstep_timeout': self._set_lockstep_timeout,
                'lockstep_groups': self._set_wait_groups,
            },
            check=lambda v: wait_groups(v.lockstep_groups, self.world.command_groups)[1] if self.world else '',
        )
        slip = SlipParams(gain=self.p.slip_gain, drift=tuple(self.p.slip_drift), noise_std=tuple(self.p.slip_noise))
        self.obstacles = ObstacleSet(self.p.obstacles, 'world')
        self.world = SimWorld(
            robot=self.p.robot,
            base_mode=self.p.base_mode,
            dt=self.p.period,
            substeps=self.p.substeps,
            slip=slip,
            seed=self.p.seed,
            gui=self.p.gui,
            start_base_pose=self.p.start_base_pose,
            start_arm=self.p.start_arm,
            obstacles=self.obstacles.obstacles,
        )
        self.contact = {
            'clearance_m': math.inf,
            'closest_link': '',
            'closest_obstacle': '',
            'contact_periods': 0,
            'deepest_contact_m': 0.0,
        }
        reason = valid_frame_prefix(self.p.frame_prefix)
        if reason:
            raise ConfigError(reason)
        self.lockstep = self.p.timing == 'lockstep'
        self.odom_covariance = OdometryCovariance()
        groups = self.world.command_groups
        self.wait_groups, reason = wait_groups(self.p.lockstep_groups, groups)
        if reason:
            raise ConfigError(reason)
        self.fresh = {g: Freshness(self.p.command_timeout) for g in groups}
        self.timed_out = {g: True for g in groups}
        self.subs = [
            self.create_subscription(
                Float64MultiArray, f'{g}_controller/commands', lambda msg, g=g: self._on_command(g, msg), COMMAND_QOS
            )
            for g in groups
        ]
        self.create_subscription(MarkerArray, '/obstacles', self._on_obstacles, COMMAND_QOS)
        self.pub_joints = self.create_publisher(JointState, 'joint_states', STATE_PUB_QOS)
        self.pub_ee = self.create_publisher(PoseStamped, 'ee_pose', STATE_PUB_QOS)
        self.pub_odom = self.create_publisher(Odometry, 'odom', STATE_PUB_QOS)
        self.pub_truth = self.create_publisher(Odometry, 'ground_truth/odom', STATE_PUB_QOS)
        # Relative: each simulator in its namespace; nodes on its sim time remap /clock to it.
        self.pub_clock = self.create_publisher(ClockMsg, 'clock', CLOCK_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.frames = RobotFrames(self, self.world.robot, self.p.frame_prefix, publish_tf=self.p.publish_tf)
        self._odom_frame = self.p.frame_prefix + 'odom'
        self._base_frame = self.p.frame_prefix + self.world.robot.base_link
        self._arrived = set()
        self._waiting_since = None
        self._steps = 0
        self._next_diag = 0.0
        self._wall_start = time.monotonic()
        # The simulator is the time source when it steps in lockstep, or when it publishes
        # /clock to nodes on sim time (itself included): its stamps are then its own time.
        use_sim_time = bool(self.get_parameter('use_sim_time').value)
        self.sim_time_source = self.lockstep or (self.p.publish_clock and use_sim_time)
        # Timers on the steady clock: under use_sim_time the ROS clock only advances when
        # this node publishes /clock, so timers on it would never fire.
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        if self.lockstep:
            # Wall-clock poll: start once every awaited controller is connected, and step
            # anyway when the commands do not come within lockstep_timeout.
            self._started = False
            self.poll = self.create_timer(_poll_period(self.p.lockstep_timeout), self._lockstep_poll, clock=steady)
        else:
            self.timer = self.create_timer(self.p.period, self._realtime_tick, clock=steady)
        self.get_logger().info(
            f'simulating {self.world.robot.name} ({self.p.base_mode} base, {self.p.timing}, '
            f'period {self.p.period} s); command groups {sorted(groups)}; {describe(self.obstacles.obstacles)}'
        )

    def _on_obstacles(self, msg):
        if self.obstacles.take(msg, self.get_logger()):
            self.world.set_obstacles(self.obstacles.obstacles)

    def _check_obstacles(self):
        """The true clearance from the obstacles after a step; contact counted and logged."""
        if not self.world.obstacles:
            return
        distance, link, obstacle = self.world.obstacle_clearance()
        self.contact.update(clearance_m=distance, closest_link=link, closest_obstacle=obstacle)
        if distance < 0.0:
            self.contact['contact_periods'] += 1
            self.contact['deepest_contact_m'] = max(self.contact['deepest_contact_m'], -distance)
            self.get_logger().error(
                f'{link} is {-distance * 1e3:.1f} mm into obstacle {obstacle!r}', throttle_duration_sec=1.0
            )

    def _set_command_timeout(self, timeout):
        for fresh in self.fresh.values():
            fresh.timeout = timeout

    def _set_wait_groups(self, text):
        self.wait_groups = wait_groups(text, self.world.command_groups)[0]

    def _set_lockstep_timeout(self, timeout):
        if self.lockstep:
            self.poll.timer_period_ns = int(_poll_period(timeout) * 1e9)

    def destroy_node(self):
        """Destroy the node and close the PyBullet client (also when the node was never spun)."""
        if self.world is not None:
            self.world.close()
        return super().destroy_node()

    # ------------------------------------------------------------------ time
    def now_s(self):
        """This node's clock [s]: the simulated time when it is the time source, else the ROS clock."""
        return self.world.time if self.sim_time_source else self.get_clock().now().nanoseconds * 1e-9

    def _stamp_now(self):
        return _stamp(self.world.time) if self.sim_time_source else self.get_clock().now().to_msg()

    # ------------------------------------------------------------------ commands
    def _on_command(self, group, msg):
        values, reason = parse_command(msg, len(self.world.command_groups[group]))
        if values is None:
            self.world.counters[group]['rejected'] += 1
            self.get_logger().warn(f'rejected {group} command: {reason}', throttle_duration_sec=1.0)
            return
        result = self.world.set_command(group, values)
        if not result.accepted:
            self.get_logger().warn(f'rejected {group} command: {result.reason}', throttle_duration_sec=1.0)
            return
        if result.clamped:
            self.get_logger().warn(
                f'{group} command clamped to the velocity limits ({result.clamped} entries)', throttle_duration_sec=1.0
            )
        self.fresh[group].mark(self.now_s())
        if self.timed_out[group]:
            self.timed_out[group] = False
        if self.lockstep and self._waiting_since is not None:
            self._arrived.add(group)
            if self.wait_groups <= self._arrived:
                self._advance()

    def _apply_watchdog(self):
        now = self.now_s()
        for group, fresh in self.fresh.items():
            if not fresh.fresh(now) and not self.timed_out[group]:
                self.world.zero_command(group)
                self.timed_out[group] = True
                self.get_logger().warn(
                    f'{group} command timed out (age {fresh.age(now):.3f} s > {fresh.timeout} s): zero velocity',
                    throttle_duration_sec=1.0,
                )

    # ------------------------------------------------------------------ stepping
    def _step_world(self):
        """One period: the command watchdog, the world's step, the odometry covariance."""
        self._apply_watchdog()
        theta = self.world.odom_pose()[2]
        self.world.step()
        self._check_obstacles()
        twist = self.world.odom_twist()
        self.odom_covariance.update(
            theta, twist, *self.world.slip.twist_error(twist, self.world.rim_speed), self.world.dt
        )

    def _realtime_tick(self):
        self._step_world()
        self._publish_state()

    def _lockstep_poll(self):
        if not self._started:
            topics = [f'{g}_controller/commands' for g in self.wait_groups]
            connected = all(self.count_publishers(t) > 0 for t in topics)
            if connected or time.monotonic() - self._wall_start > self.p.lockstep_timeout:
                self._started = True
                self._publish_state()
            return
        if self._waiting_since is not None and time.monotonic() - self._waiting_since > self.p.lockstep_timeout:
            missing = sorted(self.wait_groups - self._arrived)
            self.get_logger().warn(
                f'lockstep: no command from {missing} within {self.p.lockstep_timeout} s; stepping anyway',
                throttle_duration_sec=5.0,
            )
            self._advance()

    def _advance(self):
        self._waiting_since = None
        self._arrived.clear()
        self._step_world()
        self._publish_state()

    # ------------------------------------------------------------------ output
    def _publish_state(self):
        stamp = self._stamp_now()
        if self.lockstep or self.p.publish_clock:
            self.pub_clock.publish(ClockMsg(clock=stamp))
        names, pos, vel = self.world.joint_state()
        js = JointState()
        js.header.stamp = stamp
        js.name = list(names)
        js.position = pos.tolist()
        js.velocity = vel.tolist()
        # A topic nobody listens to is not built (a subscriber that comes later is matched
        # within a period or two and gets every message from then on).
        if _heard(self.pub_ee):
            ee_pos, ee_quat = self.world.ee_pose()
            ee = PoseStamped()
            ee.header.stamp = stamp
            ee.header.frame_id = 'world'
            set_pose(ee.pose, ee_pos, ee_quat)
            self.pub_ee.publish(ee)
        odom_pose, true_pose = self.world.odom_pose(), self.world.base_pose()
        if _heard(self.pub_odom):
            self.pub_odom.publish(
                _odometry(
                    stamp,
                    self._odom_frame,
                    self._base_frame,
                    odom_pose,
                    self.world.odom_twist(),
                    self.odom_covariance.pose,
                    self.odom_covariance.twist,
                )
            )
        if _heard(self.pub_truth):
            self.pub_truth.publish(_odometry(stamp, 'world', self._base_frame, true_pose, self.world.base_twist()))
        if self.frames.publishing_tf:
            self.frames.publish(stamp, dict(zip(names, pos.tolist())), odom_pose, true_pose)
        if self.now_s() + 1e-9 >= self._next_diag and self.p.diagnostics_period > 0:
            self._next_diag = self.now_s() + self.p.diagnostics_period
            self.pub_diag.publish(self._diagnostics(stamp))
        self._steps += 1
        if self.lockstep:
            self._waiting_since = time.monotonic()
            self._arrived.clear()
        # Joint states last: in lockstep the controllers answer them, and their answer may
        # arrive (in-process) before this method returns.
        self.pub_joints.publish(js)

    def _diagnostics(self, stamp):
        statuses = []
        wall = time.monotonic() - self._wall_start
        for group, counts in self.world.counters.items():
            stale = self.timed_out[group]
            level = 'warn' if stale or counts['clamped'] or counts['rejected'] else 'ok'
            message = 'no fresh command (zero velocity)' if stale else 'commanded'
            statuses.append(
                node_status(
                    self,
                    f'{group} commands',
                    self.world.robot.name,
                    level,
                    message,
                    {**counts, 'command_age_s': self.fresh[group].age(self.now_s())},
                )
            )
        statuses.append(
            node_status(
                self,
                'simulation',
                self.world.robot.name,
                'ok',
                f'{self.p.timing}, {self.p.base_mode}',
                {
                    'sim_time_s': self.world.time,
                    'steps': self._steps,
                    'real_time_factor': self.world.time / wall if wall > 0 else 0.0,
                },
            )
        )
        if self.world.obstacles:
            touching = self.contact['clearance_m'] < 0.0
            statuses.append(
                node_status(
                    self,
                    'obstacles',
                    self.world.robot.name,
                    'error' if touching else 'ok',
                    f'{self.contact["closest_link"]} in contact with {self.contact["closest_obstacle"]}'
                    if touching
                    else f'clear ({len(self.world.obstacles)} obstacles)',
                    self.contact,
                )
            )
        return diagnostic_array(stamp, statuses)


def _heard(publisher):
    """True when ``publisher`` has a matched subscription."""
    return publisher.get_subscription_count() > 0


def _odometry(stamp, frame, child, pose, twist, pose_covariance=None, twist_variance=None):
    """An ``Odometry`` of a planar pose and twist; covariances (x, y, θ) and (vx, vy, ω) when given
    (z, roll, pitch and their rates: :data:`~sim_bridge.slip.VARIANCE_FLOOR`, the base is planar)."""
    msg = Odometry()
    msg.header.stamp = stamp
    msg.header.frame_id = frame
    msg.child_frame_id = child
    set_planar_pose(msg.pose.pose, pose)
    set_planar_twist(msg.twist.twist, twist)
    if pose_covariance is not None:
        msg.pose.covariance = _planar_covariance(pose_covariance)
        msg.twist.covariance = _planar_covariance(np.diag(twist_variance))
    return msg


def _planar_covariance(cov3):
    """The 6×6 row-major covariance (x, y, z, roll, pitch, yaw) of a planar (x, y, yaw) one."""
    full = np.diag(np.full(6, VARIANCE_FLOOR))
    idx = np.array([0, 1, 5])
    full[np.ix_(idx, idx)] = cov3
    return full.ravel().tolist()


def main(args=None):
    return run_node(SimNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
