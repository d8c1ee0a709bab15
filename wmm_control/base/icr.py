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
    'hip_velocity',
    'icr_of_headings',
    'route_between',
    'tangent_pair',
    'wedge_row',
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
    """Wrap angles to [−π/2, π/2) [rad]: the difference to the nearest twin (β or β + π).

    A float gives a float, anything else an array.
    """
    if not isinstance(angle, float):
        angle = np.asarray(angle, dtype=float)
    return (angle + math.pi / 2) % math.pi - math.pi / 2


def tangent_pair(z0, z1, z2):
    """Orthonormal basis (e1, e2) of the plane tangent to the unit sphere at (z0, z1, z2).

    The chart ``z = z_c + e1 x₁ + e2 x₂`` of the ICR QP. Returns two 3-tuples of floats,
    ``e2 = z × e1``.
    """
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
    def from_steer_angles(cls, geometry, beta, scale=DEFAULT_ICR_SCALE, border=DEFAULT_ICR_BORDER, like=None):
        """The ICR that best fits steer angles β (least squares over the no-side-slip rows).

        Exact when the wheels agree on one ICR; for disagreeing wheels it is the twist
        direction minimising the side slip in the metric (vx, vy, ℓω) (:func:`icr_of_headings`).

        Args:
            geometry: a :class:`SteerableGeometry`.
            beta: steer angles [rad]. Shape (N,).
            like: optional homogeneous vector; the sign of ``z`` is chosen on its hemisphere.
        """
        beta = as_finite_vector(beta, geometry.n_wheels, 'beta')
        z = icr_of_headings(np.cos(beta).tolist(), np.sin(beta).tolist(), geometry.hip_list, scale, like)
        return cls(np.array(z), scale, border)

    def with_z(self, z):
        """A new ICR with the same scale and border."""
        return Icr(z, self.scale, self.border)

    def _with_z_unchecked(self, z):
        """:meth:`with_z` for a finite, non-zero ``z`` computed internally (no input checks)."""
        z0, z1, z2 = z
        n = math.sqrt(z0 * z0 + z1 * z1 + z2 * z2)
        icr = object.__new__(Icr)
        object.__setattr__(icr, 'z', np.array((z0 / n, z1 / n, z2 / n), dtype=float))
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

        Linear in ``z`` (:func:`hip_velocity`); it is the hip velocity under
        :attr:`twist_direction` (times a positive factor). Zero when the ICR sits on hip i.

        Args:
            hips: hip positions [m]. Shape (N, 2).

        Returns:
            Shape (N, 2).
        """
        hips = np.asarray(hips, dtype=float)
        return np.column_stack(hip_velocity(self.z, hips[:, 0], hips[:, 1], self.scale))

    def angle_to(self, other):
        """Distance to another ICR on the projective plane [rad], in [0, π/2].

        ``atan2(‖z × z'‖, |z · z'|)``: accurate for nearly equal ICRs too (the arc cosine of the
        dot product cannot resolve angles below ~1e-8 rad).
        """
        a0, a1, a2 = self.z.tolist()
        b0, b1, b2 = other.z.tolist()
        c = math.hypot(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
        return math.atan2(c, abs(a0 * b0 + a1 * b1 + a2 * b2))


def hip_velocity(z, hx, hy, scale):
    """Velocity direction of the hip (hx, hy) [m] under rotation about the ICR ``z``.

    ``v = (z₁ − hy z₂/ℓ, −z₀ + hx z₂/ℓ)`` ∝ ẑ × (hip − ICR): perpendicular to the line from
    the ICR to the hip, the heading of a wheel there (up to its twin). Works on floats and on
    arrays of hips alike.

    Returns:
        ``(vx, vy)``.
    """
    return z[1] - hy * z[2] / scale, hx * z[2] / scale - z[0]


def icr_of_headings(cos_beta, sin_beta, hips, scale, like=None):
    """Least-squares ICR of wheel headings: the kernel of :meth:`Icr.from_steer_angles`.

    The twist direction t = (vx, vy, ℓω) minimising ``Σ (g_i · t)²`` over the no-side-slip
    rows ``g_i = (−sin β_i, cos β_i, (hx_i cos β_i + hy_i sin β_i)/ℓ)`` is the eigenvector of the
    smallest eigenvalue of S = GᵀG: closed-form eigenvalue (trigonometric method), eigenvector
    the largest cross product of two rows of S − λI. Near-repeated eigenvalues fall back to an
    SVD of G. Plain floats, since it runs every control period.

    Args:
        cos_beta, sin_beta: cosines and sines of the steer angles (sequences of floats).
        hips: hip positions as (hx, hy) pairs [m].
        scale: ℓ [m].
        like: optional homogeneous vector; the result is on its hemisphere.

    Returns:
        The homogeneous ICR ``z ∝ (−vy, vx, ℓω)`` as a 3-tuple (unnormalised).
    """
    g = [(-s, c, (hx * c + hy * s) / scale) for c, s, (hx, hy) in zip(cos_beta, sin_beta, hips)]
    s00 = s01 = s02 = s11 = s12 = s22 = 0.0
    for g0, g1, g2 in g:
        s00 += g0 * g0
        s01 += g0 * g1
        s02 += g0 * g2
        s11 += g1 * g1
        s12 += g1 * g2
        s22 += g2 * g2
    q = (s00 + s11 + s22) / 3.0
    off = s01 * s01 + s02 * s02 + s12 * s12
    pp = math.sqrt(((s00 - q) ** 2 + (s11 - q) ** 2 + (s22 - q) ** 2 + 2.0 * off) / 6.0)
    t = None
    if pp > 1e-9 * q:
        b00, b11, b22 = (s00 - q) / pp, (s11 - q) / pp, (s22 - q) / pp
        b01, b02, b12 = s01 / pp, s02 / pp, s12 / pp
        det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
        phi = math.acos(min(1.0, max(-1.0, 0.5 * det))) / 3.0
        lam = q + 2.0 * pp * math.cos(phi + 2.0 * math.pi / 3.0)
        rows = ((s00 - lam, s01, s02), (s01, s11 - lam, s12), (s02, s12, s22 - lam))
        best, bn = None, 0.0
        for u, v in ((rows[0], rows[1]), (rows[0], rows[2]), (rows[1], rows[2])):
            c = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
            cn = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
            if cn > bn:
                best, bn = c, cn
        # The cross product scales with the two other eigenvalue gaps; too small: degenerate.
        if bn > 1e-12 * (pp * pp) ** 2:
            t = best
    if t is None:
        t = np.linalg.svd(np.array(g))[2][-1].tolist()
    z = (-t[1], t[0], t[2])
    if like is not None and z[0] * like[0] + z[1] * like[1] + z[2] * like[2] < 0:
        z = (-z[0], -z[1], -z[2])
    return z


def wedge_row(heading, side, hx, hy, scale, z, e1, e2):
    """One steer-limit line of the ICR QP in the chart ``z_c + e1 x₁ + e2 x₂``.

    The ICRs whose hip velocity (:func:`hip_velocity`) lies on the ``side`` (±1) of the wheel
    heading ``heading`` = (cos a, sin a) form a half-plane through the hip; in chart
    coordinates it is ``r · x ≥ lb``. A wedge is two such half-planes, for the extreme headings
    a_lo, a_hi of the period (``side`` +1 for a_lo, −1 for a_hi, times the wheel's orientation σ
    along its hip velocity): ``cross(e_lo, v) ≥ 0`` and ``cross(v, e_hi) ≥ 0``.

    Returns:
        ``(r0, r1, lb)`` normalised (‖r‖ = 1), or ``(0, 0, −inf)`` for a degenerate row.
    """
    cos_a, sin_a = heading
    c0, c1 = -side * sin_a, side * cos_a
    # row c·M z of the hip velocity v = M z, M = [[0, 1, −hy/ℓ], [−1, 0, hx/ℓ]]
    r2 = (hx * c1 - hy * c0) / scale
    a0, a1, a2 = e1
    b0, b1, b2 = e2
    w0 = -c1 * a0 + c0 * a1 + r2 * a2
    w1 = -c1 * b0 + c0 * b1 + r2 * b2
    nr = math.sqrt(w0 * w0 + w1 * w1)
    if nr <= 1e-12:
        return 0.0, 0.0, -math.inf
    z0, z1, z2 = z
    return w0 / nr, w1 / nr, (c1 * z0 - c0 * z1 - r2 * z2) / nr


def route_between(zc, zt):
    """The kernel of :func:`choose_route` on homogeneous 3-tuples (``zc`` unit, ``zt`` any norm).

    Returns:
        ``(target, route)``: ``±zt`` on the hemisphere of ``zc``, and 'direct' or 'complementary'.
    """
    if zc[0] * zt[0] + zc[1] * zt[1] + zc[2] * zt[2] < 0.0:
        zt = (-zt[0], -zt[1], -zt[2])
    return zt, ('complementary' if zc[2] * zt[2] < 0.0 else 'direct')


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
    tz, route = route_between(current.z.tolist(), target.z.tolist())
    return np.array(tz), route
