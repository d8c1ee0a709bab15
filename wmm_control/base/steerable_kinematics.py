"""Wheel-level kinematics of a steerable wheeled base with offset steer axes (Sorour §IV).

Module ``i`` of N (N ≥ 2) has its steer axis at hip ``h_i = (hx_i, hy_i)`` in the base frame.
The wheel centre sits at distance ``d`` (the wheel offset) to the right of the wheel heading
``u_i = (cos β_i, sin β_i)``. For a base twist ``ξ̇ = (vx, vy, ω)`` (base frame):

* rolling:   ``r_w φ̇_i = f(β_i)·ξ̇ + d β̇_i``,
  ``f(β) = [cos β, sin β, d − hy cos β + hx sin β]``  (the inverse actuation model);
* no side slip: ``g(β_i)·ξ̇ = 0``, ``g(β) = [−sin β, cos β, hx cos β + hy sin β]``.

Every method works on all N modules at once (numpy arrays over the modules).
"""

import math
from dataclasses import dataclass, field

import numpy as np

from wmm_control.base.icr import Icr, hip_velocity_map
from wmm_control.geometry import wrap_angle
from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError

__all__ = ['SteerableGeometry']

_HIP_TOL = 1e-9
"""A hip velocity (of a unit homogeneous ICR) below this: the ICR sits on the hip, any heading fits."""


@dataclass(frozen=True)
class SteerableGeometry:
    """Geometry of an N-module steerable base (N ≥ 2).

    Attributes:
        hips: steer-axis positions in the base frame [m]. Shape (N, 2).
        wheel_radius: r_w [m].
        wheel_offset: d, steer axis to wheel centre [m].
    """

    hips: np.ndarray
    wheel_radius: float
    wheel_offset: float
    _maps: dict = field(init=False, repr=False, compare=False, default_factory=dict)
    _hip_sums: tuple = field(init=False, repr=False, compare=False, default=())
    _columns: tuple = field(init=False, repr=False, compare=False, default=())

    def __post_init__(self):
        hips = np.asarray(self.hips, dtype=float)
        if hips.ndim != 2 or hips.shape[1] != 2 or hips.shape[0] < 2 or not np.all(np.isfinite(hips)):
            raise ConfigError(f'hips: expected a finite (N, 2) array with N >= 2, got shape {hips.shape}')
        if not (np.isfinite(self.wheel_radius) and self.wheel_radius > 0):
            raise ConfigError(f'wheel_radius must be > 0, got {self.wheel_radius}')
        if not (np.isfinite(self.wheel_offset) and self.wheel_offset >= 0):
            raise ConfigError(f'wheel_offset must be >= 0, got {self.wheel_offset}')
        hips = hips.copy()
        hips.flags.writeable = False
        object.__setattr__(self, 'hips', hips)
        # hx, hy and ones, per module: contiguous vectors for the per-period products
        object.__setattr__(self, '_columns', (hips[:, 0].copy(), hips[:, 1].copy(), np.ones(hips.shape[0])))
        object.__setattr__(
            self, '_hip_sums', (float(hips[:, 0].sum()), float(hips[:, 1].sum()), float((hips * hips).sum()))
        )

    @classmethod
    def from_config(cls, base) -> 'SteerableGeometry':
        """Build from a :class:`wmm_control.robot_config.SteerableBase`."""
        return cls(base.hips, base.wheel_radius, base.wheel_offset)

    @property
    def n_wheels(self) -> int:
        return self.hips.shape[0]

    # ------------------------------------------------------------------ constraint rows
    def rolling_rows(self, beta) -> np.ndarray:
        """Rows ``f(β_i)`` of the rolling constraint. Shape (..., N, 3) for β of shape (..., N)."""
        return self._rows(beta, rolling=True)

    def slip_rows(self, beta) -> np.ndarray:
        """Rows ``g(β_i)`` of the no-side-slip constraint. Shape (..., N, 3) for β of shape (..., N)."""
        return self._rows(beta, slip=True)

    def _rows(self, beta, rolling: bool = False, slip: bool = False) -> np.ndarray:
        """The rolling rows f(β_i), then the no-side-slip rows g(β_i), of those asked for.

        Returns:
            Shape (..., N, 3) for one kind, (..., 2N, 3) for both (f first).
        """
        c, s = np.cos(beta), np.sin(beta)
        hx, hy, _ = self._columns
        n = hx.shape[0]
        out = np.empty(c.shape[:-1] + ((rolling + slip) * n, 3))
        if rolling:
            f = out[..., :n, :]
            f[..., 0], f[..., 1], f[..., 2] = c, s, self.wheel_offset - hy * c + hx * s
        if slip:
            g = out[..., -n:, :]
            g[..., 0], g[..., 1], g[..., 2] = -s, c, hx * c + hy * s
        return out

    # ------------------------------------------------------------------ inverse actuation
    def wheel_rates(self, beta, beta_dot, twist) -> np.ndarray:
        """Inverse actuation: drive rates φ̇ [rad/s] for a base twist (checked inputs).

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
        return self.drive_rates(self.rolling_rows(beta), beta_dot, twist)

    def drive_rates(self, rolling_rows: np.ndarray, beta_dot, twist) -> np.ndarray:
        """The inverse actuation model ``φ̇ = (f(β)·ξ̇ + d β̇)/r_w`` on rolling rows already at hand.

        :meth:`wheel_rates` without its input checks, for a caller that has
        :meth:`rolling_rows` of β (the controller evaluates several twists on one set of rows).

        Args:
            rolling_rows: f(β_i). Shape (N, 3).
            beta_dot: steer rates [rad/s]. Shape (N,) or a scalar.
            twist: (vx, vy, ω) [m/s, m/s, rad/s]. Shape (3,).

        Returns:
            Shape (N,).
        """
        return (rolling_rows @ twist + self.wheel_offset * beta_dot) / self.wheel_radius

    # ------------------------------------------------------------------ forward kinematics
    def twist_from_wheels(self, beta, beta_dot, phi_dot) -> np.ndarray:
        """Forward kinematics: the base twist that best satisfies every wheel's constraints.

        Least squares over the N rolling and N no-side-slip equations; exact when the
        wheel commands are consistent with one instantaneous centre of rotation
        (:meth:`fit_twist` on checked inputs).

        Returns:
            (vx, vy, ω) in the base frame. Shape (3,).
        """
        n = self.n_wheels
        beta = as_finite_vector(beta, n, 'beta')
        beta_dot = as_finite_vector(beta_dot, n, 'beta_dot')
        phi_dot = as_finite_vector(phi_dot, n, 'phi_dot')
        return self.fit_twist(beta, beta_dot, phi_dot)

    def twists_from_wheels(self, beta_sets, beta_dot, phi_dot) -> np.ndarray:
        """:meth:`twist_from_wheels` for several steer-angle sets at once (same rates).

        A simulator uses it for the sub-intervals of a steering period (:meth:`fit_twist`).

        Args:
            beta_sets: steer angles [rad]. Shape (S, N).
            beta_dot: steer rates [rad/s]. Shape (N,).
            phi_dot: drive rates [rad/s]. Shape (N,).

        Returns:
            Base twists (vx, vy, ω) [m/s, m/s, rad/s]. Shape (S, 3).
        """
        return self.fit_twist(
            np.asarray(beta_sets, dtype=float), np.asarray(beta_dot, dtype=float), np.asarray(phi_dot, dtype=float)
        )

    # ------------------------------------------------------------------ the base's joints in command order
    @property
    def steered(self) -> slice:
        """The joints, in the base's command order (steer, then drive), whose positions the
        twist reads: the steer joints (:mod:`wmm_control.base.fixed_axles`)."""
        return slice(0, self.n_wheels)

    def twist_of_joints(self, positions, rates) -> np.ndarray:
        """:meth:`twist_from_wheels` of the base's joints in command order: the positions (steer
        angles, then the drive joints', not read) and rates (steer, then drive). Shape (3,)."""
        n = self.n_wheels
        return self.twist_from_wheels(positions[:n], rates[:n], rates[n:])

    def twists_of_joints(self, position_sets, rates) -> np.ndarray:
        """:meth:`twists_from_wheels` of several sets of the base's joint positions (rows, command
        order) with the same rates. Shape (S, 3)."""
        n = self.n_wheels
        return self.twists_from_wheels(np.asarray(position_sets)[:, :n], rates[:n], rates[n:])

    def fit_twist(self, beta: np.ndarray, beta_dot: np.ndarray, phi_dot: np.ndarray) -> np.ndarray:
        """The least-squares twist of :meth:`twist_from_wheels`, without input checks.

        The 3 × 3 normal equations of the rolling rows f(β_i) (right-hand side
        ``ρ_i = r_w φ̇_i − d β̇_i``) and the no-side-slip rows g(β_i) (right-hand side 0).
        With c² + s² = 1 the normal matrix Σ f fᵀ + g gᵀ is, writing q_i = hx_i s_i − hy_i c_i
        (so that f₂ = d + q):

            [[N, 0, d Σc − Σhy], [0, N, d Σs + Σhx], [·, ·, N d² + Σ|h|² + 2 d Σq]]

        and the right-hand side (Σ c ρ, Σ s ρ, Σ q ρ + d Σ ρ): one product of (1, ρ) with
        (c, s, q) over the wheels, then Cramer's rule. A (near) singular system (wheel centres
        that coincide) is solved by ``numpy.linalg.lstsq`` instead.

        Args:
            beta: steer angles [rad]. Shape (N,), or (S, N) for S sets with the same rates.
            beta_dot, phi_dot: steer and drive rates [rad/s]. Shape (N,).

        Returns:
            (vx, vy, ω). Shape (3,), or (S, 3).
        """
        c, s = np.cos(beta), np.sin(beta)
        n, d = self.n_wheels, self.wheel_offset
        hx, hy, ones = self._columns
        rhs = self.wheel_radius * phi_dot - d * beta_dot
        # (Σ(c, s, q), Σ ρ (c, s, q)) as one product; floats for one set, arrays for several
        sums = np.array((c, s, hx * s - hy * c)) @ np.array((ones, rhs)).T  # (3, ..., 2)
        (s_c, r_c), (s_s, r_s), (s_q, r_q) = sums.tolist() if sums.ndim == 2 else np.moveaxis(sums, -1, 1)
        sum_hx, sum_hy, sum_h2 = self._hip_sums
        n02 = d * s_c - sum_hy
        n12 = d * s_s + sum_hx
        n22 = n * d * d + sum_h2 + 2.0 * d * s_q
        b2 = r_q + d * float(rhs.sum())
        # Cramer's rule for [[N, 0, n02], [0, N, n12], [n02, n12, n22]] (det = N · det_2)
        det_2 = n * n22 - n12 * n12 - n02 * n02
        if np.all(abs(det_2) > 1e-12 * n * np.maximum(n22, 1.0)):
            w2 = (n * b2 - n02 * r_c - n12 * r_s) / det_2  # ω
            return np.array(((r_c - n02 * w2) / n, (r_s - n12 * w2) / n, w2)).T
        a = self._rows(beta, rolling=True, slip=True)
        rhs2 = np.concatenate((rhs, np.zeros(n)))
        if a.ndim == 2:
            return np.linalg.lstsq(a, rhs2, rcond=None)[0]
        return np.array([np.linalg.lstsq(ai, rhs2, rcond=None)[0] for ai in a])

    # ------------------------------------------------------------------ steering for an ICR
    def hip_velocity_map(self, scale: float) -> np.ndarray:
        """:func:`~wmm_control.base.icr.hip_velocity_map` of the hips at metric length ℓ (cached).

        Returns:
            A read-only array. Shape (N, 2, 3).
        """
        m = self._maps.get(scale)
        if m is None:
            m = hip_velocity_map(self.hips, scale)
            m.flags.writeable = False
            self._maps[scale] = m
        return m

    def steer_angles_for_icr(self, icr, near=None) -> np.ndarray:
        """Steer angles whose headings follow the hip velocities of rotation about ``icr``.

        Without ``near``: β_i = atan2(v_i) of the hip velocity v_i under
        :attr:`Icr.twist_direction` (for a finite ICR (X, Y) this is
        atan2(Y − hy_i, X − hx_i) − π/2, modulo 2π). With ``near``: for each wheel the twin (β or
        β + π, drive reversed) nearest ``near_i``, ``near_i + wrap_angle(β_i − near_i, math.pi)``;
        a wheel whose hip the ICR sits on (any heading fits) keeps ``near_i``.

        Args:
            icr: an :class:`Icr` (at infinity too: pure translation), or a finite point (X, Y) [m].
            near: steer angles [rad] to stay near. Shape (N,).

        Returns:
            Shape (N,).
        """
        if isinstance(icr, Icr):
            z, scale = icr.z, icr.scale
        else:  # (X, Y, 1) as it is: v_i = (Y − hy_i, hx_i − X) without round-off
            z, scale = np.array((float(icr[0]), float(icr[1]), 1.0)), 1.0
        v = self.hip_velocity_map(scale) @ z
        vx, vy = v[:, 0], v[:, 1]
        heading = np.arctan2(vy, vx)
        if near is None:
            return heading
        delta = wrap_angle(heading - near, math.pi)
        delta[np.hypot(vx, vy) < _HIP_TOL * math.sqrt(z @ z)] = 0.0
        return near + delta
