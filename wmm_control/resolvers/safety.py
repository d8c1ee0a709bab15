"""The safety stage every method passes its arm command through: velocity dampers that keep
the arm off the robot's own body, off itself and off the floor.

For each checked pair closer than the influence distance ``d_i``
(:class:`~wmm_control.kinematics.collision.CollisionModel`), the distance may shrink no
faster than (Faverjon and Tournassoud's velocity damper)

    ḋ ≥ −ξ (d − d_s) / (d_i − d_s),

so the arm may approach at ``ξ`` at the influence distance, ever more slowly nearer, and not
at all at the safety distance ``d_s`` (below it, the pair must move apart). With
``ḋ = j · q̇``, each pair is one linear row on the arm command. The stage returns the command
nearest the method's own in the method's weighting,

    min ½ (q̇ − q̇₀)ᵀ W (q̇ − q̇₀)   subject to   the dampers, and   lower ≤ q̇ ≤ upper,

``[lower, upper]`` being the period's box the method already keeps (velocity, acceleration,
braking before a position limit), solved with OSQP. Each damper row has a slack of high
linear cost: where the box leaves no command that meets every damper (the arm arrives faster
than its acceleration limits can brake), the answer meets them as far as the box allows, and
the solve never fails for it; where it leaves room, the slack is zero.

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
import osqp
from scipy import sparse

from wmm_control.errors import ConfigError

__all__ = ['SafetyParams', 'SafetyResult', 'SafetyStage']

#: Cost per unit of damper slack [per m/s], linear (an exact penalty: no slack at all where
#: the box leaves room, which a quadratic cost would not give), against weights of about 1 on
#: the command; and its small quadratic term, which keeps the problem strictly convex.
SLACK_COST = 1e3
SLACK_WEIGHT = 1.0
#: The command is taken as meeting a damper within this much [m/s].
TOLERANCE = 1e-9


@dataclass(frozen=True)
class SafetyParams:
    """Velocity-damper parameters; every method's parameters class derives from this one.

    Attributes:
        collision_avoidance: False passes every command through.
        collision_influence: d_i, distance under which a pair is constrained [m].
        collision_safety: d_s, distance the dampers keep [m]; below it, the pair must separate.
        collision_gain: ξ, the approach speed allowed at the influence distance [m/s].
    """

    collision_avoidance: bool = True
    collision_influence: float = 0.10
    collision_safety: float = 0.02
    collision_gain: float = 0.2

    def __post_init__(self):
        for name in ('collision_influence', 'collision_safety', 'collision_gain'):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f'{name} must be finite and > 0, got {value}')
        if self.collision_safety >= self.collision_influence:
            raise ConfigError(f'collision_safety ({self.collision_safety} m) must be below collision_influence '
                              f'({self.collision_influence} m)')


@dataclass(frozen=True)
class SafetyResult:
    """The stage's answer.

    Attributes:
        command: the arm command [rad/s or m/s]. Shape (n,).
        clearance: distance of the closest checked pair [m] (inf when none is checked).
        closest_pair: its links, ``'a/b'`` ('' when none).
        active: number of damper rows (pairs within the influence distance).
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
        self._settings = dict(verbose=False, eps_abs=1e-7, eps_rel=1e-7, max_iter=4000, polishing=True)

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
        pairs, clearance, names = self.collision.within(q_arm, d_i)
        label = '/'.join(names) if names else ''
        if not pairs:
            return SafetyResult(command, clearance, label, 0, False)
        rows = np.array([pair.rate_jacobian for pair in pairs])
        bound = np.array([-p.collision_gain * (pair.distance - d_s) / (d_i - d_s) for pair in pairs])
        if np.all(rows @ command >= bound - TOLERANCE):
            return SafetyResult(command, clearance, label, len(pairs), False)
        solved = self._solve(command, rows, bound, np.asarray(lower, dtype=float), np.asarray(upper, dtype=float),
                             np.ones(command.size) if weights is None else np.asarray(weights, dtype=float))
        return SafetyResult(solved, clearance, label, len(pairs), True)

    def _solve(self, command, rows, bound, lower, upper, weights):
        """The QP of the module docstring over (q̇, slack)."""
        n, m = command.size, bound.size
        p_mat = sparse.diags(np.concatenate((weights, np.full(m, SLACK_WEIGHT))), format='csc')
        q_vec = np.concatenate((-weights * command, np.full(m, SLACK_COST)))
        a_mat = sparse.vstack([sparse.hstack([sparse.csc_matrix(rows), sparse.identity(m)]),
                               sparse.identity(n + m)], format='csc')
        lo = np.concatenate((bound, lower, np.zeros(m)))
        hi = np.concatenate((np.full(m, np.inf), upper, np.full(m, np.inf)))
        solver = osqp.OSQP()
        solver.setup(p_mat, q_vec, a_mat, lo, hi, **self._settings)
        result = solver.solve(raise_error=False)
        x = np.asarray(result.x, dtype=float)[:n] if result.x is not None else None
        if x is None or not np.all(np.isfinite(x)) or result.info.status not in ('solved', 'solved inaccurate'):
            # no answer: brake as hard as the box allows (the command nearest rest)
            return np.clip(np.zeros(n), lower, upper)
        return np.clip(x, lower, upper)
