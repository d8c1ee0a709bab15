"""The resolver's half of one control period, ROS-free: what ``redundancy_resolver`` runs on
each joint state and the direct engine (:class:`~wmm_control.cycle.Cycle`) runs each period,
so that both engines take and refuse the same inputs and answer with the same commands.

Its inputs, each checked as it comes (:class:`~wmm_control.resolvers.targets.TargetManager`,
:class:`~wmm_control.resolvers.inputs.MeasuredInputs`) and answered with the
:class:`~wmm_control.resolvers.targets.LogEvent` s that tell what was taken or refused:
goals, trajectory points, the base's odometry, the end effector's measured pose, obstacles
and the base controller's lag. Then, per period (Sorour Fig 4):

1. :meth:`ResolverPeriod.plan`: with fresh inputs and a target, the resolver's command for the
   joint state (arm rates, base twist reference); else no command, and the robot is held
   (zero commands; the reason is counted in ``stale_cycles`` when an input is missing or stale);
2. the base controller answers the reference (:class:`~wmm_control.base.period.BasePeriod`);
3. :meth:`ResolverPeriod.finish`: the arm command, held meanwhile (:meth:`ResolverPeriod.hold`),
   compensated for the base's checked answer (Sorour eq 14), or as it is when no valid answer
   came (counted in ``compensation_dropped``).

Each cycle's safety-stage answers (the plan's, and the compensated arm command's) are counted
per limit in :attr:`ResolverPeriod.safety_counts` (:class:`~wmm_control.resolvers.safety.SafetyCounts`):
which limits shaped the commands since start.

Time is an argument (seconds of the caller's clock), never read here.
"""

from collections.abc import Iterable
from dataclasses import dataclass, field
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import PLAUSIBLE_FACTOR
from wmm_control.kinematics.workspace import Workspace
from wmm_control.paths import load_defaults
from wmm_control.resolvers.exchange import CompensationExchange
from wmm_control.resolvers.inputs import LatestInputs, MeasuredInputs
from wmm_control.resolvers.interface import Resolver, ResolverCommand
from wmm_control.resolvers.safety import SafetyCounts, SafetyResult
from wmm_control.resolvers.targets import LogEvent, TargetManager

__all__ = ['Plan', 'ResolverPeriod', 'ResolverSettings']


@dataclass(frozen=True)
class ResolverSettings:
    """How the resolver's period checks its inputs: the ``redundancy_resolver`` parameters of the
    same names (``config/redundancy_resolver.yaml``; :meth:`defaults`).

    Attributes:
        world_frame: the frame of goals, trajectory points and the end-effector pose.
        state_timeout: [s] inputs older than this (at receipt) hold the robot.
        max_goal_distance: [m] goals farther from the world origin are refused.
        goal_tolerance: (position [m], orientation [rad]) under which a goal is reached.
        stall_time: [s] without progress, an unreached goal is reported stalled.
        min_progress_ratio: the progress that counts within ``stall_time``.
        ground_truth: the end effector's measured pose is used (and must be fresh); else
            forward kinematics from the odometry and the joints.
    """

    world_frame: str
    state_timeout: float
    max_goal_distance: float
    goal_tolerance: tuple
    stall_time: float
    min_progress_ratio: float
    ground_truth: bool = False

    @classmethod
    def defaults(cls, **overrides: Any) -> 'ResolverSettings':
        """The node's defaults (``config/redundancy_resolver.yaml``), with ``overrides``."""
        yaml = load_defaults('redundancy_resolver.yaml', 'redundancy_resolver')
        values = {
            name: yaml[name]
            for name in (
                'world_frame',
                'state_timeout',
                'max_goal_distance',
                'goal_tolerance',
                'stall_time',
                'min_progress_ratio',
            )
        }
        values['ground_truth'] = yaml['ee_feedback'] == 'ground_truth'
        values.update(overrides)
        values['goal_tolerance'] = tuple(float(v) for v in values['goal_tolerance'])
        return cls(**values)


@dataclass(frozen=True)
class Plan:
    """What :meth:`ResolverPeriod.plan` answers.

    Attributes:
        command: the resolver's command, or None: hold the robot (zero arm rates and base
            reference).
        events: what to log.
        stale: '' or the input that is missing or stale (then ``command`` is None).
    """

    command: ResolverCommand | None
    events: list = field(default_factory=list)
    stale: str = ''


class ResolverPeriod:
    """The resolver's side of each period (module docstring).

    Args:
        resolver: the :class:`~wmm_control.resolvers.Resolver`.
        period: the control period [s].
        settings: :class:`ResolverSettings` (default: the node's defaults).

    Attributes:
        targets: the :class:`~wmm_control.resolvers.targets.TargetManager`.
        inputs: the :class:`~wmm_control.resolvers.inputs.MeasuredInputs` checks.
        latest: the :class:`~wmm_control.resolvers.inputs.LatestInputs`.
        exchange: the :class:`~wmm_control.resolvers.exchange.CompensationExchange`.
        cycles, stale_cycles: periods planned, and periods held for a missing or stale input.
        safety_counts: the cycles in which each limit of the safety stage shaped the command.
    """

    def __init__(self, resolver: Resolver, period: float, settings: ResolverSettings | None = None) -> None:
        s = settings if settings is not None else ResolverSettings.defaults()
        self.resolver = resolver
        self.settings = s
        #: the robot's :class:`~wmm_control.kinematics.workspace.Workspace` (on the resolver's
        #: model): goals no motion reaches are refused
        self.workspace = workspace = Workspace(resolver.model)
        self.targets = TargetManager(
            workspace,
            s.world_frame,
            s.max_goal_distance,
            s.state_timeout,
            s.goal_tolerance,
            s.stall_time,
            period,
            s.min_progress_ratio,
            position_only=getattr(getattr(resolver, 'params', None), 'rows', 'full') == 'position',
        )
        self.inputs = MeasuredInputs(
            s.world_frame, s.max_goal_distance, resolver.model.config.base.velocity, PLAUSIBLE_FACTOR
        )
        self.latest = LatestInputs(self.inputs, s.state_timeout, s.ground_truth)
        self.exchange = CompensationExchange(resolver)
        self.cycles = self.stale_cycles = 0
        self.safety_counts = SafetyCounts()
        self._planned: SafetyResult | None = None  # the safety stage's answer of the cycle's plan

    # ------------------------------------------------------------------ inputs
    def goal(self, frame: str, pose: ArrayLike, now: float, planned_base=None) -> list[LogEvent]:
        """A goal ``pose`` (x, y, z, qx, qy, qz, qw) in ``frame``, received at ``now`` [s], with
        where a followed plan left the base, or None (:meth:`TargetManager.goal`)."""
        return self.targets.goal(frame, pose, self.latest.base_pose(now), planned_base)

    def trajectory_point(
        self, frame: str, pose, velocity, acceleration, now: float, planned_base=None
    ) -> list[LogEvent]:
        """A trajectory point received at ``now`` [s], with a followed plan's base or None
        (:meth:`TargetManager.trajectory_point`)."""
        return self.targets.trajectory_point(
            frame, pose, velocity, acceleration, now, self.latest.base_pose(now), planned_base
        )

    def odometry(self, xy, quat, twist, now: float) -> list[LogEvent]:
        """The base's odometry received at ``now`` [s] (:meth:`LatestInputs.odometry`)."""
        return self.latest.odometry(xy, quat, twist, now)

    def ee_pose(self, frame: str, pose, now: float) -> list[LogEvent]:
        """The end effector's measured pose received at ``now`` [s] (:meth:`LatestInputs.ee_pose`)."""
        return self.latest.ee_pose(frame, pose, now)

    def set_obstacles(self, obstacles: Iterable) -> None:
        """Keep the robot off ``obstacles`` (world frame), and refuse goals inside them."""
        obstacles = tuple(obstacles)
        self.resolver.set_obstacles(obstacles)
        self.targets.obstacles = obstacles

    # ------------------------------------------------------------------ the period
    def plan(self, q: np.ndarray, dq: np.ndarray, now: float, resync: bool = False) -> Plan:
        """Phase 1 for the arm's measured positions ``q`` and rates ``dq`` at ``now`` [s]:
        the command for the target, or no command (hold the robot) without a target or
        without fresh inputs. ``resync``: the measurements come back after a gap; the resolver
        starts again from rest."""
        state, reason = self.latest.state(q, dq, now)
        if state is None or self.targets.target is None:
            if state is None:
                self.stale_cycles += 1
            self.resolver.reset()
            return Plan(None, [], reason)
        if resync:
            self.resolver.reset()
        self.cycles += 1
        target, events = self.targets.current(now)
        if target is None:  # not after the check above; for the type checker
            return Plan(None, events, '')
        command = self.resolver.step(state, target)
        self._planned = self.resolver.safety.last
        self.safety_counts.add(self._planned)
        # judged against the target the command was computed for (a new goal may come in
        # before the arm command goes out)
        events += self.targets.judge(command.diagnostics)
        return Plan(command, events)

    def feasible_twist(self, twist: ArrayLike) -> tuple[np.ndarray | None, list[LogEvent]]:
        """The base controller's answer (vx, vy, ω), checked: (twist or None, events)."""
        return self.inputs.feasible_twist(twist)

    def hold(self, key: Any, command: ResolverCommand, stamp: Any = None) -> None:
        """Hold the arm ``command`` of the cycle ``key`` (its joint state's stamp) for the base's
        answer to its reference."""
        self.exchange.hold(key, command, stamp)

    def awaits(self, key: Any) -> bool:
        """Whether the base's answer to the reference of cycle ``key`` is the one awaited."""
        return self.exchange.awaits(key)

    @property
    def pending(self) -> bool:
        """An arm command waits for the base's answer."""
        return self.exchange.pending

    def finish(self, feasible_twist: ArrayLike | None) -> tuple[ResolverCommand, Any]:
        """Phase 3: (the held arm command, its stamp), compensated for the base's answer
        ``feasible_twist`` (checked with :meth:`feasible_twist` first) when it is given, else
        as it is (counted in ``compensation_dropped``)."""
        out = self.exchange.finish(feasible_twist)
        answer = self.resolver.safety.last
        if answer is not self._planned:  # the compensated arm command went through the stage again
            self.safety_counts.add(answer, same_cycle=True)
            self._planned = answer
        return out

    @property
    def counters(self) -> dict:
        """The counts the node reports on ``/diagnostics``."""
        return {
            'cycles': self.cycles,
            'goals': self.targets.goals,
            'goals_rejected': self.targets.rejected,
            'compensation_dropped': self.exchange.dropped,
            'stale_cycles': self.stale_cycles,
            **self.safety_counts.values(),
        }
