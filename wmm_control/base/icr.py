"""Instantaneous centre of rotation (ICR) of a steerable base, including the point at infinity.

Sorour §IV works in the Cartesian ICR plane, ``X = −vy/ω``, ``Y = vx/ω`` [m], which diverges as
ω → 0. Here an ICR is stored as a point of the *projective* plane: a unit homogeneous vector

    z ∝ (X, Y, ℓ) ∝ (−vy, vx, ℓ ω)          (ℓ = ``scale`` [m], a length that only sets the metric)

so that pure translation (ω = 0) is the ordinary point ``z = (−vy, vx, 0)/‖·‖`` on the line at
infinity, and ``z`` and ``−z`` are the same ICR (the antipodal identification of the bounded
ICR plane's opposite borders). Straight lines of the Cartesian ICR plane stay straight lines in
every gnomonic chart of this sphere, which is what keeps the steer-limit wedges linear.

For display and for the node, :attr:`Icr.point` gives the *bounded* representation: the
Cartesian point clipped to the square ``|X|, |Y| ≤ L`` (``border``); an ICR beyond the border, in
particular pure translation, sits on the border, and opposite border points are the same ICR.

Route: between two ICRs there are two straight routes on the projective line through them —
the direct segment and the *complementary* one that leaves through the border and re-enters
from the opposite side (passing through pure translation). :func:`choose_route` takes the
shorter one on the sphere, i.e. the sign of ``z*`` with ``z_curr · z* ≥ 0``. For finite ICRs
p_c, p* this is the direct route iff ``p_c · p* + ℓ² ≥ 0``: switching from an arc of radius R₁
on one side to an arc of radius R₂ on the other goes through straight-line motion iff
R₁ R₂ > ℓ², and through the base centre otherwise.
"""

import math
from dataclasses import dataclass

import numpy as np

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError, NonFiniteError

__all__ = [
    'Icr',
    'choose_route',
    'hip_velocity_matrices',
    'tangent_basis',
    'tangent_pair',
    'wrap_half_turn',
    'DEFAULT_ICR_BORDER',
    'DEFAULT_ICR_SCALE',
]

DEFAULT_ICR_BORDER = 20.0
"""Default half side L [m] of the bounded ICR square used for display (border = infinity)."""

DEFAULT_ICR_SCALE = 1.0
"""Default metric length ℓ [m] of the homogeneous ICR representation."""

_TINY = 1e-12


def wrap_half_turn(angle):
    """Wrap angles to [−π/2, π/2) [rad]: the difference to the nearest twin (β or β + π)."""
    return (np.asarray(angle, dtype=float) + np.pi / 2) % np.pi - np.pi / 2


def tangent_basis(z):
    """Orthonormal basis of the plane tangent to the unit sphere at ``z``.

    Args:
        z: unit vector. Shape (3,).

    Returns:
        E with ``Eᵀ E = I``, ``Eᵀ z = 0``. Shape (3, 2).
    """
    e1, e2 = tangent_pair(float(z[0]), float(z[1]), float(z[2]))
    return np.array((e1, e2)).T


def tangent_pair(z0, z1, z2):
    """:func:`tangent_basis` of the unit vector (z0, z1, z2) as two 3-tuples of floats (e1, e2)."""
    a = (abs(z0), abs(z1), abs(z2))
    k = 0 if a[0] <= a[1] and a[0] <= a[2] else (1 if a[1] <= a[2] else 2)
    zk = (z0, z1, z2)[k]
    e = [-zk * z0, -zk * z1, -zk * z2]
    e[k] += 1.0
    n = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    a0, a1, a2 = e[0] / n, e[1] / n, e[2] / n
    return (a0, a1, a2), (z1 * a2 - z2 * a1, z2 * a0 - z0 * a2, z0 * a1 - z1 * a0)   # e2 = z × e1


def _check_positive(value, name):
    if not (np.isfinite(value) and value > 0):
        raise ConfigError(f'{name} must be finite and > 0, got {value}')


@dataclass(frozen=True)
class Icr:
    """An ICR as a unit homogeneous vector (projective point; ``z`` and ``−z`` are equal ICRs).

    Attributes:
        z: ∝ (X, Y, ℓ) ∝ (−vy, vx, ℓω), unit norm. Shape (3,).
        scale: ℓ [m], the metric length of the homogeneous coordinate.
        border: L [m], half side of the bounded display square ``|X|, |Y| ≤ L``.
    """

    z: np.ndarray
    scale: float = DEFAULT_ICR_SCALE
    border: float = DEFAULT_ICR_BORDER

    def __post_init__(self):
        z = as_finite_vector(self.z, 3, 'z')
        n = np.linalg.norm(z)
        if n < _TINY:
            raise NonFiniteError(f'ICR: homogeneous vector {z.tolist()} has zero norm')
        _check_positive(self.scale, 'scale')
        _check_positive(self.border, 'border')
        object.__setattr__(self, 'z', z / n)

    @classmethod
    def from_point(cls, x, y, scale=DEFAULT_ICR_SCALE, border=DEFAULT_ICR_BORDER):
        """A finite ICR at (x, y) [m] in the base frame."""
        return cls(np.array([x, y, scale], dtype=float), scale, border)

    @classmethod
    def from_twist(cls, twist, scale=DEFAULT_ICR_SCALE, border=DEFAULT_ICR_BORDER):
        """The ICR of a base twist (vx, vy, ω) [m/s, m/s, rad/s], exact for ω = 0.

        Raises:
            NonFiniteError: the twist is zero (no ICR) or not finite.
        """
        t = as_finite_vector(twist, 3, 'twist')
        return cls(np.array([-t[1], t[0], scale * t[2]]), scale, border)

    @classmethod
    def from_steer_angles(cls, geometry, beta, scale=DEFAULT_ICR_SCALE, border=DEFAULT_ICR_BORDER):
        """The ICR that best fits steer angles β (least squares over the no-side-slip rows).

        Exact when the wheels agree on one ICR; for disagreeing wheels it is the twist
        direction minimising the side slip in the metric (vx, vy, ℓω).

        Args:
            geometry: a :class:`SteerableGeometry`.
            beta: steer angles [rad]. Shape (N,).
        """
        beta = as_finite_vector(beta, geometry.n_wheels, 'beta')
        c, s = np.cos(beta), np.sin(beta)
        hx, hy = geometry.hips[:, 0], geometry.hips[:, 1]
        g = np.column_stack((-s, c, (hx * c + hy * s) / scale))
        t = np.linalg.svd(g)[2][-1]          # (vx, vy, ℓω) up to scale
        return cls(np.array([-t[1], t[0], t[2]]), scale, border)

    def with_z(self, z):
        """A new ICR with the same scale and border."""
        return Icr(z, self.scale, self.border)

    def _with_z_unchecked(self, z):
        """:meth:`with_z` for a finite, non-zero ``z`` computed internally (no input checks)."""
        z = np.array(z, dtype=float)
        icr = object.__new__(Icr)
        object.__setattr__(icr, 'z', z / math.sqrt(float(z @ z)))
        object.__setattr__(icr, 'scale', self.scale)
        object.__setattr__(icr, 'border', self.border)
        return icr

    @property
    def at_infinity(self):
        """True when the ICR is on or beyond the border (max(|X|, |Y|) ≥ L), e.g. pure translation."""
        return bool(self.scale * max(abs(self.z[0]), abs(self.z[1])) >= self.border * abs(self.z[2]))

    @property
    def point(self):
        """Bounded representation (X, Y) [m], clipped to the border square. Shape (2,).

        Inside the square this is the Cartesian ICR. Beyond it (and for pure translation) it is
        the border point in the ICR's direction; which of the two opposite border points is
        returned follows the sign of ``z`` (both stand for the same ICR).
        """
        xy = self.scale * self.z[:2]
        w = self.z[2]
        m = max(abs(xy[0]), abs(xy[1]))
        if m < self.border * abs(w):
            return xy / w
        sign = -1.0 if w < 0 else 1.0
        return sign * xy * (self.border / m)

    @property
    def twist_direction(self):
        """Unit twist (vx, vy, ω) compatible with this ICR: rotation about it, ∝ (Y, −X, 1).

        For an ICR at infinity this is the pure translation perpendicular to its direction.
        Its sign follows ``z``. Shape (3,).
        """
        t = np.array([self.z[1], -self.z[0], self.z[2] / self.scale])
        return t / np.linalg.norm(t)

    def hip_velocities(self, hips):
        """Velocity direction of each hip (the wheel heading, up to its twin) for this ICR.

        Linear in ``z``: ``v_i = M_i z``, ``M_i = [[0, 1, −hy_i/ℓ], [−1, 0, hx_i/ℓ]]``; it is the
        hip velocity under :attr:`twist_direction` (times a positive factor). Zero when the ICR
        sits on hip i.

        Args:
            hips: hip positions [m]. Shape (N, 2).

        Returns:
            Shape (N, 2).
        """
        return hip_velocity_matrices(hips, self.scale) @ self.z

    def angle_to(self, other):
        """Distance to another ICR on the projective plane [rad], in [0, π/2].

        ``atan2(‖z × z'‖, |z · z'|)``: accurate for nearly equal ICRs too (the arc cosine of the
        dot product cannot resolve angles below ~1e-8 rad).
        """
        a0, a1, a2 = self.z.tolist()
        b0, b1, b2 = other.z.tolist()
        c = math.hypot(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
        return math.atan2(c, abs(a0 * b0 + a1 * b1 + a2 * b2))


def hip_velocity_matrices(hips, scale):
    """Stack of the matrices M_i with ``v_i = M_i z``. Shape (N, 2, 3)."""
    hips = np.asarray(hips, dtype=float)
    n = hips.shape[0]
    m = np.zeros((n, 2, 3))
    m[:, 0, 1] = 1.0
    m[:, 0, 2] = -hips[:, 1] / scale
    m[:, 1, 0] = -1.0
    m[:, 1, 2] = hips[:, 0] / scale
    return m


def choose_route(current, target):
    """Pick the shorter route from ``current`` to ``target`` (direct or complementary).

    Args:
        current: the ICR of the present steer configuration.
        target: the desired ICR.

    Returns:
        ``(target_z, route)``: the representative of ``target`` (``±target.z``) on the
        current's hemisphere, so that the great-circle arc current → target_z is the
        shorter route, and ``'complementary'`` if that arc passes through the line at
        infinity (pure translation) — the route out through the border and back in from the
        opposite side — else ``'direct'``.
    """
    tz = target.z if float(current.z @ target.z) >= 0.0 else -target.z
    wc, wt = current.z[2], tz[2]
    route = 'complementary' if wc * wt < 0.0 else 'direct'
    return tz, route
