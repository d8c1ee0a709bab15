"""Base controller of a wheeled base whose wheel rates map linearly to its twist: Mecanum
(robot B, Xing et al. eq 16 and Table 1) and differential drive.

Each period ``dt`` the controller takes the reference base twist ξ̇* = (vx, vy, ω) [m/s, m/s,
rad/s] (base frame) and returns the wheel rates and the feasible twist q̇_bf they realise:

0. **The twists the base can follow.** The reference is projected onto them, ``J_V J_V⁺ ξ̇*``:
   all of it for a Mecanum base, (vx, 0, ω) for a differential one (no sideways motion is
   ever commanded; the projection is reported as ``dropped``).
1. **Velocity limits.** A reference beyond the base velocity limits or the wheel rate limit
   is scaled uniformly into both, as a whole: its direction is kept and the scale reported.
   A finite 1e308 therefore drives the base at its limit; NaN or infinity is an error.
2. **Acceleration limits.** The commanded twist moves towards the bounded reference; when
   the change exceeds ``accel_limit · dt`` in any component, the whole change is scaled down
   uniformly (its direction kept) so that the tightest component is exactly at its limit.
   The bounded reference and the current twist both satisfy the (convex) velocity and wheel
   limits, so every point between them does too.
3. **Wheel rates** from the exact inverse of the wheel map (eq 16 for Mecanum,
   :meth:`~wmm_control.base.mecanum.MecanumKinematics.wheel_rates`); the feasible twist is the
   map applied to them: the limited twist (to round-off).

:meth:`WheelController.stop` (a stale or missing reference) brakes at the acceleration
limits: from twist v the base is at rest after ``ceil(max_i |v_i| / a_i / dt)`` periods, i.e.
within ``max_i |v_i| / a_i + dt``.
"""

import math
from dataclasses import dataclass
from typing import Self

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.base.differential import DifferentialKinematics
from wmm_control.base.mecanum import MecanumKinematics
from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError
from wmm_control.geometry import scale_into_limits
from wmm_control.robot_config import DifferentialBase, FixedWheelBase, MecanumBase, RobotConfig

__all__ = ['WheelParams', 'WheelOutput', 'WheelController', 'wheel_kinematics']


def wheel_kinematics(robot: RobotConfig) -> MecanumKinematics | DifferentialKinematics:
    """The wheel map of a Mecanum or differential robot description.

    Raises:
        ConfigError: the robot's base is of another family.
    """
    if isinstance(robot.base, FixedWheelBase):
        return robot.base.rolling_model()
    raise ConfigError(f'robot {robot.name!r} has a {robot.base.family} base, not a Mecanum or differential one')


# A change exceeding the acceleration limit by at most this fraction is taken whole:
# it only absorbs the round-off of repeated scaling, so braking ends on an exact zero.
_SNAP = 1e-9


def _limit_vector(value, size, name):
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'WheelParams.{name}: expected {size} numbers, got {value!r}') from exc
    if arr.shape != (size,) or not np.all(np.isfinite(arr)) or np.any(arr < 0.0) or not np.any(arr > 0.0):
        raise ConfigError(
            f'WheelParams.{name}: expected {size} finite values ≥ 0 (0: an axis the base '
            f'cannot follow), got {np.ravel(arr).tolist()}'
        )
    return tuple(float(v) for v in arr)


@dataclass(frozen=True)
class WheelParams:
    """Limits and period of :class:`WheelController`.

    Attributes:
        dt: control period [s].
        velocity_limit: |vx|, |vy|, |ω| max [m/s, m/s, rad/s] (Xing Table 1: 0.25, 0.25, 1.0);
            0 on an axis the base cannot follow (a differential base's vy). Shape (3,).
        accel_limit: |v̇x|, |v̇y|, |ω̇| max [m/s², m/s², rad/s²] (Table 1: 0.025, 0.025, 1.5).
            Shape (3,).
        wheel_rate_limit: |ω_wheel| max [rad/s].
    """

    dt: float
    velocity_limit: tuple
    accel_limit: tuple
    wheel_rate_limit: float

    def __post_init__(self):
        for name in ('dt', 'wheel_rate_limit'):
            val = getattr(self, name)
            if (
                isinstance(val, bool)
                or not isinstance(val, (int, float, np.floating, np.integer))
                or not (math.isfinite(val) and val > 0)
            ):
                raise ConfigError(f'WheelParams.{name} must be a finite number > 0, got {val!r}')
            object.__setattr__(self, name, float(val))
        for name in ('velocity_limit', 'accel_limit'):
            object.__setattr__(self, name, _limit_vector(getattr(self, name), 3, name))

    @classmethod
    def from_robot_config(cls, robot: RobotConfig, dt: float) -> Self:
        """Limits from a :class:`~wmm_control.robot_config.RobotConfig` of a Mecanum or differential robot.

        Raises:
            ConfigError: the robot's base is of another family.
        """
        base = robot.base
        if not isinstance(base, (MecanumBase, DifferentialBase)):
            raise ConfigError(
                f'robot {robot.name!r} has a {base.family} base: this controller drives Mecanum and differential bases'
            )
        # __post_init__ turns the limit arrays into tuples
        return cls(
            dt=dt,
            velocity_limit=base.velocity,  # type: ignore[arg-type]
            accel_limit=base.acceleration,  # type: ignore[arg-type]
            wheel_rate_limit=base.wheel_rate_limit,
        )


@dataclass(frozen=True)
class WheelOutput:
    """One period of :class:`WheelController`.

    Attributes:
        wheel_rates: wheel rate commands [rad/s], in the robot's wheel order (the Mecanum
            ``wheel_joints``; differential left, right). Shape (m,).
        twist: feasible twist q̇_bf = the wheel map of ``wheel_rates`` (base frame). Shape (3,).
        reference: the reference after the velocity limits (zero when braking). Shape (3,).
        velocity_scale: ``reference`` = velocity_scale · the requested reference, in [0, 1].
        accel_scale: fraction of the change towards ``reference`` applied this period, in (0, 1].
        status: ``'tracking'``, ``'limited'`` (the reference was scaled into the velocity
            limits) or ``'braking'`` (:meth:`WheelController.stop`).
    """

    wheel_rates: np.ndarray
    twist: np.ndarray
    reference: np.ndarray
    velocity_scale: float
    accel_scale: float
    status: str
    dropped: np.ndarray | None = None


class WheelController:
    """Velocity- and acceleration-limited twist control of a Mecanum or differential base.

    Args:
        kinematics: the wheel map, :class:`~wmm_control.base.mecanum.MecanumKinematics`
            (eq 16) or :class:`~wmm_control.base.differential.DifferentialKinematics`.
        params: :class:`WheelParams`.
    """

    def __init__(self, kinematics: MecanumKinematics | DifferentialKinematics, params: WheelParams) -> None:
        self.kinematics = kinematics
        self.params = params
        jv = kinematics.jv
        # The inverse of the wheel map, wheel_rates(v) = M v, to bound the wheel rates of a direction.
        self._inverse = np.linalg.pinv(jv)
        # Projector onto the twists the wheels can make (identity for Mecanum).
        # (a projector of this kind has entries 0, 1 or simple fractions: rounding removes the
        # round-off that would make 1e308 overflow)
        self._followable = np.round(jv @ self._inverse, 12)
        followed = np.diag(self._followable) > 0.5
        # A zero limit on an axis the base cannot follow takes no part in the scaling.
        self._vmax = np.where(followed, np.array(params.velocity_limit), np.inf)
        self._dv_max = np.where(followed, np.array(params.accel_limit) * params.dt, np.inf)
        if np.any(np.array(params.velocity_limit)[followed] <= 0.0):
            raise ConfigError(
                f'WheelParams.velocity_limit: zero on an axis the base can follow: {params.velocity_limit}'
            )
        # bound() keeps |twist_k| ≤ velocity_limit_k and every |wheel rate| ≤ wheel_rate_limit
        self._limited_rows = np.vstack((np.eye(3), self._inverse))
        self._limits = np.concatenate((self._vmax, np.full(len(self._inverse), params.wheel_rate_limit)))
        self._twist = np.zeros(3)

    @classmethod
    def from_robot_config(cls, robot: RobotConfig, dt: float) -> Self:
        """Geometry and limits from a robot description (``config/robots/<robot>.yaml``)."""
        return cls(wheel_kinematics(robot), WheelParams.from_robot_config(robot, dt))

    @property
    def twist(self) -> np.ndarray:
        """The commanded twist (vx, vy, ω) [m/s, m/s, rad/s]. Shape (3,)."""
        return self._twist.copy()

    def reset(self, twist: ArrayLike | None = None) -> None:
        """Set the commanded twist (default rest); one beyond the limits is scaled into them.

        Raises:
            ShapeError, NonFiniteError: malformed twist.
        """
        self._twist = np.zeros(3) if twist is None else self.bound(twist)[0]

    def restart(self, wheel_rates: ArrayLike) -> None:
        """Go on from the measured wheel rates [rad/s] (the last command was not applied as sent):
        the twist they make, scaled into the limits."""
        self.reset(self.kinematics.twist_from_wheels(wheel_rates))

    def bound(self, reference: ArrayLike) -> tuple[np.ndarray, float]:
        """Scale ``reference`` uniformly into the velocity and wheel rate limits.

        Args:
            reference: (vx, vy, ω) [m/s, m/s, rad/s], within the twists the base can follow
                (:meth:`followable`); any finite size. Shape (3,).

        Returns:
            ``(bounded, scale)``: ``bounded = scale · reference`` with ``scale`` in [0, 1], 1
            (and ``reference`` itself) when it is within the limits.

        Raises:
            ShapeError, NonFiniteError: malformed reference.
        """
        ref = as_finite_vector(reference, 3, 'reference')
        return scale_into_limits(ref, self._limits, self._limited_rows)

    def followable(self, reference: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """``(followed, dropped)``: the part of ``reference`` the wheels can make and the rest.

        Raises:
            ShapeError, NonFiniteError: malformed reference.
        """
        ref = as_finite_vector(reference, 3, 'reference')
        peak = float(np.max(np.abs(ref)))
        if peak == 0.0:
            return ref.copy(), np.zeros(3)
        followed = peak * (self._followable @ (ref / peak))  # no overflow for any finite size
        return followed, ref - followed

    def step(self, reference: ArrayLike) -> WheelOutput:
        """One control period towards ``reference``.

        Args:
            reference: ξ̇* = (vx, vy, ω) in the base frame [m/s, m/s, rad/s]. Shape (3,).

        Returns:
            :class:`WheelOutput`.

        Raises:
            ShapeError, NonFiniteError: malformed reference (the state is left unchanged).
        """
        followed, dropped = self.followable(reference)
        bounded, scale = self.bound(followed)
        return self._advance(bounded, scale, 'limited' if scale < 1.0 else 'tracking', dropped)

    def stop(self) -> WheelOutput:
        """One period of braking to rest at the acceleration limits (stale or no reference)."""
        return self._advance(np.zeros(3), 1.0, 'braking', np.zeros(3))

    def _advance(self, target, scale, status, dropped):
        change = target - self._twist
        need = float(np.max(np.abs(change) / self._dv_max))
        if need <= 1.0 + _SNAP:
            self._twist = target.copy()
            accel_scale = 1.0
        else:
            accel_scale = 1.0 / need
            self._twist = self._twist + accel_scale * change
        wheels = self.kinematics.wheel_rates(self._twist)
        return WheelOutput(
            wheel_rates=wheels,
            twist=self.kinematics.twist_from_wheels(wheels),
            reference=target,
            velocity_scale=scale,
            accel_scale=accel_scale,
            status=status,
            dropped=dropped,
        )
