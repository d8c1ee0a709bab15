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

Hip velocities and steer-limit wedges: the velocity of hip i under rotation about the ICR
``z`` is linear in ``z``, ``v_i = M_i z`` (:func:`hip_velocity_map`, one (2, 3) block per hip,
all hips at once); a wheel's heading lies along it (up to its twin). A bound on a wheel's
heading is a half-plane of ICRs through its hip, a linear row in ``z``; :func:`wedge_rows`
gives every wheel's rows at once in the chart of :func:`tangent_basis`.
"""

import math
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError, NonFiniteError

__all__ = [
    'Icr',
    'choose_route',
    'hip_velocity_map',
    'icr_of_headings',
    'tangent_basis',
    'wedge_rows',
    'DEFAULT_ICR_BORDER',
    'DEFAULT_ICR_SCALE',
]

DEFAULT_ICR_BORDER = 20.0
"""Default half side L [m] of the bounded ICR square used for display (border = infinity)."""

DEFAULT_ICR_SCALE = 1.0
"""Default metric length ℓ [m] of the homogeneous ICR representation."""

_TINY = 1e-12


def tangent_basis(z: ArrayLike) -> np.ndarray:
    """Orthonormal basis E = [e1 e2] of the plane tangent to the unit sphere at ``z``.

    The chart ``z_c + E x`` (x ∈ R²) of the ICR QP: e1 is the coordinate axis least aligned
    with z, made orthogonal to it, and ``e2 = z × e1``.

    Args:
        z: a unit homogeneous vector. Shape (3,).

    Returns:
        E. Shape (3, 2).
    """
    z0, z1, z2 = np.asarray(z, dtype=float).tolist()
    a = (abs(z0), abs(z1), abs(z2))
    k = 0 if a[0] <= a[1] and a[0] <= a[2] else (1 if a[1] <= a[2] else 2)
    zk = (z0, z1, z2)[k]
    e = [-zk * z0, -zk * z1, -zk * z2]
    e[k] += 1.0
    n = math.sqrt(e[0] * e[0] + e[1] * e[1] + e[2] * e[2])
    a0, a1, a2 = e[0] / n, e[1] / n, e[2] / n
    return np.array(((a0, z1 * a2 - z2 * a1), (a1, z2 * a0 - z0 * a2), (a2, z0 * a1 - z1 * a0)))


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
    def from_point(
        cls, x: float, y: float, scale: float = DEFAULT_ICR_SCALE, border: float = DEFAULT_ICR_BORDER
    ) -> 'Icr':
        """A finite ICR at (x, y) [m] in the base frame."""
        return cls(np.array([x, y, scale], dtype=float), scale, border)

    @classmethod
    def from_twist(cls, twist, scale: float = DEFAULT_ICR_SCALE, border: float = DEFAULT_ICR_BORDER) -> 'Icr':
        """The ICR of a base twist (vx, vy, ω) [m/s, m/s, rad/s], exact for ω = 0.

        Raises:
            NonFiniteError: the twist is zero (no ICR) or not finite.
        """
        t = as_finite_vector(twist, 3, 'twist')
        return cls(np.array([-t[1], t[0], scale * t[2]]), scale, border)

    @classmethod
    def from_steer_angles(
        cls, geometry, beta, scale: float = DEFAULT_ICR_SCALE, border: float = DEFAULT_ICR_BORDER, like=None
    ) -> 'Icr':
        """The ICR that best fits steer angles β (least squares over the no-side-slip rows).

        Exact when the wheels agree on one ICR; for disagreeing wheels it is the twist
        direction minimising the side slip in the metric (vx, vy, ℓω) (:func:`icr_of_headings`).

        Args:
            geometry: a :class:`SteerableGeometry`.
            beta: steer angles [rad]. Shape (N,).
            like: optional homogeneous vector; the sign of ``z`` is chosen on its hemisphere.
        """
        beta = as_finite_vector(beta, geometry.n_wheels, 'beta')
        return cls(icr_of_headings(geometry.slip_rows(beta), scale, like), scale, border)

    def with_z(self, z) -> 'Icr':
        """A new ICR with the same scale and border."""
        return Icr(z, self.scale, self.border)

    def _with_z_unchecked(self, z: np.ndarray) -> 'Icr':
        """:meth:`with_z` for a finite, non-zero ``z`` (Shape (3,)) computed internally (no input checks)."""
        icr = object.__new__(Icr)
        object.__setattr__(icr, 'z', z / math.sqrt(z @ z))
        object.__setattr__(icr, 'scale', self.scale)
        object.__setattr__(icr, 'border', self.border)
        return icr

    @property
    def at_infinity(self) -> bool:
        """True when the ICR is on or beyond the border (max(|X|, |Y|) ≥ L), e.g. pure translation."""
        return bool(self.scale * max(abs(self.z[0]), abs(self.z[1])) >= self.border * abs(self.z[2]))

    @property
    def point(self) -> np.ndarray:
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
    def twist_direction(self) -> np.ndarray:
        """Unit twist (vx, vy, ω) compatible with this ICR: rotation about it, ∝ (Y, −X, 1).

        For an ICR at infinity this is the pure translation perpendicular to its direction.
        Its sign follows ``z``. Shape (3,).
        """
        z0, z1, z2 = self.z.tolist()
        t = np.array((z1, -z0, z2 / self.scale))
        return t / math.sqrt(t @ t)

    def hip_velocities(self, hips) -> np.ndarray:
        """Velocity direction of each hip (the wheel heading, up to its twin) for this ICR.

        ``M_i z`` (:func:`hip_velocity_map`); it is the hip velocity under
        :attr:`twist_direction` (times a positive factor). Zero when the ICR sits on hip i.

        Args:
            hips: hip positions [m]. Shape (N, 2).

        Returns:
            Shape (N, 2).
        """
        return hip_velocity_map(hips, self.scale) @ self.z

    def angle_to(self, other: 'Icr') -> float:
        """Distance to another ICR on the projective plane [rad], in [0, π/2].

        ``atan2(‖z × z'‖, |z · z'|)``: accurate for nearly equal ICRs too (the arc cosine of the
        dot product cannot resolve angles below ~1e-8 rad).
        """
        a0, a1, a2 = self.z.tolist()
        b0, b1, b2 = other.z.tolist()
        c = math.hypot(a1 * b2 - a2 * b1, a2 * b0 - a0 * b2, a0 * b1 - a1 * b0)
        return math.atan2(c, abs(a0 * b0 + a1 * b1 + a2 * b2))


def hip_velocity_map(hips, scale: float) -> np.ndarray:
    """The linear maps ``z ↦ v_i`` from a homogeneous ICR to the velocity direction of each hip.

    ``M_i = [[0, 1, −hy_i/ℓ], [−1, 0, hx_i/ℓ]]``: ``v_i = M_i z = (z₁ − hy z₂/ℓ, hx z₂/ℓ − z₀)``
    ∝ ẑ × (hip − ICR), perpendicular to the line from the ICR to the hip: the heading of a
    wheel there (up to its twin). ``M @ z`` gives all hips' velocities, Shape (N, 2), and
    ``M @ Z`` for k ICRs at once (Z of Shape (3, k)) Shape (N, 2, k).

    Args:
        hips: hip positions (hx, hy) [m]. Shape (N, 2).
        scale: ℓ [m].

    Returns:
        M. Shape (N, 2, 3).
    """
    hips = np.asarray(hips, dtype=float)
    m = np.zeros((hips.shape[0], 2, 3))
    m[:, 0, 1] = 1.0
    m[:, 1, 0] = -1.0
    m[:, 0, 2] = -hips[:, 1] / scale
    m[:, 1, 2] = hips[:, 0] / scale
    return m


def icr_of_headings(slip_rows: np.ndarray, scale: float, like=None) -> np.ndarray:
    """Least-squares ICR of wheel headings: the kernel of :meth:`Icr.from_steer_angles`.

    The twist direction t = (vx, vy, ℓω) minimising ``Σ (g_i · t)²`` over the no-side-slip
    rows ``g_i = (−sin β_i, cos β_i, (hx_i cos β_i + hy_i sin β_i)/ℓ)``, ‖t‖ = 1: the eigenvector
    of the smallest eigenvalue of S = GᵀG (``numpy.linalg.eigh``).

    Args:
        slip_rows: the rows g(β_i) = (−sin β_i, cos β_i, hx_i cos β_i + hy_i sin β_i) of
            :meth:`SteerableGeometry.slip_rows`. Shape (N, 3).
        scale: ℓ [m].
        like: optional homogeneous vector; the result is on its hemisphere.

    Returns:
        The unit homogeneous ICR ``z ∝ (−vy, vx, ℓω)``. Shape (3,).
    """
    g = slip_rows * np.array((1.0, 1.0, 1.0 / scale))  # the rows' third entry over ℓ
    t = np.linalg.eigh(g.T @ g)[1][:, 0]  # eigenvalues ascending
    z = np.array((-t[1], t[0], t[2]))
    if like is not None and z @ like < 0.0:
        z = -z
    return z


def wedge_rows(
    headings: np.ndarray, sides: np.ndarray, maps: np.ndarray, zc: np.ndarray, basis: np.ndarray
) -> tuple[np.ndarray, np.ndarray]:
    """Steer-limit lines of the ICR QP, all at once, in the chart ``z = zc + E x``.

    Row k bounds the heading of the wheel whose hip velocity map is ``maps[k]``
    (:func:`hip_velocity_map`): the ICRs whose hip velocity v = M z lies on the ``sides[k]``
    (±1) side of the heading (cos a_k, sin a_k), ``σ cross((cos a, sin a), v) ≥ 0``, form a
    half-plane through the hip; in chart coordinates it is ``r_k · x ≥ lb_k``. A wheel's wedge
    is two such rows, for the extreme headings a_lo, a_hi of the period (side +σ for a_lo, −σ
    for a_hi, σ the wheel's orientation along its hip velocity).

    Args:
        headings: a_k [rad]. Shape (K,).
        sides: ±1. Shape (K,).
        maps: each row's hip velocity map. Shape (K, 2, 3).
        zc: the chart centre, a unit homogeneous ICR. Shape (3,).
        basis: the chart's tangent basis E (:func:`tangent_basis`). Shape (3, 2).

    Returns:
        ``(rows, lb)``: rows normalised (‖r_k‖ = 1), Shape (K, 2); bounds, Shape (K,). A
        degenerate row (the heading bound does not depend on the ICR) is ``0 · x ≥ −inf``.
    """
    # σ cross((cos a, sin a), M z) = σ (cos a M₁ − sin a M₀) z: the row in z, then in the chart
    in_z = (sides * np.cos(headings))[:, None] * maps[:, 1] - (sides * np.sin(headings))[:, None] * maps[:, 0]
    rows = in_z @ basis
    norms = np.hypot(rows[:, 0], rows[:, 1])
    lower = in_z @ -zc
    if norms.min() > 1e-12:
        return rows / norms[:, None], lower / norms
    degenerate = norms <= 1e-12
    norms[degenerate] = 1.0
    rows /= norms[:, None]
    lower /= norms
    rows[degenerate] = 0.0
    lower[degenerate] = -math.inf
    return rows, lower


def choose_route(current, target) -> tuple[np.ndarray, str]:
    """Pick the shorter route from ``current`` to ``target`` (direct or complementary).

    Args:
        current: the ICR of the present steer configuration: an :class:`Icr` or its unit
            homogeneous vector (Shape (3,)).
        target: the desired ICR: an :class:`Icr` or a non-zero homogeneous vector (any norm).

    Returns:
        ``(target_z, route)``: the unit representative of ``target`` (``±z``) on the
        current's hemisphere, so that the great-circle arc current → target_z is the
        shorter route, and ``'complementary'`` if that arc passes through the line at
        infinity (pure translation) — the route out through the border and back in from the
        opposite side — else ``'direct'``.
    """
    z0, z1, z2 = np.asarray(getattr(current, 'z', current), dtype=float).tolist()
    t0, t1, t2 = np.asarray(getattr(target, 'z', target), dtype=float).tolist()
    n = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
    if z0 * t0 + z1 * t1 + z2 * t2 < 0.0:
        n = -n
    return np.array((t0 / n, t1 / n, t2 / n)), ('complementary' if z2 * t2 * n < 0.0 else 'direct')
