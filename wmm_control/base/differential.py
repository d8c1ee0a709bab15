"""Differential-drive base kinematics: two wheels on one axle through the base origin.

With wheel radius ``r`` and track ``b`` (the distance between the wheels), the base-frame
twist of the wheel rates ``(φ̇_l, φ̇_r)`` is::

    vx = r (φ̇_l + φ̇_r) / 2,   vy = 0,   ω = r (φ̇_r − φ̇_l) / b

The base cannot move sideways: :meth:`DifferentialKinematics.wheel_rates` realises the
(vx, ω) part of a twist and drops vy (the least-squares answer), so no wheel command ever
implies a sideways velocity.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import TYPE_CHECKING, ClassVar, Self

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.base.fixed_axles import FixedAxles
from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError

if TYPE_CHECKING:
    from wmm_control.robot_config import DifferentialBase

__all__ = ['DifferentialKinematics']


@dataclass(frozen=True)
class DifferentialKinematics(FixedAxles):
    """Wheel rates ↔ base twist of a differential-drive base.

    Attributes:
        wheel_radius: r [m].
        track: b, distance between the two wheels [m].
    """

    wheel_radius: float
    track: float

    if TYPE_CHECKING:  # set by __post_init__; not dataclass fields
        _jv: ClassVar[np.ndarray]
        _jv_pinv: ClassVar[np.ndarray]

    def __post_init__(self):
        for name in ('wheel_radius', 'track'):
            val = getattr(self, name)
            if not (np.isfinite(val) and val > 0):
                raise ConfigError(f'{name} must be finite and > 0, got {val}')
        r, b = self.wheel_radius, self.track
        jv = np.array([[r / 2.0, r / 2.0], [0.0, 0.0], [-r / b, r / b]])
        object.__setattr__(self, '_jv', jv)
        object.__setattr__(self, '_jv_pinv', np.linalg.pinv(jv))

    @classmethod
    def from_config(cls, base: DifferentialBase) -> Self:
        """Build from a :class:`wmm_control.robot_config.DifferentialBase`."""
        return cls(base.wheel_radius, base.track)

    @property
    def jv(self) -> np.ndarray:
        """The map wheel rates (left, right) → twist (vx, vy, ω). Shape (3, 2)."""
        return self._jv.copy()

    def twist_from_wheels(self, wheel_rates: ArrayLike) -> np.ndarray:
        """Base-frame twist (vx, 0, ω) from the wheel rates (left, right) [rad/s]. Shape (3,)."""
        return self._jv @ as_finite_vector(wheel_rates, 2, 'wheel_rates')

    def wheel_rates(self, twist: ArrayLike) -> np.ndarray:
        """Wheel rates (left, right) [rad/s] of the (vx, ω) part of a twist; vy is dropped. Shape (2,)."""
        return self._jv_pinv @ as_finite_vector(twist, 3, 'twist')
