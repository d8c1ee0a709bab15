"""What the rolling models of bases whose wheels turn on fixed axles share (Mecanum,
differential): their twist is a function of the wheel rates alone.

Every rolling model (:meth:`~wmm_control.robot_config.BaseSection.rolling_model`) answers the
same questions of the base's joints in command order (:attr:`~wmm_control.robot_config.BaseSection.joints`),
which is what a simulator's kinematic mode and odometry have: ``steered``, the joints whose
positions the twist reads (none here; the steer joints of
:class:`~wmm_control.base.steerable_kinematics.SteerableGeometry`), ``twist_of_joints`` and
``twists_of_joints``.
"""

from __future__ import annotations

from abc import ABC, abstractmethod
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

__all__ = ['FixedAxles']


class FixedAxles(ABC):
    """The joint-order answers of a rolling model whose twist is :meth:`twist_from_wheels` of
    the wheel rates (the module docstring)."""

    #: the joints, in the base's command order, whose positions the twist reads: none
    steered: ClassVar[slice] = slice(0, 0)

    @abstractmethod
    def twist_from_wheels(self, wheel_rates: ArrayLike) -> np.ndarray:
        """Base-frame twist (vx, vy, ω) from the wheel rates [rad/s]. Shape (3,)."""

    def twist_of_joints(self, positions: ArrayLike, rates: ArrayLike) -> np.ndarray:
        """The twist of the wheel joints' positions (not read) and rates [rad/s], in command
        order. Shape (3,)."""
        return self.twist_from_wheels(rates)

    def twists_of_joints(self, position_sets: ArrayLike, rates: ArrayLike) -> np.ndarray:
        """:meth:`twist_of_joints` for several sets of positions with the same rates: the one
        twist, once per set. Shape (S, 3)."""
        return np.tile(self.twist_from_wheels(rates), (len(np.asarray(position_sets)), 1))
