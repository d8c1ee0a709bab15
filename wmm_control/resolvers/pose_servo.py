"""The velocity-level machinery that the damped pseudo-inverse and task sharing share.

Sorour §II–III: the proportional pose controller of eq (12), the augmented Jacobian J_mm of
eq (7), the limits of the whole command, and the arm compensation of eq (14). A subclass
supplies only the inversion: ``_resolve(jac, p_ref, e_pos, state, pull, stance, plan_arm) -> (u_task,
u_null, mode, ψ, A)``, the task part and the null-space part, which gives way first to the limits,
and the activation ``A`` with which it shared the task, which the safety stage keeps.
Each part's change from its own share of the last command is bounded
(:class:`~wmm_control.resolvers.limits.CommandLimits`); where the safety stage changes the base's
reference, the change comes out of the null-space share first, the one that gives way first,
as far as that share goes (never turning it against what was asked), and only the rest out of
the task's. (Counted as the task's, a base out of task sharing's task but cut by the stage's
rows of a base that lags its reference left the task a share to undo within the base's
acceleration limit, and the one factor of the task's change held the arm's part back with it;
counted as the null-space share's whole, a cut of a base in the task turned that share against
the pull it was asked for.)

A followed plan's base (:class:`~wmm_control.resolvers.interface.BaseReference` on the target,
not in the paper): the base is pulled towards its planned pose by a secondary task in the null
space of the end effector's, ``z_b = ᵇR_w (ξ̇_plan + λ_p (ξ_plan − ξ))`` over the base's axes
(:meth:`PoseServoResolver.base_pull`), projected as eq (13)'s posture pull is
(:meth:`PoseServoResolver.null_motion`; task sharing with its weighting,
:meth:`PoseServoResolver.secondary_motion`): the end effector's task keeps its priority, and
what it leaves free brings the base back onto the plan with the arm making up the difference.
At the stance (the final approach) a method's own posture pull ranks below it
(:meth:`PoseServoResolver.secondary_motion`).
Without a base reference nothing changes.

Joint space. The paper's base coordinates are the 6-vector q̇_b = (ẋ, ẏ, 0, 0, 0, ω) (eq 3)
with J_b = I₆ (eq 2); three columns of ``M_RPY H J_b`` are then identically zero, and every
solution of eqs (8), (9) and (14) has zeros there. This module keeps the three that move:
``u = (vx, vy, ω, q̇_1 … q̇_7)``, base twist in the base frame. The results are the paper's.

Task space (``orientation_error``):

* ``'rpy'`` (the paper): ṗ = (ṙ, θ̇) in the base frame, θ the RPY angles of the end
  effector. J = J_mm = M_RPY [H J_b, J_a] with Ω⁻¹ damped by ``rpy_damping`` (singular at
  pitch ±π/2). The angular error is the wrapped difference of world RPY angles; for ZYX
  angles the base yaw only shifts the yaw, so the base-frame RPY error equals the world one.
  Eq (12) as printed also rotates that RPY error by ᵇR_w, which only mixes the roll and pitch
  errors once the base has turned; ``rotate_angular_error=True`` keeps that literal form.
* ``'log'``: the SO(3) log-map error ``log(R* Rᵀ)`` rotated into the base frame, and the
  geometric Jacobian [H J_b, J_a]: no singularity short of a half turn.
"""

import math
import time
from abc import abstractmethod
from dataclasses import dataclass, fields, replace
from pathlib import Path
from typing import ClassVar

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.errors import ConfigError
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.tasks import PoseTask, PostureTask, twist_columns
from wmm_control.geometry import (
    cap_norm,
    largest_step,
    norm,
    rotation_z,
)
from wmm_control.resolvers.interface import (
    BaseReference,
    PoseTarget,
    Resolver,
    ResolverCommand,
    ResolverDiagnostics,
    RobotState,
    SteeringParams,
    base_twist_of,
)
from wmm_control.resolvers.limits import CommandLimits
from wmm_control.resolvers.safety import SafetyParams, SafetyStage, task_weights
from wmm_control.resolvers.sns import saturate_in_null_space
from wmm_control.robot_config import RobotConfig

__all__ = [
    'PoseServoParams',
    'PoseServoResolver',
    'damped_pinv',
    'damped_pinv_solve',
    'singularity_damping',
    'ORIENTATION_ERRORS',
]

ORIENTATION_ERRORS = ('rpy', 'log')


@dataclass(frozen=True)
class PoseServoParams(SafetyParams, SteeringParams):
    """Parameters shared by the velocity-level resolvers (Sorour Table I defaults), the safety
    stage's (:class:`~wmm_control.resolvers.safety.SafetyParams`) and a followed plan's base's
    (:class:`~wmm_control.resolvers.interface.SteeringParams`).

    Attributes:
        dt: control period t_s [s].
        lambda_p: gain λ_p of the pose controller, eq (12) [1/s].
        rho: damping ρ of the pseudo-inverse [-].
        orientation_error: ``'rpy'`` (the paper) or ``'log'`` (SO(3) log map).
        rotate_angular_error: apply eq (12)'s ᵇR_w to the RPY error too (literal eq 12).
        rpy_damping: damping of Ω⁻¹ near pitch ±π/2 [-].
        max_linear_speed: cap on the task-space linear reference [m/s], applied before the
            inversion so that an absurdly far goal cannot overflow; far above every limit.
        max_angular_speed: same for the angular reference [rad/s].
        singular_region: ε [-]: below this smallest singular value of the Jacobian being
            inverted, the damping grows (not in the paper; see :func:`singularity_damping`).
        max_damping: ρ_max [-], the damping reached at an exact singularity.
        hold_joint_limits: hold an arm joint that the task would drive past its braking
            bound there and share its part among the others (not in the paper; see
            :meth:`PoseServoResolver.solve_task`).
        arm_takeover: where the base's acceleration limit holds back its share of the task,
            the other joints take it over (not in the paper; see
            :meth:`PoseServoResolver.solve_task`).
        pinv_tolerance: relative singular-value cut-off of the null-space projector's J⁺.
    """

    dt: float = 0.025
    lambda_p: float = 1.7
    rho: float = 0.001
    orientation_error: str = 'rpy'
    rotate_angular_error: bool = False
    rpy_damping: float = 1e-3
    max_linear_speed: float = 10.0
    max_angular_speed: float = 10.0
    singular_region: float = 0.1
    max_damping: float = 0.1
    hold_joint_limits: bool = False
    arm_takeover: bool = False
    pinv_tolerance: float = 1e-6

    #: numeric fields that may be zero (the others must be > 0)
    _allow_zero: ClassVar[tuple[str, ...]] = ('max_damping',)

    def __post_init__(self):
        super().__post_init__()
        _check_fields(self, self._allow_zero)
        if self.orientation_error not in ORIENTATION_ERRORS:
            raise ConfigError(f'orientation_error must be one of {ORIENTATION_ERRORS}, got {self.orientation_error!r}')


def _check_fields(params, allow_zero=()):
    """Every numeric field of a params dataclass is finite and > 0 (>= 0 for ``allow_zero``).

    Fields declared ``bool`` or ``str`` are checked by their owners.
    """
    for f in fields(params):
        if f.type in (bool, str, 'bool', 'str'):
            continue
        val = getattr(params, f.name)
        if isinstance(val, bool) or not isinstance(val, (int, float)):
            raise ConfigError(f'{type(params).__name__}.{f.name}: expected a number, got {val!r}')
        if not math.isfinite(val) or val < 0 or (val == 0 and f.name not in allow_zero):
            raise ConfigError(
                f'{type(params).__name__}.{f.name} must be finite and '
                f'{">= 0" if f.name in allow_zero else "> 0"}, got {val}'
            )


def singularity_damping(jac: np.ndarray, rho: float, region: float, max_damping: float) -> tuple[float, float]:
    """Damping of a singularity-robust inverse (Nakamura–Hanafusa, Chiaverini).

    ``ρ² = ρ₀² + ρ_max² (1 − (σ_min/ε)²)`` when σ_min < ε, else ρ₀: Table I's ρ₀ = 0.001
    away from singularities, growing smoothly to ρ_max at one. Near a singularity the
    inverse then slows down instead of asking for huge joint rates, and motion that leaves
    the singularity stays possible.

    Args:
        jac: the matrix to be inverted. Shape (m, n).
        rho: ρ₀.
        region: ε.
        max_damping: ρ_max.

    Returns:
        (ρ, σ_min).
    """
    sigma = float(np.linalg.svd(jac, compute_uv=False)[-1])
    if sigma >= region:
        return rho, sigma
    return math.sqrt(rho * rho + max_damping * max_damping * (1.0 - (sigma / region) ** 2)), sigma


def damped_pinv(jac: np.ndarray, rho: float, activation: np.ndarray | None = None) -> np.ndarray:
    """``A Jᵀ (J A Jᵀ + ρ² I)⁻¹``: the weighted damped pseudo-inverse of Sorour eq (9).

    Args:
        jac: J. Shape (m, n).
        rho: damping ρ.
        activation: the diagonal of A = W⁻¹ (1 = the column takes part fully, 0 = not at
            all), default all ones (eq 8's damped pseudo-inverse). Shape (n,).

    Returns:
        Shape (n, m); rows exactly zero where the activation is zero.
    """
    ja = jac if activation is None else jac * activation
    gram = ja @ jac.T
    gram.ravel()[:: gram.shape[0] + 1] += rho * rho  # the diagonal (a view: gram is a new C array)
    return np.linalg.solve(gram, ja).T  # (G⁻¹ J A)ᵀ = A Jᵀ G⁻¹, G symmetric


def damped_pinv_solve(jac: np.ndarray, rhs: np.ndarray, rho: float, activation: np.ndarray | None = None) -> np.ndarray:
    """:func:`damped_pinv` applied to the task-space vector ``rhs`` (m,): shape (n,)."""
    return damped_pinv(jac, rho, activation) @ rhs


class PoseServoResolver(Resolver):
    """Base of the velocity-level resolvers: eq (12) pose controller, limits, eq (14).

    Args:
        robot: robot name, YAML path, :class:`~wmm_control.robot_config.RobotConfig` or a
            :class:`~wmm_control.kinematics.KinematicModel` (shared, not copied).
        params: the method's parameters (a subclass of :class:`PoseServoParams`).
    """

    name = 'pose_servo'

    def __init__(self, robot: str | Path | RobotConfig | KinematicModel, params: PoseServoParams) -> None:
        self.model = robot if isinstance(robot, KinematicModel) else KinematicModel(robot)
        self.params = params
        config = self.model.config
        #: indices of (vx, vy, ω) the base can follow; u = (those, q̇_a)
        self.base_axes = config.base.axes
        #: k_y of a base without a sideways axis, 0 for the others (:meth:`base_pull`) [1/m²]
        self._steering = params.steering_gain(config.base, params.lambda_p)
        self.n_base = len(self.base_axes)
        self.n_arm = self.model.n_arm
        self.n = self.n_base + self.n_arm
        self._base_cols = twist_columns(self.base_axes)
        #: the end effector's pose task (its error and Jacobian), in the method's orientation error
        self.pose_task = PoseTask(self.model, params.orientation_error, params.rpy_damping)
        #: the posture task of eq (13)'s pull and a followed plan's arm posture
        self.posture_task = PostureTask(self.n_base, self.n_arm)
        self.limits = CommandLimits.for_robot(config, params.dt)
        self._arm_limits = self.limits.subset(slice(self.n_base, None))
        #: a of the base's (vx, vy, ω): a followed plan's pull is no faster than braking allows
        self._base_acceleration = np.asarray(config.base.acceleration, dtype=float)
        # the stage reads the configuration this method's update computes: one a cycle
        self.safety = SafetyStage.for_robot(config, params, kinematics=self.model)
        self._position = np.zeros(self.n)
        self.reset()

    def reset(self) -> None:
        n, n_arm = self.n, self.n_arm
        self._prev = np.zeros(n)  # last nominal command (base reference, arm before eq 14)
        self._prev_null = np.zeros(n)  # its null-space share
        self._prev_arm = np.zeros(n_arm)  # last arm command sent
        self._prev_arm_null = np.zeros(n_arm)
        self._arm_before = (np.zeros(n_arm), np.zeros(n_arm))
        self._arm_task = np.zeros(n_arm)  # this period's arm command: task part...
        self._arm_null = np.zeros(n_arm)  # ...and null-space part
        self._q_arm: np.ndarray | None = None
        self._jac: np.ndarray | None = None
        self._weights: np.ndarray | None = None  # the safety stage's W: the method's sharing (step)
        self._safety = None  # the safety stage's answer on the last arm command
        self._base_pose: np.ndarray | None = None
        self._base_velocity: np.ndarray | None = None
        self.arm_damping = self.params.rho

    # ------------------------------------------------------------------ eq (12)
    def task_reference(self, state: RobotState, target: PoseTarget) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
        """Pose error and eq (12)'s task-space reference, with the Jacobian it is resolved on.

        Returns:
            (jac, p_ref, position_error (3,) world, orientation_error_angle [rad]):
            ``jac`` Shape (6, n_b + n) over u = (base axes, q̇_a): (vx, vy, ω), or (vx, ω) for a differential base; ``p_ref`` Shape (6,).
        """
        p = self.params
        self.model.update(state.base_pose, state.q_arm)
        pos, rot = state.ee_placement(self.model)
        b_r_w = rotation_z(state.base_pose[2]).T
        pose = self.pose_task
        e_pos, e_rot = pose.error(pos, rot, target.position, target.rotation)
        angle = norm(e_rot)
        ff = target.velocity
        jac = pose.jacobian_base(self._base_cols)
        p_ref = np.empty(6)
        # an absurdly far goal: keep only its direction
        p_ref[:3] = b_r_w @ (p.lambda_p * cap_norm(e_pos, p.max_linear_speed / p.lambda_p) + ff[:3])
        if p.orientation_error == 'rpy':
            e_ang = pose.rpy_error(rot, target.rotation)
            if p.rotate_angular_error:
                e_ang = b_r_w @ e_ang
            p_ref[3:] = p.lambda_p * e_ang
            if ff[3:].any():  # (a set-point's zero feedforward adds exactly nothing: skip Ω⁻¹)
                p_ref[3:] += pose.rpy_rates(b_r_w @ ff[3:])
        else:
            p_ref[3:] = b_r_w @ (p.lambda_p * e_rot + ff[3:])
        p_ref[:3] = cap_norm(p_ref[:3], p.max_linear_speed)
        p_ref[3:] = cap_norm(p_ref[3:], p.max_angular_speed)
        return jac, p_ref, e_pos, angle

    def task_damping(self, jac: np.ndarray, activation: np.ndarray | None = None) -> float:
        """ρ for inverting ``jac`` with ``activation`` (:func:`singularity_damping` of the active part)."""
        p = self.params
        active = jac if activation is None else jac * np.sqrt(activation)
        return singularity_damping(active, p.rho, p.singular_region, p.max_damping)[0]

    def solve_task(
        self, jac: np.ndarray, p_ref: np.ndarray, q_arm: np.ndarray, activation: np.ndarray | None = None
    ) -> np.ndarray:
        """The task part: ``A Jᵀ (J A Jᵀ + ρ² I)⁻¹ ṗ_ref`` (:func:`damped_pinv_solve`), with the
        entries that cannot follow it held at their bounds and the task re-shared (not in the
        paper; both options are off by default).

        * ``hold_joint_limits``: an arm joint that the solution drives past its braking bound.
          The limits (:class:`CommandLimits`) clip it there anyway, but clipped out of a
          pseudo-inverse solution its share of the end-effector motion is simply lost, and the
          next period's solution asks for it again: the end effector can stay put for tens of
          seconds while the other joints could move it.
        * ``arm_takeover``: a base whose command would change by more than its acceleration
          allows this period (a·t_s). Otherwise the limits slow the whole command by one
          factor, and a slowly accelerating base (robot B: 0.025 m/s²) sets the pace of the
          arm too; its P law then asks the base for speeds it needs metres to brake from.
          The base then moves towards its share of the solution by the largest fraction of
          the way that a·t_s allows on every axis (its direction of change kept), within its
          velocity limits, and the arm takes over the rest of the task, as eq (14) has it take
          over the base controller's deficit.

        A held entry keeps its bound (its activation set to zero) and what is left of the
        task, ``ṗ_ref − J_i u_i``, is solved again on the other columns, one round per newly
        held entry (saturation in the null space, Flacco et al. 2012, at velocity level). With
        nothing held the result is the plain solution itself.

        Args:
            jac: J over u = (base axes, q̇_a). Shape (6, n_b + n).
            p_ref: ṗ_ref. Shape (6,).
            q_arm: arm positions [rad or m]. Shape (n,).
            activation: the diagonal of A (default all ones). Shape (n_b + n,).

        Returns:
            Shape (n_b + n,).
        """
        p = self.params
        if not (p.hold_joint_limits or p.arm_takeover):
            return damped_pinv_solve(jac, p_ref, self.task_damping(jac, activation), activation)
        nb, n = self.n_base, self.n
        lower, upper = np.full(n, -np.inf), np.full(n, np.inf)
        if p.hold_joint_limits:
            self._position[nb:] = q_arm
            down, up = self.limits.braking_rates(self._position)
            lower[nb:], upper[nb:] = -down[nb:], up[nb:]
        weights = np.ones(n) if activation is None else np.array(activation, dtype=float)
        held = np.zeros(n)
        if p.arm_takeover:
            # last period's base share of the task (the command less its null-space share) ± a·t_s
            last = self._prev[:nb] - self._prev_null[:nb]
            step = self.limits.acceleration[:nb] * self.limits.dt
            speed = self.limits.velocity[:nb]
            lower[:nb] = np.maximum(last - step, -speed)
            upper[:nb] = np.minimum(last + step, speed)
            base = damped_pinv_solve(jac, p_ref, self.task_damping(jac, activation), activation)[:nb]
            if np.any((base < lower[:nb] - 1e-12) | (base > upper[:nb] + 1e-12)):
                # the base turns towards its share by the largest fraction of the way that every
                # axis can go this period (its direction kept), within its velocity limits; the
                # arm does the rest
                frac, _ = largest_step(last, base - last, last - step, last + step)
                held[:nb] = np.clip(last + frac * (base - last), lower[:nb], upper[:nb])
                weights[:nb] = 0.0

        def inverse(cols: np.ndarray) -> np.ndarray:
            part, w = jac[:, cols], weights[cols]
            return damped_pinv(part, self.task_damping(part, w), w)

        return saturate_in_null_space(
            inverse,
            jac,
            p_ref,
            np.zeros(len(p_ref)),
            lower,
            upper,
            weights > 0.0,
            held,
            one_at_a_time=False,
            scale=False,
        ).qdd

    # ------------------------------------------------------------------ null space
    #: whether a followed plan's pull includes its arm posture (a method without a posture task
    #: of its own; :meth:`base_pull`)
    pulls_arm_to_plan = False

    def base_pull(self, state: RobotState, reference: BaseReference, arm: bool = False) -> np.ndarray:
        """The secondary task of a followed plan's base (module docstring): ``z`` over u, the
        base's entries ``ξ̇_plan + λ_p (ξ_plan − ξ)`` in the base's frame (eq 12's law on the base's
        planned pose, its rates as feedforward) on the axes it follows, each axis's feedback no
        faster than ``√(2 a e)``, the speed from which its acceleration limit ``a`` brakes it to
        rest over its error ``e`` (:meth:`~wmm_control.resolvers.interface.BaseReference.pull`):
        a base that brakes over metres (robot B, 0.025 m/s²) comes onto the pose instead of
        running past it (0.18 m past a pose 0.39 m away under the law alone). The arm's ``λ_p (q_a,plan − q_a)``
        with ``arm`` and the plan's arm posture given (the travel posture, or the stance's), else
        zero.

        A base without a sideways axis (differential) cannot follow the pull's sideways part; its
        turn then also steers it back onto the plan's line (Kanayama et al. 1990's tracking law,
        ``ω += k_y v_r e_y``,
        :meth:`~wmm_control.resolvers.interface.SteeringParams.steering_gain` with ``k_θ = λ_p``).
        Without it the pull held the heading to the plan's and left a sideways offset as it was
        (``docs/methods.md``). Shape (n_b + n,)."""
        body = reference.pull(state.base_pose, self.params.lambda_p, self._base_acceleration, self._steering)
        if arm and reference.arm is not None and reference.arm.shape == (self.n_arm,):
            z = self.posture_task.pull(state.q_arm, reference.arm, self.params.lambda_p)
        else:
            z = np.zeros(self.n)
        z[: self.n_base] = body[list(self.base_axes)]
        return z

    def null_motion(
        self,
        jac: np.ndarray,
        task: np.ndarray,
        q_arm: np.ndarray,
        z: np.ndarray,
        activation: np.ndarray | None = None,
    ) -> np.ndarray:
        """``(I − J⁺J) z``, kept clear of the braking bounds: the secondary task ``z`` in the
        null space of the end effector's (Sorour eqs 9 and 13), with the undamped
        Moore–Penrose J⁺ (SVD, relative tolerance ``pinv_tolerance``).

        With ``activation`` (the diagonal of A, as :func:`damped_pinv` takes it) the projector
        is the weighted one, ``I − A Jᵀ (J A Jᵀ)⁺ J``: the correction that keeps the end effector
        still is made by the entries active in the task alone, in proportion to their
        activation; an entry out of the task (A = 0) keeps its part of ``z`` whole. Where the
        active entries cannot make up for it (an arm stretched out at its elbow's singularity)
        the end effector moves with ``z``, and the task sees it next period.

        A joint that the motion would drive past its braking bound (Xing eqs 7–8) is held
        still by adding its selection row to J and projecting again, so the motion stays in
        the null space of the task (the end effector does not move) instead of being
        clipped out of it. Shape (n_b + n,).
        """
        p = self.params
        n, nb = self.n, self.n_base
        self._position[nb:] = q_arm
        down, up = self.limits.braking_rates(self._position)
        # the room the task leaves, 1e-12 tolerance included; checked on Python floats below
        # (for 10 entries a loop costs less than the half-dozen numpy calls of a mask)
        lower, upper = (-down - task - 1e-12).tolist(), (up - task + 1e-12).tolist()
        held = [False] * n
        rows = jac
        weights = None if activation is None else np.sqrt(activation)
        for _ in range(self.n_arm):
            # (I − J⁺J) z: J⁺(J z) is the minimum-norm least-squares solution of J x = J z
            # (weighted: x = A^½ y, y that of J A^½ y = J z)
            if weights is None:
                null = z - np.linalg.lstsq(rows, rows @ z, rcond=p.pinv_tolerance)[0]
            else:
                null = z - weights * np.linalg.lstsq(rows * weights, rows @ z, rcond=p.pinv_tolerance)[0]
            over = [i for i, x in enumerate(null.tolist()) if not held[i] and (x < lower[i] or x > upper[i])]
            if not over:
                return null
            for i in over:
                held[i] = True
            rows = np.vstack((jac, np.eye(n)[held]))
        return np.zeros(n)

    def secondary_motion(
        self,
        jac: np.ndarray,
        task: np.ndarray,
        q_arm: np.ndarray,
        pull: np.ndarray | None,
        posture: np.ndarray,
        stance: bool = False,
        activation: np.ndarray | None = None,
    ) -> np.ndarray:
        """The method's posture pull ``posture`` (over u) and a followed plan's pull on the base
        (:meth:`base_pull`, or None) in the null space of the end effector's task
        (:meth:`null_motion`).

        On the way (``stance`` False) the two are summed into one pull, projected as the method
        shares the task (weighted by ``activation``, :meth:`null_motion`): a base out of the task
        (fine manipulation) follows the plan's pull whole, the arm making up for it, and the
        posture pull moves what the task leaves free (the base too, in the measure it is in the
        task, Sorour eq 13). Unweighted, the correction that keeps the end effector still was
        made partly by the base itself, which followed only part of its pull: it lagged the plan,
        and the arm carried the points until it folded (``mecanum``, ``docs/randomized.md``). At
        the stance (the final approach, :attr:`BaseReference.stance`) they are a stack of
        tasks (Siciliano–Slotine): ``pull`` in the null space of the end effector's task as the
        method shares it (weighted by ``activation``, :meth:`null_motion`: a base out of the
        task follows its pull, the arm making up for it), then ``posture`` in the null space of
        the task and the base's axes together (the arm's self-motion alone), in the room the
        two before it leave. The posture pull then can
        neither move the base nor hold it off the stance: summed, the two found a balance short
        of it, where the arm, given the whole task in fine manipulation, could not reach the
        goal. Without ``pull``: ``null_motion(jac, task, q_arm, posture)``, the method as
        written. Shape (n_b + n,).
        """
        if pull is None:
            return self.null_motion(jac, task, q_arm, posture)
        if not stance:
            return self.null_motion(jac, task, q_arm, pull + posture, activation)
        first = self.null_motion(jac, task, q_arm, pull, activation)
        held_base = np.vstack((jac, np.eye(self.n)[: self.n_base]))
        return first + self.null_motion(held_base, task + first, q_arm, posture)

    # ------------------------------------------------------------------ step
    @abstractmethod
    def _resolve(self, jac, p_ref, e_pos, state, pull, stance, plan_arm):
        """The method's inversion: ``(u_task (n_b + n,), u_null (n_b + n,) or None, mode, ψ,
        A)``, ``A`` the activation with which it shared the task (the diagonal of ``W⁻¹``, as
        :func:`damped_pinv` takes it; None: every entry fully), which the safety stage keeps
        (:func:`~wmm_control.resolvers.safety.task_weights`); ``pull`` is :meth:`base_pull` of a
        followed plan's base, or None, for the null space, ``stance`` that base's
        :attr:`~wmm_control.resolvers.interface.BaseReference.stance`, ``plan_arm`` its arm posture
        (:attr:`~wmm_control.resolvers.interface.BaseReference.arm`, shape (n,)) or None."""

    def step(self, state: RobotState, target: PoseTarget) -> ResolverCommand:
        """One period: eq (12), the method's inversion, then the limits.

        The whole command (base reference and arm) is brought into the velocity, braking and
        acceleration bounds by :class:`CommandLimits`, the null-space part giving way first;
        the arm command is then checked against the arm command actually sent last period,
        so that it is safe to send as it is when no compensation follows.
        """
        t0 = time.perf_counter()
        jac, p_ref, e_pos, angle = self.task_reference(state, target)
        pull = None if target.base is None else self.base_pull(state, target.base, self.pulls_arm_to_plan)
        stance = target.base is not None and target.base.stance
        plan_arm = None if target.base is None else target.base.arm
        if plan_arm is not None and plan_arm.shape != (self.n_arm,):
            plan_arm = None
        task, null, mode, psi, activation = self._resolve(jac, p_ref, e_pos, state, pull, stance, plan_arm)
        self._weights = None if activation is None else task_weights(activation)
        nb = self.n_base
        self._position[nb:] = state.q_arm
        room = None if target.base is None else self.base_room(state.base_pose, target.base)
        lim = self.limits.apply(
            task, self._position, self._prev, secondary=null, previous_secondary=self._prev_null, room=room
        )
        self._prev, self._prev_null = lim.command.copy(), lim.secondary.copy()
        self._jac = jac
        self._q_arm = state.q_arm
        self._arm_null = lim.secondary[nb:].copy()
        self._arm_task = lim.command[nb:] - self._arm_null
        self._arm_before = (self._prev_arm, self._prev_arm_null)
        self._base_pose = state.base_pose
        self._base_velocity = state.base_twist
        arm, base = self._finish_arm(self._arm_task, lim)
        p = self.params
        self.arm_damping, sigma = singularity_damping(jac[:, nb:], p.rho, p.singular_region, p.max_damping)
        limited = sorted(set(lim.limited) | {i + nb for i in arm.limited})
        diag = ResolverDiagnostics(
            method=self.name,
            mode=mode,
            psi=float(psi),
            position_error=norm(e_pos),
            orientation_error=angle,
            limit_scale=lim.scale,
            accel_scale=lim.accel_scale,
            null_scale=lim.secondary_scale,
            compensation_scale=1.0,
            limited=tuple(limited),
            sigma_min=sigma,
            compensated=False,
            cycle_time_s=time.perf_counter() - t0,
            **self._safety_fields(),
        )
        return ResolverCommand(
            arm_velocity=arm.command.copy(), base_twist=base_twist_of(base, self.base_axes), diagnostics=diag
        )

    def _finish_arm(self, arm_task, whole=None, feasible_twist=None):
        """The arm command sent: task part ``arm_task`` plus this period's null-space share,
        within the arm's bounds relative to the arm command sent last period, then through the
        safety stage (:mod:`~wmm_control.resolvers.safety`) within the same bounds.

        With ``whole`` (the limited whole-body command, a :class:`LimitResult`) the stage
        filters the base's reference with the arm, within the base's box too, and the answer is
        ``(arm, base reference)``; otherwise the base moves at ``feasible_twist`` (the base
        controller's answer) and only the arm is left to choose.
        """
        before, before_null = self._arm_before
        arm = self._arm_limits.apply(
            arm_task, self._q_arm, before, secondary=self._arm_null, previous_secondary=before_null
        )
        nb = self.n_base
        if whole is None:
            self._safety = self.safety.filter(
                self._q_arm,
                arm.command,
                arm.lower,
                arm.upper,
                base_pose=self._base_pose,
                base_twist=feasible_twist,
                task_jacobian=self._jac[:, nb:],
            )
            base = None
            if self._safety.changed:
                arm = replace(arm, command=self._safety.command)
        else:
            base = whole.command[:nb]
            self._safety = self.safety.filter(
                self._q_arm,
                np.concatenate((base, arm.command)),
                np.concatenate((whole.lower[:nb], arm.lower)),
                np.concatenate((whole.upper[:nb], arm.upper)),
                weights=self._weights,
                base_pose=self._base_pose,
                base_axes=self.base_axes,
                base_velocity=self._base_velocity,
                task_jacobian=self._jac,
                # the base's entries nearest what the method asked of the base, each within its
                # acceleration bound (the safety stage's ``target``); the arm's as limited
                target=np.concatenate((whole.requested[:nb], arm.command)),
            )
            if self._safety.changed:
                base = self._safety.command[:nb].copy()
                # the base reference sent: next period's acceleration bound; the stage's change
                # comes out of the null-space share first, down to none of it, then out of the
                # task's (module docstring)
                share = self._prev_null[:nb]
                task = self._prev[:nb] - share
                share[:] = np.clip(base - task, np.minimum(share, 0.0), np.maximum(share, 0.0))
                self._prev[:nb] = base
                arm = replace(arm, command=self._safety.command[nb:])
        self._prev_arm, self._prev_arm_null = arm.command.copy(), arm.secondary.copy()
        return arm if whole is None else (arm, base)

    def _safety_fields(self):
        """The safety stage's diagnostics fields of the last arm command."""
        out = self._safety
        return dict(
            clearance=out.clearance,
            closest_pair=out.closest_pair,
            collision_constraints=out.active,
            collision_changed=out.changed,
        )

    # ------------------------------------------------------------------ eq (14)
    def compensation_term(self, base_reference: ArrayLike, feasible_twist: ArrayLike) -> np.ndarray:
        """Eq (14)'s arm term ``J_a⁺ M_RPY H J_b (q̇_ref(b) − q̇_bf)`` on this period's Jacobian.

        ``J_a`` is the arm's part of the same task Jacobian (analytic in ``'rpy'`` mode), its
        pseudo-inverse damped by :func:`singularity_damping`. Shape (n,).
        """
        jac: np.ndarray = self._jac  # type: ignore[assignment]  # step() has set it
        gap = np.asarray(base_reference, dtype=float) - np.asarray(feasible_twist, dtype=float)
        deficit = jac[:, : self.n_base] @ gap[list(self.base_axes)]
        return damped_pinv_solve(jac[:, self.n_base :], deficit, self.arm_damping)

    def _add_compensation(self, command, feasible_twist):
        """``command`` with the eq (14) term added to the nominal arm command, within the arm's bounds.

        The term joins the arm's task part (the null-space part gives way first) and goes
        through the arm's bounds, its acceleration measured from the arm command sent last
        period; ``compensation_scale`` is the product of the two uniform factors of that
        primary part (1: the compensated command went through whole).
        """
        t0 = time.perf_counter()
        term = self.compensation_term(command.base_twist, feasible_twist)
        arm = self._finish_arm(self._arm_task + term, feasible_twist=feasible_twist)
        elapsed = command.diagnostics.cycle_time_s + time.perf_counter() - t0
        return command.with_arm(
            arm.command.copy(),
            compensation_scale=arm.scale * arm.accel_scale,
            compensated=True,
            cycle_time_s=elapsed,
            **self._safety_fields(),
        )
