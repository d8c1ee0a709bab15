"""Seeded wheel-slip model for the kinematic base of :class:`sim_bridge.world.SimWorld`.

Real wheeled bases do not move exactly as their wheel encoders say: tyres and rollers
creep under load, more so the faster they turn, and small systematic errors (unequal
tyre radii, a floor slope, roller play) add a bias. The model turns the *nominal* base
twist ``ξ̇_nom = (vx, vy, ω)`` (the exact rolling model applied to the wheel joint rates)
into the *true* twist the base performs::

    s      = min(gain · v_rim, 1)                    slip fraction [-]
    ξ̇_true = (1 − s) · ξ̇_nom + a · (drift + n)      a = 1 while any wheel turns, else 0
    n      ~ N(0, diag(noise_std²))                  drawn once per call, seeded

* ``v_rim`` [m/s] is the mean absolute rim speed of the drive wheels (r · |φ̇| averaged
  over the wheels), so the loss grows with wheel speed;
* ``drift`` [m/s, m/s, rad/s] is a base-frame bias, applied only while the wheels turn
  (a base at rest does not creep);
* ``noise_std`` [m/s, m/s, rad/s] is the standard deviation of white velocity noise, one
  draw per call (per simulation period).

With every parameter zero (or ``slip=None`` in the world) the true twist *is* the
nominal twist: the same object, so wheel odometry and ground truth stay bit-equal.
The draws come from one ``numpy.random.Generator(PCG64(seed))``: the same seed and the
same call sequence give bit-identical results.
"""

import math
from collections.abc import Iterable
from dataclasses import dataclass

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.errors import ConfigError
from wmm_control.geometry import rotation_z, twist_to_world

__all__ = ['SlipParams', 'SlipModel', 'OdometryCovariance', 'VARIANCE_FLOOR']

#: [m², rad²] (and per s²) added to every variance: a covariance stays positive definite when
#: the model says odometry is exact (slip off, or at rest).
VARIANCE_FLOOR = 1e-9


def _triple(value, name):
    try:
        arr = np.asarray(value, dtype=float)
    except (TypeError, ValueError) as exc:
        raise ConfigError(f'{name}: expected 3 numbers, got {value!r}') from exc
    if arr.shape == ():
        arr = np.full(3, float(arr))
    if arr.shape != (3,) or not np.all(np.isfinite(arr)):
        raise ConfigError(f'{name}: expected 3 finite numbers, got {value!r}')
    return tuple(float(v) for v in arr)


@dataclass(frozen=True)
class SlipParams:
    """Parameters of :class:`SlipModel`.

    Attributes:
        gain: slip fraction per unit rim speed [1/(m/s)], >= 0. At ``gain = 0.05`` a base
            whose wheels roll at 1 m/s covers 5 % less ground than its odometry says.
        drift: base-frame twist bias (vx, vy, ω) [m/s, m/s, rad/s] while the wheels turn.
        noise_std: standard deviation of the white twist noise (vx, vy, ω)
            [m/s, m/s, rad/s]; a scalar applies to all three.
        seed: seed of the noise generator; ``None`` uses the world's seed.
    """

    gain: float = 0.0
    drift: tuple = (0.0, 0.0, 0.0)
    noise_std: tuple = (0.0, 0.0, 0.0)
    seed: int | None = None

    def __post_init__(self):
        gain = float(self.gain)
        if not math.isfinite(gain) or gain < 0.0:
            raise ConfigError(f'slip gain must be finite and >= 0, got {self.gain!r}')
        object.__setattr__(self, 'gain', gain)
        object.__setattr__(self, 'drift', _triple(self.drift, 'slip drift'))
        noise = _triple(self.noise_std, 'slip noise_std')
        if min(noise) < 0.0:
            raise ConfigError(f'slip noise_std must be >= 0, got {noise}')
        object.__setattr__(self, 'noise_std', noise)
        if self.seed is not None and (not isinstance(self.seed, (int, np.integer)) or self.seed < 0):
            raise ConfigError(f'slip seed must be a non-negative int or None, got {self.seed!r}')

    @property
    def is_zero(self) -> bool:
        """True when the model leaves every twist unchanged."""
        return self.gain == 0.0 and not any(self.drift) and not any(self.noise_std)


class SlipModel:
    """Applies :class:`SlipParams` to nominal base twists; owns the seeded generator.

    Args:
        params: the slip parameters (``None`` = no slip).
        seed: seed used when ``params.seed`` is ``None`` [-].
    """

    def __init__(self, params: SlipParams | None = None, seed: int = 0) -> None:
        self.params = params if params is not None else SlipParams()
        if not isinstance(self.params, SlipParams):
            raise ConfigError(f'slip: expected SlipParams or None, got {type(params).__name__}')
        used = self.params.seed if self.params.seed is not None else seed
        self.seed = int(used)
        self._rng = np.random.Generator(np.random.PCG64(self.seed))
        self._noise = any(self.params.noise_std)
        self._off = self.params.is_zero

    @property
    def off(self) -> bool:
        """True when the model never changes a twist."""
        return self._off

    def sample(self, rim_speed: float) -> tuple[float, tuple[float, float, float]]:
        """Slip for one period: the factor on the nominal twist and the additive bias.

        Draws the noise (one standard-normal triple per call while the wheels turn).

        Args:
            rim_speed: mean absolute rim speed of the wheels [m/s], >= 0.

        Returns:
            (keep [-], bias (vx, vy, ω) [m/s, m/s, rad/s]); the true twist is
            ``keep · ξ̇_nom + bias``. ``(1.0, (0.0, 0.0, 0.0))`` when the model is off.
        """
        if self._off:
            return 1.0, (0.0, 0.0, 0.0)
        prm = self.params
        keep = 1.0 - min(prm.gain * rim_speed, 1.0)
        if rim_speed <= 0.0:
            return keep, (0.0, 0.0, 0.0)
        dx, dy, dw = prm.drift
        if self._noise:
            n = self._rng.standard_normal(3)
            sx, sy, sw = prm.noise_std
            dx, dy, dw = dx + sx * float(n[0]), dy + sy * float(n[1]), dw + sw * float(n[2])
        return keep, (dx, dy, dw)

    def twist_error(self, nominal: ArrayLike, rim_speed: float) -> tuple[np.ndarray, np.ndarray]:
        """Expected error of the odometry twist and the variance of its random part, one period.

        Odometry reports the nominal twist; the true one differs by
        ``e = −s · ξ̇_nom + a · (drift + n)`` (module doc): its mean is
        ``a · drift − s · ξ̇_nom`` and its variance ``a · noise_std²`` (``a = 1`` while the
        wheels turn).

        Args:
            nominal: the nominal (odometry) twist (vx, vy, ω) [m/s, m/s, rad/s].
            rim_speed: mean absolute rim speed of the wheels over the period [m/s].

        Returns:
            ``(mean, variance)``, each (vx, vy, ω) [m/s, m/s, rad/s] and its square. Shape (3,).
        """
        prm = self.params
        moving = 1.0 if rim_speed > 0.0 else 0.0
        slip = min(prm.gain * rim_speed, 1.0)
        mean = moving * np.asarray(prm.drift) - slip * np.asarray(nominal, dtype=float)
        return mean, moving * np.asarray(prm.noise_std) ** 2


class OdometryCovariance:
    """Mean squared error of dead-reckoned odometry (x, y, θ) and its twist, per the slip model.

    Each period the odometry pose moves by the nominal twist held for ``dt``; the true pose by
    the nominal twist plus the twist error of :meth:`SlipModel.twist_error`. To first order the
    pose error follows ``δ⁺ = F δ + G e dt``, with ``F = ∂pose⁺/∂pose`` (the heading's effect on
    the position) and ``G`` the rotation of the base frame into the odometry frame. Its mean
    ``m`` and the covariance ``P`` of its random part propagate as
    ``m ← F m + G ē dt`` and ``P ← F P Fᵀ + G diag(σ²) Gᵀ dt²``; the reported covariance is the
    mean squared error ``P + m mᵀ`` (a systematic slip counts, as it does for a user). Every
    variance is at least :data:`VARIANCE_FLOOR`. It starts at zero: the start pose is known.
    """

    def __init__(self) -> None:
        self._mean = np.zeros(3)
        self._random = np.zeros((3, 3))
        self.twist = np.full(3, VARIANCE_FLOOR)

    @property
    def pose(self) -> np.ndarray:
        """Mean squared error of (x, y, θ) [m², m², rad² and products]. Shape (3, 3)."""
        return self._random + np.outer(self._mean, self._mean) + VARIANCE_FLOOR * np.eye(3)

    def update(
        self, theta: float, twist: Iterable[float], error_mean: ArrayLike, error_variance: ArrayLike, dt: float
    ) -> None:
        """One period at odometry heading ``theta`` [rad] (at its start) and ``twist``, with the
        twist error's mean and variance (:meth:`SlipModel.twist_error`); ``dt`` [s]."""
        vx, vy, _ = (float(v) for v in twist)
        g = rotation_z(theta)  # base-frame errors into the world
        dx, dy, _ = twist_to_world(theta, (vx, vy, 0.0)) * dt
        f = np.array([[1.0, 0.0, -dy], [0.0, 1.0, dx], [0.0, 0.0, 1.0]])
        self._mean = f @ self._mean + g @ np.asarray(error_mean) * dt
        self._random = f @ self._random @ f.T + (g * np.asarray(error_variance)) @ g.T * dt * dt
        self.twist = np.asarray(error_mean) ** 2 + np.asarray(error_variance) + VARIANCE_FLOOR
