"""Geometry, the package's one home for it (ROS-free, the lowest layer of the core): planar
poses and twists (SE(2)), rotations (SO(3) log-map errors, RPY angles, Sorour's Ω_RPY,
quaternions as ROS messages order them, (x, y, z, w)), angle wrapping, the (cos, sin) encoding
of continuous joints in pinocchio's ``q``, and scaling a vector into its limits with its
direction kept. The numerics are pinocchio's and numpy's; this module names them once.

RPY convention (Sorour §II-A): θ = [γ, β, α] = [roll, pitch, yaw] with
``R = Rz(α) Ry(β) Rx(γ)`` (also URDF's ``<origin rpy>``).

Planar poses are (x, y, θ) [m, m, rad] of a frame in another (the base in the world); planar
twists (vx, vy, ω) are in the moving frame (the base frame), world rates (ẋ, ẏ, θ̇) in the
fixed one.
"""

import math
from collections.abc import Sequence
from typing import overload

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector

__all__ = [
    'wrap_angle',
    'rotation_2d',
    'rotation_z',
    'twist_to_world',
    'twist_to_base',
    'se2_compose',
    'se2_inverse',
    'se2_transform_points',
    'se2_integrate',
    'se2_twist',
    'se3_from_planar',
    'rotation_error',
    'rotation_angle',
    'rpy_from_matrix',
    'matrix_from_rpy',
    'omega_rpy',
    'rpy_rate_map',
    'pose_error_rpy',
    'pose_error_log',
    'quaternion_from_matrix',
    'matrix_from_quaternion',
    'quaternion_multiply',
    'quaternion_from_axis_angle',
    'quaternion_from_yaw',
    'yaw_from_quaternion',
    'unit_quaternion',
    'continuous_to_q',
    'continuous_from_q',
    'angles_to_pin_q',
    'set_joint_position',
    'scale_into_limits',
    'largest_step',
    'cap_norm',
    'norm',
]

_Z = np.array([0.0, 0.0, 1.0])

Planar = Sequence[float] | np.ndarray
"""A planar pose (x, y, θ) or twist (vx, vy, ω): three numbers."""


# ---------------------------------------------------------------------- angles
@overload
def wrap_angle(angle: float, period: float = ...) -> float: ...
@overload
def wrap_angle(angle: np.ndarray, period: float = ...) -> np.ndarray: ...
def wrap_angle(angle: ArrayLike, period: float = 2.0 * math.pi) -> float | np.ndarray:
    """Wrap angles [rad] to (−period/2, period/2]: by default (−π, π]; ``period=π`` gives the
    difference to the nearer of a wheel heading's twins (β or β + π). A scalar gives a float,
    exactly (IEEE 754 remainder, ``math.remainder``, with −period/2 taken to +period/2); an
    array an array, to round-off (numpy's floored remainder after a shift by period/2)."""
    half = 0.5 * period
    value = angle if isinstance(angle, (float, int)) else np.asarray(angle, dtype=float)  # np.float64 is a float
    if isinstance(value, (float, int)) or value.ndim == 0:
        wrapped = math.remainder(float(value), period)  # in [−half, half]
        return half if wrapped == -half else wrapped
    shifted = np.remainder(value + half, period) - half
    return np.where(shifted == -half, half, shifted)


# ---------------------------------------------------------------------- SE(2)
def rotation_2d(theta: float) -> np.ndarray:
    """The planar rotation R(θ). Shape (2, 2)."""
    c, s = math.cos(theta), math.sin(theta)
    return np.array(((c, -s), (s, c)))


def rotation_z(theta: float) -> np.ndarray:
    """The rotation by θ about z, ``Rz(θ)``. Shape (3, 3)."""
    out = np.eye(3)
    out[:2, :2] = rotation_2d(theta)
    return out


def twist_to_world(theta: float, twist: ArrayLike) -> np.ndarray:
    """World rates (ẋ, ẏ, θ̇) of a frame at heading θ moving at ``twist`` = (vx, vy, ω) in its
    own axes. ``twist`` may also be a stack of twists, Shape (..., 3). Shape that of ``twist``."""
    twist = np.asarray(twist, dtype=float)
    out = twist.copy()
    out[..., :2] = twist[..., :2] @ rotation_2d(theta).T
    return out


def twist_to_base(theta: float, rates: ArrayLike) -> np.ndarray:
    """The inverse of :func:`twist_to_world`: (vx, vy, ω) in the axes of a frame at heading θ
    from world rates (ẋ, ẏ, θ̇) (or any world vector whose first two entries are planar)."""
    rates = np.asarray(rates, dtype=float)
    out = rates.copy()
    out[..., :2] = rates[..., :2] @ rotation_2d(theta)
    return out


def se2_compose(a: Planar, b: Planar) -> np.ndarray:
    """The pose ``a ∘ b``: frame b given in frame a, frame a in the world → b in the world.
    θ not wrapped. Shape (3,)."""
    xa, ya, ta = (float(v) for v in a)
    xb, yb, tb = (float(v) for v in b)
    x, y = rotation_2d(ta) @ (xb, yb)
    return np.array((xa + x, ya + y, ta + tb))


def se2_inverse(pose: Planar) -> np.ndarray:
    """The inverse pose: the world in the frame at ``pose``. Shape (3,)."""
    x, y, th = (float(v) for v in pose)
    px, py = rotation_2d(th).T @ (-x, -y)
    return np.array((px, py, -th))


def se2_transform_points(pose: Planar, points: ArrayLike) -> np.ndarray:
    """Points (x, y) given in the frame at ``pose`` (x, y, θ), in the world. Shape (N, 2) for
    points of Shape (N, 2), (2,) for one point. Invert with :func:`se2_inverse` first to take
    world points into the frame."""
    x, y, th = (float(v) for v in pose)
    return np.asarray(points, dtype=float) @ rotation_2d(th).T + (x, y)


def se2_integrate(pose: Planar, twist: Planar, dt: float) -> tuple[float, float, float]:
    """The pose after ``dt`` [s] at a constant twist (vx, vy, ω) in the moving frame: the
    SE(2) exponential ``pose ∘ exp(dt · twist)`` (pinocchio's ``exp6`` of the planar motion).

    Returns:
        (x, y, θ) as floats, θ not wrapped.
    """
    x, y, th = pose
    vx, vy, w = twist
    a = w * dt
    dxb, dyb, _ = pin.exp6(np.array((vx * dt, vy * dt, 0.0, 0.0, 0.0, a))).translation.tolist()
    c, s = math.cos(th), math.sin(th)
    return (float(x + c * dxb - s * dyb), float(y + s * dxb + c * dyb), float(th + a))


def se2_twist(start: Planar, end: Planar, dt: float) -> np.ndarray:
    """The constant twist (vx, vy, ω) in the moving frame that takes ``start`` to ``end`` in
    ``dt`` [s] (the SE(2) logarithm, pinocchio's ``log6``; the turn taken the short way, |ω dt| ≤ π):
    the inverse of :func:`se2_integrate`. Shape (3,)."""
    motion = pin.log6(se3_from_planar(start).inverse() * se3_from_planar(end)).vector
    return np.array((motion[0], motion[1], motion[5])) / dt


def se3_from_planar(pose: Planar) -> pin.SE3:
    """The placement (pinocchio SE3) of a planar pose (x, y, θ) at height zero."""
    x, y, th = (float(v) for v in pose)
    return pin.SE3(rotation_z(th), np.array((x, y, 0.0)))


# ---------------------------------------------------------------------- SO(3)
def rotation_error(desired: ArrayLike, current: ArrayLike) -> np.ndarray:
    """The SO(3) log-map orientation error ``log(R* Rᵀ)``: the world-frame rotation vector
    that takes ``current`` to ``desired``; no singularity short of a half turn. Shape (3,).
    Also for stacks of rotations, Shape (K, 3, 3) each → (K, 3)."""
    desired, current = np.asarray(desired, dtype=float), np.asarray(current, dtype=float)
    if desired.ndim == 2 and current.ndim == 2:
        return pin.log3(desired @ current.T)
    rel = desired.reshape(-1, 3, 3) @ np.swapaxes(current.reshape(-1, 3, 3), -1, -2)
    return np.array([pin.log3(r) for r in rel]).reshape(-1, 3)


def rotation_angle(desired: ArrayLike, current: ArrayLike) -> float:
    """The angle [rad] between two orientations, in [0, π]: ``‖log(R* Rᵀ)‖``."""
    return norm(rotation_error(desired, current))


# ---------------------------------------------------------------------- RPY angles
def rpy_from_matrix(rot: ArrayLike) -> np.ndarray:
    """RPY angles [roll, pitch, yaw] of a rotation matrix (ZYX Euler), by pinocchio. Shape (3,).

    ``pin.rpy.matrixToRpy``, the inverse of :func:`matrix_from_rpy`: pitch in [−π/2, π/2]; at
    the singularity (|pitch| = π/2) only roll ∓ yaw is defined, pinocchio picks the split.
    """
    return pin.rpy.matrixToRpy(np.asarray(rot, dtype=float))


def matrix_from_rpy(rpy: ArrayLike) -> np.ndarray:
    """Rotation matrix ``Rz(yaw) Ry(pitch) Rx(roll)`` from RPY angles. Shape (3, 3)."""
    roll, pitch, yaw = as_finite_vector(rpy, 3, 'rpy')
    return pin.rpy.rpyToMatrix(roll, pitch, yaw)


def omega_rpy(rpy: Sequence[float] | np.ndarray) -> np.ndarray:
    """Sorour's Ω_RPY: maps RPY rates [γ̇, β̇, α̇] to the angular velocity ω. Shape (3, 3).

    ``det Ω = cos β``: singular at pitch ±π/2.
    """
    _, beta, alpha = rpy
    ca, sa, cb, sb = np.cos(alpha), np.sin(alpha), np.cos(beta), np.sin(beta)
    return np.array([[ca * cb, -sa, 0.0], [sa * cb, ca, 0.0], [-sb, 0.0, 1.0]])


def rpy_rate_map(rpy: Sequence[float] | np.ndarray, damping: float = 1e-6) -> np.ndarray:
    """Map from a twist (v, ω) to pose rates (v, θ̇): blockdiag(I₃, Ω⁻¹). Shape (6, 6).

    Closed form of Ω⁻¹ with the one singular factor 1/cos β replaced by the damped
    ``cos β / (cos² β + ρ²)``, so the map stays finite at the pitch singularity; with the
    default ρ = 1e-6 it equals the exact inverse to about 1e-12 away from it.
    """
    _, beta, alpha = rpy
    ca, sa, cb, sb = math.cos(alpha), math.sin(alpha), math.cos(beta), math.sin(beta)
    inv_cb = cb / (cb * cb + damping * damping)
    out = np.eye(6)
    out[3, 3], out[3, 4] = ca * inv_cb, sa * inv_cb
    out[4, 3], out[4, 4] = -sa, ca
    out[5, 3], out[5, 4] = ca * sb * inv_cb, sa * sb * inv_cb
    return out


def pose_error_rpy(desired: ArrayLike, current: ArrayLike) -> np.ndarray:
    """Sorour eq (12) pose error ``e_p = p* − p`` with wrapped RPY differences. Shape (6,).

    Args:
        desired: [x, y, z, roll, pitch, yaw] [m, rad]. Shape (6,).
        current: same layout. Shape (6,).
    """
    d = as_finite_vector(desired, 6, 'desired pose')
    c = as_finite_vector(current, 6, 'current pose')
    err = d - c
    err[3:] = wrap_angle(err[3:])
    return err


def pose_error_log(
    desired_pos: ArrayLike, desired_rot: ArrayLike, current_pos: ArrayLike, current_rot: ArrayLike
) -> np.ndarray:
    """Pose error with an SO(3) log-map orientation part: ``[p* − p; log(R* Rᵀ)]``. Shape (6,).

    The rotation part is the world-frame rotation vector that takes the current
    orientation to the desired one; it has no singularity short of a half turn.
    """
    err = np.empty(6)
    err[:3] = as_finite_vector(desired_pos, 3, 'desired position') - as_finite_vector(
        current_pos, 3, 'current position'
    )
    err[3:] = rotation_error(desired_rot, current_rot)
    return err


# ---------------------------------------------------------------------- quaternions
def _pin_quaternion(quat) -> pin.Quaternion:
    """pinocchio's quaternion of ``quat`` (x, y, z, w)."""
    x, y, z, w = (float(v) for v in quat)
    return pin.Quaternion(w, x, y, z)


def unit_quaternion(quat, min_norm=1e-6) -> tuple[np.ndarray | None, float]:
    """(``quat`` (x, y, z, w, finite) scaled to unit norm, or None when its norm is below
    ``min_norm``; its norm). The norm does not overflow for entries near the largest double
    (``np.hypot``)."""
    q = np.asarray(quat, dtype=float)
    norm = float(np.hypot.reduce(q))
    return (None if norm < min_norm else q / norm), norm


def quaternion_from_matrix(rotation: np.ndarray) -> np.ndarray:
    """Unit quaternion (x, y, z, w), w ≥ 0, of a 3×3 rotation matrix (by pinocchio)."""
    q = np.array(pin.Quaternion(np.asarray(rotation, dtype=float)).normalized().coeffs())
    return -q if q[3] < 0.0 else q


def matrix_from_quaternion(quat) -> np.ndarray:
    """Rotation matrix of a quaternion (x, y, z, w), normalised first. Shape (3, 3)."""
    return _pin_quaternion(quat).normalized().toRotationMatrix()


def quaternion_multiply(a, b) -> np.ndarray:
    """The product ``a b`` of quaternions (x, y, z, w): the rotation ``b`` then ``a``. Shape (4,)."""
    return np.array((_pin_quaternion(a) * _pin_quaternion(b)).coeffs())


def quaternion_from_axis_angle(axis, angle: float) -> np.ndarray:
    """The quaternion (x, y, z, w) of a rotation by ``angle`` [rad] about the unit ``axis``. Shape (4,)."""
    return np.array(pin.Quaternion(pin.AngleAxis(float(angle), np.asarray(axis, dtype=float))).coeffs())


def quaternion_from_yaw(yaw: float) -> np.ndarray:
    """The quaternion (x, y, z, w) of a rotation by ``yaw`` [rad] about z. Shape (4,)."""
    return quaternion_from_axis_angle(_Z, yaw)


def yaw_from_quaternion(quat) -> float:
    """The heading [rad] of a quaternion (x, y, z, w), normalised first: the direction of its
    rotated x axis in the xy plane, the yaw of its ZYX Euler angles (for a planar pose, its
    rotation about z)."""
    rot = matrix_from_quaternion(quat)
    return math.atan2(rot[1, 0], rot[0, 0])


# ---------------------------------------------------------------------- continuous joints
def continuous_to_q(angle: ArrayLike) -> tuple:
    """pinocchio's configuration entries (cos θ, sin θ) of a continuous joint at angle θ [rad]
    (unbounded revolute joints have nq = 2, nv = 1). Floats for a float, arrays for an array."""
    if isinstance(angle, (int, float)):
        return math.cos(angle), math.sin(angle)
    angle = np.asarray(angle, dtype=float)
    return np.cos(angle), np.sin(angle)


@overload
def continuous_from_q(cos: float, sin: float) -> float: ...
@overload
def continuous_from_q(cos: np.ndarray, sin: np.ndarray) -> np.ndarray: ...
def continuous_from_q(cos: ArrayLike, sin: ArrayLike) -> float | np.ndarray:
    """The angle [rad] in (−π, π] of a continuous joint's (cos θ, sin θ) in pinocchio's ``q``."""
    out = np.arctan2(sin, cos)
    return float(out) if np.ndim(out) == 0 else out


def set_joint_position(q: np.ndarray, idx_q: int, nq: int, value: ArrayLike) -> None:
    """Write one joint's position into the pinocchio configuration ``q`` (in place): a
    continuous joint (nq = 2, one angle) as (cos, sin) (:func:`continuous_to_q`), any other
    joint as its ``nq`` numbers."""
    if nq == 2 and np.ndim(value) == 0:
        q[idx_q], q[idx_q + 1] = continuous_to_q(float(value))  # type: ignore[arg-type]
    else:
        q[idx_q : idx_q + nq] = value


def angles_to_pin_q(model: pin.Model, joint_angles: ArrayLike) -> np.ndarray:
    """pinocchio configuration from one number per joint velocity (angles for continuous joints).

    Continuous joints (nq = 2, nv = 1) take (cos, sin) of the angle (:func:`continuous_to_q`);
    the others take the values themselves.

    Args:
        joint_angles: one entry per velocity index. Shape (model.nv,).
    """
    values = np.asarray(joint_angles, dtype=float)
    q = pin.neutral(model)
    for joint in model.joints[1:]:
        iv = joint.idx_v
        set_joint_position(q, joint.idx_q, joint.nq, values[iv] if joint.nv == 1 else values[iv : iv + joint.nv])
    return q


# ---------------------------------------------------------------------- scaling into limits
def norm(vec: ArrayLike) -> float:
    """Euclidean norm of a vector without overflow for entries near the float range (e.g.
    1e300): ``math.hypot``."""
    return math.hypot(*np.asarray(vec, dtype=float).ravel().tolist())


def cap_norm(vec: ArrayLike, limit: float) -> np.ndarray:
    """``vec`` scaled to norm ``limit`` when it is longer, its direction kept (any finite size:
    no overflow). A new array."""
    vec = np.array(vec, dtype=float)
    length = norm(vec)
    if length > limit:
        vec *= limit / length
    return vec


def scale_into_limits(vec: ArrayLike, limits: ArrayLike, rows: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """``vec`` scaled uniformly (its direction kept) by the largest ``s ∈ [0, 1]`` that keeps
    ``|(rows @ (s vec))_k| ≤ limits_k`` for every k (``rows`` default the identity: a box).

    Any finite size (no overflow: the bound is taken on ``vec`` over its largest magnitude).

    Args:
        vec: Shape (n,).
        limits: positive bounds. Shape (m,) (n without ``rows``).
        rows: a linear map whose image is bounded. Shape (m, n).

    Returns:
        ``(s vec, s)``; ``vec`` itself (a copy) and 1 when it is within the limits. With the
        identity rows every entry of the result is within its limit exactly (clipped for
        round-off).
    """
    vec = np.array(vec, dtype=float)
    limits = np.asarray(limits, dtype=float)
    if rows is None:
        image = np.abs(vec)
    else:
        with np.errstate(over='ignore', invalid='ignore'):  # an overflow to inf (or NaN) is not within
            image = np.abs(rows @ vec)
    if (image <= limits).all():
        return vec, 1.0
    peak = float(np.max(np.abs(vec)))
    unit = vec / peak  # largest entry ±1: nothing below overflows
    image = np.abs(unit if rows is None else rows @ unit)
    with np.errstate(divide='ignore', over='ignore'):
        room = float(np.min(limits / image))  # the largest multiple of ``unit`` within the limits
    if peak <= room:
        return vec, 1.0
    out = unit * room
    if rows is None:
        np.clip(out, -limits, limits, out=out)
    return out, room / peak


def largest_step(
    start: np.ndarray, step: np.ndarray, lower: np.ndarray, upper: np.ndarray, mask: np.ndarray | None = None
) -> tuple[float, np.ndarray]:
    """Largest ``s ∈ [0, 1]`` with ``lower ≤ start + s·step ≤ upper`` (on the entries of
    ``mask``, default all): how far ``start`` may move along ``step``, its direction kept.

    Returns:
        (s, per_entry): ``per_entry`` is each entry's own largest s ≥ 0 (inf where it does
        not bind or is outside the mask, 0 where ``start`` is already out of bounds by more
        than 1e-9). Shape (n,).
    """
    per = np.where(step > 0.0, upper, lower)
    per -= start
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        per /= step
    per[step == 0.0] = np.inf  # a zero step does not bind (nor does one of 1e-300: inf)
    np.maximum(per, 0.0, out=per)
    if np.maximum(start - upper, lower - start).max(initial=-np.inf) > 1e-9:
        per[(start > upper + 1e-9) | (start < lower - 1e-9)] = 0.0
    if mask is not None:
        per[~mask] = np.inf
    return float(min(1.0, per.min(initial=np.inf))), per
