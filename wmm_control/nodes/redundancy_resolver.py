"""``redundancy_resolver``: whole-body redundancy resolution as a node (Sorour §II–III).

Publish an end-effector goal on ``/goal_pose`` (or trajectory points on ``/ee_reference``) and
the robot goes there. Each ``/joint_states`` message runs one cycle of the resolver on the
latest fresh ``/odom`` (and ``/ee_pose`` with ground-truth feedback): it publishes the base
twist on ``/base/reference``, stamped with that joint state, and, once the base controller's
``/base/feasible_twist`` with the same stamp has come (at most ``compensation_timeout``,
steady clock; eq 14's compensation), the arm's joint velocities on
``/arm_controller/commands``. ``/diagnostics`` every
``diagnostics_period``; ``~/markers`` every ``markers_period``; ``/obstacles`` adds and removes
obstacles live. Every topic, its type and frame, and the node's behaviour on bad input and
stale data: ``docs/nodes.md`` (Redundancy resolution).

Safety, in short: zero commands without a goal, after a rejected goal, while an input is older
than ``state_timeout`` and when the joint states stop (a watchdog); a joint state that is not
newer than the last cycle's, or that waited beyond ``max_state_wait``, runs no cycle; every
command within the robot's limits and through the safety stage.

Lockstep: when the simulator says it steps in lockstep (its latched ``sim/lockstep_timeout``,
:mod:`~wmm_control.nodes.sim_timing`), the inputs are aged by the simulation's time, every
joint state is answered however long it waited, the feasible twist is awaited as long as the
simulator waits for the commands (while the base controller answers:
:class:`~wmm_control.nodes.sim_timing.AnswerWait`), and the watchdog allows the simulator's wait besides
``state_timeout``; no parameter needs to change.

This module only wires parameters (:mod:`~wmm_control.nodes.redundancy_resolver_params`),
topics (through :mod:`~wmm_control.nodes.conversions`) and timers to the ROS-free core: the
resolver's half of each period in :class:`~wmm_control.resolvers.period.ResolverPeriod`, which
the direct engine runs too (the target and its checks and report, the checks of odometry,
end-effector pose and feasible twist, the state of a cycle, the compensation exchange); the
events' throttle in :class:`~wmm_control.resolvers.targets.LogThrottle`; the markers in
:class:`~wmm_control.nodes.markers.ResolverMarkers`.
"""

import time
from collections.abc import Callable
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray
from trajectory_msgs.msg import MultiDOFJointTrajectory
from visualization_msgs.msg import MarkerArray

from wmm_control.errors import ConfigError
from wmm_control.kinematics import KinematicModel
from wmm_control.nodes.diagnostics import DiagnosticsGate, diagnostic_array, log_lines, node_status
from wmm_control.nodes.inputs import JointSelector, JointStateWatchdog
from wmm_control.nodes.parameters import declare_parameters
from wmm_control.nodes.qos import COMMAND_QOS, DIAGNOSTICS_QOS, LATCHED_QOS, STATE_SUB_QOS
from wmm_control.nodes.runner import guard_clock, run_node
from wmm_control.nodes.sim_timing import AnswerWait
from wmm_control.nodes.stamps import seconds, stamp_key
from wmm_control.nodes.conversions import (
    float_array,
    odometry_values,
    planar_twist,
    planned_base_values,
    pose_values,
    twist_stamped,
    twist_values,
)
from wmm_control.nodes.markers import ResolverMarkers
from wmm_control.nodes.obstacle_topic import ObstacleSet, describe
from wmm_control.nodes.redundancy_resolver_params import PARAMS
from wmm_control.resolvers import make_resolver, method_parameters
from wmm_control.resolvers.interface import PoseTarget
from wmm_control.resolvers.progress import GoalProgress
from wmm_control.resolvers.period import ResolverPeriod, ResolverSettings
from wmm_control.resolvers.targets import LogThrottle

__all__ = ['PARAMS', 'RedundancyResolverNode', 'main']


class RedundancyResolverNode(Node):
    """Wraps one :class:`~wmm_control.resolvers.Resolver` in a
    :class:`~wmm_control.resolvers.period.ResolverPeriod`; the maths lives there."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__('redundancy_resolver', **kwargs)
        guard_clock(self)
        p = self.p = declare_parameters(
            self,
            'redundancy_resolver.yaml',
            PARAMS,
            on_change={
                'state_timeout': self._set_state_timeout,
                'max_goal_distance': self._set_max_goal_distance,
                'goal_tolerance': lambda v: setattr(self.progress, 'tolerance', self.targets.tolerance(v)),
                'stall_time': lambda v: setattr(self.progress, 'stall_time', float(v)),
                'min_progress_ratio': lambda v: setattr(self.progress, 'min_progress_ratio', float(v)),
                'max_state_wait': lambda v: setattr(self.watchdog, 'max_wait', float(v)),
            },
        )
        self.model = KinematicModel(p.robot)
        names = [n for n in method_parameters(p.method) if n != 'dt' and hasattr(p, n)]
        self.resolver = make_resolver(p.method, self.model, dt=p.period, **{n: getattr(p, n) for n in names})
        arm = self.model.config.arm
        self.arm_joints = arm.joints
        self.arm = JointSelector(
            arm.joints, velocity_limits=arm.velocity, position_limits=(arm.position_lower, arm.position_upper)
        )
        settings = ResolverSettings(
            p.world_frame,
            p.state_timeout,
            p.max_goal_distance,
            tuple(p.goal_tolerance),
            p.stall_time,
            p.min_progress_ratio,
            ground_truth=p.ee_feedback == 'ground_truth',
        )
        #: the resolver's half of each period, as the direct engine runs it (ROS-free)
        self.period = ResolverPeriod(self.resolver, p.period, settings)
        self.workspace = self.period.workspace
        self.targets, self.inputs, self.latest = self.period.targets, self.period.inputs, self.period.latest
        self.obstacles = ObstacleSet(p.obstacles, p.world_frame)
        self._set_obstacles()
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._wait = self._last = self._held = None
        self._received = 0  # when the joint state of the held arm command came (time.monotonic_ns())
        self._diagnostics_gate = DiagnosticsGate()
        self._throttle = LogThrottle()
        #: Callables ``observe(stamp, command, reached, stalled)``, each run once a cycle's arm command
        #: is out (``command``: the :class:`~wmm_control.resolvers.ResolverCommand`; ``reached``,
        #: ``stalled``: the goal's state): the cycle's exact values for code in this process (an
        #: experiment's recorder), without a ``/diagnostics`` message every period.
        self.cycle_observers: list[Callable[..., object]] = []
        self.pub_arm = self.create_publisher(Float64MultiArray, 'arm_controller/commands', COMMAND_QOS)
        self.pub_base = self.create_publisher(TwistStamped, 'base/reference', COMMAND_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.create_subscription(PoseStamped, 'goal_pose', self._on_goal, COMMAND_QOS)
        self.create_subscription(MultiDOFJointTrajectory, 'ee_reference', self._on_reference, COMMAND_QOS)
        self.create_subscription(JointState, 'joint_states', self._on_joint_states, STATE_SUB_QOS)
        self.create_subscription(Odometry, 'odom', self._on_odom, STATE_SUB_QOS)
        self.create_subscription(MarkerArray, '/obstacles', self._on_obstacles, COMMAND_QOS)
        self.create_subscription(Float64, 'base/lag', self._on_base_lag, LATCHED_QOS)
        if p.ee_feedback == 'ground_truth':
            self.create_subscription(PoseStamped, 'ee_pose', self._on_ee_pose, STATE_SUB_QOS)
        self.watchdog = JointStateWatchdog(
            self, p.state_timeout, p.period, self._steady, self._stop, 'zero commands', max_wait=p.max_state_wait
        )
        #: how long an arm command waits for its feasible twist (longer in lockstep, while they come)
        self.compensation_wait = AnswerWait(self.watchdog.timing, p.compensation_timeout)
        if self.resolver.uses_compensation:
            self.create_subscription(TwistStamped, 'base/feasible_twist', self._on_feasible, COMMAND_QOS)
            self._wait = (
                self.create_timer(
                    p.compensation_timeout, self._compensation_timeout, clock=self._steady, autostart=False
                )
                if p.compensation_timeout > 0
                else None
            )
        if p.markers_period > 0:
            self._markers = ResolverMarkers(self.model.config, p.world_frame, self.workspace)
            self.pub_markers = self.create_publisher(MarkerArray, '~/markers', COMMAND_QOS)
            self.create_timer(p.markers_period, self._publish_markers, clock=self._steady)
        if 0.0 < p.max_state_wait <= p.compensation_timeout and self.resolver.uses_compensation:
            self.get_logger().warn(
                f'max_state_wait {p.max_state_wait:g} s is within compensation_timeout {p.compensation_timeout:g} s: '
                'an arm command that waits that long for its feasible twist is dropped'
            )
        self.get_logger().info(
            f'{p.method} on robot {self.model.config.name}: t_s {p.period} s, EE feedback {p.ee_feedback}, '
            f'compensation {"on" if self.resolver.uses_compensation else "off"}, {describe(self.obstacles.obstacles)}; '
            f'waiting for /goal_pose (frame {p.world_frame!r})'
        )

    @property
    def target(self) -> PoseTarget | None:
        """The end-effector target pursued, or None."""
        return self.targets.target

    @property
    def progress(self) -> GoalProgress:
        """The :class:`~wmm_control.resolvers.progress.GoalProgress` of the target."""
        return self.targets.progress

    @property
    def counters(self) -> dict:
        """The counts reported on /diagnostics."""
        return self.period.counters

    def _set_state_timeout(self, timeout):
        self.latest.set_timeout(timeout)
        self.targets.reference.timeout = timeout
        self.watchdog.set_timeout(timeout)

    def _set_max_goal_distance(self, distance):
        self.targets.max_goal_distance = self.inputs.max_distance = float(distance)

    def _now(self):
        """The time [s] by which the inputs are aged: the simulation's in lockstep, else the steady clock."""
        return self.watchdog.now(self._steady)

    def _log(self, events):
        log_lines(self, self._throttle.lines(events, seconds(self._steady) if events else 0.0))

    # ------------------------------------------------------------------ inputs
    def _on_goal(self, msg):
        self._log(self.period.goal(msg.header.frame_id, pose_values(msg.pose), self._now()))

    def _on_reference(self, msg):
        point = msg.points[0] if msg.points else None
        pose = vel = acc = None
        if point is not None and point.transforms:
            pose = pose_values(point.transforms[0])
            vel = twist_values(point.velocities[0]) if point.velocities else np.zeros(6)
            acc = twist_values(point.accelerations[0]) if point.accelerations else np.zeros(6)
        planned = planned_base_values(msg, self.arm_joints)  # a followed plan's base (and posture), or None
        self._log(self.period.trajectory_point(msg.header.frame_id, pose, vel, acc, self._now(), planned))

    def _set_obstacles(self):
        self.period.set_obstacles(self.obstacles.obstacles)

    def _on_obstacles(self, msg):
        if self.obstacles.take(msg, self.get_logger(), self.p.max_obstacles):
            self._set_obstacles()

    def _on_base_lag(self, msg):
        """The running base controller's τ: the safety stage brakes the base with it."""
        lag = float(msg.data)
        if lag == self.resolver.safety.base_lag:
            return
        try:
            self.resolver.set_base_lag(lag)
        except ConfigError as exc:
            self.get_logger().warn(f'rejected /base/lag: {exc}; keeping τ = {self.resolver.safety.base_lag:g} s')
            return
        self.get_logger().info(f'base controller lag τ = {lag:g} s: the safety stage brakes the base with it')

    def _on_odom(self, msg):
        self._log(self.period.odometry(*odometry_values(msg), self._now()))

    def _on_ee_pose(self, msg):
        self._log(self.period.ee_pose(msg.header.frame_id, pose_values(msg.pose), self._now()))

    # ------------------------------------------------------------------ cycle
    def _on_joint_states(self, msg):
        received = time.monotonic_ns()
        q, dq, reason = self.arm.read(msg)
        if q is None:
            self.get_logger().warn(
                f'rejected /joint_states {reason}: no cycle (the watchdog stops the robot '
                'when no valid one comes within state_timeout)',
                throttle_duration_sec=1.0,
            )
            return
        if not self.watchdog.admit(msg.header.stamp):
            return
        if self.period.pending:  # the last cycle's feasible twist never came
            self._finish(None)
        stamp = msg.header.stamp
        plan = self.period.plan(q, dq, self._now(), resync=self.watchdog.resync(self.pub_arm))
        self._log(plan.events)
        if plan.command is None:
            if plan.stale:
                self.get_logger().warn(f'{plan.stale}: zero commands', throttle_duration_sec=2.0)
            self._publish_zero(stamp)
            return
        command = plan.command
        if self._dropped(received):
            return
        self.pub_base.publish(twist_stamped(stamp, self.p.base_frame, command.base_twist))
        if not self.resolver.uses_compensation:
            self._publish_arm(command, stamp, received)
            return
        self._received = received
        self._held = stamp_key(stamp)
        self.period.hold(self._held, command, stamp)
        if self._wait is None:
            self._finish(None)
        else:
            self.compensation_wait.start(self._wait)

    def _on_feasible(self, msg):
        key = stamp_key(msg.header.stamp)
        if not self.period.awaits(key):
            if key == self._held:
                self.compensation_wait.answered()  # late: the base answers, the next command waits for it
            return
        self.compensation_wait.answered()
        twist, events = self.period.feasible_twist(planar_twist(msg.twist))
        self._log(events)
        if twist is not None:
            self._finish(twist)

    def _compensation_timeout(self):
        if self.period.pending:
            self.compensation_wait.missed()
            self._finish(None)

    def _finish(self, feasible):
        """Publish the pending arm command, compensated when ``feasible`` is given."""
        if self._wait is not None:
            self._wait.cancel()
        if feasible is None:
            self.get_logger().warn(
                'no /base/feasible_twist for this cycle in time: arm command without compensation',
                throttle_duration_sec=1.0,
            )
        self._publish_arm(*self.period.finish(feasible), self._received)

    # ------------------------------------------------------------------ outputs
    def _dropped(self, received):
        """True when the joint state received at ``received`` (``time.monotonic_ns()``) waited
        beyond ``max_state_wait`` (logged): the node was held up in its cycle (stopped, or
        starved), the world has moved on from that state, and an answer published now would be
        applied as if current. The next cycle starts again from the state it measures."""
        if not self.watchdog.waited_too_long(received, 'answer dropped'):
            return False
        self.resolver.reset()
        return True

    def _publish_arm(self, command, stamp, received):
        """Publish the arm command of the cycle stamped ``stamp``, its joint state received at
        ``received`` (and, when due, its diagnostics)."""
        if self._dropped(received):
            return
        self.pub_arm.publish(float_array(command.arm_velocity))
        self._last = command
        for observe in self.cycle_observers:
            observe(stamp, command, self.progress.reached, self.progress.stalled)
        now = self._now()
        if self._diagnostics_gate.due(now, self.p.diagnostics_period):
            self.pub_diag.publish(self._diagnostics(stamp))

    def _publish_zero(self, stamp):
        self.pub_base.publish(twist_stamped(stamp, self.p.base_frame, np.zeros(3)))
        self.pub_arm.publish(float_array(np.zeros(len(self.arm_joints))))
        self.resolver.reset()

    def _stop(self):
        """Joint states stopped: zero commands every period (the watchdog's timeout action)."""
        self.period.exchange.clear()
        self._publish_zero(self.get_clock().now().to_msg())

    def _publish_markers(self) -> None:
        """~/markers: the goal, the tracked reference, the end-effector trail, the base footprint."""
        stamp = self.get_clock().now().to_msg()
        self.pub_markers.publish(
            self._markers.build(stamp, self.latest.last_state, self.targets.target, self.targets.tracking)
        )

    def _diagnostics(self, stamp):
        """Status of the cycle stamped ``stamp`` (the joint state it answers)."""
        values = dict(
            self.counters,
            joint_states_skipped=self.watchdog.skipped,
            measured_period_s=self.watchdog.stamps.measured_period,
            obstacles=len(self.obstacles.obstacles),
        )
        level, message = 'ok', 'no goal'
        if self._last is not None and self.targets.target is not None:
            level, message, goal_values = self.targets.report(self._last)
            values.update(goal_values)
        return diagnostic_array(stamp, [node_status(self, '', self.model.config.name, level, message, values)])


def main(args: list[str] | None = None) -> int:
    return run_node(RedundancyResolverNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
