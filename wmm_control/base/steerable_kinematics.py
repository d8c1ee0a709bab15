"""Wheel-level kinematics of a steerable wheeled base with offset steer axes (Sorour §IV).

Module ``i`` has its steer axis at hip ``h_i = (hx_i, hy_i)`` in the base frame. The
wheel centre sits at distance ``d`` (the wheel offset) to the right of the wheel heading
``u_i = (cos β_i, sin β_i)``. For a base twist ``ξ̇ = (vx, vy, ω)`` (base frame):

* rolling:   ``r_w φ̇_i = f(β_i)·ξ̇ + d β̇_i``,
  ``f(β) = [cos β, sin β, d − hy cos β + hx sin β]``  (the inverse actuation model);
* no side slip: ``g(β_i)·ξ̇ = 0``, ``g(β) = [−sin β, cos β, hx cos β + hy sin β]``.
"""

from dataclasses import dataclass

import numpy as np

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError

__all__ = ['SteerableGeometry']


@dataclass(frozen=True)
class SteerableGeometry:
    """Geometry of an N-module steerable base.

    Attributes:
        hips: steer-axis positions in the base frame [m]. Shape (N, 2).
        wheel_radius: r_w [m].
        wheel_offset: d, steer axis to wheel centre [m].
    """

    hips: np.ndarray
    wheel_radius: float
    wheel_offset: float

    def __post_init__(self):
        hips = np.asarray(self.hips, dtype=float)
        if hips.ndim != 2 or hips.shape[1] != 2 or hips.shape[0] < 2 or not np.all(np.isfinite(hips)):
            raise ConfigError(f'hips: expected a finite (N, 2) array with N >= 2, got shape {hips.shape}')
        if not (np.isfinite(self.wheel_radius) and self.wheel_radius > 0):
            raise ConfigError(f'wheel_radius must be > 0, got {self.wheel_radius}')
        if not (np.isfinite(self.wheel_offset) and self.wheel_offset >= 0):
            raise ConfigError(f'wheel_offset must be >= 0, got {self.wheel_offset}')
        object.__setattr__(self, 'hips', hips)

    @classmethod
    def from_config(cls, steerable_config):
        """Build from a :class:`wmm_control.robot_config.SteerableConfig`."""
        return cls(steerable_config.hips, steerable_config.wheel_radius, steerable_config.wheel_offset)

    @property
    def n_wheels(self):
        return self.hips.shape[0]

    def rolling_rows(self, beta):
        """Rows ``f(β_i)`` of the rolling constraint. Shape (..., N, 3) for β of shape (..., N)."""
        c, s = np.cos(beta), np.sin(beta)
        hx, hy = self.hips[:, 0], self.hips[:, 1]
        return np.stack((c, s, self.wheel_offset - hy * c + hx * s), axis=-1)

    def slip_rows(self, beta):
        """Rows ``g(β_i)`` of the no-side-slip constraint. Shape (..., N, 3) for β of shape (..., N)."""
        c, s = np.cos(beta), np.sin(beta)
        hx, hy = self.hips[:, 0], self.hips[:, 1]
        return np.stack((-s, c, hx * c + hy * s), axis=-1)

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
        wheel commands are consistent with one instantaneous centre of rotation.

        Returns:
            (vx, vy, ω) in the base frame. Shape (3,).
        """
        n = self.n_wheels
        beta = as_finite_vector(beta, n, 'beta')
        beta_dot = as_finite_vector(beta_dot, n, 'beta_dot')
        phi_dot = as_finite_vector(phi_dot, n, 'phi_dot')
        a = np.vstack((self.rolling_rows(beta), self.slip_rows(beta)))
        b = np.concatenate((self.wheel_radius * phi_dot - self.wheel_offset * beta_dot, np.zeros(n)))
        return np.linalg.lstsq(a, b, rcond=None)[0]

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
