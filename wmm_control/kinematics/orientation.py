"""Orientation utilities, the package's one home for rotations: RPY (ZYX Euler) angles,
Sorour's Ω_RPY, pose errors, and quaternions as ROS messages order them, (x, y, z, w).

RPY convention (Sorour §II-A): θ = [γ, β, α] = [roll, pitch, yaw] with
``R = Rz(α) Ry(β) Rx(γ)``.
"""

import math
from collections.abc import Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector

__all__ = [
    'wrap_angle',
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
]

_Z = np.array([0.0, 0.0, 1.0])


def wrap_angle(angle: ArrayLike) -> float | np.ndarray:
    """Wrap angles [rad] to the interval (−π, π]. Works on scalars and arrays."""
    wrapped = np.remainder(np.asarray(angle, dtype=float) + np.pi, 2.0 * np.pi) - np.pi
    wrapped = np.where(wrapped == -np.pi, np.pi, wrapped)
    return float(wrapped) if np.ndim(wrapped) == 0 else wrapped


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
    err[3:] = pin.log3(np.asarray(desired_rot, dtype=float) @ np.asarray(current_rot, dtype=float).T)
    return err


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
