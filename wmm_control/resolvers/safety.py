"""The safety stage every method passes its command through: the command nearest the method's,
in the task metric, under the limits' constraints.

Each cycle the stage asks its limits (:mod:`~wmm_control.resolvers.collision_limits`, where
each row is documented) for their rows on the command, as
:class:`~wmm_control.resolvers.constraints.Constraint` ``G q̇ ≤ h``: the velocity dampers that
keep the arm off the robot's own body, off itself and off the floor, and the whole robot off
obstacles (``self``, ``floor``, ``obstacle``), and the rows of a base that lags its reference or
turns (``base along path``, ``base between``, ``base after turn``, ``base without turn``,
``base turn rate``; a lagging base that already approaches too fast is held on its path in the
box). The period's box ``[lower, upper]`` (velocity, acceleration, braking before a position
limit: :meth:`~wmm_control.resolvers.limits.CommandLimits.box`, which the method already keeps)
comes as bounds (:class:`~wmm_control.resolvers.constraints.Box`). The stage stacks the rows and
sends

    min ½ (q̇ − q̇₀)ᵀ (JᵀJ + μ W) (q̇ − q̇₀)   subject to   G q̇ ≤ h,   lower ≤ q̇ ≤ upper,

``q̇₀`` the method's command, ``J`` its task Jacobian over the command and ``W`` its weighting of
the entries (``μ`` = :data:`SELF_WEIGHT`): what changes least at the end effector, so that a
damper is met in the task's null space where it can be (an elbow stops sinking towards a table
while the end effector holds its goal) rather than by whatever entry is cheapest (the base
backing away from the goal). Without ``J``, the nearest in ``W``. ``W`` keeps the method's
sharing of the task (:func:`task_weights`): an entry the method leaves out of the task changes
only as far as the rows need it, not to make up the end effector's motion that a row cut from
another.

One QP through a maintained solver (:func:`~wmm_control.resolvers.constraints.nearest`,
DAQP) over the command's entries takes every row that some command in the
box could break (a row the box alone keeps, or one on no entry the box leaves free, stays out).
Where the box leaves no command that meets every row (the arm arrives faster than its
acceleration limits can brake), the same solver takes the problem again with the rows soft, a slack per row of
high linear cost: the answer meets the rows as far as the box allows, and the stage never fails
for it.

When no pair is within the look-ahead, or the command already meets every row, it passes through
unchanged: a method runs as its paper has it until the arm nears the body. The cycle's rows stay
with the answer (:attr:`SafetyResult.constraints`; :meth:`SafetyResult.binding` counts the rows
of each limit that shape it), and :class:`SafetyCounts` counts, over a run, the cycles in which
each limit shaped the command (the resolver's ``/diagnostics`` and the direct engine's run
summary).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from wmm_control.base.contract import base_controller_class
from wmm_control.errors import ConfigError
from wmm_control.geometry import rotation_z
from wmm_control.kinematics.collision import CollisionModel, NearPairs
from wmm_control.resolvers.collision_limits import LIMITS, BaseRows, VelocityDampers
from wmm_control.resolvers.constraints import TOLERANCE, Box, Constraint, nearest

__all__ = [
    'OUT_OF_TASK_WEIGHT',
    'SELF_WEIGHT',
    'SafetyCounts',
    'SafetyParams',
    'SafetyResult',
    'SafetyStage',
    'base_lag',
    'task_weights',
]

#: μ: the weight of the command's own change against the end effector's (with a task Jacobian).
SELF_WEIGHT = 1e-2

#: W of an entry its method keeps out of the task (activation 0, :func:`task_weights`): μ W = 100,
#: a change of it costs a hundred times what it does at the end effector (|J_i|² ~ 1), so it
#: changes only as far as the rows need it, never to make up the end effector's motion for another.
OUT_OF_TASK_WEIGHT = 1e4


def task_weights(activation) -> np.ndarray:
    """W of a method that shares the task by the activation ``A`` (the diagonal of ``A = W⁻¹``,
    Sorour eq 9: 1 an entry takes part fully, 0 not at all): ``1 / A``, and
    :data:`OUT_OF_TASK_WEIGHT` where ``A`` is zero.

    Passed to :meth:`SafetyStage.filter` as ``weights``: the stage's nearest command then keeps
    the method's sharing. With W = ones, the stage met a row that cuts the arm with the base
    that the method had kept out of the task (the arm's motion to the stance's posture, the base
    held at the stance by the plan's pull): the base made up the end effector's motion the row
    cut, that change was the next period's previous command, and period by period the base ran
    off to its full twist (``docs/methods.md``, the safety stage)."""
    a = np.asarray(activation, dtype=float)
    out = np.full(a.shape, OUT_OF_TASK_WEIGHT)
    np.divide(1.0, a, out=out, where=a > 0.0)
    return np.minimum(out, OUT_OF_TASK_WEIGHT)


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
        constraints: the cycle's rows on the command, every limit's stacked (None when the
            stage is off or no pair is near).
        relaxed: the rows conflicted within the box and were met as far as it allows.
        held: a lagging base was held on its path (its entries fixed in the box,
            :meth:`~wmm_control.resolvers.collision_limits.BaseRows.hold_on_path`).
        multipliers: each row's Lagrange multiplier in the cycle's QP (:func:`nearest`; zero
            for a row the QP did not take), None when no QP ran (the command met every row).
            Shape (m,), as ``constraints``.
    """

    command: np.ndarray
    clearance: float
    closest_pair: str
    active: int
    changed: bool
    constraints: Constraint | None = None
    relaxed: bool = False
    held: bool = False
    multipliers: np.ndarray | None = None

    def binding(self) -> dict[str, int]:
        """Rows per limit that shaped the command: a multiplier above :data:`TOLERANCE` in the
        cycle's QP (met at equality, or broken where the rows were relaxed, and needed: without
        the row the answer would differ). Empty when no QP ran."""
        if self.constraints is None or self.multipliers is None:
            return {}
        return self.constraints.per_part(np.flatnonzero(self.multipliers > TOLERANCE))


class SafetyCounts:
    """The cycles since start in which each limit of the safety stage shaped the command: one
    :class:`SafetyResult` a cycle (:meth:`add`), the counts as flat ``key → cycles`` values
    (:meth:`values`) that ``/diagnostics`` and a run's summary carry alike.

    Attributes:
        binding: limit name (:data:`~wmm_control.resolvers.collision_limits.LIMITS`) → cycles in
            which a row of that limit shaped the command (:meth:`SafetyResult.binding`).
        relaxed: cycles whose rows conflicted within the box (:attr:`SafetyResult.relaxed`).
        held: cycles in which a lagging base was held on its path (:attr:`SafetyResult.held`).
    """

    def __init__(self) -> None:
        self.binding = dict.fromkeys(LIMITS, 0)
        self.relaxed = self.held = 0
        self._cycle: tuple[set[str], bool, bool] = (set(), False, False)

    def add(self, result: SafetyResult | None, same_cycle: bool = False) -> None:
        """Count ``result``, the stage's answer of a cycle (None: it gave none). ``same_cycle``:
        a further answer of the cycle counted last (a compensated arm command filtered again):
        what it adds to that cycle's counts, a limit that bound in both counted once."""
        names, relaxed, held = self._cycle if same_cycle else (set(), False, False)
        if result is not None:
            if result.multipliers is not None:  # else no QP ran: no limit shaped the command
                for name, rows in result.binding().items():
                    if rows and name not in names:
                        names.add(name)
                        self.binding[name] = self.binding.get(name, 0) + 1
            if result.relaxed and not relaxed:
                self.relaxed += 1
            if result.held and not held:
                self.held += 1
            relaxed, held = relaxed or result.relaxed, held or result.held
        self._cycle = (names, relaxed, held)

    def values(self) -> dict[str, int]:
        """``binding_<limit>`` (its name's spaces as underscores) per limit, ``relaxed_cycles``
        and ``base_held_cycles``."""
        out = {'binding_' + name.replace(' ', '_'): cycles for name, cycles in self.binding.items()}
        out['relaxed_cycles'] = self.relaxed
        out['base_held_cycles'] = self.held
        return out


class SafetyStage:
    """The command nearest the method's under the limits of
    :mod:`~wmm_control.resolvers.collision_limits`, on a :class:`CollisionModel`.

    Args:
        collision: a :class:`~wmm_control.kinematics.collision.CollisionModel`.
        params: :class:`SafetyParams` (or a method's parameters, which derive from it).
        arm_acceleration: the arm joints' acceleration limits [rad/s² or m/s²], shape
            (n_arm,); None: every row brakes at ``collision_braking``.
        base_velocity, base_acceleration: the base's limits on (vx, vy, ω) [m/s, rad/s; /s]
            (only with ``arm_acceleration``); they set the look-ahead with obstacles.
        base_lag: τ, the time constant [s] with which the base's twist follows its reference
            (:func:`base_lag`).

    Attributes:
        last: the last :class:`SafetyResult` (None before the first command).
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
        self.last: SafetyResult | None = None
        self._held_memo: tuple = (None, None)  # (near pairs, those held) of the last _held()
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
        #: [m] the room a lagging base's body keeps from obstacles beyond d_s
        self.body_margin = params.collision_lag_margin if self.base_lag > 0.0 else 0.0
        #: the limits, with this lag
        self.dampers = VelocityDampers(params, self._arm_acc, self._base_acc, self.base_lag, self.body_margin)
        self.base_rows = BaseRows(params.collision_safety, self._base_acc, self.base_lag)
        # from full speed on every linear axis at once (a diagonal is faster than either axis),
        # braking as the dampers' rows count on, on the axes the base can accelerate
        axes = self.dampers.base_axes
        linear, brake = self.dampers.linear_braking(axes)
        on = [axes[k] for k in linear]
        speed = 0.0 if self._base_velocity is None else float(np.linalg.norm(self._base_velocity[on]))
        #: [m] how far an obstacle is looked at: the base's stopping distance from full speed
        self.obstacle_lookahead = max(
            params.collision_lookahead, self.body_margin + self.dampers.stopping_distance(speed, brake)
        )

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
        target=None,
    ) -> SafetyResult:
        """The command ``command`` at arm joints ``q_arm``, under the limits' rows and within the box.

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
            target: the command the answer is nearest to where a row cuts ``command``, within
                the box (which holds each entry's acceleration bound) and the rows; None:
                ``command``. The velocity-level methods give the base's entries as the method
                asked for them before its limits scaled the change from last period uniformly
                (:attr:`~wmm_control.resolvers.limits.LimitResult.requested`): a joint the rows
                hold sets that factor near zero period after period, and the stage, nearest the
                command so frozen, kept the base at the twist it had while the task's error
                grew. Same shape as ``command``.
        """
        self.last = out = self._filter(
            q_arm,
            command,
            Box(lower, upper),
            weights,
            base_pose,
            tuple(base_axes),
            base_twist,
            base_velocity,
            world_rates,
            task_jacobian,
            target,
        )
        return out

    def _filter(
        self, q_arm, command, box, weights, base_pose, axes, base_twist, base_velocity, world_rates, jacobian, target
    ) -> SafetyResult:
        command = np.asarray(command, dtype=float)
        p = self.params
        if not p.collision_avoidance:
            return SafetyResult(command, math.inf, '', 0, False)
        d_b = p.collision_lookahead
        reach = self.obstacle_lookahead if self.collision.obstacles else d_b
        # a pair the base cannot move (no obstacle in it) is constrained within the arm's look-ahead only
        near, clearance, names = self.collision.within(q_arm, reach, base_pose, robot_influence=d_b)
        label = '/'.join(names) if names else ''
        near = self._held(near)
        if not len(near):
            return SafetyResult(command, clearance, label, 0, False)
        # the command's base entries as (vx, vy, ω): the identity, or R(θ)ᵀ for world-frame rates
        to_base = rotation_z(base_pose[2]).T if world_rates else np.eye(3)
        pairs = self.dampers.pairs(near, axes, to_base).with_twist(base_twist)
        command, box, held, base_rows = self.base_rows.constraints(
            pairs, command, box, base_velocity, base_twist, world_rates
        )
        rows = Constraint.stack(
            (self.dampers.constraints(pairs), self.dampers.stopping(pairs, box), *base_rows), command.size, 'safety'
        )
        if not rows.violated(command, TOLERANCE).any():
            return SafetyResult(command, clearance, label, len(near), held, rows, held=held)
        weights = np.ones(command.size) if weights is None else np.asarray(weights, dtype=float)
        if jacobian is None:
            metric = np.diag(weights)
        else:
            jac = np.asarray(jacobian, dtype=float)
            metric = jac.T @ jac + SELF_WEIGHT * np.diag(weights)
        # a row on no entry the box leaves free (a base held on its path, and a pair no arm joint
        # moves) is what it is: its slack is its violation whatever the QP does, so it stays out;
        # so does a row that every command in the box meets (the box alone keeps it)
        movable = (rows.G[:, box.free()] != 0.0).any(axis=1)
        use = movable & (box.greatest(rows.G) > rows.h + TOLERANCE)
        solved, relaxed, multipliers = box.clip(command), False, np.zeros(len(rows))
        if use.any():
            goal = command if target is None else np.asarray(target, dtype=float)
            solved, relaxed, multipliers[use] = nearest(goal, metric, rows.select(use), box)
        changed = held or not np.array_equal(solved, command)
        return SafetyResult(solved, clearance, label, len(near), changed, rows, relaxed, held, multipliers)

    def _held(self, near: NearPairs) -> NearPairs:
        """The pairs of ``near`` the rows hold: a pair the base cannot move only within the
        arm's look-ahead. The same ``near`` again (a second pass in one period) gets the same
        answer, whose dampers' bounds are then the first pass's."""
        if self._held_memo[0] is not near:
            keep = near.base_jacobian.any(axis=1) | (near.distance < self.params.collision_lookahead)
            self._held_memo = (near, near if keep.all() else near.select(keep))
        return self._held_memo[1]


def base_lag(robot) -> float:
    """τ [s] of ``robot``'s base controller at its robot YAML's defaults
    (:meth:`~wmm_control.base.BaseController.default_lag`: the steerable controller's
    1/K_p + 1/λ; 0 for a wheeled base, whose wheel controller tracks the reference within its
    acceleration limits). The running controller's own τ replaces it
    (:meth:`SafetyStage.set_base_lag`): the direct engine's :class:`~wmm_control.cycle.Cycle`
    passes its base controller's, the resolver node the one the base controller node
    publishes."""
    return base_controller_class(robot).default_lag(robot)
