"""Wheel-level kinematics of a steerable wheeled base with offset steer axes (Sorour §IV).

Module ``i`` has its steer axis at hip ``h_i = (hx_i, hy_i)`` in the base frame. The
wheel centre sits at distance ``d`` (the wheel offset) to the right of the wheel heading
``u_i = (cos β_i, sin β_i)``. For a base twist ``ξ̇ = (vx, vy, ω)`` (base frame):

* rolling:   ``r_w φ̇_i = f(β_i)·ξ̇ + d β̇_i``,
  ``f(β) = [cos β, sin β, d − hy cos β + hx sin β]``  (the inverse actuation model);
* no side slip: ``g(β_i)·ξ̇ = 0``, ``g(β) = [−sin β, cos β, hx cos β + hy sin β]``.
"""

import math
from dataclasses import dataclass, field

import numpy as np

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError

__all__ = ['SteerableGeometry', 'rolling_row', 'slip_row']


def rolling_row(c, s, hx, hy, d):
    """Rolling row ``f(β) = (cos β, sin β, d − hy cos β + hx sin β)`` from c = cos β, s = sin β.

    Floats or arrays (broadcast): one formula for the per-period kernels and the batch methods.
    """
    return c, s, d - hy * c + hx * s


def slip_row(c, s, hx, hy):
    """No-side-slip row ``g(β) = (−sin β, cos β, hx cos β + hy sin β)``; floats or arrays."""
    return -s, c, hx * c + hy * s


@dataclass(frozen=True)
class SteerableGeometry:
    """Geometry of an N-module steerable base.

    Attributes:
        hips: steer-axis positions in the base frame [m]. Shape (N, 2).
        wheel_radius: r_w [m].
        wheel_offset: d, steer axis to wheel centre [m].
        hip_list: the hips as a tuple of (hx, hy) float pairs (derived, for the per-period kernels).
    """

    hips: np.ndarray
    wheel_radius: float
    wheel_offset: float
    hip_list: tuple = field(init=False, repr=False, compare=False, default=())

    def __post_init__(self):
        hips = np.asarray(self.hips, dtype=float)
        if hips.ndim != 2 or hips.shape[1] != 2 or hips.shape[0] < 2 or not np.all(np.isfinite(hips)):
            raise ConfigError(f'hips: expected a finite (N, 2) array with N >= 2, got shape {hips.shape}')
        if not (np.isfinite(self.wheel_radius) and self.wheel_radius > 0):
            raise ConfigError(f'wheel_radius must be > 0, got {self.wheel_radius}')
        if not (np.isfinite(self.wheel_offset) and self.wheel_offset >= 0):
            raise ConfigError(f'wheel_offset must be >= 0, got {self.wheel_offset}')
        object.__setattr__(self, 'hips', hips)
        object.__setattr__(self, 'hip_list', tuple((float(hx), float(hy)) for hx, hy in hips))

    @classmethod
    def from_config(cls, steerable_config):
        """Build from a :class:`wmm_control.robot_config.SteerableConfig`."""
        return cls(steerable_config.hips, steerable_config.wheel_radius, steerable_config.wheel_offset)

    @property
    def n_wheels(self):
        return self.hips.shape[0]

    def rolling_rows(self, beta):
        """Rows ``f(β_i)`` of the rolling constraint. Shape (..., N, 3) for β of shape (..., N)."""
        return np.stack(rolling_row(np.cos(beta), np.sin(beta), self.hips[:, 0], self.hips[:, 1],
                                    self.wheel_offset), axis=-1)

    def slip_rows(self, beta):
        """Rows ``g(β_i)`` of the no-side-slip constraint. Shape (..., N, 3) for β of shape (..., N)."""
        return np.stack(slip_row(np.cos(beta), np.sin(beta), self.hips[:, 0], self.hips[:, 1]), axis=-1)

    def wheel_rates(self, beta, beta_dot, twist):
        """Inverse actuation: drive rates φ̇ [rad/s] for a base twist.

        Args:
            beta: steer angles [rad]. Shape (N,).
            beta_dot: steer rates [rad/s]. Shape (N,).
            twist: (vx, vy, ω) in the base frame [m/s, m/s, rad/s]. Shape (3,).

        Returns:
            Drive rates φ̇. Shape (N,).
        """
        n = self.n_wheels
        beta = as_finite_vector(beta, n, 'beta')
        beta_dot = as_finite_vector(beta_dot, n, 'beta_dot')
        twist = as_finite_vector(twist, 3, 'twist')
        return (self.rolling_rows(beta) @ twist + self.wheel_offset * beta_dot) / self.wheel_radius

    def twist_from_wheels(self, beta, beta_dot, phi_dot):
        """Forward kinematics: the base twist that best satisfies every wheel's constraints.

        Least squares over the N rolling and N no-side-slip equations; exact when the
        wheel commands are consistent with one instantaneous centre of rotation
        (:meth:`fit_twist` on checked arrays).

        Returns:
            (vx, vy, ω) in the base frame. Shape (3,).
        """
        n = self.n_wheels
        beta = as_finite_vector(beta, n, 'beta')
        beta_dot = as_finite_vector(beta_dot, n, 'beta_dot')
        phi_dot = as_finite_vector(phi_dot, n, 'phi_dot')
        return np.array(self.fit_twist(beta.tolist(), beta_dot.tolist(), phi_dot.tolist()))

    def fit_twist(self, beta, beta_dot, phi_dot):
        """The least-squares twist of :meth:`twist_from_wheels` on sequences of floats.

        The 3 × 3 normal equations of the rolling rows f(β_i) (right-hand side
        ``r_w φ̇_i − d β̇_i``) and the no-side-slip rows g(β_i) (right-hand side 0), solved
        by Cramer's rule: the per-period kernel that the controller runs. A (near) singular
        system falls back to ``numpy.linalg.lstsq``.

        Returns:
            ``(vx, vy, ω)`` as a 3-tuple of floats.
        """
        d, r_w = self.wheel_offset, self.wheel_radius
        n00 = n01 = n02 = n11 = n12 = n22 = b0 = b1 = b2 = 0.0
        for beta_i, rate, phi, (hx, hy) in zip(beta, beta_dot, phi_dot, self.hip_list):
            c, s = math.cos(beta_i), math.sin(beta_i)
            _, _, f2 = rolling_row(c, s, hx, hy, d)
            _, _, g2 = slip_row(c, s, hx, hy)
            rhs = r_w * phi - d * rate
            n00 += 1.0                       # c² + s²
            n02 += c * f2 - s * g2
            n12 += s * f2 + c * g2
            n22 += f2 * f2 + g2 * g2
            b0 += c * rhs
            b1 += s * rhs
            b2 += f2 * rhs
        n11 = n00                            # the (0, 1) entry c s − s c vanishes
        m00, m01, m02 = n11 * n22 - n12 * n12, n02 * n12 - n01 * n22, n01 * n12 - n02 * n11
        det = n00 * m00 + n01 * m01 + n02 * m02
        if abs(det) <= 1e-12 * n00 * n00 * max(n22, 1.0):
            a = np.vstack((self.rolling_rows(np.asarray(beta)), self.slip_rows(np.asarray(beta))))
            rhs = np.concatenate((r_w * np.asarray(phi_dot) - d * np.asarray(beta_dot), np.zeros(len(beta))))
            return tuple(np.linalg.lstsq(a, rhs, rcond=None)[0].tolist())
        m11, m12, m22 = n00 * n22 - n02 * n02, n01 * n02 - n00 * n12, n00 * n11 - n01 * n01
        return ((m00 * b0 + m01 * b1 + m02 * b2) / det,
                (m01 * b0 + m11 * b1 + m12 * b2) / det,
                (m02 * b0 + m12 * b1 + m22 * b2) / det)

    def twists_from_wheels(self, beta_sets, beta_dot, phi_dot):
        """:meth:`twist_from_wheels` for several steer-angle sets at once (same rates).

        The same least-squares fit, solved through its 3 × 3 normal equations for every set
        together; a simulator uses it for the sub-intervals of a steering period. Falls back
        to :meth:`twist_from_wheels` if a normal matrix is singular.

        Args:
            beta_sets: steer angles [rad]. Shape (S, N).
            beta_dot: steer rates [rad/s]. Shape (N,).
            phi_dot: drive rates [rad/s]. Shape (N,).

        Returns:
            Base twists (vx, vy, ω) [m/s, m/s, rad/s]. Shape (S, 3).
        """
        n = self.n_wheels
        a = np.concatenate((self.rolling_rows(beta_sets), self.slip_rows(beta_sets)), axis=-2)
        b = np.zeros((a.shape[0], 2 * n, 1))
        b[:, :n, 0] = self.wheel_radius * np.asarray(phi_dot) - self.wheel_offset * np.asarray(beta_dot)
        at = a.transpose(0, 2, 1)
        try:
            return np.linalg.solve(at @ a, at @ b)[:, :, 0]
        except np.linalg.LinAlgError:
            return np.array([self.twist_from_wheels(bb, beta_dot, phi_dot) for bb in beta_sets])

    def steer_angles_for_icr(self, icr):
        """Steer angles β_i = atan2(Y − hy_i, X − hx_i) − π/2 for a finite ICR (X, Y) [m]. Shape (N,)."""
        x, y = float(icr[0]), float(icr[1])
        return np.arctan2(y - self.hips[:, 1], x - self.hips[:, 0]) - np.pi / 2

    def steer_angles_for_translation(self, direction):
        """Steer angles for pure translation along ``direction`` (vx, vy) (ICR at infinity). Shape (N,)."""
        return np.full(self.n_wheels, np.arctan2(direction[1], direction[0]))
