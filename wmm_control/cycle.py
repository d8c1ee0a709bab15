"""The whole-body control cycle of one period, in the order of Sorour et al. 2019 Fig 4 (ROS-free).

1. :meth:`Cycle.plan`: the resolver turns the measured state and the target into the arm
   command and the base twist reference ξ̇* (:class:`~wmm_control.resolvers.ResolverCommand`);
2. :meth:`Cycle.base`: the base controller answers ξ̇* with joint rate commands per command
   group and the feasible twist q̇_bf (:class:`~wmm_control.base.BaseCommand`);
3. :meth:`Cycle.finish`: the resolver compensates the arm command for the base's answer
   (eq 14, :meth:`~wmm_control.resolvers.Resolver.compensate`), or leaves it as it is when
   no feasible twist came.

:meth:`Cycle.step` chains the three. The direct engine
(:class:`sim_bridge.closed_loop.ClosedLoop`) runs it on a simulated world; the ROS nodes run
the same phases over topics, each phase in the node that owns it.
"""

from dataclasses import dataclass

from wmm_control.base.contract import BaseCommand, BaseController
from wmm_control.resolvers.interface import Resolver, ResolverCommand

__all__ = ['Cycle', 'CycleResult']


@dataclass(frozen=True)
class CycleResult:
    """One period of :class:`Cycle`.

    Attributes:
        command: the resolver's final command (compensated for the base's answer).
        base: the base controller's answer (rates per group, feasible twist).
    """

    command: ResolverCommand
    base: BaseCommand


class Cycle:
    """A resolver and a base controller (:class:`~wmm_control.base.BaseController`), one period at a time.

    Args:
        resolver: a :class:`~wmm_control.resolvers.Resolver`.
        base_controller: the robot's base controller (:func:`~wmm_control.base.make_base_controller`).
    """

    def __init__(self, resolver: Resolver, base_controller: BaseController):
        self.resolver = resolver
        self.base_controller = base_controller
        # the safety stage brakes a lagging base with the lag of the controller that runs
        resolver.set_base_lag(base_controller.lag)

    def plan(self, state, target) -> ResolverCommand:
        """Phase 1: the resolver's command (arm velocity and base twist reference) for ``state``
        (:class:`~wmm_control.resolvers.RobotState`) and ``target``
        (:class:`~wmm_control.resolvers.PoseTarget`)."""
        return self.resolver.step(state, target)

    def base(self, reference, positions=None) -> BaseCommand:
        """Phase 2: the base controller's answer to ``reference`` (None: brake), closed on the
        measured joint ``positions`` per command group when given."""
        return self.base_controller.step(reference, positions)

    def finish(self, command: ResolverCommand, feasible_twist=None) -> ResolverCommand:
        """Phase 3: ``command`` compensated for the feasible twist q̇_bf (Sorour eq 14); unchanged
        when ``feasible_twist`` is None (the base's answer did not come)."""
        if feasible_twist is None:
            return command
        return self.resolver.compensate(command, feasible_twist)

    def step(self, state, target, positions=None) -> CycleResult:
        """The three phases of one period: plan → base → finish."""
        planned = self.plan(state, target)
        answer = self.base(planned.base_twist, positions)
        return CycleResult(self.finish(planned, answer.feasible_twist), answer)
