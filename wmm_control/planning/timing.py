"""Timed: a base path as poses and twists at the control period, within the base's limits.

A path is a sequence of pieces, each a motion ``pose(λ)``, λ from 0 to 1, of the base:

* :class:`TwistPiece`: at one twist (vx, vy, ω) in the base's frame, per unit of λ (an arc or a
  straight line of a Reeds–Shepp curve);
* :class:`LinearPiece`: (x, y) along a straight line while θ turns the short way, at once (a
  holonomic base's motion between two waypoints in SE(2)).

The base stops at the end of each piece (where the direction of a holonomic path or the curvature
of a Reeds–Shepp curve jumps, no finite acceleration would carry it through at speed). On each
piece λ follows a trapezoidal (or triangular) speed profile: λ̇ ≤ V, |λ̈| ≤ A. The base's twist
is ``u(λ) λ̇`` with ``u`` the twist per unit λ in the base's frame, and its rate ``u λ̈ + u' λ̇²``;
with ``U_k`` and ``U'_k`` bounds of ``|u_k|`` and ``|du_k/dλ|`` over the piece (each piece gives
them), V and A are the largest for which, on every axis k the base follows,

    U_k V ≤ v_k,   U'_k V² ≤ a_k / 2,   U_k A + U'_k V² ≤ a_k,

(v, a) the limits of the robot YAML times ``fraction`` (headroom for the controller that tracks
it). A piece's duration is rounded up to whole control periods by slowing it down (time scaled by
c ≥ 1 scales the twists by 1/c and their rates by 1/c²), so each piece starts and ends on a sample.

:func:`joint_motion` times the arm's straight joint-space motion (to the stance's posture, after
the path) on the same profile, within a fraction of the arm's joint limits.

:class:`BaseTrajectory` holds the samples: each period's pose, and the twist that takes the base
from it to the next sample's pose in one period (the SE(2) logarithm: what a base integrating a
constant twist over the period does), in the base's frame and as world rates (ẋ, ẏ, θ̇).
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Protocol

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.errors import WmmError
from wmm_control.geometry import se2_integrate, se2_twist, twist_to_world, wrap_angle
from wmm_control.robot_config import BaseSection

__all__ = ['BaseTrajectory', 'LinearPiece', 'Piece', 'TwistPiece', 'joint_motion', 'rest_to_rest', 'time_path']

#: steps of λ over which a piece's steered wheel headings are differenced (:func:`_steer_bounds`)
STEER_SAMPLES = 256

_AXES = ('vx', 'vy', 'ω')


class Piece(Protocol):
    """One motion of the base, λ from 0 to 1."""

    @property
    def start(self) -> np.ndarray:
        """The pose (x, y, θ) at λ = 0."""
        ...

    def pose(self, lam: float) -> np.ndarray:
        """The pose (x, y, θ) at λ. Shape (3,)."""
        ...

    def rate_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(U, U'): bounds of |u_k| and |du_k/dλ| over λ ∈ [0, 1], u the twist (vx, vy, ω) in
        the base's frame per unit of λ. Shapes (3,), (3,)."""
        ...

    def unit_twists(self, lam: np.ndarray) -> np.ndarray:
        """u(λ) at each λ of ``lam``: the twist (vx, vy, ω) in the base's frame per unit of λ.
        Shape (K, 3)."""
        ...


@dataclass(frozen=True)
class TwistPiece:
    """The base at one twist per unit of λ: ``pose(λ) = start ∘ exp(λ twist)``.

    Attributes:
        start: (x, y, θ). Shape (3,).
        twist: (vx, vy, ω) in the base's frame [m, m, rad per unit λ]. Shape (3,).
    """

    start: np.ndarray
    twist: np.ndarray

    def pose(self, lam: float) -> np.ndarray:
        """The pose at λ. Shape (3,)."""
        return np.array(se2_integrate(self.start, self.twist, lam))

    def rate_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """(|twist|, 0): the twist does not change."""
        return np.abs(self.twist), np.zeros(3)

    def unit_twists(self, lam: np.ndarray) -> np.ndarray:
        """The twist at every λ. Shape (K, 3)."""
        return np.tile(np.asarray(self.twist, dtype=float), (len(lam), 1))


def _max_abs_cos(lo: float, hi: float) -> float:
    """max |cos α| over α ∈ [lo, hi]."""
    if hi - lo >= math.pi or math.floor(hi / math.pi) >= math.ceil(lo / math.pi):
        return 1.0
    return max(abs(math.cos(lo)), abs(math.cos(hi)))


@dataclass(frozen=True)
class LinearPiece:
    """(x, y) along the straight line from ``start`` to ``end`` while θ turns the short way.

    Attributes:
        start, end: (x, y, θ). Shape (3,).
    """

    start: np.ndarray
    end: np.ndarray

    @property
    def delta(self) -> np.ndarray:
        """(Δx, Δy, Δθ), Δθ the short way."""
        d = np.asarray(self.end, dtype=float) - np.asarray(self.start, dtype=float)
        d[2] = wrap_angle(float(d[2]))
        return d

    def pose(self, lam: float) -> np.ndarray:
        """The pose at λ. Shape (3,)."""
        return np.asarray(self.start, dtype=float) + lam * self.delta

    def rate_bounds(self) -> tuple[np.ndarray, np.ndarray]:
        """In the base's frame u = (d cos α, d sin α, Δθ), α = φ − θ(λ) the line's bearing from
        the heading, d its length: the bounds of |cos α| and |sin α| over the turn, and
        |du/dλ| = d |Δθ| |sin α|, d |Δθ| |cos α|, 0."""
        dx, dy, dth = self.delta.tolist()
        d = math.hypot(dx, dy)
        a0 = math.atan2(dy, dx) - float(self.start[2])
        lo, hi = min(a0, a0 - dth), max(a0, a0 - dth)
        cos_max = _max_abs_cos(lo, hi)
        sin_max = _max_abs_cos(lo - 0.5 * math.pi, hi - 0.5 * math.pi)
        turn = abs(dth)
        return np.array((d * cos_max, d * sin_max, turn)), np.array((d * turn * sin_max, d * turn * cos_max, 0.0))

    def unit_twists(self, lam: np.ndarray) -> np.ndarray:
        """u(λ) = (d cos α, d sin α, Δθ), α = φ − θ(λ). Shape (K, 3)."""
        dx, dy, dth = self.delta.tolist()
        alpha = math.atan2(dy, dx) - float(self.start[2]) - dth * np.asarray(lam, dtype=float)
        d = math.hypot(dx, dy)
        return np.column_stack((d * np.cos(alpha), d * np.sin(alpha), np.full(len(alpha), dth)))


@dataclass(frozen=True)
class BaseTrajectory:
    """A timed base path, sampled at the control period.

    Attributes:
        dt: [s] the period.
        t: [s] each sample's time, from 0. Shape (K,).
        poses: (x, y, θ) in the world [m, m, rad], θ in (−π, π]. Shape (K, 3).
        twists: (vx, vy, ω) in the base's frame [m/s, m/s, rad/s], held from each sample to the
            next (zero at the last). Shape (K, 3).
        rates: the same twists as world rates (ẋ, ẏ, θ̇) at each sample. Shape (K, 3).
    """

    dt: float
    t: np.ndarray
    poses: np.ndarray
    twists: np.ndarray
    rates: np.ndarray

    @property
    def duration(self) -> float:
        """[s] from the first sample to the last."""
        return float(self.t[-1])


def _profile(speed: float, accel: float) -> tuple[float, float]:
    """(duration [s], time at full speed's start [s]) of λ from 0 to 1 at λ̇ ≤ speed, |λ̈| ≤ accel."""
    if speed * speed >= accel:  # no room to reach full speed: a triangle
        ramp = math.sqrt(1.0 / accel)
        return 2.0 * ramp, ramp
    ramp = speed / accel
    return 2.0 * ramp + (1.0 - speed * ramp) / speed, ramp


def rest_to_rest(distance: float, speed: float, accel: float) -> float:
    """[s] the least time to move ``distance`` [m or rad] from rest to rest within ``speed`` and
    ``accel`` (the profile of :func:`_profile`: accelerate, cruise, brake; without the cruise
    when there is no room for full speed): ``distance / speed + speed / accel``, or
    ``2 √(distance / accel)``."""
    if not (distance > 0.0 and speed > 0.0 and accel > 0.0):
        raise ValueError(f'distance, speed and acceleration must be > 0, got {distance}, {speed}, {accel}')
    return _profile(speed / distance, accel / distance)[0]


def _lam(t: float, duration: float, ramp: float, accel: float) -> float:
    """λ at time t of the profile of :func:`_profile`."""
    if t <= ramp:
        return 0.5 * accel * t * t
    if t >= duration - ramp:
        rest = duration - t
        return 1.0 - 0.5 * accel * rest * rest
    peak = accel * ramp
    return 0.5 * accel * ramp * ramp + peak * (t - ramp)


def _samples(speed: float, accel: float, dt: float) -> np.ndarray:
    """λ every ``dt`` [s] of the profile of :func:`_profile`, its duration rounded up to whole
    periods by slowing it down, from 0 to 1 (both included)."""
    duration, ramp = _profile(speed, accel)
    periods = max(1, math.ceil(duration / dt - 1e-9))
    stretch = periods * dt / duration  # ≥ 1: slowed to whole periods
    return np.array([_lam(k * dt / stretch, duration, ramp, accel) for k in range(periods)] + [1.0])


def joint_motion(
    q_from: ArrayLike,
    q_to: ArrayLike,
    velocity: ArrayLike,
    acceleration: ArrayLike,
    dt: float,
    fraction: float,
    max_speed: float = math.inf,
    max_accel: float = math.inf,
) -> np.ndarray:
    """The straight joint-space motion from ``q_from`` to ``q_to`` sampled every ``dt`` [s]:
    ``q_from + λ (q_to − q_from)``, λ on the trapezoidal profile of a piece (module docstring)
    at the largest speed and acceleration within ``fraction`` of the joints' ``velocity`` and
    ``acceleration`` limits and within ``max_speed`` and ``max_accel`` of λ itself [1/s, 1/s²]
    (further bounds: the end effector's), its duration rounded up to whole periods. Shape
    (K + 1, n), the first row ``q_from``, the last ``q_to``; one row when they are equal."""
    start, end = np.asarray(q_from, dtype=float), np.asarray(q_to, dtype=float)
    delta = np.abs(end - start)
    moving = delta > 0.0
    if not moving.any():
        return start[None, :].copy()
    speed = min(float((fraction * np.asarray(velocity, dtype=float)[moving] / delta[moving]).min()), max_speed)
    accel = min(float((fraction * np.asarray(acceleration, dtype=float)[moving] / delta[moving]).min()), max_accel)
    lam = _samples(speed, accel, dt)
    out = start + lam[:, None] * (end - start)
    out[-1] = end
    return out


def _steer_bounds(piece: Piece, base: BaseSection) -> tuple[np.ndarray, np.ndarray]:
    """(B, B'): bounds of |dβ_i/dλ| and |d²β_i/dλ²| over the piece, β_i each steered wheel's
    heading (modulo π) for the twist u(λ) (:meth:`~wmm_control.robot_config.BaseSection.steer_headings`),
    by differences over :data:`STEER_SAMPLES` steps of λ. Shapes (N,), (N,): empty without
    steered wheels."""
    lam = np.linspace(0.0, 1.0, STEER_SAMPLES + 1)
    headings = base.steer_headings(piece.unit_twists(lam))
    if not headings.shape[1]:
        return np.zeros(0), np.zeros(0)
    rate = wrap_angle(2.0 * np.diff(headings, axis=0)) * (0.5 * STEER_SAMPLES)  # each step modulo π
    curvature = np.diff(rate, axis=0) * STEER_SAMPLES
    return np.abs(rate).max(axis=0), np.abs(curvature).max(axis=0, initial=0.0)


def _speed_and_accel(piece: Piece, base: BaseSection, fraction: float) -> tuple[float, float] | None:
    """(V, A) of the piece within ``fraction`` of ``base``'s limits (module docstring); None for a
    piece that does not move."""
    velocity = fraction * np.asarray(base.velocity, dtype=float)
    acceleration = fraction * np.asarray(base.acceleration, dtype=float)
    bound, slope = piece.rate_bounds()
    scale = float(np.max(bound))
    if scale <= 0.0:
        return None
    moving = bound > 1e-12 * scale
    for k in np.flatnonzero(moving & ~(velocity > 0.0)).tolist():
        raise WmmError(f'the path needs {_AXES[k]} of the base, which it cannot follow (limit 0)')
    # the steered wheels' headings as further axes, within the steering's limits
    steer_bound, steer_slope = _steer_bounds(piece, base)
    steer_rate, steer_accel = base.steer_limits
    steering = steer_bound > 0.0
    bound = np.concatenate((bound[moving], steer_bound[steering]))
    slope = np.concatenate((slope[moving], steer_slope[steering]))
    velocity = np.concatenate((velocity[moving], np.full(int(steering.sum()), fraction * steer_rate)))
    acceleration = np.concatenate((acceleration[moving], np.full(int(steering.sum()), fraction * steer_accel)))
    speed = float((velocity / bound).min())
    bent = slope > 0.0
    if bent.any():
        speed = min(speed, float(np.sqrt(acceleration[bent] / (2.0 * slope[bent])).min()))
    return speed, float(((acceleration - slope * speed**2) / bound).min())


def time_path(pieces, base: BaseSection, dt: float, fraction: float = 0.95) -> BaseTrajectory:
    """The pieces one after the other, timed within ``fraction`` of the base's twist and
    acceleration limits and sampled every ``dt`` [s] (module docstring).

    Raises:
        WmmError: a piece moves the base along an axis it cannot follow (a holonomic motion for a
            differential base), or there are no pieces.
    """
    if not (dt > 0.0 and 0.0 < fraction <= 1.0):
        raise ValueError(f'dt must be > 0 and fraction in (0, 1], got {dt}, {fraction}')
    pieces = list(pieces)
    if not pieces:
        raise WmmError('a path without pieces has no timing')
    poses: list[np.ndarray] = []
    for piece in pieces:
        limits = _speed_and_accel(piece, base, fraction)
        if limits is None:
            continue
        poses += [piece.pose(lam) for lam in _samples(*limits, dt)[:-1]]
    poses.append(pieces[-1].pose(1.0))
    out = np.array(poses)
    twists = np.zeros_like(out)
    for k in range(len(out) - 1):
        twists[k] = se2_twist(out[k], out[k + 1], dt)
    rates = np.array([twist_to_world(th, tw) for th, tw in zip(out[:, 2], twists)])
    out[:, 2] = wrap_angle(out[:, 2])
    return BaseTrajectory(float(dt), dt * np.arange(len(out)), out, twists, rates)
