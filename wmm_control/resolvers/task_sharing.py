"""Task-sharing redundancy resolution: Sorour et al. 2019, eqs (9)–(14).

Each period:

1. ψ from the end-effector position error, eq (11): 1 (fine manipulation) within ``r_fm``,
   0.5 (mobile manipulation) within ``r_mm``, 0 (gross motion) beyond. Optionally ψ moves
   towards that value at a bounded rate ``psi_rate`` instead of jumping (off in the paper's
   runs).
2. The particular solution ``J⁺ᵂ ṗ_ref`` with the weighted damped pseudo-inverse of eq (9),
   ``J⁺ᵂ = A Jᵀ (J A Jᵀ + ρ² I)⁻¹`` (ρ grows near a singularity of the active part:
   :func:`~wmm_control.resolvers.pose_servo.singularity_damping`). The diagonal of eq (10), ``diag((1 − ψ) I, ψ I)``, acts
   as ``A = W⁻¹``, the *activation* of each part: ψ = 1 gives the base exactly no share of
   the task, ψ = 0 gives the arm none, as the text describes. (Used as W, as printed, it
   would do the opposite.)
3. The null-space pull of eqs (9) and (13): ``λ_dex (I − J⁺J) z_dex``,
   ``z_dex = (0, −(q_a − q_a,dex))``, with the undamped Moore–Penrose J⁺ (SVD, relative
   tolerance ``pinv_tolerance``). It spans the base too: in fine manipulation the base may
   still move to restore the dexterous arm pose, keeping the end effector still. A followed
   plan's base pull (:meth:`~wmm_control.resolvers.pose_servo.PoseServoResolver.base_pull`,
   not in the paper) joins ``z`` there, the sum projected with eq (10)'s weighting (a base out of
   the task follows the plan's pull whole, the arm making up for it); at the stance, in the
   final approach, it takes priority:
   the posture pull then moves the arm alone, in the null space of the task and the base
   (:meth:`~wmm_control.resolvers.pose_servo.PoseServoResolver.secondary_motion`). While a plan
   is followed, its arm posture (:attr:`~wmm_control.resolvers.interface.BaseReference.arm`: the
   travel posture, the arm's motion to the stance's posture, the stance's at the final approach)
   takes q_a,dex's place in ``z_dex`` (not in the paper): the posture the points were made with,
   and the stance's, which reaches the goal within the limits and clear of the obstacles. Pulled
   to q_a,dex, robot A's arm left the planned motion to the stance's posture for joints on their
   limits (``doorway`` goals 1 and 5: joints 2, 6 and 7 at 2.09, 2.09 and −2.97 rad), from which
   the final approach stalled 4 and 13 cm off.
4. The whole command scaled into the limits (:mod:`wmm_control.resolvers.limits`).
5. Eq (14) in :meth:`TaskSharingResolver.compensate`, when the base controller has answered
   with the feasible twist q̇_bf of this period: the arm takes over the base's predicted
   velocity error, scaled into the arm's limits.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError
from wmm_control.resolvers.interface import ResolverCommand
from wmm_control.geometry import norm
from wmm_control.resolvers.pose_servo import PoseServoParams, PoseServoResolver
from wmm_control.kinematics import KinematicModel
from wmm_control.robot_config import RobotConfig

__all__ = ['TaskSharingParams', 'TaskSharingResolver', 'MODES', 'psi_of_error']

#: Mode name by the value of ψ that eq (11) gives.
MODES = {0.0: 'gross_motion', 0.5: 'mobile_manipulation', 1.0: 'fine_manipulation'}


def psi_of_error(error_norm: float, r_fm: float, r_mm: float) -> float:
    """Eq (11): the task-sharing factor ψ from the position error norm [m]."""
    if error_norm <= r_fm:
        return 1.0
    if error_norm <= r_mm:
        return 0.5
    return 0.0


@dataclass(frozen=True)
class TaskSharingParams(PoseServoParams):
    """Parameters of :class:`TaskSharingResolver` (Sorour Table I defaults).

    Attributes:
        r_fm: fine manipulation range [m].
        r_mm: mobile manipulation range [m].
        lambda_dex: gain of the null-space pull to the dexterous arm pose [1/s].
        compensation: apply eq (14) when :meth:`TaskSharingResolver.compensate` is called.
        psi_rate: largest change of ψ per second [1/s]; 0 lets ψ jump as eq (11) does.
    """

    r_fm: float = 0.25
    r_mm: float = 0.9
    lambda_dex: float = 3.5
    compensation: bool = True
    psi_rate: float = 0.0

    _allow_zero = PoseServoParams._allow_zero + ('psi_rate', 'lambda_dex')

    def __post_init__(self):
        super().__post_init__()
        if self.r_fm >= self.r_mm:
            raise ConfigError(f'r_fm ({self.r_fm} m) must be below r_mm ({self.r_mm} m)')


class TaskSharingResolver(PoseServoResolver):
    """Sorour eqs (9)–(14): task sharing, null-space pull to q_a,dex, arm compensation.

    Args:
        robot: robot name, YAML path, RobotConfig or KinematicModel.
        params: :class:`TaskSharingParams` (Table I defaults).
        q_dex: dexterous arm posture [rad], default the robot's ``arm.dexterous``. Shape (n,).
    """

    name = 'task_sharing'
    params: TaskSharingParams

    def __init__(
        self,
        robot: str | Path | RobotConfig | KinematicModel,
        params: TaskSharingParams | None = None,
        q_dex: ArrayLike | None = None,
    ) -> None:
        super().__init__(robot, params if params is not None else TaskSharingParams())
        dex = self.model.config.arm.dexterous if q_dex is None else q_dex
        self.q_dex = as_finite_vector(dex, self.n_arm, 'q_dex').copy()
        self._psi = None

    @property
    def uses_compensation(self) -> bool:
        return self.params.compensation

    def reset(self) -> None:
        super().reset()
        self._psi = None

    def _share(self, error_norm):
        p = self.params
        target = psi_of_error(error_norm, p.r_fm, p.r_mm)
        if p.psi_rate == 0.0 or self._psi is None:
            self._psi = target
        else:
            step = p.psi_rate * p.dt
            self._psi += min(step, max(-step, target - self._psi))
        return self._psi, MODES[target]

    def _resolve(self, jac, p_ref, e_pos, state, pull, stance, plan_arm):
        psi, mode = self._share(norm(e_pos))
        activation = np.empty(self.n)
        activation[: self.n_base] = 1.0 - psi
        activation[self.n_base :] = psi
        task = self.solve_task(jac, p_ref, state.q_arm, activation)
        # eqs (9) and (13): λ_dex (I − J⁺J) z_dex, with a followed plan's base pull; a followed
        # plan's arm posture takes q_a,dex's place (module docstring)
        posture = self.q_dex if plan_arm is None else plan_arm
        z = self.posture_task.pull(state.q_arm, posture, self.params.lambda_dex)
        return task, self.secondary_motion(jac, task, state.q_arm, pull, z, stance, activation), mode, psi, activation

    def compensate(self, command: ResolverCommand, feasible_twist: ArrayLike) -> ResolverCommand:
        """Eq (14): add ``J_a⁺ M_RPY H J_b (q̇_ref(b) − q̇_bf)`` to the arm command.

        Args:
            command: this period's :meth:`step` result.
            feasible_twist: q̇_bf, the base controller's answer to ``command.base_twist``
                (vx, vy, ω), base frame. Shape (3,).
        """
        if not self.params.compensation:
            return command
        feasible_twist = as_finite_vector(feasible_twist, 3, 'feasible_twist')
        return self._add_compensation(command, feasible_twist)
