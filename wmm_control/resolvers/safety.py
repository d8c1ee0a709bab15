"""The safety stage every method passes its command through: velocity dampers that keep the
arm off the robot's own body, off itself and off the floor, and the whole robot off obstacles.

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

the stricter of the two where both hold. ``a_b`` is taken no larger than the deceleration the
command's own acceleration limits can give that distance (``Σ_i |j_i| q̈_max,i`` over the arm's
joints, plus ``|j_xy|`` times the slower of the base's linear axes: the pair's normal turns
under a base that brakes, so both axes are not counted on at once): a Mecanum base that brakes
at 0.025 m/s² is not counted on to stop at 1 m/s². For a pair of a wheeled base's own body
(chassis, wheels) and an obstacle, the row also holds without the turn's share: a turn that
swings one corner away for the moment cannot hide a linear approach faster than the base can
stop; and a row on the turn rate keeps the turn from turning the base's velocity towards the
obstacle (at v ω, v its speed) by more than ``TURN_SHARE`` of the linear deceleration, which
the braking rows then count on the rest of (the turn row holds for a lagging base too). With
obstacles, whose distance the base's twist changes too, the look-ahead grows to the base's
stopping distance from full speed (``d_s + v τ + v² / (2 min(a, a_b))``, ``v`` the norm of
the linear axes' speed limits, since the base may drive on a diagonal, and ``a`` the
deceleration its rows count on: the slower axis's limit, less the turn's share) so that it
brakes in time.

The stage shapes the base's *reference*; a base whose twist follows its reference with a lag
(a steerable base's ICR and twist controllers, ICṘ = λ (ICR* − ICR), ξ̈ = K_p (ξ̇* − ξ̇): lags
in series, τ = 1/K_p + 1/λ, 0.75 s on robot A: :func:`base_lag`) drives on at about the
reference of τ ago. A row the base moves (a pair with an obstacle) therefore counts on
stopping within ``v τ + v² / (2 a_b)``:

    ḋ ≥ −a_b (√(τ² + 2 (d − d_s) / a_b) − τ),

and its damper gain is no steeper than ``1/τ``. Where the base's measured twist ``v₀`` already
approaches a pair faster than that (it lagged, or a steerable base swept its wheels round
towards the obstacle while changing its ICR), the base is sent ``s v₀``: a twist on its own
path, which a steerable base follows by slowing its wheels without steering them, with ``s``
low enough (down to −1, or lower where a pair must separate faster than the base approaches
it) to brake the approach within the room left, within the method's box.
The part of the reference along ``v₀`` is held to the same row as the reference: a steerable
base first drives on along its path at that part while its wheels turn to the new one. The
row also holds at every corner of the box between the measured twist and the reference, axis
by axis (the base gets to its reference on each axis at its own pace: a steerable base drives
on along its wheels' heading, and turns, before it has steered to a sideways reference), and
against the pair's normal as the base will see it after the turn it cannot stop at once
(turned by ω τ, and for a reference in the base's frame, which turns with it, by the turn's
braking ω |ω| / (2 α) too). A lagging base's own body (chassis, wheels) keeps
``collision_lag_margin`` more than ``d_s`` from obstacles: while its wheels steer from one ICR
to another its twist sweeps through directions that neither its reference nor its measured
twist has (robot A spinning beside the pillar approached it faster and faster for 0.3 s
while its reference asked it away), which no lag on each axis describes. A wheeled base that
tracks its reference within its acceleration limits has τ = 0: the rows above, no such
braking and no margin.

With ``ḋ = j · q̇`` (``q̇`` the command: the base's axes, when the method commands the base
with it, then the arm's joints; :class:`~wmm_control.kinematics.collision.CollisionModel`),
each pair is one linear row on the command; a base twist that is not part of the command
(the base controller's, when only the arm is left to choose) moves each row's bound by its
share. The stage returns the command nearest the method's own,

    min ½ (q̇ − q̇₀)ᵀ (JᵀJ + μ W) (q̇ − q̇₀)   subject to   the dampers, and   lower ≤ q̇ ≤ upper,

``J`` the method's task Jacobian over the command and ``W`` its weighting of the entries (``μ``
= :data:`SELF_WEIGHT`): what changes least at the end effector, so that a damper is met in the
task's null space where it can be (an elbow stops sinking towards a table while the end
effector holds its goal) rather than by whatever entry is cheapest (the base backing away
from the goal). Without ``J``, the nearest in ``W``.

``[lower, upper]`` being the period's box the method already keeps (velocity, acceleration,
braking before a position limit). One QP through a maintained solver (:mod:`qpsolvers`,
:data:`QP_SOLVER`) over the command's entries takes every damper row that some command in the
box could break (a row the box alone keeps, or one on no entry the box leaves free, stays out).
Where the box leaves no command that meets every damper (the arm arrives faster than its
acceleration limits can brake), the same solver takes the problem again with a slack per row
of high linear cost: the answer meets the dampers as far as the box allows, and the stage never
fails for it.

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
from numpy.typing import ArrayLike
import qpsolvers

from wmm_control.base.swmr_controller import SwmrParams
from wmm_control.errors import ConfigError
from wmm_control.geometry import rotation_z
from wmm_control.kinematics.collision import CollisionModel
from wmm_control.robot_config import SteerableBase

__all__ = ['SafetyParams', 'SafetyResult', 'SafetyStage', 'base_lag']

#: Cost per unit of damper slack [per m/s], linear (an exact penalty: no slack at all where
#: the box leaves room, which a quadratic cost would not give), against weights of about 1 on
#: the command; and its small quadratic term, which keeps the problem strictly convex.
SLACK_COST = 1e3
SLACK_WEIGHT = 1.0
#: μ: the weight of the command's own change against the end effector's (with a task Jacobian).
SELF_WEIGHT = 1e-2
#: The command is taken as meeting a damper within this much [m/s].
TOLERANCE = 1e-9
#: [m/s] a lagging base's measured twist below this tells no path (at rest).
PATH_SPEED = 1e-4
#: The share of a wheeled base's linear deceleration near obstacles that its turn may take
#: (turning under a moving base turns its path, towards an obstacle too, and the linear axes
#: must brake that); the dampers count on the rest.
TURN_SHARE = 0.25
#: The corners of the box between a lagging base's measured twist and its reference other than
#: the reference itself: the axes (vx, vy, ω) on which each takes the reference.
_PARTS = tuple(
    np.array(part, dtype=bool) for part in ((1, 0, 0), (0, 1, 0), (0, 0, 1), (1, 1, 0), (1, 0, 1), (0, 1, 1))
)
#: The QP solver (:mod:`qpsolvers`' name). DAQP, a dual active-set method in C, solves these
#: dense QPs (the command's few entries, up to a few hundred damper rows) to rounding; on this
#: machine 300 random QPs of 10 variables and 40 rows with bounds took DAQP 17 µs and quadprog (compiled
#: Goldfarb–Idnani) 28 µs at the median, through qpsolvers.
QP_SOLVER = 'daqp'


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
        collision_lag_margin: the room [m] a lagging base's own body (chassis, wheels) keeps
            from obstacles beyond d_s: a steerable base re-steering its wheels sweeps its twist
            through directions that neither its reference nor its measured twist has, which
            the lag τ does not describe (no effect on a base without lag).
    """

    collision_avoidance: bool = True
    collision_influence: float = 0.10
    collision_safety: float = 0.02
    collision_gain: float = 0.2
    collision_lookahead: float = 0.3
    collision_braking: float = 0.5
    collision_lag_margin: float = 0.03

    def __post_init__(self):
        for name in (
            'collision_influence',
            'collision_safety',
            'collision_gain',
            'collision_lookahead',
            'collision_braking',
        ):
            value = getattr(self, name)
            if not (math.isfinite(value) and value > 0.0):
                raise ConfigError(f'{name} must be finite and > 0, got {value}')
        if not (math.isfinite(self.collision_lag_margin) and self.collision_lag_margin >= 0.0):
            raise ConfigError(f'collision_lag_margin must be finite and >= 0, got {self.collision_lag_margin}')
        if self.collision_safety >= self.collision_influence:
            raise ConfigError(
                f'collision_safety ({self.collision_safety} m) must be below collision_influence '
                f'({self.collision_influence} m)'
            )
        if self.collision_lookahead < self.collision_influence:
            raise ConfigError(
                f'collision_lookahead ({self.collision_lookahead} m) must not be below '
                f'collision_influence ({self.collision_influence} m)'
            )


@dataclass(frozen=True)
class SafetyResult:
    """The stage's answer.

    Attributes:
        command: the command (base axes, then arm) [rad/s or m/s]. Shape (n,).
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
    """Velocity dampers on a command of a :class:`CollisionModel`.

    Args:
        collision: a :class:`~wmm_control.kinematics.collision.CollisionModel`.
        params: :class:`SafetyParams` (or a method's parameters, which derive from it).
        arm_acceleration: the arm joints' acceleration limits [rad/s² or m/s²], shape
            (n_arm,); None: every row brakes at ``collision_braking``.
        base_velocity, base_acceleration: the base's limits on (vx, vy, ω) [m/s, rad/s; /s]
            (only with ``arm_acceleration``); they set the look-ahead with obstacles.
        base_lag: τ, the time constant [s] with which the base's twist follows its reference
            (:func:`base_lag`).
    """

    @classmethod
    def for_robot(cls, robot, params: SafetyParams = SafetyParams(), obstacles=(), kinematics=None):
        """The stage of a :class:`~wmm_control.robot_config.RobotConfig`: its collision model
        (with ``obstacles``), on the method's :class:`~wmm_control.kinematics.model.KinematicModel`
        ``kinematics`` when given (the distances then read the configuration the method's update
        of the cycle computed), and its acceleration limits."""
        return cls(
            CollisionModel.from_robot(robot, obstacles=obstacles, kinematics=kinematics),
            params,
            robot.arm.acceleration,
            robot.base.velocity,
            robot.base.acceleration,
            base_lag(robot),
        )

    def __init__(
        self,
        collision,
        params: SafetyParams = SafetyParams(),
        arm_acceleration=None,
        base_velocity=None,
        base_acceleration=None,
        base_lag=0.0,
    ):
        self.collision = collision
        self.params = params
        self._arm_acc = None if arm_acceleration is None else np.asarray(arm_acceleration, dtype=float)
        self._base_acc = np.zeros(3) if base_acceleration is None else np.asarray(base_acceleration, dtype=float)
        self._base_velocity = None if base_velocity is None else np.asarray(base_velocity, dtype=float)
        self.set_base_lag(base_lag)

    def set_base_lag(self, base_lag: float) -> None:
        """Plan a lagging base's braking with τ = ``base_lag`` [s] from now on (the base
        controller that actually runs: :attr:`~wmm_control.base.BaseController.lag`).

        Raises:
            ConfigError: ``base_lag`` is not finite and ≥ 0.
        """
        if not (math.isfinite(base_lag) and base_lag >= 0.0):
            raise ConfigError(f'base_lag must be finite and >= 0, got {base_lag}')
        self.base_lag = float(base_lag)
        params = self.params
        stopping = 0.0
        if self._base_velocity is not None and self._base_acc.any():
            linear = [k for k in range(2) if self._base_acc[k] > 0.0]
            if linear:
                # from full speed on every linear axis at once (a diagonal is faster than either
                # axis), braking as its rows count on (_allowed): the slower axis's limit, less
                # the turn's share where the base tracks without lag, and no harder than a_b
                speed = float(np.linalg.norm(self._base_velocity[linear]))
                brake = float(np.min(self._base_acc[linear]))
                if self.base_lag == 0.0:
                    brake *= 1.0 - TURN_SHARE
                brake = min(brake, params.collision_braking)
                stopping = speed * self.base_lag + speed * speed / (2.0 * brake)
        #: [m] the room a lagging base's body keeps from obstacles beyond d_s
        self.body_margin = params.collision_lag_margin if self.base_lag > 0.0 else 0.0
        #: [m] how far an obstacle is looked at: the base's stopping distance from full speed
        self.obstacle_lookahead = max(params.collision_lookahead, params.collision_safety + self.body_margin + stopping)

    def set_obstacles(self, obstacles) -> None:
        """Keep the robot off ``obstacles`` (:class:`~wmm_control.kinematics.obstacles.Obstacle`) from now on."""
        self.collision.set_obstacles(obstacles)

    def filter(
        self,
        q_arm,
        command,
        lower,
        upper,
        weights=None,
        *,
        base_pose=None,
        base_axes=(),
        base_twist=None,
        base_velocity=None,
        world_rates=False,
        task_jacobian=None,
    ) -> SafetyResult:
        """The command ``command`` at arm joints ``q_arm``, within the dampers and the box.

        Args:
            q_arm: arm joint positions. Shape (n_arm,).
            command: the method's command within ``[lower, upper]``: the base's twist on
                ``base_axes`` (if any), then the arm's rates. Shape (len(base_axes) + n_arm,).
            lower, upper: this period's box. Same shape.
            weights: the diagonal of W, the method's weighting of the entries (default
                ones). Same shape.
            base_pose: (x, y, θ) of the base in the world [m, rad]; needed with obstacles.
            base_axes: indices into (vx, vy, ω) of the command's base entries.
            base_twist: the base's twist (vx, vy, ω) when it is not part of the command (None:
                taken as at rest, or as commanded on ``base_axes``).
            base_velocity: the base's measured twist (vx, vy, ω) [m/s, rad/s], when the command
                holds its reference: a lagging base's rows hold on the twist it will have.
            world_rates: the command's base entries are the world frame's (ẋ, ẏ, θ̇) instead
                of the base frame's (vx, vy, ω).
            task_jacobian: J, the end effector's task Jacobian over the command. Shape (r, n).
        """
        command = np.asarray(command, dtype=float)
        p = self.params
        if not p.collision_avoidance:
            return SafetyResult(command, math.inf, '', 0, False)
        axes = list(base_axes)
        d_b = p.collision_lookahead
        reach = self.obstacle_lookahead if self.collision.obstacles else d_b
        near, clearance, names = self.collision.within(q_arm, reach, base_pose)
        moved = near.base_jacobian.any(axis=1)  # pairs with an obstacle
        # a pair the base cannot move is constrained within the arm's look-ahead only
        keep = moved | (near.distance < d_b)
        if not keep.all():
            near, moved = near.select(keep), moved[keep]
        label = '/'.join(names) if names else ''
        if not len(near):
            return SafetyResult(command, clearance, label, 0, False)
        base_full = near.base_jacobian  # over (vx, vy, ω), base frame
        # the command's base entries as (vx, vy, ω): the identity, or R(θ)ᵀ for world-frame rates
        to_base = rotation_z(base_pose[2]).T if world_rates else np.eye(3)  # R(θ)ᵀ
        rows = np.hstack(((base_full @ to_base)[:, axes], near.rate_jacobian))
        distance = near.distance
        if self.body_margin > 0.0:  # a lagging base's body keeps its margin: its pairs are as much nearer
            distance = distance - self.body_margin * _body_pairs(rows, axes, moved)
        allowed = self._allowed(distance, rows, axes, moved)
        lower, upper = np.asarray(lower, dtype=float), np.asarray(upper, dtype=float)
        bound = -allowed
        overtaking = False
        if base_twist is not None:
            bound = bound - base_full @ np.asarray(base_twist, dtype=float)
        elif axes and base_velocity is not None and self.base_lag > 0.0:
            v0 = np.asarray(base_velocity, dtype=float)
            own = base_full @ v0  # the base's approach rates
            command, lower, upper, overtaking = self._brake_on_path(
                distance, rows, bound, axes, command, v0, own, moved, to_base, lower, upper
            )
            rows, bound = self._along_path(rows, bound, axes, v0, own, moved, to_base)
            rows, bound = self._between(rows, bound, axes, base_full, v0, moved, to_base)
            rows, bound = self._after_turn(rows, bound, axes, base_full, v0, command, moved, to_base, world_rates)
        if base_twist is None and self.base_lag == 0.0:
            # a base that tracks its reference: its linear approach must brake on its own (a
            # lagging base's is held along its measured path above)
            rows, bound = _without_turn(rows, bound, axes, base_full, moved, to_base)
        if base_twist is None and moved.any() and not world_rates:
            rows, bound = self._turn_rows(rows, bound, axes, base_full, moved, base_velocity)
        violated = rows @ command < bound - TOLERANCE
        if not violated.any():
            return SafetyResult(command, clearance, label, len(near), overtaking)
        weights = np.ones(command.size) if weights is None else np.asarray(weights, dtype=float)
        if task_jacobian is None:
            hessian = np.diag(weights)
        else:
            jac = np.asarray(task_jacobian, dtype=float)
            hessian = jac.T @ jac + SELF_WEIGHT * np.diag(weights)
        # a row on no entry the box leaves free (a base held on its path, and a pair no arm joint
        # moves) is what it is: its slack is its violation whatever the QP does, so it stays out;
        # so does a row that every command in the box meets (the box alone keeps it)
        lower, upper = np.minimum(lower, upper), np.maximum(lower, upper)
        movable = (rows[:, upper > lower] != 0.0).any(axis=1)
        weakest = np.minimum(rows * lower, rows * upper).sum(axis=1)  # the row's least value in the box
        use = movable & (weakest < bound - TOLERANCE)
        solved = np.clip(command, lower, upper)
        if use.any():
            solved = self._solve(command, rows[use], bound[use], lower, upper, hessian)
        changed = overtaking or not np.array_equal(solved, command)
        return SafetyResult(solved, clearance, label, len(near), changed)

    def _along_path(self, rows, bound, axes, v0, own, moved, to_base):
        """``rows`` and ``bound`` with, for each pair the base moves (``moved``), the same row on the
        part of the reference along the base's measured twist ``v0`` (``own`` = j_b v₀): a steerable
        base first moves along its current path, at that part, while its wheels turn towards the
        reference's (a sideways reference drives it on along its wheels' heading for a while, into
        what lies ahead)."""
        norm = float(v0 @ v0)
        if norm < PATH_SPEED**2 or not moved.any():
            return rows, bound
        along = (own[moved, None] * v0 / norm) @ to_base  # j_b v₀ v₀ᵀ / |v₀|²
        return _with_base_rows(rows, bound, axes, moved, along)

    def _between(self, rows, bound, axes, base_full, v0, moved, to_base):
        """``rows`` and ``bound`` with, for each pair the base moves (``moved``), the row at every
        corner of the box between the base's measured twist ``v0`` and its reference, axis by
        axis (vx, vy, ω of its own frame): a lagging base gets to its reference on each axis at
        its own pace (a steerable base drives on along its wheels' heading, and turns, before it
        has steered to a sideways reference), so a reference whose approach is a part towards
        the obstacle and a part away from it may not count on the part that comes last. Each
        corner takes the reference on some axes and ``v0`` on the others."""
        if not moved.any():
            return rows, bound
        j = base_full[moved]
        measured = j * np.asarray(v0, dtype=float)  # each axis's share of the approach at v₀
        for part in _PARTS:
            rows, bound = _with_base_rows(
                rows, bound, axes, moved, (j * part) @ to_base, -measured[:, ~part].sum(axis=1)
            )
        return rows, bound

    def _after_turn(self, rows, bound, axes, base_full, v0, command, moved, to_base, world_rates):
        """``rows`` and ``bound`` with, for each pair the base moves (``moved``), the same row as
        the base will see it once it has turned on by Δθ: the pair's normal turns the other way
        in the base's frame (j_xy becomes R(−Δθ) j_xy). A lagging base turning at ω (its
        measured twist ``v0``) drives at its reference of τ ago: a reference in the world frame
        (``world_rates``) is driven turned by Δθ = ω τ. A reference held in the base's frame
        turns with the base, which turns on for its lag and then while the turn brakes at the
        base's limit α, whatever its reference asks: Δθ = ω τ + ω |ω| / (2 α), ω the faster of
        the measured turn and the ``command``'s. Without it, a reference that approaches at the
        bound now swings into the obstacle as the turn goes on (robot A passing a table's
        corner while it turns)."""
        if 2 not in axes or not moved.any():
            return rows, bound
        if world_rates:
            turn = float(v0[2]) * self.base_lag
        else:
            omega = max(float(v0[2]), float(command[axes.index(2)]), key=abs)
            alpha = float(self._base_acc[2])
            turn = omega * self.base_lag + (omega * abs(omega) / (2.0 * alpha) if alpha > 0.0 else 0.0)
        if abs(turn) < TOLERANCE:
            return rows, bound
        ahead = base_full[moved] @ rotation_z(turn)  # rows R(−Δθ) j: jᵀ R(Δθ)
        return _with_base_rows(rows, bound, axes, moved, ahead @ to_base)

    def _brake_on_path(self, distances, rows, bound, axes, command, v0, own, moved, to_base, lower, upper):
        """A lagging base that already approaches a pair faster than allowed (its measured twist
        ``v0``, approach rates ``own`` = j_b v₀, with the arm's share of ``command``) is sent
        ``s v₀`` instead of its reference: the largest ``s`` in [−1, 1] that the pairs allow. That
        twist lies on the base's own path (a steerable base keeps its ICR and only slows its
        wheels: no re-steering, whose sweep would carry it on towards the obstacle), and the base
        entries are held there for the arm's QP. Returns ``(command, lower, upper, overtaking)``."""
        nb = len(axes)
        arm = rows[:, nb:] @ command[nb:]
        approaching = moved & (own < -TOLERANCE)
        if not (approaching & (own + arm < bound - TOLERANCE)).any():
            return command, lower, upper, False
        # the approach at the pair's bound once the base has settled at s v₀, and braking at
        # K_p (1 − s) |ḋ_b| from now on strong enough to stop it within the room left
        scale = settle = 1.0
        d_s = self.params.collision_safety
        for i in np.flatnonzero(approaching):
            room = max(distances[i] - d_s, 1e-6)
            settle = min(settle, (bound[i] - arm[i]) / own[i])
            scale = min(scale, settle, 1.0 + own[i] * self.base_lag / (2.0 * room))
        # back along the path at up to the speed it came, or as fast as a pair must separate (a
        # base that crept inside the safety distance at a crawl must leave faster than it came)
        scale = max(scale, min(-1.0, settle))
        command, lower, upper = command.copy(), lower.copy(), upper.copy()
        # the twist in the command's terms, v₀ᵀ R(θ)ᵀ = (R(θ) v₀)ᵀ (to_base is a rotation), within the
        # method's box: the reference changes no faster than its own limits allow
        target = (v0 @ to_base)[axes] * scale
        command[:nb] = lower[:nb] = upper[:nb] = np.clip(target, lower[:nb], upper[:nb])
        return command, lower, upper, True

    def _linear_axes(self, axes):
        """The command's entries on the base's linear axes, and the slower axis's acceleration
        limit [m/s²] (None without them)."""
        linear = [k for k, axis in enumerate(axes) if axis < 2]
        return linear, (float(np.min(self._base_acc[[axes[k] for k in linear]])) if linear else None)

    def _turn_rows(self, rows, bound, axes, base_full, moved, base_velocity):
        """``rows`` and ``bound`` with, for each pair of the base's own body and an obstacle, a
        row on the turn rate: turning at ω while driving at ``v`` (the measured twist, base
        frame) turns the pair's normal under the base's velocity, which changes the approach
        rate n · v at ω (n_x v_y − n_y v_x) per second, towards the obstacle for one sign of
        ω. The linear axes must brake that as well, so the turn may take no more than
        ``TURN_SHARE`` of their deceleration (the dampers count on the rest): a base driving
        past an obstacle may not swing its path into it faster than it can brake."""
        linear, slowest = self._linear_axes(axes)
        if 2 not in axes or not linear or base_velocity is None:
            return rows, bound
        body = _body_pairs(rows, axes, moved)
        v = np.asarray(base_velocity, dtype=float)
        bend = base_full[body, 0] * v[1] - base_full[body, 1] * v[0]  # n_x v_y − n_y v_x
        if not bend.any():
            return rows, bound
        extra = np.zeros((int(body.sum()), rows.shape[1]))
        extra[:, axes.index(2)] = -bend
        budget = TURN_SHARE * slowest * np.hypot(base_full[body, 0], base_full[body, 1])
        return np.vstack((rows, extra)), np.concatenate((bound, -budget))

    def _allowed(self, distances, rows, axes, moved) -> np.ndarray:
        """Each pair's fastest allowed approach [m/s], braking no harder than the command's
        acceleration limits can slow that distance. The base's turn rate is left out: turning
        swings the near point aside for a moment, but does not stop a base that drives at an
        obstacle."""
        lags = np.where(moved, self.base_lag, 0.0)
        if self._arm_acc is None:
            return np.asarray(self.allowed_approach(distances, lag=lags))
        nb = len(axes)
        reach = np.abs(rows[:, nb:]) @ self._arm_acc
        linear, slowest = self._linear_axes(axes)
        if linear:
            # the base's linear axes brake the distance at no more than |j_xy| times the slower
            # axis's limit, whichever way the pair's normal turns while it brakes (Σ |j_i| a_i
            # would count on braking both axes at once along a normal that the base's turn, or
            # its approach to another face, changes under it)
            if 2 in axes and self.base_lag == 0.0:
                slowest *= 1.0 - TURN_SHARE  # the rest is the turn's (_turn_rows)
            reach = reach + np.linalg.norm(rows[:, linear], axis=1) * slowest
        return np.asarray(self.allowed_approach(distances, reach, lags))

    def allowed_approach(
        self, distance: ArrayLike, deceleration: ArrayLike = math.inf, lag: ArrayLike = 0.0
    ) -> float | np.ndarray:
        """The fastest a pair ``distance`` [m] apart may approach [m/s] (negative: it must
        separate), its distance braking at no more than ``deceleration`` [m/s²] (and
        ``collision_braking``) after a lag of ``lag`` [s]. Each argument a number or an array
        (one entry per pair); the answer is a float for numbers, else an array."""
        p = self.params
        d_i, d_s = p.collision_influence, p.collision_safety
        distance, deceleration, lag = np.broadcast_arrays(
            *(np.asarray(v, dtype=float) for v in (distance, deceleration, lag))
        )
        a = np.minimum(p.collision_braking, deceleration)
        room = np.maximum(distance - d_s, 0.0)
        with np.errstate(divide='ignore', invalid='ignore', over='ignore'):  # a tiny a: inf, then min
            braking = np.where(a > 0.0, a * (np.sqrt(lag * lag + 2.0 * room / a) - lag), 0.0)
            gain = np.where(
                lag > 0.0, np.minimum(p.collision_gain / (d_i - d_s), 1.0 / lag), p.collision_gain / (d_i - d_s)
            )
        damper = np.where(distance < d_i, gain * (distance - d_s), math.inf)
        out = np.minimum(damper, braking)
        return float(out) if out.ndim == 0 else out

    def _solve(self, command, rows, bound, lower, upper, hessian):
        """The QP of the module docstring: the command nearest ``command`` in the metric
        ``hessian`` within the box that meets the dampers ``rows`` q̇ ≥ ``bound``, through
        :func:`qpsolvers.solve_problem` (:data:`QP_SOLVER`). Where no command in the box meets
        them all, the same solver takes the problem with a slack per row (cost
        :data:`SLACK_COST` per unit, and :data:`SLACK_WEIGHT` quadratic): the dampers met as far
        as the box allows."""
        n, m = command.size, bound.size
        hard = qpsolvers.Problem(hessian, -hessian @ command, -rows, -bound, lb=lower, ub=upper)
        answer = qpsolvers.solve_problem(hard, solver=QP_SOLVER)
        if answer.found and answer.x is not None and np.all(np.isfinite(answer.x)):
            return np.clip(answer.x, lower, upper)
        # over y = (q̇, slack): rows q̇ + slack ≥ bound, slack ≥ 0
        cost = np.zeros((n + m, n + m))
        cost[:n, :n] = hessian
        cost[n:, n:] = SLACK_WEIGHT * np.eye(m)
        linear = np.concatenate((-hessian @ command, np.full(m, SLACK_COST)))
        relaxed = qpsolvers.Problem(
            cost,
            linear,
            -np.hstack((rows, np.eye(m))),
            -bound,
            lb=np.concatenate((lower, np.zeros(m))),
            ub=np.concatenate((upper, np.full(m, np.inf))),
        )
        answer = qpsolvers.solve_problem(relaxed, solver=QP_SOLVER)
        if not (answer.found and answer.x is not None and np.all(np.isfinite(answer.x))):
            # the box itself is empty or the solver failed: brake as hard as the box allows
            return np.clip(np.zeros(n), lower, upper)
        return np.clip(answer.x[:n], lower, upper)


def _without_turn(rows, bound, axes, base_full, moved, to_base):
    """``rows`` and ``bound`` with, for each pair of the base's own body (chassis, wheels: no arm
    joint moves it) and an obstacle whose distance the base's turn changes, the same row without
    the turn's share: the base's linear approach brakes as the row counts on even when the turn
    stops. Without it, a turn that swings a corner away for the moment meets the row while the
    base drives on at the obstacle faster than its linear acceleration limits can stop (and the
    next corner swings in). The arm's pairs keep the turn: the arm brakes its own share fast."""
    if 2 not in axes:
        return rows, bound
    n = len(moved)  # the pairs' own rows come first
    turning = _body_pairs(rows, axes, moved) & (base_full[:, 2] != 0.0)
    if not turning.any():
        return rows, bound
    linear = base_full[turning] * np.array([1.0, 1.0, 0.0])
    extra = np.hstack(((linear @ to_base)[:, axes], rows[:n][turning, len(axes) :]))
    return np.vstack((rows, extra)), np.concatenate((bound, bound[:n][turning]))


def _with_base_rows(rows, bound, axes, moved, base, shift=0.0):
    """``rows`` and ``bound`` with, for each pair the base moves (``moved``, over the pairs' own
    rows, which come first), its row again with the base part ``base`` (over (vx, vy, ω) in
    the command's terms, one row per moved pair) and its bound plus ``shift``."""
    pairs = slice(0, moved.size)
    extra = np.hstack((base[:, axes], rows[pairs][moved, len(axes) :]))
    return np.vstack((rows, extra)), np.concatenate((bound, bound[pairs][moved] + shift))


def _body_pairs(rows, axes, moved):
    """The pairs of the base's own body (no arm joint moves them: chassis, wheels) and an
    obstacle, among the first ``len(moved)`` rows."""
    return moved & ~rows[: len(moved), len(axes) :].any(axis=1)


def base_lag(robot) -> float:
    """τ [s] of ``robot``'s base controller at its robot YAML's defaults
    (:attr:`~wmm_control.base.swmr_controller.SwmrParams.lag` for a steerable base; 0 for a
    wheeled base, whose wheel controller tracks the reference within its acceleration limits).
    The running controller's own τ replaces it (:meth:`SafetyStage.set_base_lag`): the direct
    engine's :class:`~wmm_control.cycle.Cycle` passes its base controller's, the resolver node
    the one the base controller node publishes."""
    if not isinstance(robot.base, SteerableBase):
        return 0.0
    return SwmrParams.from_robot_config(robot).lag
