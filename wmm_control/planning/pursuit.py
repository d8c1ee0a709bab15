"""A goal pursued past what is in the way: the ``goal_planner`` node's logic, ROS-free.

:class:`GoalPursuit` stands between the user's goals and the resolver. Each goal is checked as
the resolver checks it (:func:`~wmm_control.resolvers.targets.check_goal`: frame, NaN/inf,
``max_goal_distance``, the floor and the highest reach, a zero quaternion); a refused one is
logged, and the robot is held where it is. An accepted one is planned
(:class:`~wmm_control.planning.GoalPlanner`) from the base's pose, in a thread of its own
(:class:`PlanWorker`): the caller's period never waits for a plan. The plan decides:

* **direct**: the best stance is where the base stands (the arm reaches the goal from here,
  clear of the obstacles): the goal goes to the resolver unchanged, as without the planner; a
  plan made *again* that finds this (the follower stalled at or near its stance) gives the final
  approach instead (below), from this stance, with ``hold_base``;
* **following**: a base path to a stance elsewhere: its hand-off points
  (:class:`~wmm_control.planning.handoff.Handoff`, the arm's motion to the stance's posture at
  their end) are given one per period at the pace the robot keeps
  (:class:`~wmm_control.planning.follow.PlanFollower`), then the goal itself for the
  resolver's final whole-body approach (**approach**): with ``hold_base`` as the last point
  (:attr:`PursuitStep.reference`), at rest, with the plan's last base pose (the stance) and the
  stance's arm posture as its base (:attr:`PlanFollower.approach <wmm_control.planning.follow.PlanFollower.approach>`),
  which the resolver holds once no point follows it and judges as a goal
  (:meth:`TargetManager.current <wmm_control.resolvers.targets.TargetManager.current>`), so
  that the base is held at the stance as in the direct engine; without ``hold_base`` the goal
  alone (:attr:`PursuitStep.forward_goal`);
* **no way**: the planner's reason (the goal inside an obstacle, out of reach, no stance, no
  path within the budget); nothing is forwarded and the robot is held.

The follower paces the points by the measured base and end effector (forward kinematics of
the base pose and arm joints). While following, the plan is made again from where the base is
when the follower reports a stall, or when the obstacles change and the rest of the planned
path (:meth:`PlanFollower.remaining_poses`) comes nearer an obstacle than the travel margin
(checked by the worker, on the new obstacles); the arm then travels in the posture it has (the
planner's own when that finds no way). Until the new plan comes the robot is held. After
``max_replans`` such plans for a goal the goal goes to the resolver from where the robot is (the
method's own approach), as ``wmm_randomized --plan`` does.

**Holding** the robot is giving the resolver the end effector's current pose as its goal (what
the viewer's "Hold here" does), from the measured base pose and arm joints; it is due whenever
the resolver may be pursuing something this object gave it (a point, a goal) and the pursuit
stops or changes course. It waits until both are known.

Time is what :meth:`GoalPursuit.step` is told.
"""

from __future__ import annotations

import math
import queue
import threading
from collections.abc import Iterable, Mapping
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.geometry import matrix_from_quaternion, quaternion_from_matrix
from wmm_control.kinematics.model import KinematicModel
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.kinematics.workspace import Workspace
from wmm_control.planning.follow import MAX_REPLANS, FollowParams, FollowState, PlanFollower
from wmm_control.planning.handoff import Handoff
from wmm_control.planning.outcome import NoWay
from wmm_control.planning.planner import GoalPlanner, Plan
from wmm_control.resolvers.interface import PoseTarget
from wmm_control.resolvers.targets import LogEvent, LogThrottle, check_goal, goal_key, goal_text
from wmm_control.robot_config import RobotConfig

__all__ = ['GoalPursuit', 'PlanWorker', 'PursuitLog', 'PursuitState', 'PursuitStep', 'path_blocked', 'run_limit']


class PursuitState(str, Enum):
    """Where the pursuit of the goal is."""

    #: no goal yet
    IDLE = 'idle'
    #: a plan is being made (the robot held)
    PLANNING = 'planning'
    #: the plan's points go to the resolver
    FOLLOWING = 'following'
    #: the plan is done: the resolver has the goal for the final approach
    APPROACH = 'approach'
    #: within reach with nothing in the way: the goal went to the resolver unchanged
    DIRECT = 'direct'
    #: the planner found no way (the reason says why): the robot held
    NO_WAY = 'no_way'
    #: the goal was refused (the reason says why): the robot held
    REJECTED = 'rejected'


class PursuitLog(LogThrottle):
    """:class:`~wmm_control.resolvers.targets.LogThrottle` with the pursuit's own kinds: the
    course of a goal as information, the rest as throttled warnings."""

    INFO = ('accepted', 'planning', 'planned', 'direct', 'approach')
    INTERVALS = {'no_way': 0.0, 'replan': 0.0}


@dataclass(frozen=True)
class PursuitStep:
    """What to send this period.

    Attributes:
        reference: the trajectory point for the resolver (``/ee_reference``), or None; the
            final approach's goal, at rest with the stance as its base, once the plan is done.
        forward_goal: give the resolver the user's goal now, unchanged.
        hold: a goal that holds the robot where it is (the end effector's pose now), or None.
        path: the planned base poses (x, y, θ) when they changed (empty: no plan), else None.
        events: what to log.
    """

    reference: PoseTarget | None = None
    forward_goal: bool = False
    hold: PoseTarget | None = None
    path: np.ndarray | None = None
    events: tuple[LogEvent, ...] = ()


@dataclass(frozen=True)
class _PlanJob:
    ticket: int
    version: int
    obstacles: tuple[Obstacle, ...]
    goal: PoseTarget
    base_pose: np.ndarray
    #: the arm's posture to travel in, first (the planner's own when that finds no way); None: its own
    q_travel: np.ndarray | None = None


@dataclass(frozen=True)
class _CheckJob:
    ticket: int
    version: int
    obstacles: tuple[Obstacle, ...]
    poses: np.ndarray


@dataclass(frozen=True)
class _Planned:
    ticket: int
    version: int
    plan: Plan
    handoff: Handoff | None
    here: bool


@dataclass(frozen=True)
class _Checked:
    ticket: int
    blocked: str


@dataclass(frozen=True)
class _Failed:
    ticket: int
    error: str


def run_limit(duration: float, planned_end: float | None) -> float:
    """[s] a run's limit that gives the robot ``duration`` [s] after the base path of the goal's
    first plan is planned to end, at ``planned_end`` [s] (:attr:`GoalPursuit.planned_end`;
    ``duration`` itself when None: no path to follow): a long way round is not taken out of the
    time the final approach has."""
    return duration + (planned_end or 0.0)


def path_blocked(planner: GoalPlanner, poses: np.ndarray) -> str:
    """Why the base poses (x, y, θ) ``poses`` of a path are no longer clear for ``planner`` (its
    obstacles), '' when they are: the first pose nearer an obstacle than the least margin a path
    of the planner keeps (the travel margin, or the narrow one through a gap:
    :attr:`~wmm_control.planning.base_path.BasePathPlanner.least_margin`), arm in the travel
    posture (:class:`~wmm_control.planning.clearance.Travel`)."""
    travel, margin = planner.travel, planner.paths.least_margin
    for pose in np.asarray(poses, dtype=float).reshape(-1, 3):
        d = travel.obstacle_clearance(pose)
        if d < margin:
            return (
                f'an obstacle is {d:.3f} m from the planned path at ({pose[0]:.2f}, {pose[1]:.2f}) m, '
                f'within the margin {margin:g} m'
            )
    return ''


class PlanWorker:
    """Runs plans and path checks one after the other in a thread of its own (daemon), so that
    the caller's period never waits for them; :meth:`results` gives what is done.

    Args:
        robot: the robot.
        options: keyword arguments of :class:`~wmm_control.planning.GoalPlanner` (margins, budget,
            seed, ...).
    """

    def __init__(self, robot: RobotConfig, options: Mapping[str, Any] | None = None, threaded: bool = True) -> None:
        self.robot = robot
        self.options = dict(options or {})
        self._jobs: queue.SimpleQueue = queue.SimpleQueue()
        self._results: queue.SimpleQueue = queue.SimpleQueue()
        self._planner: GoalPlanner | None = None
        self._version = -1
        #: the ticket of the job the caller waits for: others queued are skipped
        self.wanted = 0
        self._thread: threading.Thread | None = None
        if threaded:
            self._thread = threading.Thread(target=self._run, name='goal_planner_worker', daemon=True)
            self._thread.start()

    def submit(self, job: _PlanJob | _CheckJob) -> None:
        """Queue ``job``; without a thread, do it now (its result is there at :meth:`results`)."""
        if self._thread is None:
            self._do(job)
        else:
            self._jobs.put(job)

    def results(self) -> list:
        """The jobs' results done since the last call, oldest first."""
        out = []
        while True:
            try:
                out.append(self._results.get_nowait())
            except queue.Empty:
                return out

    def close(self, timeout: float | None = None) -> None:
        """Stop: the jobs queued are dropped, the one under way is finished (an OMPL search
        cannot be cut short), waited for up to ``timeout`` [s] (None: until it is done). A
        process must not end while the thread is inside OMPL: the interpreter's finalization
        then aborts it."""
        self.wanted = -1
        if self._thread is not None:
            self._jobs.put(None)
            self._thread.join(timeout)

    def _planner_for(self, version: int, obstacles: tuple[Obstacle, ...]) -> GoalPlanner:
        if self._planner is None or version != self._version:
            self._planner = GoalPlanner(self.robot, obstacles, **self.options)
            self._version = version
        return self._planner

    def _run(self) -> None:
        while True:
            job = self._jobs.get()
            if job is None:
                return
            self._do(job)

    def _do(self, job: _PlanJob | _CheckJob) -> None:
        if job.ticket != self.wanted:
            return  # given up before it started
        try:
            planner = self._planner_for(job.version, job.obstacles)
            if isinstance(job, _CheckJob):
                self._results.put(_Checked(job.ticket, path_blocked(planner, job.poses)))
                return
            plan, travel = planner.plan_in_posture(job.goal.position, job.goal.rotation, job.base_pose, job.q_travel)
            here = plan.stance is not None and np.array_equal(plan.stance.base_pose, job.base_pose)
            handoff = None
            if plan.trajectory is not None and not here:
                stance = None if plan.stance is None else plan.stance.q_arm
                handoff = Handoff.of(planner.model, plan.trajectory, travel, stance)
            self._results.put(_Planned(job.ticket, job.version, plan, handoff, here))
        except Exception as exc:  # a bug or a bad robot: reported, and the worker lives on
            self._results.put(_Failed(job.ticket, f'{type(exc).__name__}: {exc}'))


@dataclass
class _Counters:
    goals: int = 0
    goals_rejected: int = 0
    plans: int = 0
    replans: int = 0
    no_way: int = 0
    points: int = 0
    #: [s] the time of every plan made
    planning_s: float = 0.0


class GoalPursuit:
    """The pursuit of the user's goals for one robot (module docstring).

    Args:
        robot: the robot.
        obstacles: the obstacles at the start (world frame); :meth:`set_obstacles` changes them.
        world_frame: the frame of the goals.
        max_goal_distance: [m] goals farther from the world origin (on an axis) are refused.
        follow: the :class:`~wmm_control.planning.follow.FollowParams` (default: its defaults).
        max_replans: plans made again for one goal (a stall, an obstacle on the path) before the
            goal goes to the resolver from where the robot is.
        planner: keyword arguments of :class:`~wmm_control.planning.GoalPlanner`.
        threaded: plan in a thread of the worker's own (a node: its period never waits); False:
            a plan is made within the :meth:`step` that asks for it, and its result taken at the
            next (the direct engine, which steps the simulation itself: the same runs whatever
            the machine's load).
    """

    def __init__(
        self,
        robot: RobotConfig,
        obstacles: Iterable[Obstacle],
        world_frame: str,
        max_goal_distance: float,
        follow: FollowParams | None = None,
        max_replans: int = MAX_REPLANS,
        planner: Mapping[str, Any] | None = None,
        threaded: bool = True,
    ) -> None:
        self.robot = robot
        self.model = KinematicModel(robot)
        self.workspace = Workspace(self.model)
        self.world_frame = world_frame
        self.max_goal_distance = float(max_goal_distance)
        self.follow = follow if follow is not None else FollowParams()
        self.max_replans = int(max_replans)
        self.worker = PlanWorker(robot, planner, threaded)
        self.obstacles = tuple(obstacles)
        self.version = 0  # of the obstacles
        self.state = PursuitState.IDLE
        self.reason = ''
        #: the kind of the last no way (its reason in :attr:`reason`), None before any
        self.no_way_kind: NoWay | None = None
        self.goal: PoseTarget | None = None
        self.follower: PlanFollower | None = None
        self.progress = 0.0
        self.planning_time = math.nan
        self.replans = 0  # of the goal in force
        self.counters = _Counters()
        self._key: tuple | None = None
        self._ticket = 0  # of the plan in force (or awaited); results of others are dropped
        self._plan_due = ''  # why a plan is due at the next step ('' none)
        self._engaged = False  # the resolver may pursue something given by this object
        self._hold_due = False
        self._path: np.ndarray | None = None
        self._no_way_version = -1  # of the obstacles when the goal in force got no way
        self._planned_from: np.ndarray | None = None  # the base pose of the last plan asked for
        self._approach: PoseTarget | None = None  # a final approach due at the next point given
        #: [s] the time :meth:`step` has been told so far (the sum of its periods)
        self.elapsed = 0.0
        #: [s] when (on :attr:`elapsed`'s clock) the base path of the goal's first plan is planned
        #: to end: the time it came plus the path's timed duration; None before it (or with no
        #: path to follow: a goal sent straight, no way)
        self.planned_end: float | None = None

    def close(self, timeout: float | None = None) -> None:
        """Stop the worker, waiting up to ``timeout`` [s] for a plan under way (None: until done)."""
        self.worker.close(timeout)

    # ------------------------------------------------------------------ inputs
    def new_goal(self, frame: str, pose: ArrayLike) -> list[LogEvent]:
        """A goal ``pose`` (x, y, z, qx, qy, qz, qw) in ``frame`` from the user."""
        values = np.asarray(pose, dtype=float)
        quat, reason, events = check_goal(frame, values, self.world_frame, self.max_goal_distance, self.workspace)
        if quat is None:
            self.counters.goals_rejected += 1
            self._stop(PursuitState.REJECTED, reason)
            self._key = None
            return events + [LogEvent('rejected', f'rejected goal_pose: {reason}; holding still')]
        key = goal_key(values[:3], quat)
        if key == self._key and not (self.state is PursuitState.NO_WAY and self._no_way_version != self.version):
            return events  # the same goal again (a sequencer re-publishing it)
        self._key = key
        self.counters.goals += 1
        self.goal = PoseTarget(values[:3], matrix_from_quaternion(quat))
        self.replans = 0
        self.planned_end = None
        self._plan_due = 'new goal'
        self._stop(PursuitState.PLANNING, '')
        return events + [LogEvent('accepted', f'new goal: {goal_text(values[:3], quat)}: planning')]

    def follow_plan(self, follower: PlanFollower) -> list[LogEvent]:
        """Pursue ``follower``'s goal by its plan, made elsewhere (a study's, a test's), from the
        next :meth:`step` on, as if the planner had made it: replanned as a plan of its own
        would be. The same goal given to :meth:`new_goal` afterwards changes nothing."""
        goal = follower.goal
        self._stop(PursuitState.FOLLOWING, '')
        self.goal = PoseTarget(goal.position, goal.rotation)
        self._key = goal_key(goal.position, quaternion_from_matrix(goal.rotation))
        self.counters.goals += 1
        self.replans = 0
        self.planned_end = None
        self._follow(follower)
        self._path = follower.remaining_poses()
        return [LogEvent('planned', f'following a plan given for the goal {np.round(goal.position, 3).tolist()}')]

    def set_obstacles(self, obstacles: Iterable[Obstacle]) -> None:
        """The obstacles changed (world frame): the rest of a path followed is checked on them."""
        self.obstacles = tuple(obstacles)
        self.version += 1
        if self.state is PursuitState.FOLLOWING and self.follower is not None:
            self.worker.submit(_CheckJob(self._ticket, self.version, self.obstacles, self.follower.remaining_poses()))

    # ------------------------------------------------------------------ the period
    def step(self, dt: float, base_pose: ArrayLike | None, q_arm: ArrayLike | None) -> PursuitStep:
        """One period of ``dt`` [s]: what to send, from the measured base pose (x, y, θ) and arm
        joints (None while they are not known, or stale: then no point is given, no plan started
        and no hold sent)."""
        events: list[LogEvent] = []
        self.elapsed += dt
        base = None if base_pose is None else np.asarray(base_pose, dtype=float)
        forward = self._take_results(events, base)
        reference, self._approach = self._approach, None
        arm = None if q_arm is None else np.asarray(q_arm, dtype=float)
        ee = self._end_effector(base, arm)
        if self.state is PursuitState.FOLLOWING and self.follower is not None and base is not None:
            step = self.follower.step(dt, base, *(ee if ee is not None else (None, None)))
            self.progress = step.progress
            if step.state is FollowState.APPROACH:
                self.state = PursuitState.APPROACH
                if step.target.base is None:  # without hold_base: the goal alone, as a goal
                    forward = True
                    events.append(LogEvent('approach', 'the planned path is done: the goal goes to the resolver'))
                else:  # the goal as the last point, at rest, with the stance: the resolver holds it
                    reference = step.target
                    events.append(
                        LogEvent(
                            'approach',
                            'the planned path is done: the goal goes to the resolver as the last point, with the '
                            f'stance {np.round(step.target.base.pose, 3).tolist()} as its base',
                        )
                    )
            elif step.state is FollowState.STALLED:
                forward = self._replan(events, 'progress stalled on the planned path', base)
            else:
                reference = step.target
                self._engaged = True
                self.counters.points += 1
        if forward or reference is not None:
            self._engaged = True
            self._hold_due = False  # what is sent now replaces a hold
        if self._plan_due and base is not None:
            self._submit_plan(events, base, arm)
        hold = None
        if self._hold_due and ee is not None:
            hold = PoseTarget(*ee)
            self._hold_due = self._engaged = False
        path, self._path = self._path, None
        return PursuitStep(reference, forward, hold, path, tuple(events))

    def _end_effector(self, base: np.ndarray | None, q_arm: np.ndarray | None) -> tuple[np.ndarray, np.ndarray] | None:
        """(position, rotation) of the end effector at the base pose and arm joints, or None."""
        if base is None or q_arm is None:
            return None
        self.model.update(base, q_arm)
        position, rotation = self.model.ee_placement_world()
        return np.array(position, dtype=float), np.array(rotation, dtype=float)

    def _stop(self, state: PursuitState, reason: str) -> None:
        """Stop pursuing what was pursued: no plan followed, a hold due if the resolver may be
        pursuing something of ours, results of plans under way dropped."""
        self.state, self.reason = state, reason
        self.follower = None
        self._approach = None
        self.progress = 0.0
        self._ticket += 1
        self.worker.wanted = self._ticket
        if self._engaged:
            self._hold_due = True
        if state is not PursuitState.PLANNING:
            self._plan_due = ''
        self._path = np.zeros((0, 3))

    def _no_way(self, events: list[LogEvent], reason: str) -> None:
        self.counters.no_way += 1
        self._no_way_version = self.version
        self._stop(PursuitState.NO_WAY, reason)
        events.append(LogEvent('no_way', f'no way to the goal: {reason}; holding still'))

    def _replan(self, events: list[LogEvent], why: str, base: np.ndarray) -> bool:
        """Plan again from ``base`` for ``why``; after ``max_replans`` the goal goes to the resolver
        from where the robot is instead (True: forward it now), as ``wmm_randomized --plan`` does."""
        if self.replans >= self.max_replans:
            self.follower = None
            self.state, self.reason = PursuitState.APPROACH, ''
            events.append(
                LogEvent(
                    'approach',
                    f'{why}, after {self.replans} plans made again: the goal goes to the resolver from where the '
                    'robot is',
                )
            )
            return True
        self.replans += 1
        self.counters.replans += 1
        self._plan_due = why
        self._stop(PursuitState.PLANNING, '')
        events.append(
            LogEvent('replan', f'{why}: planning again from where the base is ({self.replans} of {self.max_replans})')
        )
        return False

    def _submit_plan(self, events: list[LogEvent], base: np.ndarray, q_arm: np.ndarray | None) -> None:
        """Queue the plan due: a plan made again lets the arm travel in the posture it has (the
        first point where the end effector is), the planner's own when that finds no way."""
        assert self.goal is not None
        why, self._plan_due = self._plan_due, ''
        q_travel = q_arm.copy() if self.replans > 0 and q_arm is not None else None
        self._planned_from = base.copy()
        self.worker.submit(_PlanJob(self._ticket, self.version, self.obstacles, self.goal, base.copy(), q_travel))
        self.counters.plans += 1
        events.append(LogEvent('planning', f'planning ({why}) from the base at {np.round(base, 3).tolist()}'))

    def _take_results(self, events: list[LogEvent], base: np.ndarray | None) -> bool:
        """Take the worker's results; True when the goal is to be forwarded now (direct)."""
        forward = False
        for result in self.worker.results():
            if result.ticket != self._ticket:
                continue  # for a goal or a plan given up meanwhile
            if isinstance(result, _Failed):
                self._no_way(events, f'the planner failed ({result.error})')
            elif isinstance(result, _Checked):
                if result.blocked and self.state is PursuitState.FOLLOWING and base is not None:
                    forward = self._replan(events, result.blocked, base) or forward
            else:
                forward = self._planned(events, result) or forward
        return forward

    def _follow(self, follower: PlanFollower) -> None:
        """Follow ``follower``'s plan from now on; the goal's first plan sets :attr:`planned_end`."""
        self.follower = follower
        if self.planned_end is None:
            handoff = follower.handoff
            self.planned_end = self.elapsed + handoff.path_end * handoff.dt

    def limit(self, duration: float) -> float:
        """[s] :func:`run_limit` of ``duration`` with this pursuit's :attr:`planned_end`."""
        return run_limit(duration, self.planned_end)

    def _planned(self, events: list[LogEvent], result: _Planned) -> bool:
        plan = result.plan
        self.planning_time = plan.planning_time
        self.counters.planning_s += plan.planning_time
        if plan.no_way is not None or plan.trajectory is None:
            self.no_way_kind = plan.no_way
            self._no_way(events, plan.reason or 'no plan')
            return False
        if result.here and self.replans > 0 and self.follow.hold_base and plan.stance is not None:
            # made again where the base stands (a stall at the stance, as a rule): the final
            # approach from this stance, held, as after a plan followed to its end
            assert self.goal is not None
            here = plan.stance
            self.state, self.reason = PursuitState.APPROACH, ''
            self._path = np.zeros((0, 3))
            self._approach = PoseTarget.goal(self.goal.position, self.goal.rotation, here.base_pose, here.q_arm)
            events.append(
                LogEvent(
                    'approach',
                    f'planned again in {plan.planning_time:.3f} s: the goal is within reach from where the base '
                    f'stands: it goes to the resolver as the last point, with the stance '
                    f'{np.round(here.base_pose, 3).tolist()} as its base',
                )
            )
            return False
        if result.here:
            self.state, self.reason = PursuitState.DIRECT, ''
            self._path = np.zeros((0, 3))
            events.append(
                LogEvent(
                    'direct',
                    f'the goal is within reach with nothing in the way: sent to the resolver unchanged '
                    f'(planned in {plan.planning_time:.3f} s)',
                )
            )
            return True
        assert result.handoff is not None and self.goal is not None
        follower = PlanFollower(result.handoff, self.goal, self.follow)
        self._follow(follower)
        self.state, self.reason, self.progress = PursuitState.FOLLOWING, '', 0.0
        poses = plan.trajectory.poses
        self._path = poses
        length = float(np.sum(np.hypot(*np.diff(poses[:, :2], axis=0).T)))
        stance = plan.stance.base_pose if plan.stance is not None else poses[-1]
        events.append(
            LogEvent(
                'planned',
                f'planned in {plan.planning_time:.3f} s: the base drives {length:.2f} m to '
                f'{np.round(stance, 3).tolist()} in {plan.trajectory.duration:.1f} s, then the goal'
                + (
                    ''
                    if plan.stance is None or plan.stance.motion_clear
                    else "; the arm's straight way to the stance's posture passes within its margins "
                    '(no stance with a clear way had a path): the safety stage may hold it there'
                ),
            )
        )
        if result.version != self.version:  # the obstacles changed while it was planned
            self.worker.submit(_CheckJob(self._ticket, self.version, self.obstacles, follower.remaining_poses()))
        return False

    # ------------------------------------------------------------------ report
    @property
    def needs_base(self) -> bool:
        """A plan is due or a path is followed: :meth:`step` does nothing for it without the base's pose."""
        return bool(self._plan_due) or self.state is PursuitState.FOLLOWING

    def status(self) -> tuple[str, str, dict]:
        """(level 'ok' or 'warn', message, values) for ``/diagnostics``."""
        level = 'warn' if self.state in (PursuitState.NO_WAY, PursuitState.REJECTED) else 'ok'
        message = self.state.value + (f': {self.reason}' if self.reason else '')
        c = self.counters
        values = {
            'state': self.state.value,
            'reason': self.reason,
            'goal': [] if self.goal is None else self.goal.position.tolist(),
            'progress': self.progress,
            'replans_of_goal': self.replans,
            'goals': c.goals,
            'goals_rejected': c.goals_rejected,
            'plans': c.plans,
            'replans': c.replans,
            'no_way': c.no_way,
            'points': c.points,
            'obstacles': len(self.obstacles),
        }
        if math.isfinite(self.planning_time):  # none before the first plan
            values['planning_time_s'] = self.planning_time
        return level, message, values

    @property
    def goal_handed(self) -> bool:
        """The resolver has the user's goal itself: the plan's final approach, or the goal sent
        straight. Before that it tracks a plan's points, or holds the robot while one is made."""
        return self.state in (PursuitState.APPROACH, PursuitState.DIRECT)

    def account(self) -> dict:
        """What the pursuit of a goal came to, for a study's row: ``planning_time_s`` (of every
        plan), ``plans``, ``replans``, ``no_way`` (its kind when the pursuit ended with no way,
        else None), ``no_way_reason``, ``no_way_from`` (the base pose (x, y, θ) the plan that
        found no way was made from, else None) and ``planned_end_s`` (:attr:`planned_end`)."""
        c = self.counters
        no_way = self.state is PursuitState.NO_WAY
        return {
            'planning_time_s': c.planning_s,
            'plans': c.plans,
            'replans': c.replans,
            'no_way': (self.no_way_kind.value if self.no_way_kind else 'no_way') if no_way else None,
            'no_way_reason': self.reason if no_way else None,
            'no_way_from': self._planned_from.tolist() if no_way and self._planned_from is not None else None,
            'planned_end_s': self.planned_end,
        }
