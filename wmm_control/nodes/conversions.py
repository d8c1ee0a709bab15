"""ROS messages to and from the core's arrays, in one place.

A pose is a position (x, y, z) [m] and a quaternion (x, y, z, w) as ROS orders it; a planar
pose is (x, y, θ); a twist is (linear, angular) [m/s, rad/s], a planar one (vx, vy, ω). The
readers take the values as they are (no check: the nodes judge them), except the ``parse_*``
ones, which validate a command and say why they refuse it; the rotation maths is
:mod:`wmm_control.geometry`'s, imported where it is used, so that a node that
needs none of it (a base controller) starts without loading pinocchio.
"""

import math
from collections.abc import Iterable

import numpy as np
from builtin_interfaces.msg import Duration, Time
from geometry_msgs.msg import PoseStamped, Transform, Twist, TwistStamped
from nav_msgs.msg import Odometry
from std_msgs.msg import Float64MultiArray
from trajectory_msgs.msg import MultiDOFJointTrajectory, MultiDOFJointTrajectoryPoint

__all__ = [
    'pose_values',
    'set_pose',
    'set_quaternion',
    'set_rotation',
    'pose_rotation',
    'odometry_values',
    'odometry_pose',
    'set_planar_pose',
    'twist_values',
    'set_twist',
    'planar_twist',
    'set_planar_twist',
    'twist_stamped',
    'pose_stamped',
    'target_pose_stamped',
    'REFERENCE_JOINTS',
    'reference_message',
    'planned_base_values',
    'split_seconds',
    'stamp_from_seconds',
    'planar_covariance',
    'odometry',
    'float_array',
    'parse_command',
    'parse_base_reference',
]


def pose_values(pose) -> np.ndarray:
    """(x, y, z, qx, qy, qz, qw) of a ``geometry_msgs/Pose`` or ``Transform``. Shape (7,)."""
    p = pose.position if hasattr(pose, 'position') else pose.translation
    q = pose.orientation if hasattr(pose, 'orientation') else pose.rotation
    return np.array([p.x, p.y, p.z, q.x, q.y, q.z, q.w], dtype=float)


def pose_rotation(pose) -> tuple[np.ndarray, np.ndarray]:
    """(position (3,), rotation (3, 3)) of a ``geometry_msgs/Pose`` or ``Transform`` (the
    quaternion normalised)."""
    from wmm_control.geometry import matrix_from_quaternion

    values = pose_values(pose)
    return values[:3], matrix_from_quaternion(values[3:])


def set_quaternion(orientation, quat) -> None:
    """Write the quaternion (x, y, z, w) into a ``geometry_msgs/Quaternion``."""
    orientation.x, orientation.y, orientation.z, orientation.w = (float(v) for v in quat)


def set_rotation(orientation, rotation) -> None:
    """Write the quaternion of a rotation matrix into a ``geometry_msgs/Quaternion``."""
    from wmm_control.geometry import quaternion_from_matrix

    set_quaternion(orientation, quaternion_from_matrix(rotation))


def set_pose(pose, position, quat) -> None:
    """Write a position and a quaternion (x, y, z, w) into a ``geometry_msgs/Pose`` or ``Transform``."""
    if hasattr(pose, 'position'):
        p, q = pose.position, pose.orientation
    else:
        p, q = pose.translation, pose.rotation
    p.x, p.y, p.z = (float(v) for v in position)
    set_quaternion(q, quat)


def odometry_values(msg) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(position (x, y), quaternion (x, y, z, w), planar twist (vx, vy, ω)) of a ``nav_msgs/Odometry``."""
    p = msg.pose.pose.position
    values = pose_values(msg.pose.pose)
    return np.array([p.x, p.y], dtype=float), values[3:], planar_twist(msg.twist.twist)


def odometry_pose(msg) -> tuple[np.ndarray, np.ndarray]:
    """(planar pose (x, y, θ), planar twist (vx, vy, ω)) of a ``nav_msgs/Odometry``."""
    from wmm_control.geometry import yaw_from_quaternion

    xy, quat, twist = odometry_values(msg)
    return np.array([xy[0], xy[1], yaw_from_quaternion(quat)]), twist


def set_planar_pose(pose, planar) -> None:
    """Write a planar pose (x, y, θ) into a ``geometry_msgs/Pose`` (z = 0)."""
    from wmm_control.geometry import quaternion_from_yaw

    x, y, th = (float(v) for v in planar)
    set_pose(pose, (x, y, 0.0), quaternion_from_yaw(th))


def twist_values(twist) -> np.ndarray:
    """(linear, angular) of a ``geometry_msgs/Twist`` (or ``Accel``). Shape (6,)."""
    return np.array(
        [twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y, twist.angular.z], dtype=float
    )


def set_twist(twist, values) -> None:
    """Write (linear, angular) into a ``geometry_msgs/Twist`` (or ``Accel``)."""
    (twist.linear.x, twist.linear.y, twist.linear.z, twist.angular.x, twist.angular.y, twist.angular.z) = (
        float(v) for v in values
    )


def planar_twist(twist) -> np.ndarray:
    """(vx, vy, ω) of a ``geometry_msgs/Twist``. Shape (3,)."""
    return np.array([twist.linear.x, twist.linear.y, twist.angular.z], dtype=float)


def set_planar_twist(twist, values) -> None:
    """Write (vx, vy, ω) into a ``geometry_msgs/Twist``."""
    twist.linear.x, twist.linear.y, twist.angular.z = (float(v) for v in values)


def twist_stamped(stamp: Time | tuple[int, int], frame: str, twist: Iterable[float]) -> TwistStamped:
    """A ``TwistStamped`` of the planar twist (vx, vy, ω); ``stamp`` a Time or ``(sec, nanosec)``."""
    msg = TwistStamped()
    msg.header.stamp = stamp if isinstance(stamp, Time) else Time(sec=stamp[0], nanosec=stamp[1])
    msg.header.frame_id = frame
    set_planar_twist(msg.twist, twist)
    return msg


def pose_stamped(stamp: Time, frame: str, position, quat) -> PoseStamped:
    """A ``PoseStamped`` in ``frame`` of a position [m] and a quaternion (x, y, z, w)."""
    msg = PoseStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = frame
    set_pose(msg.pose, position, quat)
    return msg


def target_pose_stamped(stamp: Time, frame: str, target) -> PoseStamped:
    """A ``PoseStamped`` in ``frame`` of a :class:`~wmm_control.resolvers.PoseTarget`'s pose."""
    from wmm_control.geometry import quaternion_from_matrix

    return pose_stamped(stamp, frame, target.position, quaternion_from_matrix(target.rotation))


def _twist(values) -> Twist:
    msg = Twist()
    set_twist(msg, values)
    return msg


#: The ``joint_names`` of an ``/ee_reference`` message: the end effector, then, when a plan is
#: followed, its planned base (:func:`reference_message`), and after them the arm's joints of the
#: plan's travel posture, each by its own name.
REFERENCE_JOINTS = ('end_effector', 'base')


def reference_message(
    target, frame: str, stamp: Time, t: float, arm_joints: Iterable[str] = ()
) -> MultiDOFJointTrajectory:
    """A one-point ``MultiDOFJointTrajectory`` (an ``/ee_reference`` message) of a
    :class:`~wmm_control.resolvers.PoseTarget` at time ``t`` [s] along its trajectory:
    ``transforms[0]`` its pose, ``velocities[0]`` and ``accelerations[0]`` its twist and
    acceleration (linear, angular; world axes); with a followed plan's base (``target.base``)
    a second joint ``base``: its planned pose (x, y, 0; yaw), its world rates (ẋ, ẏ in linear,
    θ̇ in angular z) and accelerations; with the plan's travel posture (``target.base.arm``) one
    joint more per arm joint, named ``arm_joints``, its position [rad or m] in
    ``translation.x`` (the message has no scalar joints; rates and accelerations zero)
    (:func:`planned_base_values` reads them back).

    Raises:
        ValueError: a travel posture whose size is not that of ``arm_joints``.
    """
    from wmm_control.geometry import quaternion_from_matrix

    msg = MultiDOFJointTrajectory()
    msg.header.stamp = stamp
    msg.header.frame_id = frame
    msg.joint_names = list(REFERENCE_JOINTS[:1])
    point = MultiDOFJointTrajectoryPoint()
    tf = Transform()
    set_pose(tf, target.position, quaternion_from_matrix(target.rotation))
    point.transforms = [tf]
    point.velocities = [_twist(target.velocity)]
    point.accelerations = [_twist(target.acceleration)]
    if target.base is not None:
        msg.joint_names = list(REFERENCE_JOINTS)
        base = Transform()
        set_planar_pose(base, target.base.pose)
        rates, acceleration = Twist(), Twist()
        set_planar_twist(rates, target.base.rates)
        set_planar_twist(acceleration, target.base.acceleration)
        point.transforms.append(base)
        point.velocities.append(rates)
        point.accelerations.append(acceleration)
        if target.base.arm is not None:
            names = list(arm_joints)
            if len(names) != len(target.base.arm):
                raise ValueError(f'a travel posture of {len(target.base.arm)} joints, named {names}')
            msg.joint_names += names
            for q in target.base.arm:
                joint = Transform()
                joint.translation.x = float(q)
                joint.rotation.w = 1.0
                point.transforms.append(joint)
                point.velocities.append(Twist())
                point.accelerations.append(Twist())
    point.time_from_start = Duration(**split_seconds(t))
    msg.points = [point]
    return msg


def planned_base_values(msg, arm_joints: Iterable[str] = ()) -> tuple[np.ndarray, ...] | None:
    """(pose (x, y, θ), world rates, world accelerations[, travel posture]) of the planned base
    of an ``/ee_reference`` message's first point (its joint ``base``, :func:`reference_message`),
    or None when it has none. Missing rates or accelerations are zero. The travel posture is
    given when the message names joints after ``base``: the positions of ``arm_joints`` in that
    order, read by name (a joint missing, or one named twice, gives fewer positions than the arm
    has, and one without its transform NaN: the resolver rejects both)."""
    from wmm_control.geometry import unit_quaternion, yaw_from_quaternion

    names = list(msg.joint_names)
    if not msg.points or names[:2] != list(REFERENCE_JOINTS):
        return None
    point = msg.points[0]
    if len(point.transforms) < 2:
        return None
    values = pose_values(point.transforms[1])
    unit = unit_quaternion(values[3:])[0] if np.all(np.isfinite(values[3:])) else None
    yaw = math.nan if unit is None else yaw_from_quaternion(unit)  # NaN: rejected as non-finite
    pose = np.array([values[0], values[1], yaw])
    rates = planar_twist(point.velocities[1]) if len(point.velocities) > 1 else np.zeros(3)
    acceleration = planar_twist(point.accelerations[1]) if len(point.accelerations) > 1 else np.zeros(3)
    extra = names[2:]
    if not extra:
        return pose, rates, acceleration
    index = {name: 2 + k for k, name in enumerate(extra) if extra.count(name) == 1}
    arm = np.array(
        [
            point.transforms[index[n]].translation.x if index[n] < len(point.transforms) else math.nan
            for n in arm_joints
            if n in index
        ],
        dtype=float,
    )
    return pose, rates, acceleration, arm


def split_seconds(seconds: float) -> dict:
    """``sec`` and ``nanosec`` of ``seconds`` >= 0 (the fields of a ``builtin_interfaces`` Time or
    Duration), rounded to the nanosecond (never rounded up into the next second)."""
    sec = math.floor(seconds)
    return dict(sec=int(sec), nanosec=min(int(round((seconds - sec) * 1e9)), 999_999_999))


def stamp_from_seconds(seconds: float) -> Time:
    """A ``builtin_interfaces/Time`` of ``seconds`` >= 0 (:func:`split_seconds`)."""
    return Time(**split_seconds(seconds))


def planar_covariance(cov3, floor: float) -> list[float]:
    """The 6×6 row-major covariance (x, y, z, roll, pitch, yaw) of a ROS message, of a planar
    (x, y, yaw) one, shape (3, 3); z, roll and pitch (which a planar base does not move in) get
    variance ``floor``, so that the whole stays positive definite."""
    full = np.diag(np.full(6, floor))
    idx = np.array([0, 1, 5])
    full[np.ix_(idx, idx)] = cov3
    return full.ravel().tolist()


def odometry(stamp: Time, frame: str, child: str, pose, twist, covariances=None) -> Odometry:
    """A ``nav_msgs/Odometry`` of a planar pose (x, y, θ) in ``frame`` and twist (vx, vy, ω) of
    ``child``; ``covariances``, when given, are the (pose, twist) 36-entry row-major lists
    (:func:`planar_covariance`), else they stay zero (unknown)."""
    msg = Odometry()
    msg.header.stamp = stamp
    msg.header.frame_id = frame
    msg.child_frame_id = child
    set_planar_pose(msg.pose.pose, pose)
    set_planar_twist(msg.twist.twist, twist)
    if covariances is not None:
        msg.pose.covariance, msg.twist.covariance = covariances
    return msg


def float_array(values: Iterable[float]) -> Float64MultiArray:
    """A ``std_msgs/Float64MultiArray`` holding ``values``."""
    msg = Float64MultiArray()
    msg.data = [float(v) for v in values]
    return msg


def parse_command(msg: Float64MultiArray, size: int) -> tuple[np.ndarray, str] | tuple[None, str]:
    """Validate a ``Float64MultiArray`` command.

    Returns:
        ``(array, '')`` when it holds ``size`` finite numbers, else ``(None, reason)``.
    """
    data = np.asarray(msg.data, dtype=float)
    if data.shape != (size,):
        return None, f'expected {size} values, got {data.size}'
    if not np.all(np.isfinite(data)):
        return None, f'non-finite values at indices {np.flatnonzero(~np.isfinite(data)).tolist()}'
    return data, ''


def parse_base_reference(msg: TwistStamped, base_frame: str) -> tuple[np.ndarray, str] | tuple[None, str]:
    """Validate a ``/base/reference`` ``TwistStamped`` of a planar base.

    Returns:
        ``(array (vx, vy, ω), warning)`` when it is finite and in ``base_frame`` (or has an
        empty frame, taken as ``base_frame``); ``warning`` is '' unless the frame is empty or
        it moves out of the plane (ignored). Else ``(None, reason)``.
    """
    ref = np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z])
    if not np.all(np.isfinite(ref)):
        return None, f'non-finite values {ref.tolist()}'
    if msg.header.frame_id not in ('', base_frame):
        return None, f'frame {msg.header.frame_id!r}: expected {base_frame!r}'
    warnings = []
    if not msg.header.frame_id:
        warnings.append(f'empty frame_id, taken as {base_frame!r}')
    other = (msg.twist.linear.z, msg.twist.angular.x, msg.twist.angular.y)
    if any(abs(v) > 1e-9 for v in other):
        warnings.append('linear.z, angular.x, angular.y are ignored (planar base)')
    return ref, '; '.join(warnings)
