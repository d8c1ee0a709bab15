"""Mecanum base kinematics (Xing et al., eq 16).

Wheel order ``[fl, fr, rl, rr]`` (Xing's ``[fl, fr, bl, br]``). With wheel radius ``R``,
half wheelbase ``d1`` and half track ``d2``, the base-frame twist is ``J_V ω_w`` with::

    J_V = R/4 [[   1,    1,    1,    1],
               [  -1,    1,    1,   -1],
               [-1/k,  1/k, -1/k,  1/k]],   k = d1 + d2

and the world-frame rate of (x, y, θ) is ``J_I(θ) J_V ω_w`` (eq 16, ``P = J_I J_V``).
"""

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError
from wmm_control.geometry import twist_to_world
from wmm_control.robot_config import MecanumConfig

__all__ = ['MecanumKinematics']


@dataclass(frozen=True)
class MecanumKinematics:
    """Eq (16) of Xing et al. and its exact inverse.

    Attributes:
        wheel_radius: R [m].
        d1: half wheelbase, along x [m].
        d2: half track, along y [m].
    """

    wheel_radius: float
    d1: float
    d2: float

    if TYPE_CHECKING:  # set by __post_init__; not dataclass fields
        _jv: ClassVar[np.ndarray]
        _jv_pinv: ClassVar[np.ndarray]

    def __post_init__(self):
        for name in ('wheel_radius', 'd1', 'd2'):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                raise ConfigError(f'{name} must be finite and > 0, got {val}')
        k = self.d1 + self.d2
        jv = (
            self.wheel_radius
            / 4.0
            * np.array(
                [
                    [1.0, 1.0, 1.0, 1.0],
                    [-1.0, 1.0, 1.0, -1.0],
                    [-1.0 / k, 1.0 / k, -1.0 / k, 1.0 / k],
                ]
            )
        )
        object.__setattr__(self, '_jv', jv)
        # J_V has full row rank; its right inverse is exact: J_V @ J_V⁺ = I₃.
        object.__setattr__(self, '_jv_pinv', np.linalg.pinv(jv))

    @classmethod
    def from_config(cls, mecanum_config: MecanumConfig) -> Self:
        """Build from a :class:`wmm_control.robot_config.MecanumConfig`."""
        return cls(mecanum_config.wheel_radius, mecanum_config.d1, mecanum_config.d2)

    @property
    def jv(self) -> np.ndarray:
        """J_V. Shape (3, 4)."""
        return self._jv.copy()

    def twist_from_wheels(self, wheel_rates: ArrayLike) -> np.ndarray:
        """Base-frame twist (vx, vy, ω) from wheel rates [rad/s]. Shape (3,)."""
        return self._jv @ as_finite_vector(wheel_rates, 4, 'wheel_rates')

    def world_rates(self, theta: float, wheel_rates: ArrayLike) -> np.ndarray:
        """World-frame (ẋ, ẏ, θ̇) = J_I(θ) J_V ω_w (eq 16). Shape (3,)."""
        return twist_to_world(theta, self.twist_from_wheels(wheel_rates))

    def wheel_rates(self, twist: ArrayLike) -> np.ndarray:
        """Wheel rates [rad/s] that realise a base-frame twist exactly. Shape (4,).

        The inverse is ``(1/R) [[1, -1, -k], [1, 1, k], [1, 1, -k], [1, -1, k]] ξ̇``, the
        minimum-norm solution of ``J_V ω_w = ξ̇``.
        """
        return self._jv_pinv @ as_finite_vector(twist, 3, 'twist')
