"""Mecanum base kinematics of N ≥ 3 wheels from their positions and roller angles (Xing et al.,
eq 16, for four).

Wheel i turns about an axle along the base's y axis, at (x_i, y_i) in the base frame, with
radius R; the roller touching the floor turns freely about an axis at angle γ_i from the axle,
counter-clockwise about +z seen from above, a_i = (−sin γ_i, cos γ_i). The floor under the wheel
moves at (vx − ω y_i, vy + ω x_i) for the base twist ξ̇ = (vx, vy, ω); the wheel drives along x
at R φ̇_i and the roller lets it slide freely across a_i, so the two agree along a_i:
a_i · (vx − ω y_i − R φ̇_i, vy + ω x_i) = 0, i.e. the inverse kinematics row of wheel i::

    R φ̇_i = vx − vy / tan γ_i − (y_i + x_i / tan γ_i) ω

γ_i = 0 (rollers along the axle) gives no traction and is rejected; γ_i = ±π/2 is an omni
wheel. The N rows make the (N, 3) matrix W, φ̇ = W ξ̇; the base can make every twist when W
has rank 3. The forward kinematics (odometry) is its least-squares inverse J_V = W⁺, exact for
wheel rates that agree (W J_V W = W) and the best fit of those that do not.

Four wheels fl, fr, rl, rr at (±d1, ±d2) with γ = (π/4, −π/4, −π/4, π/4) give Xing's::

    J_V = R/4 [[   1,    1,    1,    1],
               [  -1,    1,    1,   -1],
               [-1/k,  1/k, -1/k,  1/k]],   k = d1 + d2

and the world-frame rate of (x, y, θ) is ``J_I(θ) J_V ω_w`` (eq 16, ``P = J_I J_V``).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.base.fixed_axles import FixedAxles
from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError
from wmm_control.geometry import twist_to_world

if TYPE_CHECKING:
    from wmm_control.robot_config import MecanumBase

__all__ = ['MecanumKinematics']

#: A roller angle closer than this to 0 (mod π) [rad]: rollers along the axle, no traction.
_MIN_ROLLER_ANGLE = 1e-6


@dataclass(frozen=True, eq=False)
class MecanumKinematics(FixedAxles):
    """Wheel rates ↔ base twist of a Mecanum base of N ≥ 3 wheels.

    Attributes:
        wheel_radius: R [m].
        positions: each wheel's (x, y) in the base frame [m]. Shape (N, 2).
        roller_angles: γ_i [rad] (the module docstring's convention). Shape (N,).

    Raises:
        ConfigError: a radius not > 0, positions and angles of different lengths or not
            finite, a roller along its axle, or wheels that cannot make every twist (rank < 3).
    """

    wheel_radius: float
    positions: np.ndarray
    roller_angles: np.ndarray

    if TYPE_CHECKING:  # set by __post_init__; not dataclass fields
        _inverse: ClassVar[np.ndarray]
        _jv: ClassVar[np.ndarray]

    def __post_init__(self):
        radius = self.wheel_radius
        if not (np.isfinite(radius) and radius > 0):
            raise ConfigError(f'wheel_radius must be finite and > 0, got {radius}')
        xy = np.array(self.positions, dtype=float)
        gamma = np.array(self.roller_angles, dtype=float)
        if xy.ndim != 2 or xy.shape[1] != 2 or gamma.shape != (len(xy),):
            raise ConfigError(
                f'expected N wheel positions (N, 2) and N roller angles, got shapes {xy.shape} and {gamma.shape}'
            )
        if not (np.all(np.isfinite(xy)) and np.all(np.isfinite(gamma))):
            raise ConfigError('wheel positions and roller angles must be finite')
        if np.any(np.abs(np.sin(gamma)) < _MIN_ROLLER_ANGLE):
            raise ConfigError(f'a roller along its axle (γ = 0 mod π) gives no traction: {gamma.tolist()}')
        cot = np.cos(gamma) / np.sin(gamma)
        inverse = np.column_stack((np.ones(len(xy)), -cot, -(xy[:, 1] + xy[:, 0] * cot))) / radius
        rank = np.linalg.matrix_rank(inverse)
        if rank < 3:
            raise ConfigError(
                f'{len(xy)} wheels at {xy.round(4).tolist()} with roller angles {gamma.round(4).tolist()} '
                f'make twists of rank {rank} only: a Mecanum base needs rank 3 to follow every twist'
            )
        for name, value in (('positions', xy), ('roller_angles', gamma), ('_inverse', inverse)):
            value.flags.writeable = False
            object.__setattr__(self, name, value)
        jv = np.linalg.pinv(inverse)
        jv.flags.writeable = False
        object.__setattr__(self, '_jv', jv)

    @classmethod
    def from_config(cls, base: MecanumBase) -> Self:
        """Build from a :class:`wmm_control.robot_config.MecanumBase`."""
        return cls(base.wheel_radius, base.positions, base.roller_angles)

    @classmethod
    def rectangle(cls, wheel_radius: float, d1: float, d2: float) -> Self:
        """Four wheels fl, fr, rl, rr at (±d1, ±d2) with the rollers of Xing eq (16)."""
        sx, sy = np.array([1.0, 1.0, -1.0, -1.0]), np.array([1.0, -1.0, 1.0, -1.0])
        return cls(wheel_radius, np.column_stack((sx * d1, sy * d2)), np.pi / 4 * sx * sy)

    @property
    def n_wheels(self) -> int:
        """Number of wheels N."""
        return len(self.positions)

    @property
    def inverse(self) -> np.ndarray:
        """W, the map twist (vx, vy, ω) → wheel rates. Shape (N, 3)."""
        return self._inverse.copy()

    @property
    def jv(self) -> np.ndarray:
        """J_V = W⁺, the map wheel rates → twist (vx, vy, ω). Shape (3, N)."""
        return self._jv.copy()

    def twist_from_wheels(self, wheel_rates: ArrayLike) -> np.ndarray:
        """Base-frame twist (vx, vy, ω) from wheel rates [rad/s], the least-squares fit when
        they disagree. Shape (3,)."""
        return self._jv @ as_finite_vector(wheel_rates, self.n_wheels, 'wheel_rates')

    def world_rates(self, theta: float, wheel_rates: ArrayLike) -> np.ndarray:
        """World-frame (ẋ, ẏ, θ̇) = J_I(θ) J_V ω_w (eq 16). Shape (3,)."""
        return twist_to_world(theta, self.twist_from_wheels(wheel_rates))

    def wheel_rates(self, twist: ArrayLike) -> np.ndarray:
        """Wheel rates [rad/s] that realise a base-frame twist exactly, W ξ̇. Shape (N,)."""
        return self._inverse @ as_finite_vector(twist, 3, 'twist')
