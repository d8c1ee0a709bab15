"""Per-period bounds on the whole-body velocity command, and scaling into them.

The command vector is ``u = (vx, vy, ω, q̇_1 … q̇_7)``: the base twist reference (base
frame) and the arm joint velocities. Each period every entry must lie in an interval built
from

* the velocity limit ``|u_i| ≤ v_i``;
* the acceleration limit ``|u_i − u_i,prev| ≤ a_i dt`` (``u_prev``: the last command);
* for arm joints, braking in time before a position limit (Xing eqs 7–8): the largest rate
  from which braking at ``a_i``, one period at a time (the rates v, v − a dt, …, then rest),
  stops the joint within the distance ``D`` to the limit (:func:`_braking_rate`; close to
  ``v = −a dt/2 + sqrt((a dt/2)² + 2 a D)``, exactly ``D/dt`` within ``a dt²`` of the limit).
  After a period at that rate, ``v − a dt`` is within the next period's bound: braking is
  always reachable within the acceleration limit, and no period passes the limit.

A command is the sum of a *primary* part (the end-effector task, and the arm compensation of
Sorour eq 14) and a *secondary* part (the null-space pull to the dexterous posture):

1. velocity: the whole command is scaled by the largest ``s_v ∈ [0, 1]`` that keeps every
   ``|u_i| ≤ v_i``: every entry slows by the same factor, so the end effector keeps its
   direction of motion and the null-space motion keeps its share;
2. acceleration: each part changes from its own share of the previous command. The primary
   part moves the largest fraction ``s_a ∈ [0, 1]`` of its way that keeps every change
   within ``a dt`` (the whole body accelerates in step); the secondary part then moves as
   far along its own way as the room left allows, and otherwise holds its previous value.
   (A secondary part that had to drop out whenever the task's change saturated would
   switch on and off from one period to the next.)

Position limits are kept by braking joint by joint: before the steps above, the primary part
is clipped into the braking bounds and the secondary part into the room left, and the result
is clipped again into this period's box.
Scaling the whole command for a position limit instead would freeze the whole robot whenever
one joint rests at its limit with the task pulling it further; clipped, that joint stops, the
others go on, the task error they leave is taken up by the other joints in the next periods,
and the null-space motion keeps its room to move the joint away from its limit. Where braking
and acceleration bounds cannot both hold (a previous command that broke a bound, e.g. after a
reset) braking wins and the entry is reported as forced.
"""

import math
from dataclasses import dataclass
from typing import Self

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import as_vector
from wmm_control.errors import ConfigError, ShapeError
from wmm_control.geometry import largest_step
from wmm_control.robot_config import RobotConfig

__all__ = ['CommandLimits', 'LimitResult']


@dataclass(frozen=True)
class LimitResult:
    """Outcome of :meth:`CommandLimits.apply`.

    Attributes:
        command: the limited command. Shape (n,).
        secondary: the secondary share of ``command``; pass it back as ``previous_secondary``
            next period. Shape (n,).
        scale: the velocity factor s_v in [0, 1] of the primary part (1 = it fits).
        accel_scale: the acceleration factor s_a in [0, 1] of the primary part (1 = its
            change fits).
        secondary_scale: ‖secondary share‖ / ‖secondary part asked‖, in [0, 1] (1 when none
            was asked).
        limited: indices whose bound set a factor below 1, or that were clipped or forced.
        lower, upper: the period's box, acceleration included. Shape (n,) each.
        requested: the command within the braking and velocity bounds, before the acceleration
            bound's uniform factors (the change the method asks for this period). Shape (n,).
    """

    command: np.ndarray
    secondary: np.ndarray
    scale: float
    accel_scale: float
    secondary_scale: float
    limited: tuple
    lower: np.ndarray
    upper: np.ndarray
    requested: np.ndarray


class CommandLimits:
    """Velocity, acceleration and position-braking bounds of a command vector.

    Args:
        velocity: velocity limits per entry (> 0). Shape (n,).
        acceleration: acceleration limits per entry (> 0). Shape (n,).
        position_lower, position_upper: position limits of the entries that have one
            (±inf for the others, e.g. the base twist). Shape (n,).
        dt: control period [s].

    Raises:
        ConfigError: non-positive or non-finite limits, or inconsistent shapes.
    """

    def __init__(
        self,
        velocity: ArrayLike,
        acceleration: ArrayLike,
        position_lower: ArrayLike,
        position_upper: ArrayLike,
        dt: float,
    ) -> None:
        self.velocity = np.asarray(velocity, dtype=float)
        n = self.velocity.size
        self.acceleration = np.asarray(acceleration, dtype=float)
        self.position_lower = np.asarray(position_lower, dtype=float)
        self.position_upper = np.asarray(position_upper, dtype=float)
        for name in ('velocity', 'acceleration', 'position_lower', 'position_upper'):
            if getattr(self, name).shape != (n,):
                raise ConfigError(f'CommandLimits.{name}: expected shape ({n},), got {getattr(self, name).shape}')
        for name in ('velocity', 'acceleration'):
            v = getattr(self, name)
            if not np.all(np.isfinite(v)) or np.any(v <= 0):
                raise ConfigError(f'CommandLimits.{name}: every entry must be finite and > 0, got {v.tolist()}')
        if np.any(self.position_lower >= self.position_upper):
            raise ConfigError('CommandLimits: position_lower must be below position_upper')
        if not (np.isfinite(dt) and dt > 0):
            raise ConfigError(f'CommandLimits.dt must be finite and > 0, got {dt}')
        self.dt = float(dt)
        self.n = n
        self._adt = self.acceleration * self.dt
        self._shape = (n,)
        self._zero = np.zeros(n)
        self._inf = np.full(n, np.inf)
        self._neg_velocity = -self.velocity
        # the entries with a position limit, twice: their distances below (position − lower) and
        # above (−(position − upper), the same number as upper − position) in one array
        bounded = np.flatnonzero(np.isfinite(self.position_lower) | np.isfinite(self.position_upper))
        self._bounded = bounded
        self._bounded2 = np.tile(bounded, 2)
        self._limit2 = np.concatenate((self.position_lower[bounded], self.position_upper[bounded]))
        self._sign2 = np.repeat((1.0, -1.0), bounded.size)
        self._rate_constants = _BrakingConstants.of(np.tile(self._adt[bounded], 2), self.dt)
        self._room_constants = _BrakingConstants.of(np.tile(self._adt, 2), self.dt)
        self._last_braking: tuple[tuple, tuple[np.ndarray, ...]] = ((), (self._zero,) * 5)

    def braking_rates(self, position: ArrayLike, room=None, previous=None) -> tuple[np.ndarray, np.ndarray]:
        """Largest rates towards the lower and upper position limits from which braking stops in time.

        Args:
            position: current positions (any value for entries without limits). Shape (n,).
            room: ``(down, up)``, how far each entry may still move down and up this period,
                beyond its position limits' own [unit] (inf: no end; a followed plan's base,
                :meth:`~wmm_control.resolvers.interface.BaseReference.braking_room`), or None.
                Shape (n,) each. An entry whose ``previous`` rate (shape (n,)) heads beyond what
                its room allows brakes from it at its acceleration limit: a room that shrinks
                at once (its plan slowed) never asks for more than the limit.

        Returns:
            (down, up): non-negative rate bounds [unit/s]; inf where there is no limit. Shape (n,) each.
        """
        down, up = self._braking(as_vector(position, self.n, 'position'), room, previous)[:2]
        return down.copy(), up.copy()

    def box(self, position: ArrayLike, previous: ArrayLike, room=None) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """This period's interval for every entry (``room``: as :meth:`braking_rates`'s).

        Velocity and braking bounds always contain zero. The acceleration interval around
        ``previous`` is intersected with them; where the two do not meet (a previous command
        that broke a bound, e.g. after a reset), the point of the velocity/braking interval
        nearest the acceleration interval is the only one allowed.

        Returns:
            (lower, upper, forced): Shape (n,) each; ``forced`` flags the entries above.
        """
        previous = as_vector(previous, self.n, 'previous command')
        braking = self._braking(as_vector(position, self.n, 'position'), room, previous)
        lower, upper, forced = self._box(braking, previous, previous - self._adt, previous + self._adt)
        return lower, upper, np.zeros(self.n, dtype=bool) if forced is None else forced

    @classmethod
    def for_robot(cls, robot: RobotConfig, dt: float) -> Self:
        """Limits of the whole-body command (base, q̇_1 … q̇_n) of a robot description.

        The base entries are the twist axes the base can follow (``robot.base.axes``: vx, vy,
        ω, or vx, ω for a differential base), with the robot YAML's base velocity and
        acceleration limits and no position limits; the arm has its joint limits.
        """
        arm, axes = robot.arm, list(robot.base.axes)
        inf = np.full(len(axes), np.inf)
        return cls(
            velocity=np.concatenate((robot.base.velocity[axes], arm.velocity)),
            acceleration=np.concatenate((robot.base.acceleration[axes], arm.acceleration)),
            position_lower=np.concatenate((-inf, arm.position_lower)),
            position_upper=np.concatenate((inf, arm.position_upper)),
            dt=dt,
        )

    def subset(self, index: slice | np.ndarray) -> 'CommandLimits':
        """The limits of some entries only (``index``: a slice or an index array)."""
        return CommandLimits(
            self.velocity[index],
            self.acceleration[index],
            self.position_lower[index],
            self.position_upper[index],
            self.dt,
        )

    def apply(self, primary, position, previous, secondary=None, previous_secondary=None, room=None):
        """Bring ``primary + secondary`` into this period's bounds (see the module docstring).

        The arguments are arrays of shape (n,) (any sequence of n numbers is taken); their
        values are not checked again here, where a resolver calls this twice a period: the
        positions are a checked :class:`~wmm_control.resolvers.interface.RobotState`'s, the
        previous command and its secondary share an earlier result's.

        Args:
            primary: the command that matters most (the task). Shape (n,). Non-finite
                entries are treated as a request to stop.
            position: current positions (finite). Shape (n,).
            previous: last period's command (finite: the result's ``command``). Shape (n,).
            secondary: the part that gives way first (null-space motion), default none.
                Shape (n,). Non-finite entries are treated as a request to stop.
            previous_secondary: the secondary share of ``previous`` (the result's
                ``secondary``), default zero. Shape (n,).
            room: ``(down, up)`` as :meth:`braking_rates`'s, or None.

        Returns:
            :class:`LimitResult`.

        Raises:
            ShapeError: an argument that is not n numbers.
        """
        previous = np.asarray(previous, dtype=float)
        prev_s = self._zero if previous_secondary is None else np.asarray(previous_secondary, dtype=float)
        primary = np.asarray(primary, dtype=float)
        secondary = self._zero if secondary is None else np.asarray(secondary, dtype=float)
        position = np.asarray(position, dtype=float)
        if not (primary.shape == secondary.shape == position.shape == previous.shape == prev_s.shape == self._shape):
            raise ShapeError(
                f'CommandLimits.apply: expected shape {self._shape} for primary, position, previous, secondary '
                f'and previous_secondary, got {[np.shape(a) for a in (primary, position, previous, secondary, prev_s)]}'
            )
        braking = self._braking(position, room, previous)
        neg_down, up = braking[2], braking[1]
        # 0. a non-finite entry is a request to stop
        limited = np.isfinite(primary)
        limited &= np.isfinite(secondary)
        np.logical_not(limited, out=limited)
        if np.count_nonzero(limited):
            primary, secondary = np.where(limited, 0.0, primary), np.where(limited, 0.0, secondary)
        # 1. braking, joint by joint: the primary part first, the secondary part in the room left
        clipped = np.minimum(np.maximum(primary, neg_down), up)
        sec = np.minimum(np.maximum(secondary, neg_down - clipped), up - clipped)
        limited |= clipped != primary
        limited |= sec != secondary
        # 2. velocity: the whole command, uniformly (the braking bounds hold all the way to rest)
        s_v = _largest_step(self._zero, clipped + sec, self._neg_velocity, self.velocity, limited, True)
        # 3. acceleration: the primary part's change first, the secondary part's in the room left;
        #    each part changes from its own share of the previous command (primary: u − u_s)
        lo_a, hi_a = previous - self._adt, previous + self._adt
        fast_p = s_v * clipped if s_v < 1.0 else clipped
        fast_s = s_v * sec if s_v < 1.0 else sec
        d_p = fast_p - (previous - prev_s)
        d_s = fast_s - prev_s
        s_a = _largest_step(previous, d_p, lo_a, hi_a, limited, True)  # previous ∓ a dt holds previous
        mid = previous + (s_a * d_p if s_a < 1.0 else d_p)
        s_s = _largest_step(mid, d_s, lo_a, hi_a, limited)
        moved = s_s * d_s if s_s < 1.0 else d_s
        # 4. the period's box, braking first where it conflicts with the acceleration limit
        lo, hi, forced = self._box(braking, previous, lo_a, hi_a)
        raw = mid + moved
        command = np.minimum(np.maximum(raw, lo), hi)
        out_s = prev_s + moved
        if forced is not None:
            limited |= forced
        clip = command - raw
        np.abs(clip, out=clip)
        limited |= clip > 1e-12
        share = 1.0
        if np.count_nonzero(secondary):
            share = min(1.0, math.sqrt(out_s @ out_s) / max(math.sqrt(secondary @ secondary), 1e-300))
        return LimitResult(
            command=command,
            secondary=out_s,
            scale=s_v,
            accel_scale=s_a,
            secondary_scale=share,
            limited=tuple(limited.nonzero()[0].tolist()),
            lower=lo,
            upper=hi,
            requested=fast_p + fast_s,
        )

    def _braking(self, position, room=None, previous=None):
        """:meth:`braking_rates` of a checked position vector (and ``room``, ``previous``), not to be modified:
        (down, up, −down, and the velocity and braking interval ``max(−v, −down)``,
        ``min(v, up)``). The last answer is kept: a resolver asks several times a period at one
        position."""
        if room is not None:
            room = np.concatenate([np.asarray(r, dtype=float) for r in room])
        key = (
            position.tobytes(),
            None if room is None else room.tobytes(),
            None if room is None or previous is None else np.asarray(previous, dtype=float).tobytes(),
        )
        if key == self._last_braking[0]:
            return self._last_braking[1]
        # distances to the limits, of the entries that have one (NaN passes through np.maximum)
        distance = position[self._bounded2]
        distance -= self._limit2
        distance *= self._sign2
        np.maximum(distance, 0.0, out=distance)
        rates = _braking_rate(distance, self._rate_constants)
        i, k = self._bounded, self._bounded.size
        down, up = self._inf.copy(), self._inf.copy()
        down[i], up[i] = rates[:k], rates[k:]
        if room is not None:  # and within the room given, braking all the same
            room_rates = _braking_rate(np.maximum(room, 0.0), self._room_constants)
            if previous is not None:  # from a rate beyond it, as hard as the acceleration limit allows
                heading = np.concatenate((-previous, previous)) - self._room_constants.adt
                np.maximum(room_rates, heading, out=room_rates)
            np.minimum(down, room_rates[: self.n], out=down)
            np.minimum(up, room_rates[self.n :], out=up)
        neg_down = -down
        braking = (down, up, neg_down, np.maximum(self._neg_velocity, neg_down), np.minimum(self.velocity, up))
        self._last_braking = (key, braking)
        return braking

    def _box(self, braking, previous, lower_accel, upper_accel):
        """:meth:`box` from the braking rates (:meth:`_braking`) and the acceleration interval
        ``previous ∓ a dt``: (lower, upper, forced), ``forced`` None where no entry is."""
        lo_v, hi_v = braking[3], braking[4]
        lo, hi = np.maximum(lo_v, lower_accel), np.minimum(hi_v, upper_accel)
        forced = lo > hi
        if not np.count_nonzero(forced):
            return lo, hi, None
        nearest = np.clip(previous, lo_v, hi_v)
        return np.where(forced, nearest, lo), np.where(forced, nearest, hi), forced


@dataclass(frozen=True)
class _BrakingConstants:
    """What :func:`_braking_rate` needs of ``a dt`` (per entry) and ``dt``, computed once."""

    adt: np.ndarray
    half: np.ndarray  # a dt / 2
    half_squared: np.ndarray
    two_a: np.ndarray  # (2 / dt) a dt
    dt: float

    @classmethod
    def of(cls, adt: np.ndarray, dt: float) -> '_BrakingConstants':
        half = 0.5 * adt
        return cls(adt, half, half * half, (2.0 / dt) * adt, dt)


def _braking_rate(distance, c):
    """Largest rates v from which braking by a·dt per period, one period at a time, stops within
    ``distance`` (arrays, element-wise; ``c``: :class:`_BrakingConstants`; an infinite distance
    gives inf).

    Braking from v covers ``dt (n + 1) v − a dt² n (n + 1)/2`` with ``n = ⌊v / (a dt)⌋`` (v, v − a dt,
    …, the last rate below a dt, then rest): piecewise linear in v, so on each piece
    ``v = (D/dt + a dt n (n + 1)/2) / (n + 1)``. The continuous bound ``v²/(2a) + v dt/2 = D``
    meets it at every multiple of a dt and lies above it in between, so its ``n`` is right or
    one too high (then the rate on its piece falls below n a dt). From any v within this bound, ``v − a dt`` is
    within the next period's bound: braking always stays within the acceleration limit, and
    ``v dt ≤ D``. A distance of zero gives zero; NaN passes through.
    """
    half = c.half
    n = np.floor((np.sqrt(c.half_squared + c.two_a * distance) - half) / c.adt)
    n[~np.isfinite(n)] = 0.0
    per_dt = distance / c.dt
    n1 = n + 1.0
    n -= (n > 0.0) & ((per_dt + half * n * n1) < n * n1 * c.adt)  # one too high
    n1 = n + 1.0
    return (per_dt + half * n * n1) / n1


def _largest_step(start, step, lower, upper, binding, inside=False):
    """:func:`~wmm_control.geometry.largest_step`; the entries whose bounds bind (when the
    whole step does not fit) are set in the boolean array ``binding``.

    The whole step is tried first: with ``start`` within its bounds (known when ``inside``,
    checked otherwise), every entry's own ``(bound − start) / step`` is at least 1 exactly when
    ``step`` lies within ``bound − start`` (a rounded quotient keeps its order with 1), so the
    answer is then 1 without dividing."""
    room_down, room_up = lower - start, upper - start
    if inside:
        out = (step < room_down) | (step > room_up)
    else:
        out = (room_down > np.minimum(step, 0.0)) | (room_up < np.maximum(step, 0.0))
    if not np.count_nonzero(out):
        return 1.0
    s, per = largest_step(start, step, lower, upper)
    if s < 1.0:
        binding |= per <= s + 1e-12
    return s
