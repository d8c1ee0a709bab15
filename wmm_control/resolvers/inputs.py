"""The measured inputs of ``redundancy_resolver`` checked, ROS-free: the base's odometry, the
end effector's measured pose and the base controller's feasible twist.

Each check answers the value, or None, with the :class:`~wmm_control.resolvers.targets.LogEvent`
s that tell why (one kind per reason, so that a node throttles each reason apart) and the
note of a normalised quaternion. Rejected: odometry with NaN/inf, beyond the distance bound
from the world origin, with a twist beyond ``factor`` times the base velocity limits or a zero
quaternion; an end-effector pose in another frame than the world's, with NaN/inf or a zero
quaternion; a feasible twist with NaN/inf or beyond ``factor`` times the base limits.
:class:`LatestInputs` keeps the latest accepted odometry and end-effector pose and makes the
robot state of a cycle of them while they are fresh.
"""

import numpy as np

from wmm_control.checks import Freshness
from wmm_control.geometry import matrix_from_quaternion, yaw_from_quaternion
from wmm_control.resolvers.interface import RobotState
from wmm_control.resolvers.targets import LogEvent, checked_quaternion

__all__ = ['MeasuredInputs', 'LatestInputs']


class MeasuredInputs:
    """Checks of the measured inputs.

    Args:
        world_frame: the frame of the end-effector pose.
        max_distance: odometry farther than this from the world origin is a glitch [m].
        base_velocity: the base's velocity limits (vx, vy, ω); a measured linear speed is
            judged against the faster linear axis.
        factor: a twist beyond this many times the limits is a glitch [-].
    """

    def __init__(self, world_frame, max_distance, base_velocity, factor) -> None:
        self.world_frame = world_frame
        self.max_distance = float(max_distance)
        self.factor = float(factor)
        limits = np.asarray(base_velocity, dtype=float)
        # both linear axes against the faster one: a base that cannot drive sideways (a
        # differential base, vy limit 0) still measures some sideways slip
        linear = float(max(limits[0], limits[1]))
        self.plausible_twist = self.factor * np.array([linear, linear, limits[2]])

    def odometry(self, xy, quat, twist) -> tuple[tuple[np.ndarray, np.ndarray] | None, list[LogEvent]]:
        """(((x, y, θ), twist (vx, vy, ω)) or None, events) of the base's odometry: position
        (x, y), quaternion (x, y, z, w) and planar twist."""
        (x, y), twist = (float(v) for v in xy), np.asarray(twist, dtype=float)
        values = np.concatenate(([x, y], np.asarray(quat, dtype=float), twist))
        if not np.all(np.isfinite(values)):
            return None, [LogEvent('odom non-finite', f'rejected /odom with non-finite values {values.tolist()}')]
        if max(abs(x), abs(y)) > self.max_distance:
            return None, [
                LogEvent(
                    'odom far',
                    f'rejected /odom at ({x:.6g}, {y:.6g}): beyond max_goal_distance '
                    f'{self.max_distance} m from the origin',
                )
            ]
        if np.any(np.abs(twist) > self.plausible_twist):
            return None, [
                LogEvent(
                    'odom twist',
                    f'rejected /odom with twist {twist.tolist()} beyond {self.factor:g} times the base velocity limits',
                )
            ]
        unit, events = checked_quaternion(values[2:6], '/odom')
        if unit is None:
            return None, events + [LogEvent('odom zero quaternion', 'rejected /odom with a zero quaternion')]
        return (np.array([x, y, yaw_from_quaternion(unit)]), twist), events

    def ee_pose(self, frame, pose) -> tuple[tuple[np.ndarray, np.ndarray] | None, list[LogEvent]]:
        """((position, rotation) or None, events) of the end effector's measured ``pose``
        (x, y, z, qx, qy, qz, qw) in ``frame``."""
        if frame != self.world_frame:
            return None, [LogEvent('ee_pose frame', f'rejected /ee_pose in frame {frame!r}')]
        values = np.asarray(pose, dtype=float)
        unit, events = checked_quaternion(values[3:], '/ee_pose') if np.all(np.isfinite(values)) else (None, [])
        if unit is None:
            return None, events + [
                LogEvent('ee_pose invalid', 'rejected /ee_pose with non-finite values or a zero quaternion')
            ]
        return (values[:3], matrix_from_quaternion(unit)), events

    def feasible_twist(self, twist) -> tuple[np.ndarray | None, list[LogEvent]]:
        """(``twist`` (vx, vy, ω) or None, events) of the base controller's answer."""
        twist = np.asarray(twist, dtype=float)
        if np.all(np.isfinite(twist)) and not np.any(np.abs(twist) > self.plausible_twist):
            return twist, []
        return None, [
            LogEvent(
                'feasible twist',
                f'rejected /base/feasible_twist {twist.tolist()}: non-finite or '
                f'beyond {self.factor:g} times the base velocity limits',
            )
        ]


class LatestInputs:
    """The latest odometry and end-effector pose that :class:`MeasuredInputs` accepted, each
    fresh for ``timeout`` [s] after its receipt (the receiver's clock: a sender's stamps cannot
    make stale data look fresh), and the robot state of a cycle made of them.

    Args:
        checks: the checks they pass.
        timeout: how long [s] after its receipt an input is fresh.
        ground_truth: the state carries the measured end-effector pose (``ee_feedback``
            ``ground_truth``), which must then be fresh too; else forward kinematics.

    Attributes:
        odom: ((x, y, θ), twist (vx, vy, ω)) of the latest odometry, or None.
        ee: (position, rotation) of the latest end-effector pose, or None.
        last_state: the last :class:`RobotState` made, or None.
    """

    def __init__(self, checks: MeasuredInputs, timeout: float, ground_truth: bool) -> None:
        self.checks = checks
        self.ground_truth = ground_truth
        self.fresh = {k: Freshness(timeout) for k in ('odom', 'ee_pose')}
        self.odom: tuple[np.ndarray, np.ndarray] | None = None
        self.ee: tuple[np.ndarray, np.ndarray] | None = None
        self.last_state: RobotState | None = None

    def set_timeout(self, timeout: float) -> None:
        """Judge both inputs by a new ``timeout`` [s] from now on."""
        for fresh in self.fresh.values():
            fresh.timeout = timeout

    def odometry(self, xy, quat, twist, now: float) -> list[LogEvent]:
        """Take the odometry received at ``now`` [s] when it passes :meth:`MeasuredInputs.odometry`."""
        odom, events = self.checks.odometry(xy, quat, twist)
        if odom is not None:
            self.odom = odom
            self.fresh['odom'].mark(now)
        return events

    def ee_pose(self, frame, pose, now: float) -> list[LogEvent]:
        """Take the end-effector pose received at ``now`` [s] when it passes :meth:`MeasuredInputs.ee_pose`."""
        ee, events = self.checks.ee_pose(frame, pose)
        if ee is not None:
            self.ee = ee
            self.fresh['ee_pose'].mark(now)
        return events

    def base_pose(self, now: float) -> np.ndarray | None:
        """The base pose (x, y, θ) while the odometry is fresh at ``now`` [s], else None."""
        return self.odom[0] if self.odom is not None and self.fresh['odom'].fresh(now) else None

    def state(self, q, dq, now: float) -> tuple[RobotState | None, str]:
        """The robot state of a cycle at ``now`` [s] with the arm's positions ``q`` and rates
        ``dq``, and '', or (None, the input that is missing or stale)."""
        if self.odom is None or not self.fresh['odom'].fresh(now):
            return None, 'no fresh /odom'
        ee = None
        if self.ground_truth:
            if self.ee is None or not self.fresh['ee_pose'].fresh(now):
                return None, 'no fresh /ee_pose'
            ee = self.ee
        pose, twist = self.odom
        self.last_state = RobotState(
            pose, twist, q, dq, ee_position=None if ee is None else ee[0], ee_rotation=None if ee is None else ee[1]
        )
        return self.last_state, ''
