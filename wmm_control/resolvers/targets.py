"""The end effector's target, ROS-free: goals and trajectory points checked and taken, a stopped
trajectory held, and how the goal fares. ``redundancy_resolver`` wires its topics to it.

:class:`TargetManager` takes

* **goals** (``/goal_pose``): a pose (x, y, z, qx, qy, qz, qw) in a frame. A goal in another
  frame than the world's, with NaN/inf or a zero quaternion, beyond ``max_goal_distance``
  from the world origin, or where :meth:`Workspace.impossible
  <wmm_control.kinematics.workspace.Workspace.impossible>` says no motion reaches it (below
  the floor, above the highest the end effector can reach, inside the base's body at its
  current pose, or at the planned base's pose of a goal or point that carries one, inside an
  obstacle) is rejected with its reason, and the target is then none
  (the robot holds still). A non-unit quaternion is normalised with a note. The same goal
  again (a sequencer re-publishing it) changes nothing: the goal is not restarted;
* **trajectory points** (``/ee_reference``): a pose with its twist and acceleration (world
  axes), checked as goals are (a twist or acceleration entry beyond 1e3 is rejected too). The
  latest of a goal and a point is the target. A trajectory whose last point is older than
  ``timeout`` is held as a set-point at that point's pose (:meth:`TargetManager.current`).
  A point may carry a followed plan's base (its planned pose, rates and accelerations,
  checked as the point is), which the methods hold the base to below the end effector's task;
  a held point keeps its planned pose, at rest, as its stance, and is judged as a goal from
  then on (its progress afresh, ``reached`` reported): so a plan's final approach, sent as the goal at rest
  with the stance as its base and then no more points, reaches the methods with the stance.

Time is an argument (seconds of a steady clock), never read here. Each call answers with
:class:`LogEvent` s for the node to log: ``accepted`` (a new goal), ``tracking`` (a
trajectory starts), ``normalised``, ``rejected`` (with the reason), ``held`` (a trajectory
stopped), ``reached`` (a goal, once) and ``stalled`` (once, again after it made progress),
judged by :class:`~wmm_control.resolvers.progress.GoalProgress` on the diagnostics of the
commands computed for the target (:meth:`TargetManager.judge`).
"""

import math
from dataclasses import dataclass

import numpy as np

from wmm_control.checks import Freshness
from wmm_control.geometry import matrix_from_quaternion, unit_quaternion
from wmm_control.resolvers.interface import BaseReference, PoseTarget
from wmm_control.resolvers.progress import GoalProgress

__all__ = [
    'GOAL',
    'REFERENCE',
    'LogEvent',
    'LogThrottle',
    'TargetManager',
    'check_goal',
    'checked_quaternion',
    'goal_key',
    'goal_text',
]

GOAL = 'goal_pose'
#: The fields of a goal's pose (x, y, z, qx, qy, qz, qw), for the reasons.
POSE_FIELDS = tuple(f'position.{a}' for a in 'xyz') + tuple(f'orientation.{a}' for a in 'xyzw')
REFERENCE = 'ee_reference'
#: Largest entry of a trajectory point's twist or acceleration.
MAX_REFERENCE_RATE = 1e3


@dataclass(frozen=True)
class LogEvent:
    """Something to log: ``kind`` (:class:`TargetManager`'s accepted, tracking, normalised,
    rejected, held, reached, stalled; :class:`~wmm_control.planning.pursuit.PursuitLog` lists
    the goal planner's) and its ``message``."""

    kind: str
    message: str


class LogThrottle:
    """Which :class:`LogEvent` s a node logs, and how: ``accepted``, ``tracking`` and ``reached``
    always, as information; every other kind as a warning, at most once per its interval of
    the caller's clock (``held`` 5 s, ``stalled`` every time, the others 1 s), each kind apart.
    """

    INFO: tuple[str, ...] = ('accepted', 'tracking', 'reached')
    INTERVALS: dict[str, float] = {'held': 5.0, 'stalled': 0.0}
    INTERVAL = 1.0

    def __init__(self) -> None:
        self._logged: dict[str, float] = {}  # the last time each kind of warning was logged

    def lines(self, events, now: float) -> list[tuple[str, str]]:
        """(level 'info' or 'warn', message) of each of ``events`` to log at ``now`` [s]."""
        out = []
        for event in events:
            if event.kind in self.INFO:
                out.append(('info', event.message))
            elif now - self._logged.get(event.kind, -math.inf) >= self.INTERVALS.get(event.kind, self.INTERVAL):
                self._logged[event.kind] = now
                out.append(('warn', event.message))
        return out


def checked_quaternion(quat, topic) -> tuple[np.ndarray | None, list[LogEvent]]:
    """(``quat`` (x, y, z, w, finite) normalised, or None when it is zero; a ``normalised``
    event when its norm was off 1 by more than 1e-3, naming ``topic``)."""
    unit, norm = unit_quaternion(quat)
    if unit is None or abs(norm - 1.0) <= 1e-3:
        return unit, []
    return unit, [LogEvent('normalised', f'{topic} quaternion has norm {norm:.6g}: normalised')]


def check_goal(
    frame, pose, world_frame, max_goal_distance, workspace, base=None, obstacles=()
) -> tuple[np.ndarray | None, str, list[LogEvent]]:
    """The checks of a goal ``pose`` (x, y, z, qx, qy, qz, qw) in ``frame`` (module docstring):
    (its unit quaternion, '', events) when it passes, else (None, why not, events).

    Args:
        world_frame: the one frame accepted.
        max_goal_distance: [m] from the world origin, on each axis.
        workspace: the robot's :class:`~wmm_control.kinematics.workspace.Workspace`.
        base: the base's pose (x, y, θ), or None (the body is not checked).
        obstacles: a goal inside one is refused (world frame).
    """
    values = np.asarray(pose, dtype=float)
    if frame != world_frame:
        return None, f'frame {frame!r}, expected {world_frame!r}', []
    if not np.all(np.isfinite(values)):
        # The fields, not the values: a reason that quotes NaN would carry it on to /diagnostics.
        bad = ', '.join(POSE_FIELDS[i] for i in np.flatnonzero(~np.isfinite(values)))
        return None, f'non-finite values of {bad}', []
    if float(np.max(np.abs(values[:3]))) > max_goal_distance:
        return None, f'position {values[:3].tolist()} is beyond max_goal_distance {max_goal_distance} m', []
    impossible = workspace.impossible(values[:3], base, obstacles)
    if impossible:
        return None, f'position {values[:3].tolist()}: {impossible}', []
    quat, events = checked_quaternion(values[3:], '/' + GOAL)
    if quat is None:
        return None, 'zero quaternion', events
    return quat, '', events


def goal_key(position, quat) -> tuple:
    """What tells a goal from another: its position and unit quaternion (x, y, z, w) to 1e-9 (the
    same goal re-published has the same key)."""
    return tuple(np.round(np.concatenate((position, quat)), 9))


def goal_text(position, quat) -> str:
    """A goal's position and unit quaternion (x, y, z, w) for a log."""
    return f'position {np.round(position, 4).tolist()}, quaternion (x, y, z, w) {np.round(quat, 4).tolist()}'


class TargetManager:
    """The target of the end effector and the events of its goals (module docstring).

    Args:
        workspace: :class:`~wmm_control.kinematics.workspace.Workspace` of the robot.
        world_frame: the frame of goals and trajectory points.
        max_goal_distance: goals farther than this from the world origin are rejected [m].
        timeout: age [s] after which a trajectory point is held as a set-point.
        tolerance: (position [m], orientation [rad]) under which a goal is reached.
        stall_time, period, min_progress_ratio: of :class:`GoalProgress`.
        position_only: the method tracks the position alone; the orientation never counts.

    Attributes:
        target: the :class:`PoseTarget` pursued, or None.
        tracking: the target is a point of a trajectory.
        obstacles: the obstacles a goal must not lie in (world frame).
        goals, rejected: goals (and trajectories) taken, and goals and points rejected.
        progress: the :class:`GoalProgress` of the target.
    """

    def __init__(
        self,
        workspace,
        world_frame,
        max_goal_distance,
        timeout,
        tolerance,
        stall_time,
        period,
        min_progress_ratio,
        position_only=False,
    ) -> None:
        self.workspace = workspace
        self.world_frame = world_frame
        self.max_goal_distance = float(max_goal_distance)
        self.reference = Freshness(timeout)
        self.position_only = position_only
        self.progress = GoalProgress(
            self.tolerance(tolerance), stall_time, period, min_progress_ratio=min_progress_ratio
        )
        self.obstacles = ()
        self.target: PoseTarget | None = None
        self.tracking = False
        self.goals = 0
        self.rejected = 0
        self._goal_key: tuple | None = None
        self._cycles = 0
        self._reached_logged = False
        self._stall_logged = False

    def tolerance(self, goal_tolerance) -> tuple[float, float]:
        """(position, orientation) tolerance of ``goal_tolerance``: a method that tracks the
        position alone leaves the orientation free, so only the position counts."""
        return float(goal_tolerance[0]), math.inf if self.position_only else float(goal_tolerance[1])

    # ------------------------------------------------------------------ inputs
    def reject(self, reason, topic=GOAL) -> list[LogEvent]:
        """Reject an input of ``topic`` for ``reason``: no target until the next one."""
        self.rejected += 1
        self.target = None
        self._goal_key = None
        self.tracking = False
        return [LogEvent('rejected', f'rejected {topic}: {reason}; holding still')]

    def _planned_base(self, planned_base) -> tuple[BaseReference | None, str]:
        """(a followed plan's base (pose, rates, accelerations[, the arm's posture]) as a
        :class:`BaseReference`, or None when there is none; '' or why it is refused)."""
        if planned_base is None:
            return None, ''
        values = [np.asarray(v, dtype=float) for v in planned_base]
        if len(values) not in (3, 4) or any(v.shape != (3,) for v in values[:3]):
            return None, 'a planned base needs a pose (x, y, θ), its rates and accelerations'
        if len(values) == 4 and values[3].shape != (self.workspace.n_arm,):
            return None, f'a planned arm posture needs {self.workspace.n_arm} joint positions'
        if not all(np.all(np.isfinite(v)) for v in values):
            return None, 'non-finite values of the planned base'
        if (
            float(np.max(np.abs(values[0][:2]))) > self.max_goal_distance
            or float(np.max(np.abs(np.concatenate(values[1:3])))) > MAX_REFERENCE_RATE
        ):
            return None, 'planned base beyond max_goal_distance, or its rates beyond 1e3'
        return BaseReference(values[0], values[1], values[2], values[3] if len(values) == 4 else None), ''

    def goal(self, frame, pose, base=None, planned_base=None) -> list[LogEvent]:
        """A goal ``pose`` (x, y, z, qx, qy, qz, qw) in ``frame``; ``base`` the base's pose
        (x, y, θ) while it is known (a goal inside the body is rejected then), else None;
        ``planned_base`` where a followed plan left the base for the final approach
        (:meth:`trajectory_point`), or None."""
        values = np.asarray(pose, dtype=float)
        planned, why = self._planned_base(planned_base)
        quat, reason, events = check_goal(
            frame,
            values,
            self.world_frame,
            self.max_goal_distance,
            self.workspace,
            _body_at(base, planned),
            self.obstacles,
        )
        if quat is None:
            return events + self.reject(reason)
        if why:
            return events + self.reject(why)
        key = goal_key(values[:3], quat)
        if key == self._goal_key:
            return events  # the same goal again (a sequencer re-publishing it)
        # a planned base given with a goal is where the base stands for it (its stance)
        self.target = PoseTarget.goal(
            values[:3],
            matrix_from_quaternion(quat),
            None if planned is None else planned.pose,
            None if planned is None else planned.arm,
        )
        self._goal_key = key
        self.tracking = False
        self._start()
        self.goals += 1
        return events + [LogEvent('accepted', f'new goal: {goal_text(values[:3], quat)}')]

    def trajectory_point(
        self, frame, pose, velocity, acceleration, now, base=None, planned_base=None
    ) -> list[LogEvent]:
        """A trajectory point received at ``now`` [s]: ``pose`` as a goal's (None: the message
        had no point), ``velocity`` and ``acceleration`` (linear, angular; world axes);
        ``planned_base``: a followed plan's base with it, (pose (x, y, θ), world rates, world
        accelerations) (:class:`~wmm_control.resolvers.interface.BaseReference`), or None.
        ``base`` is the measured base pose (x, y, θ) of the checks."""
        if frame != self.world_frame:
            return self.reject(f'frame {frame!r}, expected {self.world_frame!r}', REFERENCE)
        if pose is None:
            return self.reject('no point or no transform', REFERENCE)
        pose, vel, acc = (np.asarray(v, dtype=float) for v in (pose, velocity, acceleration))
        if not (np.all(np.isfinite(pose)) and np.all(np.isfinite(vel)) and np.all(np.isfinite(acc))):
            return self.reject('non-finite values', REFERENCE)
        if (
            float(np.max(np.abs(pose[:3]))) > self.max_goal_distance
            or float(np.max(np.abs(np.concatenate((vel, acc))))) > MAX_REFERENCE_RATE
        ):
            return self.reject('beyond max_goal_distance, or a twist or acceleration beyond 1e3', REFERENCE)
        planned, why = self._planned_base(planned_base)
        if why:
            return self.reject(why, REFERENCE)
        impossible = self.workspace.impossible(pose[:3], _body_at(base, planned), self.obstacles)
        if impossible:
            return self.reject(f'position {pose[:3].tolist()}: {impossible}', REFERENCE)
        quat, events = checked_quaternion(pose[3:], '/' + REFERENCE)
        if quat is None:
            return events + self.reject('zero quaternion', REFERENCE)
        if not self.tracking:
            events.append(LogEvent('tracking', 'tracking /ee_reference'))
            self._start()
        self.target = PoseTarget(pose[:3], matrix_from_quaternion(quat), velocity=vel, acceleration=acc, base=planned)
        self._goal_key = None
        self.tracking = True
        self.reference.mark(now)
        return events

    # ------------------------------------------------------------------ cycles
    def current(self, now) -> tuple[PoseTarget | None, list[LogEvent]]:
        """The target of a cycle at ``now`` [s]: a trajectory whose last point is older than
        the timeout is held at that point's pose, a set-point from then on, with its planned
        base (if any) held at rest as the stance; the set-point is judged as a goal from then on (its
        progress afresh, its arrival reported). A followed plan's final approach comes so: the
        goal as the last point, at rest, with the stance as its base."""
        if self.tracking and self.target is not None and not self.reference.fresh(now):
            base = self.target.base
            self.target = PoseTarget.goal(
                self.target.position,
                self.target.rotation,
                None if base is None else base.pose,
                None if base is None else base.arm,
            )
            self.tracking = False
            self._start(keep_clock=True)
            return self.target, [LogEvent('held', '/ee_reference stopped: holding its last pose')]
        return self.target, []

    def judge(self, diagnostics) -> list[LogEvent]:
        """Account for the diagnostics of a command computed for the target: a goal reached is
        told once; a stall once, and again after the goal made progress."""
        self.progress.update(diagnostics)
        self._cycles += 1
        events = []
        pos, ori = diagnostics.position_error, diagnostics.orientation_error
        if self.progress.reached and not self._reached_logged and not self.tracking:
            events.append(
                LogEvent(
                    'reached',
                    f'goal reached: {pos:.4f} m, {ori:.4f} rad away after '
                    f'{self._cycles * self.progress.period:.2f} s ({self._cycles} cycles)',
                )
            )
            self._reached_logged = True
        if not self.progress.stalled:
            self._stall_logged = False
        elif not self._stall_logged:
            events.append(
                LogEvent(
                    'stalled',
                    f'goal not reached: {pos:.3f} m, {ori:.3f} rad away, '
                    f'{self.no_progress()} (out of reach, or held by a limit?)',
                )
            )
            self._stall_logged = True
        return events

    def status(self, diagnostics) -> tuple[str, str]:
        """(level, message) of the goal, ``diagnostics`` those of the last command."""
        if self.progress.stalled:
            return 'warn', (
                f'goal not reached: {diagnostics.position_error:.3f} m, '
                f'{diagnostics.orientation_error:.3f} rad; {self.no_progress()} (out of reach?)'
            )
        return 'ok', 'goal reached' if self.progress.reached else diagnostics.mode

    def report(self, command) -> tuple[str, str, dict]:
        """(level, message, values) of the goal for ``/diagnostics``: :meth:`status`, and the
        values of the last ``command`` (a :class:`~wmm_control.resolvers.ResolverCommand`) and
        of the goal's progress, under the keys the panel and the docs name."""
        d = command.diagnostics
        values = {
            'method': d.method,
            'mode': d.mode,
            'psi': d.psi,
            'position_error_m': d.position_error,
            'orientation_error_rad': d.orientation_error,
            'limit_scale': d.limit_scale,
            'accel_scale': d.accel_scale,
            'null_scale': d.null_scale,
            'compensation_scale': d.compensation_scale,
            'compensated': d.compensated,
            'limited': list(d.limited),
            'sigma_min': d.sigma_min,
            'cycle_time_us': d.cycle_time_s * 1e6,
            'reference_time_left_s': d.reference_time_left,
            'clearance_m': d.clearance,
            'closest_pair': d.closest_pair,
            'collision_constraints': d.collision_constraints,
            'collision_changed': d.collision_changed,
            'goal_reached': self.progress.reached,
            'goal_stalled': self.progress.stalled,
            'arm_command': command.arm_velocity,
            'base_reference': command.base_twist,
        }
        return (*self.status(d), values)

    def no_progress(self) -> str:
        """What 'no progress' means with the current settings."""
        floor = self.progress.min_progress
        return (
            f'no progress in {self.progress.stall_time} s (best error down by less than '
            f'{100 * self.progress.min_progress_ratio:g} %, {1e3 * floor[0]:g} mm, {1e3 * floor[1]:g} mrad)'
        )

    def _start(self, keep_clock: bool = False) -> None:
        """A new goal or trajectory: progress judged afresh, its reach and stall told anew.
        ``keep_clock``: a trajectory held at its last point keeps counting its time from the
        trajectory's start, so the arrival it reports is the whole way's (a planned path's final
        approach), not the last cycle's."""
        self.progress.start()
        self._stall_logged = False
        self._reached_logged = False
        if not keep_clock:
            self._cycles = 0


def _body_at(base, planned: BaseReference | None):
    """The base pose a target is checked against the body at: a followed plan's base where
    there is one (where the base will be when the point is to be met: at the end of a path
    that ends beside a low goal the base may stand over it, and the goal of the final approach,
    checked there, was refused and the robot held for good), else the measured ``base``."""
    return base if planned is None else planned.pose
