"""``mecanum_controller`` and ``differential_controller``: the base controller of a Mecanum
base (robot B, Xing eq 16) or a differential-drive base as a node (one class, two executables;
each checks its robot's base family).

Subscribes:
  ``/base/reference`` (``geometry_msgs/TwistStamped``, frame ``base_frame`` or empty):
  ξ̇* = (ẋ, ẏ, ω);
  ``/joint_states`` (``sensor_msgs/JointState``): each message with the wheel joints runs
  exactly one control cycle.
Publishes, every cycle:
  ``/wheel_controller/commands`` (``std_msgs/Float64MultiArray``): the wheel rates
  [rad/s], order of the robot YAML's ``wheel_joints`` (Mecanum fl, fr, rl, rr; differential
  left, right). A differential base's reference loses its vy (it cannot move sideways):
  the feasible twist says what it follows, and the resolver's arm compensation covers the rest;
  ``/base/feasible_twist`` (``TwistStamped``, frame ``base_frame``): q̇_bf, the twist the
  wheel rates realise over the coming period, stamped with the joint state the cycle answers;
  ``/diagnostics``: status, scales, reference and twist, every ``diagnostics_period``.

The exchange, one per period, is that of ``swmr_controller``: a joint state stamped S runs
the cycle that answers the reference stamped S, at once if the latest reference carries S,
else as soon as it comes, or after ``reference_wait`` seconds of steady time with the latest
reference (:class:`~wmm_control.nodes.common.StampedExchange`).

Geometry (R, d1, d2 or the track), the wheel joints and every limit come from the robot
description (its YAML and URDF); ``config/mecanum_controller.yaml`` holds only the node's
tuning (both executables read it).

Safety: when the latest reference is older than ``reference_timeout`` (this node's clock at
receipt) the base brakes to rest at the acceleration limits. Non-finite references and
references in another frame are rejected (an empty frame is taken as ``base_frame``, with a
warning); finite references beyond the limits are scaled into them by the core, with a
warning. When joint states stop for ``joint_state_timeout`` (steady clock), zero wheel rates
are published, and the controller restarts from the measured wheel rates when they come
back. It does so too when the wheel rates of a joint state, those applied over its period,
differ from the last command by more than ``applied_rate_tolerance``: that command was not
applied as sent (lost or late, superseded when queued joint states are answered back to back,
or zeroed by the simulator's command timeout; logged, counted). A joint state without the wheel joints or naming one twice, with positions or
velocities not matching its names, with non-finite wheel values or rates beyond ten times
the wheel rate limit runs no cycle. Nor does one whose stamp is not after the last cycle's
or jumps more than the timeout ahead (:class:`~wmm_control.nodes.common.StampGate`: a second
publisher, a replayed message); a joint-state period that differs from ``period`` is
reported. Every rejection is logged, throttled. Nothing non-finite is ever published. Timers run on the steady clock, so
the node works under ``use_sim_time``.
"""

import functools
import time

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistStamped
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from wmm_control.base import WheelController, unapplied_command
from wmm_control.nodes.common import (
    BaseReference, COMMAND_QOS, DIAGNOSTICS_QOS, JointSelector, JointStateWatchdog, Param, STATE_SUB_QOS,
    StampedExchange, declare_parameters, diagnostic_array, float_array, guard_clock, max_state_wait_param, require_base,
    node_status, robot_param, robot_period, run_node, seconds, twist_stamped)
from wmm_control.robot_config import load_robot

__all__ = ['MecanumControllerNode', 'main', 'main_differential']

PARAMS = (
    robot_param('A robot with a Mecanum or differential base. Geometry and limits come from its description.'),
    Param('period', 'Control period [s]; default: the robot YAML\'s period.', lo=1e-3, hi=1.0, read_only=True,
          default_from=robot_period),
    Param('base_frame', 'Frame of the reference and feasible twists.', read_only=True),
    Param('reference_timeout', 'Reference age [s] after which the base brakes to rest.', lo=1e-3, hi=60.0),
    Param('reference_wait', 'Steady time [s] a joint state waits for the reference of its stamp.',
          lo=0.0, hi=1.0, read_only=True),
    Param('joint_state_timeout', 'Joint-state age [s] after which zero wheel rates are commanded.', lo=1e-3, hi=60.0),
    max_state_wait_param(),
    Param('applied_rate_tolerance', 'Largest difference [rad/s] between the wheel rates of a joint state and the '
          'last command under which that command counts as applied; beyond it the controller restarts from the '
          'measured wheel rates. 0: never.', lo=0.0, hi=100.0, read_only=True),
    Param('diagnostics_period', 'Time [s] between /diagnostics messages; 0 = none.', lo=0.0, hi=3600.0),
)


class MecanumControllerNode(Node):
    """Wraps one :class:`wmm_control.base.WheelController`.

    Args:
        family: the base family this executable drives (``mecanum`` or ``differential``); its
            default node name is ``<family>_controller``.
    """

    def __init__(self, family='mecanum', **kwargs):
        super().__init__(f'{family}_controller', **kwargs)
        guard_clock(self)
        self.family = family
        p = declare_parameters(self, f'{family}_controller.yaml', PARAMS, on_change={
            'reference_timeout': lambda v: setattr(self.reference.freshness, 'timeout', v),
            'joint_state_timeout': lambda v: self.watchdog.set_timeout(v),
            'max_state_wait': lambda v: setattr(self.watchdog, 'max_wait', float(v))})
        self.p = p
        robot = load_robot(p.robot)
        require_base(robot, (family,), f'{family}_controller')
        self.controller = WheelController.from_robot_config(robot, p.period)
        wheels = robot.mecanum or robot.differential
        self.wheels = JointSelector(wheels.wheel_joints, velocity_limits=wheels.wheel_rate_limit)
        self.reference = BaseReference(self, p.base_frame, p.reference_timeout, robot.base.velocity)
        self.counters = {'cycles': 0, 'joint_states_rejected': 0, 'stale_cycles': 0, 'commands_not_applied': 0}
        self._last_wheels = None
        self._next_diag = 0.0
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.pub_wheels = self.create_publisher(Float64MultiArray, 'wheel_controller/commands', COMMAND_QOS)
        self.pub_feasible = self.create_publisher(TwistStamped, 'base/feasible_twist', COMMAND_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.exchange = StampedExchange(self, p.reference_wait, self._cycle, steady)
        self.watchdog = JointStateWatchdog(
            self, p.joint_state_timeout, p.period, steady, lambda: self.pub_wheels.publish(float_array(np.zeros(len(wheels.wheel_joints)))),
            'zero wheel rates; will restart from the measured wheel rates', max_wait=p.max_state_wait)
        self.create_subscription(TwistStamped, 'base/reference', self._on_reference, COMMAND_QOS)
        self.create_subscription(JointState, 'joint_states', self._on_joint_states, STATE_SUB_QOS)
        lim = self.controller.params
        self.get_logger().info(
            f'{family.capitalize()} base controller, robot {robot.name}: t_s {p.period} s, |v| ≤ {list(lim.velocity_limit)}, '
            f'|a| ≤ {list(lim.accel_limit)}, wheels ≤ {lim.wheel_rate_limit} rad/s')

    # ------------------------------------------------------------------ inputs
    def _on_reference(self, msg):
        if self.reference.accept(msg):
            self.exchange.reference_received(msg.header.stamp)

    def _wheel_rates_measured(self, msg):
        """Measured wheel rates (zero when the message has no velocities), or None (logged)."""
        _, rates, reason = self.wheels.read(msg)
        if rates is None:
            self._reject_joint_state(reason)
        return rates

    def _reject_joint_state(self, reason):
        self.counters['joint_states_rejected'] += 1
        self.get_logger().warn(f'rejected /joint_states {reason}: cycle skipped', throttle_duration_sec=1.0)

    def _on_joint_states(self, msg):
        received = time.monotonic_ns()
        rates = self._wheel_rates_measured(msg)
        if rates is None or not self.watchdog.admit(msg.header.stamp):
            return
        self.exchange.state_received(msg.header.stamp, (rates, bool(len(msg.velocity)), received))

    # ------------------------------------------------------------------ cycle
    def _cycle(self, stamp, measured):
        """One period: the latest reference (braking when stale) → wheel rates and q̇_bf; ``measured``
        is (the wheel rates of the joint state, whether it has velocities, when this node
        received it (``time.monotonic_ns()``))."""
        wheel_rates, has_rates, received = measured
        if self.watchdog.waited_too_long(received):
            return
        now = seconds(self.get_clock())
        if self.watchdog.resync(self.pub_wheels):
            self.controller.restart(wheel_rates)
        elif has_rates:
            why = unapplied_command(wheel_rates, self._last_wheels, self.p.applied_rate_tolerance)
            if why:
                self.counters['commands_not_applied'] += 1
                self.get_logger().warn(f'last wheel command: {why}; restarting from the measured wheel rates',
                                       throttle_duration_sec=1.0)
                self.controller.restart(wheel_rates)
        reference = self.reference.current(now)
        if reference is not None:
            out = self.controller.step(reference)
        else:
            self.counters['stale_cycles'] += 1
            out = self.controller.stop()
        wheels, twist = out.wheel_rates, out.twist
        if not (np.all(np.isfinite(wheels)) and np.all(np.isfinite(twist))):   # cannot happen: never publish it
            self.get_logger().error(f'non-finite command {wheels.tolist()}: zero wheel rates',
                                    throttle_duration_sec=1.0)
            self.controller.reset()
            wheels, twist = np.zeros(len(wheels)), np.zeros(3)
        self.counters['cycles'] += 1
        self.pub_wheels.publish(float_array(wheels))
        self._last_wheels = wheels
        feasible = twist_stamped(stamp, self.p.base_frame, twist)
        self.pub_feasible.publish(feasible)
        if self.p.diagnostics_period > 0 and now >= self._next_diag:
            self._next_diag = now + self.p.diagnostics_period
            self.pub_diag.publish(self._diagnostics(feasible.header.stamp, out, now))

    def _diagnostics(self, stamp, out, now):
        ref = self.reference
        level = 'warn' if out.status == 'braking' and np.any(ref.value) else 'ok'
        lim = self.controller.params.wheel_rate_limit
        values = {'status': out.status, 'velocity_scale': out.velocity_scale, 'accel_scale': out.accel_scale,
                  'reference': ref.value, 'reference_dropped': out.dropped, 'reference_limited': out.reference,
                  'feasible_twist': out.twist,
                  'wheel_rates': out.wheel_rates,
                  'wheel_rate_ratio': float(np.max(np.abs(out.wheel_rates))) / lim,
                  'reference_age_s': ref.freshness.age(now), 'references_rejected': ref.rejected,
                  'joint_states_skipped': self.watchdog.skipped,
                  'measured_period_s': self.watchdog.stamps.measured_period, **self.counters}
        return diagnostic_array(stamp, [node_status(self, '', f'{self.family} base', level,
                                            out.status, values)])


def main(args=None):
    return run_node(MecanumControllerNode, args)


def main_differential(args=None):
    """``differential_controller``: the same node for a differential-drive base."""
    return run_node(functools.partial(MecanumControllerNode, family='differential'), args)


if __name__ == '__main__':
    raise SystemExit(main())
