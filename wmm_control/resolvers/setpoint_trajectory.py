"""A set-point turned into a smooth trajectory for the acceleration-level methods.

A goal pose is not a step for a PD law at acceleration level: with K_p = 20 a 10 cm step
asks 2 m/s², saturates the arm and would switch the base on. :class:`SetpointTrajectory`
goes from the start pose to the goal along the straight line and the slerp, with the quintic
time scaling ``s(τ) = 10τ³ − 15τ⁴ + 6τ⁵`` (zero velocity and acceleration at both ends).
Its duration makes the peak speeds ``1.875 d/T`` and ``1.875 θ/T`` and the peak
accelerations ``5.77 d/T²`` and ``5.77 θ/T²`` stay within the given limits.
"""

import math

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from wmm_control.geometry import rotation_error
from wmm_control.resolvers.interface import PoseTarget

__all__ = ['SetpointTrajectory']

_PEAK_SPEED = 1.875  # max of ds/dτ for the quintic
_PEAK_ACCEL = 10.0 / math.sqrt(3)  # max of d²s/dτ² for the quintic (5.7735)


class SetpointTrajectory:
    """Straight line + slerp from ``start`` to ``goal`` with a quintic time scaling.

    Args:
        start_position, start_rotation: the pose now (world) [m], (3, 3).
        goal: the :class:`~wmm_control.resolvers.PoseTarget` set-point.
        max_speed: peak linear speed [m/s]; max_accel: peak linear acceleration [m/s²].
        max_angular_speed: peak angular speed [rad/s]; max_angular_accel: [rad/s²].
    """

    def __init__(
        self,
        start_position: ArrayLike,
        start_rotation: ArrayLike,
        goal: PoseTarget,
        max_speed: float,
        max_accel: float,
        max_angular_speed: float,
        max_angular_accel: float,
    ) -> None:
        self.goal = goal
        self.p0 = np.asarray(start_position, dtype=float).copy()
        self.r0 = np.asarray(start_rotation, dtype=float).copy()
        self.dp = goal.position - self.p0
        self.rotvec = rotation_error(goal.rotation, self.r0)  # world-frame rotation vector
        d, angle = float(np.linalg.norm(self.dp)), float(np.linalg.norm(self.rotvec))
        self.duration = max(
            _PEAK_SPEED * d / max_speed,
            math.sqrt(_PEAK_ACCEL * d / max_accel),
            _PEAK_SPEED * angle / max_angular_speed,
            math.sqrt(_PEAK_ACCEL * angle / max_angular_accel),
            1e-9,
        )

    def sample(self, t: float) -> PoseTarget:
        """The reference at time ``t`` [s] since the start: pose, twist and acceleration (world)."""
        tau = min(max(t / self.duration, 0.0), 1.0)
        s = tau**3 * (10.0 - 15.0 * tau + 6.0 * tau * tau)
        ds = 30.0 * tau * tau * (1.0 - tau) ** 2 / self.duration
        dds = 60.0 * tau * (1.0 - tau) * (1.0 - 2.0 * tau) / self.duration**2
        if tau >= 1.0:
            return self.goal
        rot = pin.exp3(s * self.rotvec) @ self.r0
        return PoseTarget(
            self.p0 + s * self.dp,
            rot,
            velocity=np.concatenate((ds * self.dp, ds * self.rotvec)),
            acceleration=np.concatenate((dds * self.dp, dds * self.rotvec)),
        )
