"""The whole-body control cycle of one period, in the order of Sorour et al. 2019 Fig 4 (ROS-free).

:class:`Cycle` is the one orchestration of a period. Its two halves are what the nodes run:
the resolver's (:class:`~wmm_control.resolvers.period.ResolverPeriod`, in
``redundancy_resolver``) and the base controller's (:class:`~wmm_control.base.period.BasePeriod`,
in the base controller nodes); the direct engine (:class:`sim_bridge.closed_loop.ClosedLoop`)
runs the same two halves back to back:

1. **plan**: the resolver turns the measured state and the target into the arm command and the
   base twist reference ξ̇* (:class:`~wmm_control.resolvers.ResolverCommand`), or holds the
   robot (no target, or an input missing or stale);
2. **base**: the base controller answers ξ̇* with joint rate commands per command group and the
   feasible twist q̇_bf (:class:`~wmm_control.base.BaseCommand`), starting again from the
   measured joints after a gap or a command that was not applied;
3. **finish**: the resolver compensates the arm command for the base's checked answer (eq 14,
   :meth:`~wmm_control.resolvers.Resolver.compensate`).

Inputs come in as they do in the nodes, each checked as it comes: goals and trajectory points,
odometry, the end effector's measured pose, obstacles; and the joint state each period is run
for, checked as the nodes check ``/joint_states`` (:class:`~wmm_control.checks.JointCheck`):
joints that fail are answered as the nodes answer them (:meth:`Cycle.step`). So both engines
take and refuse the same inputs and answer with the same commands.
"""

import gc
from collections.abc import Iterator
from contextlib import contextmanager
from dataclasses import dataclass

import numpy as np

from wmm_control.base.contract import BaseController
from wmm_control.base.period import BasePeriod, PeriodAnswer, node_default
from wmm_control.checks import Freshness, JointCheck
from wmm_control.resolvers.interface import Resolver, ResolverCommand
from wmm_control.resolvers.period import ResolverPeriod, ResolverSettings
from wmm_control.resolvers.targets import LogEvent

__all__ = ['Cycle', 'CycleResult', 'steady_heap']


@contextmanager
def steady_heap() -> Iterator[None]:
    """Periods run inside keep the garbage collector's full passes short.

    Python's collector now and then walks every container object the process has (its oldest
    generation): with the models, the simulator and a run's log built, one such pass took
    35.5 ms inside a 25 ms period (measured in a randomized study: one cycle of 38 ms CPU
    against a p99 of 1.9 ms). On entry the garbage so far is collected and what survives is
    frozen (``gc.freeze``): later passes walk only what was allocated since. On exit it is
    handed back to the collector (``gc.unfreeze``).
    """
    gc.collect()
    gc.freeze()
    try:
        yield
    finally:
        gc.unfreeze()


@dataclass(frozen=True)
class CycleResult:
    """One period of :class:`Cycle`.

    Attributes:
        command: the resolver's final command (compensated for the base's answer, when one came),
            or None when the robot is held (zero arm rates, zero base reference) or the arm's
            joints were refused.
        arm_velocity: the arm rates to send [rad/s or m/s] (zero when held). Shape (n,). None
            when the arm's joints were refused: nothing is sent to the arm.
        base: the base controller's answer (rates per group, feasible twist; finite); None when
            the base's joints were refused: nothing is sent to the base.
        events: what the period has to log (:class:`~wmm_control.resolvers.targets.LogEvent`).
        stale: '' or the input whose absence held the robot.
        rejected: '' or why joints of the state were refused (the reason the nodes log).
    """

    command: ResolverCommand | None
    arm_velocity: np.ndarray | None
    base: PeriodAnswer | None
    events: list
    stale: str
    rejected: str = ''


class Cycle:
    """A resolver and a base controller (:class:`~wmm_control.base.BaseController`), one period at a time.

    Args:
        resolver: a :class:`~wmm_control.resolvers.Resolver`.
        base_controller: the robot's base controller (:func:`~wmm_control.base.make_base_controller`).
        period: the control period [s].
        settings: the resolver's input checks (:class:`ResolverSettings`; default the
            ``redundancy_resolver`` node's defaults).
        applied_rate_tolerance: [rad/s] between a measured base rate and the last command under
            which the command counts as applied (the base controller nodes' parameter); 0
            never checks.
        reference_timeout: [s] after which the last base reference is stale and the base brakes,
            in a period whose arm joints are refused (the base controller nodes' parameter;
            default its default for the base's family).

    Attributes:
        resolver_period: the resolver's half (:class:`ResolverPeriod`); its inputs
            (``goal``, ``trajectory_point``, ``odometry``, ``ee_pose``, ``set_obstacles``).
        base_period: the base controller's half (:class:`BasePeriod`).
    """

    def __init__(
        self,
        resolver: Resolver,
        base_controller: BaseController,
        period: float,
        settings: ResolverSettings | None = None,
        applied_rate_tolerance: float = 0.0,
        reference_timeout: float | None = None,
    ) -> None:
        self.resolver = resolver
        self.base_controller = base_controller
        # the safety stage brakes a lagging base with the lag of the controller that runs
        resolver.set_base_lag(base_controller.lag)
        self.resolver_period = ResolverPeriod(resolver, period, settings)
        self.base_period = BasePeriod(base_controller, applied_rate_tolerance)
        arm = resolver.model.config.arm
        #: the checks of the arm's measured joints (the resolver node's)
        self.arm_check = JointCheck(arm.joints, arm.velocity, (arm.position_lower, arm.position_upper))
        if reference_timeout is None:
            reference_timeout = node_default(base_controller.family, 'reference_timeout')
        #: the age of the last base reference, for a period whose arm joints are refused
        self.reference = Freshness(reference_timeout)
        self._reference = np.zeros(3)

    def step(
        self,
        q_arm,
        dq_arm,
        base_positions: dict | None,
        base_rates: dict | None,
        now: float,
        resync: bool = False,
    ) -> CycleResult:
        """One period: the arm's measured positions ``q_arm`` and rates ``dq_arm``, the base
        joints' measured positions and rates per command group (None when not measured: the
        base controller goes on from its own state), at ``now`` [s] of the caller's clock; the
        odometry, end-effector pose and target as the inputs last gave them. ``resync``: the
        measurements start, or come back after a gap; the resolver starts again from rest and
        the base controller from the measured joints.

        Joints that fail the nodes' checks (non-finite, a glitch's rates or positions) are
        answered as the nodes answer them, each controller on its own joints (the result's
        ``rejected`` says why): with the arm's refused, no arm command, and the base controller
        answers the last reference while it is fresh (``reference_timeout``; else it brakes);
        with a required base group's refused, no base answer, and the arm command goes
        uncompensated; with both, nothing."""
        q, dq, arm_why = self.arm_check.read(q_arm, dq_arm)
        base_why = ''
        if base_positions is not None:
            base_positions, base_rates, base_why = self.base_period.check(base_positions, base_rates)
        if q is None or dq is None:
            if base_why or base_positions is None:
                return CycleResult(None, None, None, [_refused(arm_why)], '', arm_why)
            command, events, stale = None, [_refused(arm_why)], ''
            reference = self._reference if self.reference.fresh(now) else None
        else:
            plan = self.resolver_period.plan(q, dq, now, resync)
            command, events, stale = plan.command, list(plan.events), plan.stale
            reference = self._reference = np.zeros(3) if command is None else command.base_twist
            self.reference.mark(now)
        answer = None
        if base_why:
            events.append(_refused(base_why))
        else:
            if base_positions is not None:
                self.base_period.start(base_positions, base_rates, resync)
            answer = self.base_period.step(reference, base_positions)
            self.base_period.published(answer)
        if command is not None and self.resolver.uses_compensation:
            self.resolver_period.hold(None, command)
            twist = None
            if answer is not None:
                twist, checked = self.resolver_period.feasible_twist(answer.twist)
                events += checked
            command, _ = self.resolver_period.finish(twist)
        arm = None if q is None else np.zeros(len(q)) if command is None else command.arm_velocity
        return CycleResult(command, arm, answer, events, stale, arm_why or base_why)


def _refused(why: str) -> LogEvent:
    """The event of joints refused (a node logs it as its warning)."""
    return LogEvent('joint_states rejected', f'rejected /joint_states {why}: no cycle')
