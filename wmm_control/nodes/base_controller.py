"""The base controller node: any :class:`~wmm_control.base.BaseController` over topics.

One class, three executables, each for one base family (it checks its robot's):
``swmr_controller`` (steerable, Sorour §IV; :mod:`wmm_control.nodes.swmr_controller`),
``mecanum_controller`` (robot B, Xing eq 16) and ``differential_controller``
(:mod:`wmm_control.nodes.mecanum_controller`). Geometry, joints and every limit come from the
robot description; ``config/<executable>.yaml`` holds only the node's tuning.

Subscribes:
  ``/base/reference`` (``geometry_msgs/TwistStamped``, frame ``base_frame`` or empty):
  ξ̇* = (ẋ, ẏ, ω);
  ``/joint_states`` (``sensor_msgs/JointState``): each message with the joints of the
  controller's required groups (the steer joints; the wheel joints) runs exactly one cycle.
Publishes, every cycle:
  ``/<group>_controller/commands`` (``std_msgs/Float64MultiArray``), one per command group
  of the controller, in the order of the robot YAML's joints: ``steer`` (β̇_ref) and
  ``drive`` (φ̇_ref) for a steerable base, ``wheel`` for a Mecanum (fl, fr, rl, rr) or
  differential (left, right) one;
  ``/base/feasible_twist`` (``TwistStamped``, frame ``base_frame``): q̇_bf, the twist the base
  executes over the coming period, stamped with the joint state the cycle answers;
  ``/diagnostics``: status, the family's values, reference and counters, every
  ``diagnostics_period``.
Publishes once (transient local):
  ``/base/lag`` (``std_msgs/Float64``): τ [s], the time constant with which the base's twist
  follows its reference (a steerable base's 1/K_p + 1/λ, from this node's ``kp`` and
  ``icr_gain``; 0 for a wheeled base); the resolver's safety stage brakes the base with it.

The exchange, one per period: a joint state stamped S runs the cycle that answers the
reference stamped S, at once if the latest reference carries S, else as soon as it comes, or
after ``reference_wait`` seconds of steady (wall) time with the latest reference
(:class:`~wmm_control.nodes.stamps.StampedExchange`). A resolver that answers each joint state
with a reference of the same stamp therefore gets its feasible twist in the same period, and a
reference published by hand (stamp 0) still drives the base, one short wait later. A
steerable base closes each cycle on the measured steer angles.

Lockstep: when the simulator says it steps in lockstep (its latched ``sim/lockstep_timeout``,
:mod:`~wmm_control.nodes.sim_timing`), the reference is aged by the simulation's time, a joint
state waits for its reference as long as the simulator waits for the commands (while the
references answer the states: :class:`~wmm_control.nodes.sim_timing.AnswerWait`), no state is
skipped for its wait, and the joint-state watchdog allows the simulator's wait besides
``joint_state_timeout``; no parameter needs to change.

Safety: when the latest reference is older than ``reference_timeout`` (this node's clock at
receipt; the simulation's time in lockstep) the base brakes to rest at its acceleration limits
(at rest within |v|/a + one period; a steerable base holds its steer angles). Non-finite references and references in
another frame are rejected (an empty frame is taken as ``base_frame``, with a warning); finite
references beyond the limits are scaled into them by the core, with a warning. When joint
states stop for ``joint_state_timeout`` (steady clock, so a paused sim clock cannot hide it),
zero rates are published on every command topic, and when they come back the controller
restarts from the measured state (a steerable base re-reads its steer angles and starts at
rest; a wheeled one goes on from the measured wheel rates). A joint state also reports the rates applied over its
period: when they differ from the last command by more than ``applied_rate_tolerance``, that
command was not applied as sent (lost or late, superseded when queued joint states are
answered back to back, or zeroed by the simulator's command timeout), and the controller
goes on from the measured state (logged, counted): the rates the base receives then change by
at most one period of acceleration. That state is, for a steerable base, the measured steer
angles, steer rates and the twist that best fits them and the drive rates; for a wheeled one,
the twist of the measured wheel rates. A joint state without a required joint or naming one
twice, with positions or velocities not matching its names, non-finite values or rates beyond
ten times their limit, runs no cycle. Nor does one whose stamp is not after the last cycle's
or jumps more than the timeout ahead (:class:`~wmm_control.nodes.stamps.StampGate`: a second
publisher, a replayed message), nor one that waited in the node longer than
``max_state_wait`` (:class:`~wmm_control.nodes.inputs.JointStateWatchdog`), and a cycle that
finishes later than that after its state came (the node was held up mid-cycle) publishes
nothing: the next cycle restarts from the measured state; a joint-state
period that differs from ``period`` is reported. Every rejection is logged, throttled. Nothing
non-finite is ever published. Timers run on the steady clock, so the node works under
``use_sim_time``.
"""

import time
from typing import Any

import numpy as np
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistStamped
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64, Float64MultiArray

from wmm_control.base import make_base_controller
from wmm_control.base.period import BasePeriod
from wmm_control.nodes.conversions import float_array, twist_stamped
from wmm_control.nodes.diagnostics import DiagnosticsGate, diagnostic_array, node_status
from wmm_control.nodes.inputs import BaseReference, JointSelector, JointStateWatchdog
from wmm_control.nodes.base_controller_params import GAINS, NODE_NAMES, STEERABLE_PARAMS, WHEEL_PARAMS
from wmm_control.nodes.parameters import declare_parameters, require_base
from wmm_control.nodes.qos import COMMAND_QOS, DIAGNOSTICS_QOS, LATCHED_QOS, STATE_SUB_QOS
from wmm_control.nodes.runner import guard_clock
from wmm_control.nodes.sim_timing import AnswerWait
from wmm_control.nodes.stamps import StampedExchange
from wmm_control.robot_config import load_robot

__all__ = ['BaseControllerNode']


class BaseControllerNode(Node):
    """Wraps the base controller of one robot (:func:`~wmm_control.base.make_base_controller`).

    Args:
        family: the base family this executable drives (``steerable``, ``mecanum`` or
            ``differential``); the node name is :data:`NODE_NAMES` ``[family]``.
    """

    def __init__(self, family: str, **kwargs: Any) -> None:
        name = NODE_NAMES[family]
        super().__init__(name, **kwargs)
        guard_clock(self)
        self.family = family
        specs = STEERABLE_PARAMS if family == 'steerable' else WHEEL_PARAMS
        p = declare_parameters(
            self,
            f'{name}.yaml',
            specs,
            on_change={
                'reference_timeout': lambda v: setattr(self.reference.freshness, 'timeout', v),
                'joint_state_timeout': lambda v: self.watchdog.set_timeout(v),
                'max_state_wait': lambda v: setattr(self.watchdog, 'max_wait', float(v)),
            },
        )
        self.p = p
        robot = load_robot(p.robot)
        require_base(robot, (family,), name)
        gains = {g.name: getattr(p, g.name) for g in GAINS if g in specs}
        self.base = make_base_controller(robot, p.period, **gains)
        self.controller = self.base.controller
        self.groups = tuple(self.base.command_groups)
        self.selectors = {
            g: JointSelector(joints, velocity_limits=self.base.rate_limits[g])
            for g, joints in self.base.command_groups.items()
        }
        self.reference = BaseReference(
            self, p.base_frame, p.reference_timeout, self.base.velocity_limit, now=self._input_time
        )
        self.counters = {'cycles': 0, 'joint_states_rejected': 0, 'stale_cycles': 0, 'commands_not_applied': 0}
        self.period = BasePeriod(self.base, p.applied_rate_tolerance)
        self._diagnostics_gate = DiagnosticsGate()
        steady = Clock(clock_type=ClockType.STEADY_TIME)
        self.pub_commands = {
            g: self.create_publisher(Float64MultiArray, f'{g}_controller/commands', COMMAND_QOS) for g in self.groups
        }
        self.pub_feasible = self.create_publisher(TwistStamped, 'base/feasible_twist', COMMAND_QOS)
        self.pub_diag = self.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        # τ of this controller, for the resolver's safety stage (latched: a resolver started later gets it)
        self.pub_lag = self.create_publisher(Float64, 'base/lag', LATCHED_QOS)
        self.pub_lag.publish(Float64(data=float(self.base.lag)))
        then = (
            'restart from the measured wheel rates'
            if self.base.resync_from_rates
            else 'resync from the measured angles'
        )
        self.watchdog = JointStateWatchdog(
            self,
            p.joint_state_timeout,
            p.period,
            steady,
            self._zero_rates,
            f'zero {" and ".join(self.groups)} rates; will {then}',
            max_wait=p.max_state_wait,
        )
        # One cycle per joint state, run with the reference of the same stamp (see the module doc).
        self.exchange = StampedExchange(self, AnswerWait(self.watchdog.timing, p.reference_wait), self._cycle, steady)
        self.create_subscription(TwistStamped, 'base/reference', self._on_reference, COMMAND_QOS)
        self.create_subscription(JointState, 'joint_states', self._on_joint_states, STATE_SUB_QOS)
        self.get_logger().info(f'{family} base controller, robot {robot.name}: {self.base.describe()}')

    # ------------------------------------------------------------------ inputs
    def _input_time(self) -> float:
        """The time [s] by which the reference is aged: the simulation's in lockstep, else the ROS clock."""
        return self.watchdog.now(self.get_clock())

    def _on_reference(self, msg):
        if self.reference.accept(msg):
            self.exchange.reference_received(msg.header.stamp)

    def _measured(self, msg):
        """``(positions, rates)`` per group, or None (logged, counted) when a required group cannot
        be read (:meth:`~wmm_control.base.period.BasePeriod.measured`). ``rates`` is None unless
        the message has velocities for every group."""
        reads = {group: selector.read(msg) for group, selector in self.selectors.items()}
        positions, rates, reason = self.period.measured(reads, bool(len(msg.velocity)))
        if reason:
            self.counters['joint_states_rejected'] += 1
            self.get_logger().warn(f'rejected /joint_states {reason}: cycle skipped', throttle_duration_sec=1.0)
            return None
        return positions, rates

    def _on_joint_states(self, msg):
        received = time.monotonic_ns()
        measured = self._measured(msg)
        if measured is not None and self.watchdog.admit(msg.header.stamp):
            self.exchange.state_received(msg.header.stamp, (*measured, received))

    # ------------------------------------------------------------------ cycle
    def _cycle(self, stamp, measured):
        """The cycle of the joint state stamped ``stamp``: ``measured`` is (positions and rates per
        group, when this node received it (``time.monotonic_ns()``)); with the latest reference
        (braking when it is stale)."""
        positions, rates, received = measured
        if self.watchdog.waited_too_long(received):
            return
        now = self._input_time()
        why = self.period.start(positions, rates, self.watchdog.resync(*self.pub_commands.values()))
        if why:
            self.counters['commands_not_applied'] += 1
            self.get_logger().warn(
                f'last {"/".join(self.groups)} command: {why}; restarting from the measured state',
                throttle_duration_sec=1.0,
            )
        reference = self.reference.current(now)
        if reference is None:
            self.counters['stale_cycles'] += 1
        answer = self.period.step(reference, positions)
        command = answer.command
        if command.status == 'solver_failure':
            self.get_logger().error(
                f'ICR QP failed ({command.detail.qp_status}): steering held, drive ramping down',
                throttle_duration_sec=1.0,
            )
        if answer.non_finite:  # cannot happen: never publish it
            self.get_logger().error(answer.non_finite, throttle_duration_sec=1.0)
        if self.watchdog.waited_too_long(received, 'answer dropped'):
            # Held up mid-cycle (stopped, or starved): the world has moved on from this state, and
            # an answer published now would be applied as if current. The next cycle starts again
            # from the state it measures.
            self.period.dropped()
            return
        self.counters['cycles'] += 1
        for group, rates_out in answer.rates.items():
            self.pub_commands[group].publish(float_array(rates_out))
        self.period.published(answer)
        feasible = twist_stamped(stamp, self.p.base_frame, answer.twist)
        self.pub_feasible.publish(feasible)
        if self._diagnostics_gate.due(now, self.p.diagnostics_period):
            self.pub_diag.publish(self._diagnostics(feasible.header.stamp, command, answer.twist, now))

    def _zero_rates(self):
        for group, joints in self.base.command_groups.items():
            self.pub_commands[group].publish(float_array(np.zeros(len(joints))))

    def _diagnostics(self, stamp, command, twist, now):
        ref = self.reference
        status = command.status
        level = 'error' if status == 'solver_failure' else 'warn' if status == 'braking' and np.any(ref.value) else 'ok'
        values = {
            'status': status,
            **self.base.diagnostic_values(command),
            'feasible_twist': twist,
            'reference': ref.value,
            'reference_age_s': ref.freshness.age(now),
            'references_rejected': ref.rejected,
            'joint_states_skipped': self.watchdog.skipped,
            'measured_period_s': self.watchdog.stamps.measured_period,
            **self.counters,
        }
        return diagnostic_array(stamp, [node_status(self, '', f'{self.family} base', level, status, values)])
