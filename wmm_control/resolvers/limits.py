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

from wmm_control.checks import as_finite_vector, as_vector
from wmm_control.errors import ConfigError
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
    """

    command: np.ndarray
    secondary: np.ndarray
    scale: float
    accel_scale: float
    secondary_scale: float
    limited: tuple
    lower: np.ndarray
    upper: np.ndarray


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
        # per-entry constants of the scalar kernels below, as Python floats
        self._velocity = self.velocity.tolist()
        self._neg_velocity = (-self.velocity).tolist()
        self._adt_list = self._adt.tolist()
        self._half = (0.5 * self._adt).tolist()
        self._two_a = (2.0 * self.acceleration).tolist()
        self._lower = self.position_lower.tolist()
        self._upper = self.position_upper.tolist()
        self._has_lower = np.isfinite(self.position_lower).tolist()
        self._has_upper = np.isfinite(self.position_upper).tolist()

    def braking_rates(self, position: ArrayLike) -> tuple[np.ndarray, np.ndarray]:
        """Largest rates towards the lower and upper position limits from which braking stops in time.

        Args:
            position: current positions (any value for entries without limits). Shape (n,).

        Returns:
            (down, up): non-negative rate bounds [unit/s]; inf where there is no limit. Shape (n,) each.
        """
        down, up = self._braking(self._floats(position, 'position'))
        return np.array(down), np.array(up)

    def box(self, position: ArrayLike, previous: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """This period's interval for every entry.

        Velocity and braking bounds always contain zero. The acceleration interval around
        ``previous`` is intersected with them; where the two do not meet (a previous command
        that broke a bound, e.g. after a reset), the point of the velocity/braking interval
        nearest the acceleration interval is the only one allowed.

        Returns:
            (lower, upper, forced): Shape (n,) each; ``forced`` flags the entries above.
        """
        down, up = self._braking(self._floats(position, 'position'))
        previous = self._floats(previous, 'previous command')
        lo, hi, forced = self._box(down, up, previous, *self._accel_interval(previous))
        return np.array(lo), np.array(hi), np.array(forced, dtype=bool)

    @classmethod
    def for_robot(cls, robot: RobotConfig, dt: float) -> Self:
        """Limits of the whole-body command (base, q̇_1 … q̇_n) of a robot description.

        The base entries are the twist axes the base can follow (``robot.base_axes``: vx, vy,
        ω, or vx, ω for a differential base), with the robot YAML's base velocity and
        acceleration limits and no position limits; the arm has its joint limits.
        """
        arm, axes = robot.arm, list(robot.base_axes)
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

    # apply and the helpers below work entry by entry on Python floats: for the n = 7 or 10
    # entries of a command, numpy's overhead per call (about 1 µs per operation, some 60 of
    # them per apply) costs several times the arithmetic itself (apply on 10 entries: 79 µs
    # as array operations, 22 µs so). Each entry sees the same IEEE operations in the same
    # order as in the array form, so the results are the same to the bit.

    def apply(self, primary, position, previous, secondary=None, previous_secondary=None):
        """Bring ``primary + secondary`` into this period's bounds (see the module docstring).

        Args:
            primary: the command that matters most (the task). Shape (n,). Non-finite
                entries are treated as a request to stop.
            position: current positions. Shape (n,).
            previous: last period's command. Shape (n,).
            secondary: the part that gives way first (null-space motion), default none.
                Shape (n,).
            previous_secondary: the secondary share of ``previous`` (the result's
                ``secondary``), default zero. Shape (n,).

        Returns:
            :class:`LimitResult`.
        """
        n = self.n
        previous = self._floats(previous, 'previous command', finite=True)
        prev_s = (
            [0.0] * n
            if previous_secondary is None
            else self._floats(previous_secondary, 'previous secondary', finite=True)
        )
        primary = self._floats(primary, 'primary')
        secondary = [0.0] * n if secondary is None else self._floats(secondary, 'secondary')
        down, up = self._braking(self._floats(position, 'position'))
        limited = set()
        # 1. braking, joint by joint: the primary part first, the secondary part in the room left
        clipped, sec = [0.0] * n, [0.0] * n
        for i, (p, s, d, u) in enumerate(zip(primary, secondary, down, up)):
            if not (math.isfinite(p) and math.isfinite(s)):  # a request to stop
                p = s = primary[i] = secondary[i] = 0.0
                limited.add(i)
            clipped[i] = c = _clip(p, -d, u)
            sec[i] = _clip(s, -d - c, u - c)
            if c != p or sec[i] != s:
                limited.add(i)
        # 2. velocity: the whole command, uniformly (the braking bounds hold all the way to rest)
        s_v, arg = _largest_step([0.0] * n, [c + s for c, s in zip(clipped, sec)], self._neg_velocity, self._velocity)
        limited.update(arg)
        # 3. acceleration: the primary part's change first, the secondary part's in the room left;
        #    each part changes from its own share of the previous command (primary: u − u_s)
        lo_a, hi_a = self._accel_interval(previous)
        d_p = [s_v * c - (u - us) for c, u, us in zip(clipped, previous, prev_s)]
        d_s = [s_v * s - us for s, us in zip(sec, prev_s)]
        s_a, arg = _largest_step(previous, d_p, lo_a, hi_a)
        limited.update(arg)
        mid = [u + s_a * d for u, d in zip(previous, d_p)]
        s_s, arg = _largest_step(mid, d_s, lo_a, hi_a)
        limited.update(arg)
        # 4. the period's box, braking first where it conflicts with the acceleration limit
        lo, hi, forced = self._box(down, up, previous, lo_a, hi_a)
        command, out_s = [0.0] * n, [0.0] * n
        for i, (m, d, us, a, b) in enumerate(zip(mid, d_s, prev_s, lo, hi)):
            raw = m + s_s * d
            command[i] = c = _clip(raw, a, b)
            out_s[i] = us + s_s * d
            if forced[i] or abs(c - raw) > 1e-12:
                limited.add(i)
        out_s = np.array(out_s)
        share = 1.0
        if any(secondary):
            # the norms as np.linalg.norm takes them (sqrt of a BLAS dot), at a third of its cost
            asked = np.array(secondary)
            share = min(1.0, math.sqrt(out_s.dot(out_s)) / max(math.sqrt(asked.dot(asked)), 1e-300))
        return LimitResult(
            command=np.array(command),
            secondary=out_s,
            scale=s_v,
            accel_scale=s_a,
            secondary_scale=share,
            limited=tuple(sorted(limited)),
            lower=np.array(lo),
            upper=np.array(hi),
        )

    def _floats(self, value, name, finite=False):
        """``value`` as a list of n floats; :func:`as_finite_vector` / :func:`as_vector` errors otherwise."""
        arr = np.asarray(value, dtype=float)
        out = arr.tolist() if arr.shape == (self.n,) else None
        if out is None or (finite and not all(map(math.isfinite, out))):
            (as_finite_vector if finite else as_vector)(value, self.n, name)  # raises the detailed error
        return out

    def _braking(self, position):
        """:meth:`braking_rates` on a list of floats: (down, up) lists."""
        down, up = [], []
        inv_dt = 1.0 / self.dt
        for x, lower, upper, has_lower, has_upper, half, two_a in zip(
            position, self._lower, self._upper, self._has_lower, self._has_upper, self._half, self._two_a
        ):
            # distances to the limits, max(·, 0) letting a NaN position through as np.maximum does
            d_up, d_dn = upper - x, x - lower
            d_up = 0.0 if d_up < 0.0 else d_up
            d_dn = 0.0 if d_dn < 0.0 else d_dn
            up.append(_braking_rate(d_up, half, two_a, inv_dt) if has_upper else math.inf)
            down.append(_braking_rate(d_dn, half, two_a, inv_dt) if has_lower else math.inf)
        return down, up

    def _accel_interval(self, previous):
        """``previous ∓ a dt`` (lists)."""
        return ([u - a for u, a in zip(previous, self._adt_list)], [u + a for u, a in zip(previous, self._adt_list)])

    def _box(self, down, up, previous, lower_accel, upper_accel):
        """:meth:`box` from the braking rates and the acceleration interval ``previous ∓ a dt``
        (lists): (lower, upper, forced) lists."""
        lower, upper, forced = [], [], []
        for d, u, v, prev, lo_a, hi_a in zip(down, up, self._velocity, previous, lower_accel, upper_accel):
            lo_v = -v if -v >= -d else -d
            hi_v = v if v <= u else u
            lo = lo_v if lo_v >= lo_a else lo_a
            hi = hi_v if hi_v <= hi_a else hi_a
            if lo > hi:
                lo = hi = _clip(prev, lo_v, hi_v)
                forced.append(True)
            else:
                forced.append(False)
            lower.append(lo)
            upper.append(hi)
        return lower, upper, forced


def _braking_rate(distance, half, two_a, inv_dt):
    """Largest rate v from which braking by a·dt per period, one period at a time, stops within ``distance``.

    Braking from v covers ``dt (n + 1) v − a dt² n (n + 1)/2`` with ``n = ⌊v / (a dt)⌋`` (v, v − a dt,
    …, the last rate below a dt, then rest): piecewise linear in v. The continuous bound
    ``v²/(2a) + v dt/2 = D`` meets it at every multiple of a dt and lies above it in between, so
    its ``n`` is right or one too high. From any v within this bound, ``v − a dt`` is within the
    next period's bound: braking always stays within the acceleration limit, and ``v dt ≤ D``.
    (``half`` = a dt/2, ``two_a`` = 2a, ``inv_dt`` = 1/dt.)
    """
    if not distance > 0.0:
        return 0.0 if distance <= 0.0 else distance  # NaN passes through
    adt = 2.0 * half
    n = int((-half + math.sqrt(half * half + two_a * distance)) / adt)
    for _ in range(3):
        rate = (distance * inv_dt + adt * n * (n + 1) * 0.5) / (n + 1)
        if rate < n * adt and n > 0:
            n -= 1
        elif rate >= (n + 1) * adt:
            n += 1
        else:
            return rate
    return rate


def _clip(x, lower, upper):
    """``np.clip`` of one float: ``min(max(x, lower), upper)``."""
    x = lower if lower > x else x
    return upper if upper < x else x


def _largest_step(start, step, lower, upper):
    """Largest ``s ∈ [0, 1]`` with ``lower ≤ start + s·step ≤ upper``, and the binding indices.

    ``start`` lies within the bounds. Sequences of floats, all of one length.
    """
    s_each = [
        (hi - x) / d if d > 0.0 else (lo - x) / d if d < 0.0 else math.inf
        for x, d, lo, hi in zip(start, step, lower, upper)
    ]
    s = min(s_each, default=math.inf)
    if s >= 1.0:
        return 1.0, ()
    s = min(1.0, max(0.0, s))
    return s, [i for i, si in enumerate(s_each) if si <= s + 1e-12]
