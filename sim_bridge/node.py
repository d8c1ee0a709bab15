"""``wmm_sim``: the PyBullet simulator node standing in for the robot hardware.

Subscribes (``std_msgs/Float64MultiArray``, ros2_control JointGroupVelocityController style,
joint order = the robot YAML's):
  ``/arm_controller/commands`` (7); robot A ``/steer_controller/commands`` and
  ``/drive_controller/commands`` (4 each); robot B ``/wheel_controller/commands`` (4);
  ``/obstacles`` (``visualization_msgs/MarkerArray``, frame ``world``): obstacles added and
  removed live, beside those of the ``obstacles`` file: static bodies of the simulated world;
  bad input (an empty message, more than ``max_obstacles`` markers, a bad marker) refused with a
  warning (:mod:`wmm_control.nodes.obstacle_topic`).
Publishes, every period:
  ``/joint_states`` (``sensor_msgs/JointState``: every simulated joint, position and velocity:
  the arm and base joints, then the joints held outside them, at the robot YAML's
  ``held_joints``, so that robot_state_publisher places the head and the fingers where they are),
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

Once, transient local: ``sim/lockstep_timeout`` (``std_msgs/Float64``: 0 in realtime, else
``lockstep_timeout``, again when it changes), from which the other nodes learn that they run in
lockstep (:mod:`wmm_control.nodes.sim_timing`); ``robot_description`` (``std_msgs/String``, the URDF text) and, where
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

import time

from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from std_msgs.msg import Float64MultiArray
from visualization_msgs.msg import MarkerArray

from sim_bridge.node_params import PARAMS, make_world
from sim_bridge.outputs import SimOutputs
from sim_bridge.slip import OdometryCovariance
from sim_bridge.supervision import (
    CommandWatchdog,
    LockstepWait,
    ObstacleContact,
    poll_period,
    statuses,
    step_world,
    wait_groups,
)
from wmm_control.errors import ConfigError
from wmm_control.nodes.conversions import parse_command, stamp_from_seconds
from wmm_control.nodes.diagnostics import DiagnosticsGate
from wmm_control.nodes.obstacle_topic import ObstacleSet, describe
from wmm_control.nodes.parameters import declare_parameters
from wmm_control.nodes.qos import COMMAND_QOS
from wmm_control.nodes.robot_frames import RobotFrames, valid_frame_prefix
from wmm_control.nodes.runner import guard_clock, run_node

__all__ = ['SimNode', 'PARAMS', 'main']


class SimNode(Node):
    """Wraps one :class:`sim_bridge.world.SimWorld`; all physics and kinematics live there, the
    rules between steps in :mod:`sim_bridge.supervision`."""

    def __init__(self, **kwargs):
        super().__init__('wmm_sim', **kwargs)
        guard_clock(self)
        self.world = None
        self.p = declare_parameters(
            self,
            'wmm_sim.yaml',
            PARAMS,
            on_change={
                'command_timeout': lambda timeout: self.watchdog.set_timeout(timeout),
                'lockstep_timeout': self._set_lockstep_timeout,
                'lockstep_groups': self._set_wait_groups,
            },
            check=lambda v: wait_groups(v.lockstep_groups, self.world.command_groups)[1] if self.world else '',
        )
        self.obstacles = ObstacleSet(self.p.obstacles, 'world')
        self.world = make_world(self.p, self.obstacles.obstacles)
        self.contact = ObstacleContact()
        reason = valid_frame_prefix(self.p.frame_prefix)
        if reason:
            raise ConfigError(reason)
        self.lockstep = self.p.timing == 'lockstep'
        self.odom_covariance = OdometryCovariance()
        groups = self.world.command_groups
        awaited, reason = wait_groups(self.p.lockstep_groups, groups)
        if reason:
            raise ConfigError(reason)
        self.wait = LockstepWait(awaited)
        self.watchdog = CommandWatchdog(groups, self.p.command_timeout)
        self.subs = [
            self.create_subscription(
                Float64MultiArray, f'{g}_controller/commands', lambda msg, g=g: self._on_command(g, msg), COMMAND_QOS
            )
            for g in groups
        ]
        self.create_subscription(MarkerArray, '/obstacles', self._on_obstacles, COMMAND_QOS)
        self.frames = RobotFrames(self, self.world.robot, self.p.frame_prefix, publish_tf=self.p.publish_tf)
        base_frame = self.p.frame_prefix + self.world.robot.base_link
        self.out = SimOutputs(self, self.frames, self.p.frame_prefix + 'odom', base_frame)
        self.out.publish_timing(self.p.lockstep_timeout if self.lockstep else 0.0)
        self._steps = 0
        self._diagnostics_gate = DiagnosticsGate()
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
            self.poll = self.create_timer(poll_period(self.p.lockstep_timeout), self._lockstep_poll, clock=steady)
        else:
            self.timer = self.create_timer(self.p.period, self._realtime_tick, clock=steady)
        self.get_logger().info(
            f'simulating {self.world.robot.name} ({self.p.base_mode} base, {self.p.timing}, '
            f'period {self.p.period} s); command groups {sorted(groups)}; {describe(self.obstacles.obstacles)}'
        )

    def _on_obstacles(self, msg):
        if self.obstacles.take(msg, self.get_logger(), self.p.max_obstacles):
            self.world.set_obstacles(self.obstacles.obstacles)

    def _set_wait_groups(self, text):
        self.wait.groups = wait_groups(text, self.world.command_groups)[0]

    def _set_lockstep_timeout(self, timeout):
        if self.lockstep:
            self.poll.timer_period_ns = int(poll_period(timeout) * 1e9)
            self.out.publish_timing(timeout)

    def destroy_node(self) -> None:
        """Destroy the node and close the PyBullet client (also when the node was never spun)."""
        if self.world is not None:
            self.world.close()
        return super().destroy_node()

    def now_s(self) -> float:
        """This node's clock [s]: the simulated time when it is the time source, else the ROS clock."""
        return self.world.time if self.sim_time_source else self.get_clock().now().nanoseconds * 1e-9

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
        self.watchdog.accepted(group, self.now_s())
        if self.lockstep and self.wait.arrived(group):
            self._advance()

    def _step_world(self):
        """One period (:func:`~sim_bridge.supervision.step_world`), its timeouts and contact logged."""
        timeouts, contact = step_world(self.world, self.watchdog, self.contact, self.odom_covariance, self.now_s())
        for line in timeouts:
            self.get_logger().warn(line, throttle_duration_sec=1.0)
        if contact:
            self.get_logger().error(contact, throttle_duration_sec=1.0)

    def _realtime_tick(self):
        self._step_world()
        self._publish_state()

    def _lockstep_poll(self):
        if not self.wait.started:
            if self._controllers_listening() or time.monotonic() - self._wall_start > self.p.lockstep_timeout:
                self.wait.started = True
                self._publish_state()
            return
        if self.wait.overdue(time.monotonic(), self.p.lockstep_timeout):
            self.get_logger().warn(
                f'lockstep: no command from {self.wait.missing()} within {self.p.lockstep_timeout} s; stepping anyway',
                throttle_duration_sec=5.0,
            )
            self._advance()

    def _controllers_listening(self) -> bool:
        """Every awaited group's command topic has a publisher, and each node that publishes one
        subscribes to the joint states: the first state reaches them all (a node whose
        publisher is seen before its subscription would miss it, and the first step would wait
        out ``lockstep_timeout``)."""
        writers = set()
        for group in self.wait.groups:
            found = self.get_publishers_info_by_topic(self.resolve_topic_name(f'{group}_controller/commands'))
            if not found:
                return False
            writers |= {(i.node_namespace, i.node_name) for i in found}
        readers = self.get_subscriptions_info_by_topic(self.out.pub_joints.topic_name)
        return writers <= {(i.node_namespace, i.node_name) for i in readers}

    def _advance(self):
        self.wait.end()
        self._step_world()
        self._publish_state()

    def _publish_state(self):
        stamp = stamp_from_seconds(self.world.time) if self.sim_time_source else self.get_clock().now().to_msg()
        joints = self.out.publish_state(stamp, self.world, self.odom_covariance, self.lockstep or self.p.publish_clock)
        if self._diagnostics_gate.due(self.now_s(), self.p.diagnostics_period):
            pace = (self.world.time, self._steps, time.monotonic() - self._wall_start)
            mode = f'{self.p.timing}, {self.p.base_mode}'
            found = statuses(
                self.world.counters, self.watchdog, self.now_s(), mode, pace, self.contact, len(self.world.obstacles)
            )
            self.out.publish_diagnostics(stamp, self.world.robot.name, found)
        self._steps += 1
        if self.lockstep:
            self.wait.begin(time.monotonic())
        # Joint states last: in lockstep the controllers answer them, and their answer may
        # arrive (in-process) before this method returns.
        self.out.publish_joints(joints)


def main(args: list[str] | None = None) -> int:
    return run_node(SimNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
