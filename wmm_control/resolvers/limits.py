"""Per-period bounds on the whole-body velocity command, and scaling into them.

The command vector is ``u = (vx, vy, ω, q̇_1 … q̇_7)``: the base twist reference (base
frame) and the arm joint velocities. Each period every entry must lie in an interval built
from

* the velocity limit ``|u_i| ≤ v_i``;
* the acceleration limit ``|u_i − u_i,prev| ≤ a_i dt`` (``u_prev``: the last command);
* for arm joints, braking in time before a position limit (Xing eqs 7–8): the largest rate
  from which braking at ``a_i``, one period at a time, stops the joint before the limit.
  With distance ``D`` to the limit that rate is ``v = −a dt/2 + sqrt((a dt/2)² + 2 a D)``;
  it satisfies ``v²/(2a) + v dt/2 = D``, so after a period at ``v`` the bound of the next
  period is exactly ``v − a dt``: braking is always reachable within the acceleration limit.

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

from dataclasses import dataclass

import numpy as np

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError

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

    def __init__(self, velocity, acceleration, position_lower, position_upper, dt):
        self.velocity = np.asarray(velocity, dtype=float)
        n = self.velocity.size
        self.acceleration = np.asarray(acceleration, dtype=float)
        self.position_lower = np.asarray(position_lower, dtype=float)
        self.position_upper = np.asarray(position_upper, dtype=float)
        for name in ('velocity', 'acceleration', 'position_lower', 'position_upper'):
            if getattr(self, name).shape != (n,):
                raise ConfigError(f'CommandLimits.{name}: expected shape ({n},), '
                                  f'got {getattr(self, name).shape}')
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

    def braking_rates(self, position):
        """Largest rates towards the lower and upper position limits from which braking stops in time.

        Args:
            position: current positions (any value for entries without limits). Shape (n,).

        Returns:
            (down, up): non-negative rate bounds [unit/s]; inf where there is no limit. Shape (n,) each.
        """
        position = np.asarray(position, dtype=float)
        half = 0.5 * self._adt
        with np.errstate(invalid='ignore'):
            d_up = np.maximum(self.position_upper - position, 0.0)
            d_dn = np.maximum(position - self.position_lower, 0.0)
            up = -half + np.sqrt(half * half + 2.0 * self.acceleration * d_up)
            down = -half + np.sqrt(half * half + 2.0 * self.acceleration * d_dn)
        up = np.where(np.isfinite(self.position_upper), up, np.inf)
        down = np.where(np.isfinite(self.position_lower), down, np.inf)
        return down, up

    def box(self, position, previous):
        """This period's interval for every entry.

        Velocity and braking bounds always contain zero. The acceleration interval around
        ``previous`` is intersected with them; where the two do not meet (a previous command
        that broke a bound, e.g. after a reset), the point of the velocity/braking interval
        nearest the acceleration interval is the only one allowed.

        Returns:
            (lower, upper, forced): Shape (n,) each; ``forced`` flags the entries above.
        """
        down, up = self.braking_rates(position)
        lo_v = np.maximum(-self.velocity, -down)
        hi_v = np.minimum(self.velocity, up)
        lo = np.maximum(lo_v, previous - self._adt)
        hi = np.minimum(hi_v, previous + self._adt)
        forced = lo > hi
        if np.any(forced):
            point = np.clip(previous, lo_v, hi_v)
            lo = np.where(forced, point, lo)
            hi = np.where(forced, point, hi)
        return lo, hi, forced

    def subset(self, index):
        """The limits of some entries only (``index``: a slice or an index array)."""
        return CommandLimits(self.velocity[index], self.acceleration[index], self.position_lower[index],
                             self.position_upper[index], self.dt)

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
        previous = as_finite_vector(previous, self.n, 'previous command')
        prev_s = (np.zeros(self.n) if previous_secondary is None
                  else as_finite_vector(previous_secondary, self.n, 'previous secondary'))
        prev_p = previous - prev_s
        primary = np.asarray(primary, dtype=float)
        secondary = np.zeros(self.n) if secondary is None else np.asarray(secondary, dtype=float)
        bad = ~np.isfinite(primary) | ~np.isfinite(secondary)
        if np.any(bad):
            primary = np.where(bad, 0.0, primary)
            secondary = np.where(bad, 0.0, secondary)
        limited = set(np.flatnonzero(bad).tolist())
        # 1. braking, joint by joint: the primary part first, the secondary part in the room left
        down, up = self.braking_rates(position)
        clipped = np.clip(primary, -down, up)
        sec = np.clip(secondary, -down - clipped, up - clipped)
        limited |= set(np.flatnonzero((clipped != primary) | (sec != secondary)).tolist())
        # 2. velocity: the whole command, uniformly (the braking bounds hold all the way to rest)
        s_v, arg = _largest_step(np.zeros(self.n), clipped + sec, -self.velocity, self.velocity)
        limited |= set(arg)
        goal_p, goal_s = s_v * clipped, s_v * sec
        # 3. acceleration: the primary part's change first, the secondary part's in the room left
        lo_a, hi_a = previous - self._adt, previous + self._adt
        d_p, d_s = goal_p - prev_p, goal_s - prev_s
        s_a, arg = _largest_step(previous, d_p, lo_a, hi_a)
        limited |= set(arg)
        mid = previous + s_a * d_p
        s_s, arg = _largest_step(mid, d_s, lo_a, hi_a)
        limited |= set(arg)
        out_s = prev_s + s_s * d_s
        raw = mid + s_s * d_s
        # 4. the period's box, braking first where it conflicts with the acceleration limit
        lo, hi, forced = self.box(position, previous)
        command = np.clip(raw, lo, hi)
        limited |= set(np.flatnonzero(forced | (np.abs(command - raw) > 1e-12)).tolist())
        share = float(np.linalg.norm(out_s)) / max(float(np.linalg.norm(secondary)), 1e-300)
        return LimitResult(command=command, secondary=out_s, scale=s_v, accel_scale=s_a,
                           secondary_scale=min(1.0, share) if np.any(secondary) else 1.0,
                           limited=tuple(sorted(int(i) for i in limited)), lower=lo, upper=hi)


def _largest_step(start, step, lower, upper):
    """Largest ``s ∈ [0, 1]`` with ``lower ≤ start + s·step ≤ upper``, and the binding indices.

    ``start`` lies within the bounds.
    """
    with np.errstate(divide='ignore', invalid='ignore', over='ignore'):
        s_each = np.where(step > 0, (upper - start) / step, np.where(step < 0, (lower - start) / step, np.inf))
    s = float(np.min(s_each)) if s_each.size else np.inf
    if s >= 1.0:
        return 1.0, ()
    s = min(1.0, max(0.0, s))
    return s, tuple(np.flatnonzero(s_each <= s + 1e-12).tolist())
