"""The safety stage every method passes its arm command through: velocity dampers that keep
the arm off the robot's own body, off itself and off the floor.

For each checked pair closer than the influence distance ``d_i``
(:class:`~wmm_control.kinematics.collision.CollisionModel`), the distance may shrink no
faster than (Faverjon and Tournassoud's velocity damper)

    ḋ ≥ −ξ (d − d_s) / (d_i − d_s),

so the arm may approach at ``ξ`` at the influence distance, ever more slowly nearer, and not
at all at the safety distance ``d_s`` (below it, the pair must move apart). An arm that
arrives at ``d_i`` much faster than ``ξ`` cannot slow down to it at once within its
acceleration limits, so a pair closer than the look-ahead distance ``d_b`` (≥ ``d_i``) also
keeps its approach within what braking at ``a_b`` can stop before ``d_s``:

    ḋ ≥ −√(2 a_b (d − d_s)),

the stricter of the two where both hold. With ``ḋ = j · q̇``, each pair is one linear row on
the arm command. The stage returns the command
nearest the method's own in the method's weighting,

    min ½ (q̇ − q̇₀)ᵀ W (q̇ − q̇₀)   subject to   the dampers, and   lower ≤ q̇ ≤ upper,

``[lower, upper]`` being the period's box the method already keeps (velocity, acceleration,
braking before a position limit). Each damper row has a slack of high linear cost: where the
box leaves no command that meets every damper (the arm arrives faster than its acceleration
limits can brake), the answer meets them as far as the box allows, and the solve never fails
for it; where it leaves room, the slack is zero. The QP is small (the arm's joints, a slack
per damper row the command breaks) and solved exactly by a dual active-set method
(:func:`_least_distance`): its answer meets every constraint to rounding, and its cost is a
few small linear solves per constraint that binds.

When no pair is within ``d_i``, or the command already meets every damper, it passes through
unchanged: a method runs as its paper has it until the arm nears the body.

At acceleration level (Xing's methods) the stage acts on the rates the method has integrated
for this period, within its box of ``q̇_prev ± q̈_max T``: a row ``j · (q̇_prev + q̈ T) ≥ b``
is the matching bound on the acceleration, ``j · q̈ ≥ (b − ḋ_prev) / T`` (the dampers
discretised over the period, J̇'s share neglected).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy.linalg import lapack

from wmm_control.errors import ConfigError

__all__ = ['SafetyParams', 'SafetyResult', 'SafetyStage']

#: Cost per unit of damper slack [per m/s], linear (an exact penalty: no slack at all where
#: the box leaves room, which a quadratic cost would not give), against weights of about 1 on
#: the command; and its small quadratic term, which keeps the problem strictly convex.
SLACK_COST = 1e3
SLACK_WEIGHT = 1.0
#: The command is taken as meeting a damper within this much [m/s].
TOLERANCE = 1e-9
#: The QP's answer meets every constraint within this much (a distance in its scaled variables,
#: about [m/s] for weights about 1).
LEAST_DISTANCE_TOLERANCE = 1e-10


@dataclass(frozen=True)
class SafetyParams:
    """Velocity-damper parameters; every method's parameters class derives from this one.

    Attributes:
        collision_avoidance: False passes every command through.
        collision_influence: d_i, distance under which a pair is constrained [m].
        collision_safety: d_s, distance the dampers keep [m]; below it, the pair must separate.
        collision_gain: ξ, the approach speed allowed at the influence distance [m/s].
        collision_lookahead: d_b ≥ d_i, distance under which a pair's approach is kept within
            what braking can stop [m].
        collision_braking: a_b, the deceleration of a distance that braking counts on [m/s²]
            (below what the arm's joint acceleration limits give).
    """

    collision_avoidance: bool = True
    collision_influence: float = 0.10
    collision_safety: float = 0.02
    collision_gain: float = 0.2
    collision_lookahead: float = 0.3
    collision_braking: float = 1.0

    def __post_init__(self):
        for name in ('collision_influence', 'collision_safety', 'collision_gain', 'collision_lookahead',
                     'collision_braking'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f'{name} must be finite and > 0, got {value}')
        if self.collision_safety >= self.collision_influence:
            raise ConfigError(f'collision_safety ({self.collision_safety} m) must be below collision_influence '
                              f'({self.collision_influence} m)')
        if self.collision_lookahead < self.collision_influence:
            raise ConfigError(f'collision_lookahead ({self.collision_lookahead} m) must not be below '
                              f'collision_influence ({self.collision_influence} m)')


@dataclass(frozen=True)
class SafetyResult:
    """The stage's answer.

    Attributes:
        command: the arm command [rad/s or m/s]. Shape (n,).
        clearance: distance of the closest checked pair [m] (inf when none is checked).
        closest_pair: its links, ``'a/b'`` ('' when none).
        active: number of damper rows (pairs within the look-ahead distance).
        changed: True when the command differs from the method's.
    """

    command: np.ndarray
    clearance: float
    closest_pair: str
    active: int
    changed: bool


class SafetyStage:
    """Velocity dampers on the arm command of a :class:`CollisionModel`.

    Args:
        collision: a :class:`~wmm_control.kinematics.collision.CollisionModel`.
        params: :class:`SafetyParams` (or a method's parameters, which derive from it).
    """

    def __init__(self, collision, params: SafetyParams = SafetyParams()):
        self.collision = collision
        self.params = params

    def filter(self, q_arm, command, lower, upper, weights=None) -> SafetyResult:
        """The arm command ``command`` at arm joints ``q_arm``, within the dampers and the box.

        Args:
            q_arm: arm joint positions. Shape (n,).
            command: the method's arm command, within ``[lower, upper]``. Shape (n,).
            lower, upper: this period's box. Shape (n,) each.
            weights: the diagonal of W, the method's weighting of the arm joints (default
                ones). Shape (n,).
        """
        command = np.asarray(command, dtype=float)
        p = self.params
        if not p.collision_avoidance:
            return SafetyResult(command, math.inf, '', 0, False)
        d_i, d_s = p.collision_influence, p.collision_safety
        pairs, clearance, names = self.collision.within(q_arm, p.collision_lookahead)
        label = '/'.join(names) if names else ''
        if not pairs:
            return SafetyResult(command, clearance, label, 0, False)
        rows = np.array([pair.rate_jacobian for pair in pairs])
        bound = -np.array([self.allowed_approach(pair.distance) for pair in pairs])
        violated = rows @ command < bound - TOLERANCE
        if not violated.any():
            return SafetyResult(command, clearance, label, len(pairs), False)
        lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        weights = np.ones(command.size) if weights is None else np.asarray(weights, dtype=float)
        # active set: the rows the command breaks, then any the answer breaks, until it breaks none
        # (most periods one solve: the rows far from binding never enter the QP)
        use = violated
        for _ in range(len(pairs)):
            solved = self._solve(command, rows[use], bound[use], lower, upper, weights)
            broken = (rows @ solved < bound - 1e-7) & ~use
            if not broken.any():
                break
            use = use | broken
        return SafetyResult(solved, clearance, label, len(pairs), True)

    def allowed_approach(self, distance: float) -> float:
        """The fastest a pair ``distance`` [m] apart may approach [m/s] (negative: it must separate)."""
        p = self.params
        d_i, d_s = p.collision_influence, p.collision_safety
        braking = math.sqrt(2.0 * p.collision_braking * max(distance - d_s, 0.0))
        damper = p.collision_gain * (distance - d_s) / (d_i - d_s) if distance < d_i else math.inf
        return min(damper, braking)

    def _solve(self, command, rows, bound, lower, upper, weights):
        """The QP of the module docstring over y = (q̇, slack), the dampers ``rows`` ≥ ``bound``.

        Its cost is ½ (y − y₀)ᵀ H (y − y₀) plus a constant, H = diag(W, SLACK_WEIGHT) and y₀ =
        (q̇₀, −SLACK_COST / SLACK_WEIGHT) its unconstrained minimum; in z = H^½ (y − y₀) it is
        the nearest point to the origin that meets every constraint (:func:`_least_distance`),
        started from the slacks held at zero: there, y = (q̇₀, 0), each slack's bound has the
        multiplier SLACK_COST.
        """
        n, m = command.size, bound.size
        scale = 1.0 / np.sqrt(np.concatenate((weights, np.full(m, SLACK_WEIGHT))))
        y0 = np.concatenate((command, np.full(m, -SLACK_COST / SLACK_WEIGHT)))
        # a y ≥ e: the dampers (rows q̇ + slack ≥ bound), slack ≥ 0, q̇ ≥ lower and −q̇ ≥ −upper
        a = np.zeros((2 * m + 2 * n, n + m))
        a[:m, :n] = rows
        a[:m, n:] = a[m:2 * m, n:] = np.eye(m)
        a[2 * m:2 * m + n, :n] = np.eye(n)
        a[2 * m + n:, :n] = -np.eye(n)
        e = np.concatenate((bound, np.zeros(m), lower, -upper))
        try:
            z = _least_distance(a * scale, e - a @ y0, list(range(m, 2 * m)))
        except np.linalg.LinAlgError:                   # active constraints dependent through rounding
            z = None
        if z is None:
            # no answer (a box with lower > upper): brake as hard as the box allows
            return np.clip(np.zeros(n), lower, upper)
        return np.clip(command + scale[:n] * z[:n], lower, upper)


def _least_distance(normals, rhs, active):
    """The ``z`` of least norm with ``normals @ z ≥ rhs``, or None when there is none.

    Goldfarb and Idnani's dual method ("A numerically stable dual method for solving strictly
    convex quadratic programs", Math. Programming 27, 1983), for the identity Hessian. It starts
    from the nearest point that meets the constraints ``active`` as equalities (their
    multipliers must be ≥ 0) and adds the most violated constraint: it moves z along the part
    of the new constraint's normal that the active ones leave free, raising its multiplier,
    until the new constraint is met, or, first, an active multiplier falls to zero and that
    constraint is dropped. Every multiplier stays ≥ 0 and ½ |z|² never falls, so no active set
    comes back; it ends, exactly, when no constraint is violated. A normal in the span of the
    active ones (to 1e-6 of its length) moves no z and only drops: the active normals stay
    independent. The answer is computed anew from the last active set, without the steps'
    rounding.

    Raises:
        numpy.linalg.LinAlgError: the active normals became dependent through rounding.
    """
    active = list(active)
    u = _gram_solve(normals[active], rhs[active])     # the active constraints' multipliers
    z = u @ normals[active]
    norms = np.linalg.norm(normals, axis=1)
    adding, u_add = None, 0.0
    for _ in range(20 * len(rhs)):
        if adding is None:
            gap = (rhs - normals @ z) / norms           # how far z is from meeting each
            gap[active] = -np.inf
            adding = int(np.argmax(gap))
            if gap[adding] <= LEAST_DISTANCE_TOLERANCE:
                a = normals[active]
                return _gram_solve(a, rhs[active]) @ a
            u_add = 0.0
        n_add, a = normals[adding], normals[active]
        r = _gram_solve(a, a @ n_add)                   # n_add's part in the span of the active normals
        d = n_add - r @ a                               # the rest: moving z along it keeps them met
        dd = d @ d
        full = (rhs[adding] - n_add @ z) / dd if dd > 1e-12 * (n_add @ n_add) else np.inf
        ratios = np.full(r.size, np.inf)                # as u_add rises by t, u falls by t r:
        np.divide(u, r, out=ratios, where=r > 0)        # the t that takes each to zero
        drop = int(np.argmin(ratios)) if r.size else -1
        partial = ratios[drop] if r.size else np.inf
        step = min(full, partial)
        if not np.isfinite(step):
            return None                                 # n_add in the span, nothing to drop
        if np.isfinite(full):
            z = z + step * d
        u = u - step * r
        u_add += step
        if full <= partial:
            active.append(adding)
            u = np.append(u, u_add)
            adding = None
        else:
            del active[drop]
            u = np.delete(u, drop)
    return None


def _gram_solve(a, b):
    """``x`` with ``(a aᵀ) x = b``, the rows of ``a`` independent (Cholesky, LAPACK's dposv)."""
    if not a.shape[0]:
        return np.zeros(0)
    _, x, info = lapack.dposv(a @ a.T, b)
    if info != 0:
        raise np.linalg.LinAlgError(f'dependent rows (dposv info {info})')
    return x
