"""Following a plan: the hand-off's points given at the pace the robot keeps.

A :class:`~wmm_control.planning.handoff.Handoff` is timed for a base that follows it exactly.
A real one lags: a steerable base re-steers its wheels at a turn before it moves, task sharing
gives part of the motion to the arm, the safety stage slows the robot near an obstacle. Points
given by the wall clock then run ahead of the robot, and the resolver, tracking the point, cuts
the corner the path went round.

:class:`PlanFollower` gives the points by the plan's own clock ``s`` [s], which advances at a
rate ``r ∈ [0, 1]`` of the elapsed time set by how far the robot lags the plan at ``s``. A lag
is taken as a fraction of the lead, ``e = max(‖Δp‖ / lead_distance, |Δθ| / lead_angle)`` (Δp
the position's difference, Δθ the rotation's angle), and gives the pace

    r(e) = clip((1 − e) / (1 − slow_from), 0, 1)

(full pace while the lag is within ``slow_from`` of the lead, stopped at the lead). Two lags
are taken:

* the measured base's behind the planned base pose at ``s``, ``e_b``, against its own lead
  (``base_lead_distance``, ``base_lead_angle``: the arm's posture while following may differ
  from the travel posture the plan assumed, by a method's choice of how to share the motion);
* with the measured end effector (``ee_position``, ``ee_rotation``), its lag behind the point
  in force at ``s``, ``e_e``.

``r* = min(r(e_e), max(r(e_b), f(e_b)))`` with the end effector, ``r* = r(e_b)`` without,
``f(e_b) = base_floor · clip((L − e_b) / (L − 1), 0, 1)`` with ``L = base_floor_lag``.
So the point waits for the end effector, which every method servoes to it, and slows for the
base down to ``base_floor`` of the pace, not to a stop, while the base lags less than a lead:
a method that moves the end effector
partly with the arm (task sharing, or any whole-body one whose share of the base lags, as a
steerable base's does while it re-steers) does not bring its base back onto the plan once the
end effector is on its point, given the point alone, and a point that waited for it would wait
for ever (with ``hold_base`` it is pulled back, but only in what the end effector's task leaves
free). Past a lead the floor fades, and at ``base_floor_lag`` leads the clock waits for the base
whatever the end effector does: the arm cannot carry the point on without limit. A steerable
base that stops to re-steer its wheels at a turn (robot A) fell 0.45 m behind while its clock crept
on and the arm reached after the points until its elbow was straight and its first joint on its
limit, a posture the arm's task never left again (task sharing, the planner's example in the
README, direct engine: 65 s to the goal with one plan made again, 32 s with the fade). The fade
is slow because the acceleration-level methods move the base as the end effector's point draws
it on (AMP keeps the base still until the arm runs out of reach): with the clock stopped at two
leads, robot A's `traditional` stalled three times where its base had fallen behind at a turn
(`table_pillar` goal 18), and converged with the fade to three. (Stopping
the clock, and so stalling and planning again, once the base lags two leads behind converged
fewer runs: `panda_diff`'s base, which cannot move sideways, lags that far on most paths.) ``r`` rises
towards ``r*`` by at most ``rate_slew`` per second (the point does not start at once) and falls
to it at once: a period's step of the clock moves the point by at most ``(1 − e)`` of the room
left to the lead when the plan's speed over a period is within ``(1 − slow_from)`` of the lead
(1 m/s and 1 rad/s at 40 Hz with the defaults), so the robot is never more than the lead
behind the point it is given, save what its own last period's motion adds. The point's twist is
the planned one times ``r``, its acceleration times ``r²`` (the planned motion slowed down).

The point carries the planned base pose of its sample (``hold_base``,
:class:`~wmm_control.resolvers.interface.BaseReference`; its rates times ``r``, accelerations
times ``r²``): every method pulls the base towards it below the end effector's task, so the
base is held to the plan rather than left where the method's sharing of the motion puts it
(``docs/methods.md``, the planner's section).

A base that is ahead of the plan (it cut a corner, or the planned pose at ``s`` is behind it)
pulls the clock forward: the follower keeps the last planned pose the measured base has passed
(the nearest planned pose, in the lag's metric, from the last one passed up to ``lookahead``
[s] ahead of ``s``), and ``s`` never lags it.

A hand-off made with the stance's arm posture ends with the arm's motion to it, the base at
rest at the stance (:meth:`~wmm_control.planning.handoff.Handoff.of`): its points are given
like the others, once the measured base is at rest at the stance (within ``settle_distance``
and ``settle_angle`` of it, moving slower than that per second): until then the clock is held
at the motion's first point, which holds the base to the stance, for at most ``settle_time``;
a base not at rest there by then goes to the final approach without the arm's motion. A base
that accelerates slowly (robot B's, 0.025 m/s²) may reach the path's end short of the stance and
still moving, and swing about it: the arm's motion begun then leaves the end effector behind its
points, the follower stalls and the plan made again from there goes astray. Once ``s`` reaches
the plan's end the target is the goal itself
(:attr:`FollowState.APPROACH`): the method's final whole-body approach, with the plan's last
base pose (the stance, from which the goal is reachable with margin from the obstacles) held as
the base's reference and the stance's arm posture as the arm's (:attr:`PlanFollower.approach`;
with ``hold_base``): a method whose secondary task would move the base (task sharing's posture
pull) otherwise drives it from the stance into the safety stage's hold. While following, the
follower is :attr:`FollowState.STALLED` when for ``stall_time`` the robot has made no progress
on the plan: the last planned pose the base has passed has not moved on by ``stall_distance``
or turned by ``stall_angle``, the measured base has not come that much nearer to the planned
pose at ``s`` (in distance or in heading), the planned pose at ``s`` has not moved on that much
with the base within its lead of it (``e_b < 1``), and, in the arm's motion after the path, the
planned arm posture has not moved by ``stall_angle`` on a joint: the robot is held off the plan
(by an obstacle the plan did not know, by the safety stage; moving along the obstacle is no
progress), and the caller plans again from where it is. It is following again as soon as one
of them moves on. The clock creeping on at ``base_floor`` away from a base that stays a lead
behind is no progress: counted as such, `panda_diff`'s base held by the safety stage at the
pillar of `table_pillar` while its arm reached out after the points was never stalled, and
crept for up to 69 s before its arm ran out of reach (12 of 100 `pinv` runs neither reached the
goal nor were reported stalled in 90 s). Waiting for the base at rest at the stance is not a
stall.

Pure and ROS-free: time is what :meth:`PlanFollower.step` is told.
"""

from __future__ import annotations

import enum
import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError
from wmm_control.geometry import norm, rotation_angle, wrap_angle
from wmm_control.planning.handoff import Handoff
from wmm_control.planning.timing import LinearPiece
from wmm_control.resolvers.interface import BaseReference, PoseTarget

__all__ = ['FollowParams', 'FollowState', 'FollowStep', 'PlanFollower', 'MAX_REPLANS']

#: The default of how many times one goal is planned again after the robot stalled on its plan
#: (the direct engine, ``wmm_randomized --plan`` and the ``goal_planner`` node's ``max_replans``).
MAX_REPLANS = 3


@dataclass(frozen=True)
class FollowParams:
    """Settings of :class:`PlanFollower` (module docstring).

    Attributes:
        lead_distance: [m] the end effector's lag behind its point at which the plan's clock stops.
        lead_angle: [rad] the same for its orientation.
        base_lead_distance: [m] the base's lag behind its planned pose at which the base's pace
            is least (module docstring).
        base_lead_angle: [rad] the same for its heading.
        slow_from: the fraction of the lead, in [0, 1), up to which the clock keeps full pace.
        base_floor: the pace, in [0, 1], the base's lag leaves the clock when the end effector
            is measured.
        base_floor_lag: the base's lag, in leads (> 1), at which ``base_floor`` has faded to
            nothing (whole up to one lead, linear in between): beyond it the clock waits for the
            base whatever the end effector does.
        rate_slew: [1/s] the most the clock's rate rises per second.
        lookahead: [s] of the plan, ahead of its clock, searched for the pose the base has passed.
        stall_time: [s] without progress (module docstring) before the follower is stalled.
        stall_distance: [m] of motion that is progress.
        stall_angle: [rad] of turn that is progress.
        settle_distance: [m] from the stance within which, moving slower than this per second,
            the base is at rest there: the arm's motion to the stance's posture starts then
            (module docstring).
        settle_angle: [rad] the same for its heading (and [rad/s] its turn rate).
        settle_time: [s] the arm's motion waits at most for the base to be at rest; then the
            final approach follows without it.
        hold_base: give the point's planned base with it (module docstring): the methods
            hold the base to the plan; False gives the end effector's point alone.

    Raises:
        ConfigError: a value out of its range.
    """

    lead_distance: float = 0.15
    lead_angle: float = 0.35
    base_lead_distance: float = 0.3
    base_lead_angle: float = 0.6
    slow_from: float = 0.5
    base_floor: float = 0.25
    base_floor_lag: float = 3.0
    rate_slew: float = 2.0
    lookahead: float = 2.0
    stall_time: float = 5.0
    stall_distance: float = 0.02
    stall_angle: float = 0.05
    settle_distance: float = 0.03
    settle_angle: float = 0.05
    settle_time: float = 5.0
    hold_base: bool = True

    def __post_init__(self) -> None:
        positive = (
            'lead_distance',
            'lead_angle',
            'base_lead_distance',
            'base_lead_angle',
            'rate_slew',
            'stall_time',
            'stall_distance',
            'stall_angle',
            'settle_distance',
            'settle_angle',
        )
        for name in positive:
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0.0):
                raise ConfigError(f'FollowParams.{name} must be a finite number > 0, got {value!r}')
        for name in ('lookahead', 'settle_time'):
            value = getattr(self, name)
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value >= 0.0):
                raise ConfigError(f'FollowParams.{name} must be a finite number >= 0 [s], got {value!r}')
        if not (isinstance(self.slow_from, (int, float)) and 0.0 <= self.slow_from < 1.0):
            raise ConfigError(f'FollowParams.slow_from must be in [0, 1), got {self.slow_from!r}')
        if not isinstance(self.hold_base, bool):
            raise ConfigError(f'FollowParams.hold_base must be True or False, got {self.hold_base!r}')
        if not (isinstance(self.base_floor, (int, float)) and 0.0 <= self.base_floor <= 1.0):
            raise ConfigError(f'FollowParams.base_floor must be in [0, 1], got {self.base_floor!r}')
        lag = self.base_floor_lag
        if isinstance(lag, bool) or not (isinstance(lag, (int, float)) and math.isfinite(lag) and lag > 1.0):
            raise ConfigError(f'FollowParams.base_floor_lag must be a finite number > 1 [leads], got {lag!r}')


class FollowState(enum.Enum):
    """Where the follower is."""

    #: giving the plan's points
    FOLLOWING = 'following'
    #: the plan is done: the target is the goal
    APPROACH = 'approach'
    #: following, but neither the plan's clock nor the base has made progress for the stall time
    STALLED = 'stalled'


@dataclass(frozen=True)
class FollowStep:
    """What the follower gives for one period.

    Attributes:
        target: what to give the resolver: a point of the plan (a trajectory point), or the goal
            once the plan is done.
        state: :class:`FollowState`.
        progress: the fraction of the plan's time done, in [0, 1].
    """

    target: PoseTarget
    state: FollowState
    progress: float


class PlanFollower:
    """Gives a hand-off's points at the pace of the measured base, then the goal (module
    docstring).

    Args:
        handoff: the plan's points and planned base poses.
        goal: the end-effector goal, given once the plan is done.
        params: :class:`FollowParams`.
    """

    def __init__(self, handoff: Handoff, goal: PoseTarget, params: FollowParams = FollowParams()) -> None:
        if len(handoff.base_poses) != len(handoff.points) or not handoff.points:
            raise ConfigError('a hand-off needs one planned base pose per point, and at least one point')
        self.handoff = handoff
        self.goal = goal
        self.params = params
        self._clock = 0.0  # s [s]
        self._rate = 0.0  # the clock's rate, starting from rest as the robot does
        self._passed = 0  # the last planned sample the base has passed
        self._idle = 0.0  # [s] without progress
        self._anchor_plan: np.ndarray | None = None  # the planned pose at the last progress
        self._anchor_passed: np.ndarray | None = None  # the planned pose the base had passed then
        self._anchor_point = 0  # the sample of the point given then
        self._anchor_lag = (math.inf, math.inf)  # the base's lag (distance, angle) then
        self._previous: np.ndarray | None = None  # the base measured the period before
        self._settling = 0.0  # [s] the arm's motion has waited for the base to be at rest
        self._arm_begun = False  # the base was at rest at the stance: the arm's motion goes on

    @property
    def approach(self) -> PoseTarget:
        """The target of the final approach: the goal, with the plan's last base pose (the
        stance, at rest) as its base and the stance's arm posture (``handoff.stance_arm``) when
        ``hold_base`` (module docstring)."""
        last = self.handoff.points[-1].base
        if not self.params.hold_base or last is None:
            return self.goal
        return PoseTarget.goal(self.goal.position, self.goal.rotation, last.pose, self.handoff.stance_arm)

    @property
    def clock(self) -> float:
        """[s] the plan's time reached."""
        return self._clock

    @property
    def rate(self) -> float:
        """The plan's clock's current rate, in [0, 1]."""
        return self._rate

    def planned_pose(self, s: float | None = None) -> np.ndarray:
        """The planned base pose (x, y, θ) at the plan's time ``s`` [s] (default: its clock),
        interpolated between samples (the heading the short way). Shape (3,)."""
        poses, dt = self.handoff.base_poses, self.handoff.dt
        if len(poses) == 1:
            return poses[0].copy()
        u = min(max((self._clock if s is None else s) / dt, 0.0), len(poses) - 1.0)
        k = min(int(math.floor(u)), len(poses) - 2)
        return LinearPiece(poses[k], poses[k + 1]).pose(u - k)

    def _lag(self, planned: np.ndarray, base: np.ndarray) -> np.ndarray:
        """The lag of ``base`` behind the ``planned`` pose(s) as a fraction of the lead."""
        p = self.params
        planned = np.atleast_2d(planned)
        distance = np.hypot(planned[:, 0] - base[0], planned[:, 1] - base[1])
        angle = np.abs(wrap_angle(planned[:, 2] - base[2]))
        return np.maximum(distance / p.base_lead_distance, angle / p.base_lead_angle)

    @staticmethod
    def _apart(a: np.ndarray, b: np.ndarray) -> tuple[float, float]:
        """(distance [m], heading difference [rad]) of two poses."""
        return math.hypot(a[0] - b[0], a[1] - b[1]), abs(wrap_angle(float(a[2] - b[2])))

    def _moved(self, a: np.ndarray, b: np.ndarray) -> bool:
        """Whether two poses are a step of progress apart."""
        distance, angle = self._apart(a, b)
        return distance >= self.params.stall_distance or angle >= self.params.stall_angle

    def _posture_moved(self, k: int, anchor: int) -> bool:
        """Whether the planned arm postures of samples ``k`` and ``anchor`` are a step of progress
        apart (a joint by ``stall_angle``: the arm's motion to the stance's posture, the base at
        rest, may move the end effector little)."""
        a, b = self.handoff.points[k].base, self.handoff.points[anchor].base
        if a is None or b is None or a.arm is None or b.arm is None:
            return False
        return float(np.max(np.abs(a.arm - b.arm))) >= self.params.stall_angle

    def _settled(self, base: np.ndarray, dt: float) -> bool:
        """Whether the measured ``base`` is at rest at the stance (the path's end): within
        ``settle_distance`` and ``settle_angle`` of it, and moved less than that per second since
        the period before."""
        p = self.params
        distance, angle = self._apart(self.handoff.base_poses[self.handoff.path_end], base)
        if distance > p.settle_distance or angle > p.settle_angle or self._previous is None:
            return False
        moved, turned = self._apart(base, self._previous)
        return moved <= p.settle_distance * dt and turned <= p.settle_angle * dt

    def _index(self, s: float) -> int:
        """The sample in force at the plan's time ``s``."""
        return min(int(math.floor(s / self.handoff.dt + 1e-9)), len(self.handoff.points) - 1)

    def _ee_lag(self, k: int, ee: PoseTarget) -> float:
        """The end effector's lag behind the point of sample ``k`` as a fraction of the lead."""
        point, p = self.handoff.points[k], self.params
        return max(
            norm(point.position - ee.position) / p.lead_distance,
            rotation_angle(point.rotation, ee.rotation) / p.lead_angle,
        )

    def _pace(self, lag: float, floor: float = 0.0) -> float:
        return min(max((1.0 - lag) / (1.0 - self.params.slow_from), floor), 1.0)

    def _floor(self, base_lag: float) -> float:
        """``base_floor``, faded out between one lead and ``base_floor_lag`` leads of ``base_lag``."""
        p = self.params
        fade = (p.base_floor_lag - base_lag) / (p.base_floor_lag - 1.0)
        return p.base_floor * min(max(fade, 0.0), 1.0)

    def step(
        self,
        dt: float,
        base_pose: ArrayLike,
        ee_position: ArrayLike | None = None,
        ee_rotation: ArrayLike | None = None,
    ) -> FollowStep:
        """Advance the plan's clock by the period ``dt`` [s] at the pace the robot keeps (its
        measured base pose ``base_pose`` (x, y, θ) and, if given, end-effector pose
        ``ee_position`` [m], ``ee_rotation`` (3, 3) in the world), and give what the resolver
        tracks this period.

        Raises:
            ValueError: ``dt`` not a finite number ≥ 0, ``base_pose`` not three finite numbers,
                an end-effector pose malformed or given by half.
        """
        if not (math.isfinite(dt) and dt >= 0.0):
            raise ValueError(f'dt must be a finite number >= 0 [s], got {dt!r}')
        base = as_finite_vector(base_pose, 3, 'base pose')
        ee = None
        if ee_position is not None and ee_rotation is not None:  # PoseTarget checks them
            ee = PoseTarget(np.asarray(ee_position, dtype=float), np.asarray(ee_rotation, dtype=float))
        elif ee_position is not None or ee_rotation is not None:
            raise ValueError('the end effector is measured by its position and its rotation together')
        p, handoff = self.params, self.handoff
        end = handoff.duration
        if self._clock >= end:
            return FollowStep(self.approach, FollowState.APPROACH, 1.0)
        # the base ahead of the plan pulls the clock forward
        given = self._index(self._clock)  # the point given last period
        window = handoff.base_poses[self._passed : self._index(self._clock + p.lookahead) + 1]
        if len(window):
            self._passed += int(np.argmin(self._lag(window, base)))
        self._clock = max(self._clock, self._passed * handoff.dt)
        # the clock's pace from the lags behind the plan at it
        base_lag = float(self._lag(self.planned_pose(self._clock), base)[0])
        wanted = self._pace(base_lag)
        if ee is not None:
            wanted = min(self._pace(self._ee_lag(self._index(self._clock), ee)), max(wanted, self._floor(base_lag)))
        self._rate = min(wanted, self._rate + p.rate_slew * dt)
        before = self.planned_pose(self._clock)
        clock = min(self._clock + self._rate * dt, end)
        if ee is not None:  # no new point beyond the lead from the end effector (the samples' step)
            k = self._index(clock)
            while k > given and self._ee_lag(k, ee) > 1.0:
                k -= 1
            if clock > (k + 1.0 - 1e-6) * handoff.dt:  # held at sample k: the rate it moved at
                clock = max(self._clock, (k + 1.0 - 1e-6) * handoff.dt)
                self._rate = (clock - self._clock) / dt if dt > 0.0 else 0.0
        # the arm's motion to the stance's posture waits for the base at rest there (or settle_time)
        settling = not self._arm_begun and handoff.path_end < len(handoff.points) - 1
        settling = settling and self._index(clock) >= handoff.path_end  # held there by any rule
        if settling and self._settled(base, dt):
            self._arm_begun, settling = True, False
        elif settling and self._settling < p.settle_time:
            clock = min(clock, handoff.path_end * handoff.dt)
            self._rate = 0.0
            self._settling += dt
        elif settling:  # never at rest there: the final approach without the arm's motion
            clock, settling = end, False
        self._previous = base
        self._clock = clock
        if self._clock >= end:
            return FollowStep(self.approach, FollowState.APPROACH, 1.0)
        # progress since the last: the base passed planned poses further on or came nearer to the
        # planned pose, or the planned pose moved on with the base within its lead of it (the clock
        # creeping at base_floor away from a base that stays behind is none), or the arm's motion
        planned = self.planned_pose(self._clock)
        passed = handoff.base_poses[self._passed]
        k = self._index(self._clock)
        lag = self._apart(planned, base)
        if self._anchor_plan is None or self._anchor_passed is None:
            self._anchor_plan, self._anchor_point, self._anchor_passed = before, given, passed
        closer = lag[0] <= self._anchor_lag[0] - p.stall_distance or lag[1] <= self._anchor_lag[1] - p.stall_angle
        along = self._moved(passed, self._anchor_passed)
        kept = self._moved(planned, self._anchor_plan) and float(self._lag(planned, base)[0]) < 1.0
        arm = k > self.handoff.path_end and self._posture_moved(k, self._anchor_point)  # the arm's motion
        if kept or along or arm or closer or settling:
            self._anchor_plan, self._anchor_point, self._anchor_lag, self._idle = planned, k, lag, 0.0
            self._anchor_passed = passed
        else:
            self._idle += dt
        point = handoff.points[k]
        planned_base = None
        if p.hold_base and point.base is not None:  # the planned base, slowed as the point is
            planned_base = BaseReference(
                point.base.pose, self._rate * point.base.rates, self._rate**2 * point.base.acceleration, point.base.arm
            )
        target = PoseTarget(
            point.position,
            point.rotation,
            velocity=self._rate * point.velocity,
            acceleration=self._rate**2 * point.acceleration,
            base=planned_base,
        )
        state = FollowState.STALLED if self._idle >= p.stall_time else FollowState.FOLLOWING
        return FollowStep(target, state, self._clock / end)

    def remaining_poses(self) -> np.ndarray:
        """The planned base poses (x, y, θ) the base has not passed yet, from the one at the
        plan's clock to the path's end (empty once the plan is done). Shape (N, 3)."""
        if self._clock >= self.handoff.duration:
            return np.zeros((0, 3))
        return self.handoff.base_poses[self._index(self._clock) :].copy()
