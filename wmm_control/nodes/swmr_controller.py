"""``swmr_controller``: the steerable-base controller of Sorour §IV as a node.

Subscribes:
  ``/base/reference`` (``geometry_msgs/TwistStamped``, frame ``base_frame``): ξ̇* = (ẋ, ẏ, ω);
  ``/joint_states`` (``sensor_msgs/JointState``): measured steer angles; each message runs
  exactly one control cycle.
Publishes, every cycle:
  ``/steer_controller/commands`` (``std_msgs/Float64MultiArray``): β̇_ref, order ``steer_joints``;
  ``/drive_controller/commands`` (``Float64MultiArray``): φ̇_ref, order ``drive_joints``;
  ``/base/feasible_twist`` (``TwistStamped``): q̇_bf, the twist the base executes over the
  coming period (compatible with the next ICR, corrected for the steering during the period),
  stamped with the joint state the cycle answers;
  ``/diagnostics``: ICR, route, active constraints, solve time, every ``diagnostics_period``.

The exchange, one per period: a joint state stamped S runs the cycle that answers the
reference stamped S. If the latest reference already carries S (it came first), the cycle
runs at once; otherwise the node waits for it at most ``reference_wait`` seconds of steady
(wall) time, then runs with the latest reference. A resolver that answers each joint state
with a reference of the same stamp therefore gets its feasible twist in the same period,
and a reference published by hand (stamp 0) still drives the base, one short wait later.
The cycle closes on the measured steer angles.

Safety: when the latest reference is older than ``reference_timeout`` (by this node's clock
at receipt) the base brakes to rest at its acceleration limits (at rest within |v|/a + one
period) and the steer angles are held. References beyond ``base_velocity_limit`` are scaled into it by the core;
non-finite ones, or ones in another frame, are rejected. When joint states stop for
``joint_state_timeout`` (steady clock, so a paused sim clock cannot hide it), zero steer and
drive rates are published, and the controller re-reads the measured steer angles when they
come back. A joint state also reports the steer and drive rates applied over its period: when
they differ from the last command by more than ``applied_rate_tolerance``, that command was not
applied as sent (lost or late, superseded by the next one when queued joint states are answered
back to back, or zeroed by the simulator's command timeout), and the controller restarts from
the measured angles, rates and twist (logged, counted): the rates the base receives then change
by at most one period of acceleration, not by as many as were answered meanwhile. A joint
state without every steer joint or naming one twice, with positions and names of different
lengths, non-finite values or steer rates beyond ten times the limit, is
rejected with a throttled log and runs no cycle. Nor does one whose stamp is not after the
last cycle's or jumps more than the timeout ahead (:class:`~wmm_control.nodes.common.StampGate`:
a second publisher, a replayed message); a joint-state period that differs from ``period`` is
reported. An empty reference frame is taken as ``base_frame`` and a reference beyond the
limits is scaled into them, both with a warning. The node's timers run on the
steady clock: they keep working under ``use_sim_time``.
"""

import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistStamped
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from wmm_control.base import SteerableGeometry, SwmrController, SwmrParams, unapplied_command
from wmm_control.nodes.common import (
    BaseReference, COMMAND_QOS, DIAGNOSTICS_QOS, JointSelector, JointStateWatchdog, Param, STATE_SUB_QOS,
    StampedExchange, declare_parameters, diagnostic_array, float_array, guard_clock, max_state_wait_param, require_base,
    node_status, robot_param, robot_period, run_node, seconds, twist_stamped)
from wmm_control.robot_config import load_robot

__all__ = ['SwmrControllerNode', 'main']

PARAMS = (
    robot_param('A robot with a steerable base (A, Sorour). Geometry, joints and limits come from its YAML.'),
    Param('period', 'Control period t_s [s]; default: the robot YAML\'s period.', lo=1e-3, hi=1.0, read_only=True,
          default_from=robot_period),
    Param('kp', 'Gain K_p of the twist controller [1/s].', lo=1e-3, hi=40.0, read_only=True),
    Param('icr_gain', 'Gain λ of the ICR P-controller [1/s].', lo=1e-3, hi=40.0, read_only=True),
    Param('base_frame', 'Frame of the reference and feasible twists.', read_only=True),
    Param('reference_timeout', 'Reference age [s] (this node\'s clock at receipt) after which the base brakes '
          'to rest.', lo=1e-3, hi=60.0),
    Param('reference_wait', 'Steady time [s] a joint state waits for the reference of its stamp.',
          lo=0.0, hi=1.0, read_only=True),
    Param('joint_state_timeout', 'Joint-state age [s] (steady clock) after which zero rates are commanded.',
          lo=1e-3, hi=60.0),
    max_state_wait_param(),
    Param('applied_rate_tolerance', 'Largest difference [rad/s] between the steer and drive rates of a joint state '
          'and the last command under which that command counts as applied; beyond it the controller restarts '
          'from the measured state. 0: never.', lo=0.0, hi=100.0, read_only=True),
    Param('diagnostics_period', 'Time [s] between /diagnostics messages; 0 = none.', lo=0.0, hi=3600.0),
)


class SwmrControllerNode(Node):
    """Wraps one :class:`wmm_control.base.SwmrController`."""

    def __init__(self, **kwargs):
        super().__init__('swmr_controller', **kwargs)
        guard_clock(self)
        p = declare_parameters(self, 'swmr_controller.yaml', PARAMS, on_change={
            'reference_timeout': lambda v: setattr(self.reference.freshness, 'timeout', v),
            'joint_state_timeout': lambda v: self.watchdog.set_timeout(v),
            'max_state_wait': lambda v: setattr(self.watchdog, 'max_wait', float(v))})
        self.p = p
        robot = load_robot(p.robot)
        require_base(robot, ('steerable',), 'swmr_controller')
        self.steer_joints = robot.steerable.steer_joints
        params = SwmrParams.from_robot_config(robot, dt=p.period, kp=p.kp, icr_gain=p.icr_gain)
        self.controller = SwmrController(SteerableGeometry.from_config(robot.steerable), params)
        self.reference = BaseReference(self, p.base_frame, p.reference_timeout, params.base_velocity_limit)
        self.steer = JointSelector(self.steer_joints, velocity_limits=params.steer_rate_limit)
        self.drive = JointSelector(robot.steerable.drive_joints, velocity_limits=params.drive_rate_limit)
        self.not_applied = 0
        self._next_diag = 0.0
        self._last = None
        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.pub_steer = self.create_publisher(Float64MultiArray, 'steer_controller/commands', COMMAND_QOS)
        self.pub_drive = self.create_publisher(Float64MultiArray, 'drive_controller/commands', COMMAND_QOS)
        self.pub_feasible = self.create_publisher(TwistStamped, 'base/feasible_twist', COMMAND_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.create_subscription(TwistStamped, 'base/reference', self._on_reference, COMMAND_QOS)
        self.create_subscription(JointState, 'joint_states', self._on_joint_states, STATE_SUB_QOS)
        self.watchdog = JointStateWatchdog(
            self, p.joint_state_timeout, p.period, self._steady, self._zero_rates,
            'zero steer and drive rates; will resync from the measured angles', max_wait=p.max_state_wait)
        # Started for each joint state that waits for its reference, cancelled by the cycle.
        # One cycle per joint state, run with the reference of the same stamp (see the module doc).
        self.exchange = StampedExchange(self, p.reference_wait, self._cycle, self._steady)
        self.get_logger().info(f'steerable base controller, robot {robot.name}: {self.controller.geometry.n_wheels} modules, '
                               f't_s {p.period} s, '
                               f'β̇ ≤ {params.steer_rate_limit} rad/s, β̈ ≤ {params.steer_accel_limit} rad/s²')

    # ------------------------------------------------------------------ inputs
    def _on_reference(self, msg):
        if self.reference.accept(msg):
            self.exchange.reference_received(msg.header.stamp)

    def _on_joint_states(self, msg):
        received = time.monotonic_ns()
        beta, beta_dot, reason = self.steer.read(msg)
        if beta is None:
            self.get_logger().warn(f'rejected /joint_states {reason}: cycle skipped', throttle_duration_sec=1.0)
            return
        # The rates applied over the period the message closes (none when it has no velocities or
        # no drive joints): the check that the last command was applied.
        phi_dot = self.drive.read(msg)[1] if len(msg.velocity) else None
        rates = None if phi_dot is None else (beta_dot, phi_dot)
        if self.watchdog.admit(msg.header.stamp):
            self.exchange.state_received(msg.header.stamp, (beta, rates, received))

    # ------------------------------------------------------------------ cycle
    def _cycle(self, stamp, measured):
        """The cycle of the joint state stamped ``stamp`` ((sec, nanosec)), measured steer angles and
        ``(steer rates, drive rates)`` or None, and when this node received it (``time.monotonic_ns()``); with the
        latest reference (braking when it is stale)."""
        beta, rates, received = measured
        if self.watchdog.waited_too_long(received):
            return
        sec, nanosec = stamp
        now = seconds(self.get_clock())
        if self.watchdog.resync(self.pub_steer, self.pub_drive):
            self.controller.reset(beta)
        elif rates is not None and self._last is not None:
            self._restart_unless_applied(beta, *rates)
        reference = self.reference.current(now)
        fresh = reference is not None
        if not fresh:
            reference = np.zeros(3)
        out = self.controller.step(reference, beta_meas=beta, brake=not fresh)
        if out.status == 'solver_failure':
            self.get_logger().error(f'ICR QP failed ({out.qp_status}): steering held, drive ramping down',
                                    throttle_duration_sec=1.0)
        self.pub_steer.publish(float_array(out.beta_dot_ref))
        self.pub_drive.publish(float_array(out.phi_dot_ref))
        feasible = twist_stamped((sec, nanosec), self.p.base_frame, out.twist_executed)
        self.pub_feasible.publish(feasible)
        self._last = out
        if self.p.diagnostics_period > 0 and now >= self._next_diag:
            self._next_diag = now + self.p.diagnostics_period
            self.pub_diag.publish(self._diagnostics(feasible.header.stamp, out))

    def _restart_unless_applied(self, beta, beta_dot, phi_dot):
        """Restart from the measured state when the rates applied are not the last command's."""
        last = self._last
        why = unapplied_command(np.concatenate((beta_dot, phi_dot)),
                                np.concatenate((last.beta_dot_ref, last.phi_dot_ref)), self.p.applied_rate_tolerance)
        if not why:
            return
        self.not_applied += 1
        self.get_logger().warn(f'last steer/drive command: {why}; restarting from the measured state',
                               throttle_duration_sec=1.0)
        self.controller.restart(beta, beta_dot, phi_dot)

    def _zero_rates(self):
        n = len(self.steer_joints)
        self.pub_steer.publish(float_array(np.zeros(n)))
        self.pub_drive.publish(float_array(np.zeros(n)))

    def _diagnostics(self, stamp, out):
        icr = out.icr_next
        level = 'error' if out.status == 'solver_failure' else 'ok'
        values = {'status': out.status, 'route': out.route, 'qp_status': out.qp_status,
                  'icr_next_xy': icr.point, 'icr_at_infinity': icr.at_infinity,
                  'active_constraints': list(out.active_constraints),
                  'solve_time_us': out.solve_time_s * 1e6,
                  'beta_ref': out.beta_ref, 'feasible_twist': out.twist_executed,
                  'reference': self.reference.value, 'references_rejected': self.reference.rejected,
                  'joint_states_skipped': self.watchdog.skipped, 'commands_not_applied': self.not_applied,
                  'measured_period_s': self.watchdog.stamps.measured_period}
        return diagnostic_array(stamp, [node_status(self, '', 'steerable base', level,
                                            out.status, values)])


def main(args=None):
    return run_node(SwmrControllerNode, args)


if __name__ == '__main__':
    raise SystemExit(main())
