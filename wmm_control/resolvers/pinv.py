"""The whole-body damped pseudo-inverse: Sorour eq (8), the baseline.

``u = Jᵀ (J Jᵀ + ρ² I)⁻¹ ṗ_ref`` with ṗ_ref the eq (12) pose controller: the minimum-norm
joint velocity, base and arm moving together, no null-space task and no compensation (save a
followed plan's base pull, :meth:`~wmm_control.resolvers.pose_servo.PoseServoResolver.base_pull`,
which the base takes whole in place of its share of the task, the arm making up for it in the
task's null space, and below it the arm's pull towards the plan's arm posture, at the gain λ_p,
in the null space of the task and the base: projected together, the arm's pull drove the base
off the plan, `docs/methods.md`). ρ is
Table I's 0.001 away from singularities (see :func:`~wmm_control.resolvers.pose_servo.singularity_damping`).
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wmm_control.resolvers.pose_servo import PoseServoParams, PoseServoResolver
from wmm_control.kinematics import KinematicModel
from wmm_control.robot_config import RobotConfig

__all__ = ['PinvParams', 'PinvResolver']


@dataclass(frozen=True)
class PinvParams(PoseServoParams):
    """Parameters of :class:`PinvResolver`: those of :class:`PoseServoParams`."""


class PinvResolver(PoseServoResolver):
    """Sorour eq (8), damped by ρ, inside the limits of :class:`PoseServoResolver`.

    Args:
        robot: robot name, YAML path, RobotConfig or KinematicModel.
        params: :class:`PinvParams` (Table I defaults).
    """

    name = 'pinv'
    pulls_arm_to_plan = True  # no posture task of its own: a followed plan's arm posture

    def __init__(self, robot: str | Path | RobotConfig | KinematicModel, params: PinvParams | None = None) -> None:
        super().__init__(robot, params if params is not None else PinvParams())
        # the diagonal of A for the base's pull: the base out of the correction that keeps the
        # end effector still (:meth:`null_motion`)
        self._base_out = np.concatenate((np.zeros(self.n_base), np.ones(self.n_arm)))

    def _resolve(self, jac, p_ref, e_pos, state, pull, stance):
        task = self.solve_task(jac, p_ref, state.q_arm)
        if pull is None:
            return task, None, 'whole_body', 1.0
        # a followed plan's pull (not in the paper; :meth:`base_pull`): the base takes its pull
        # whole, in place of its share of the task, the arm making up for it in the task's null
        # space; the arm's pull to the plan's posture ranks below, in the null space of the task
        # and the base together (stacked as at the stance, :meth:`secondary_motion`)
        nb = self.n_base
        base, arm = np.zeros_like(pull), pull.copy()
        base[:nb], arm[:nb] = pull[:nb] - task[:nb], 0.0
        null = self.secondary_motion(jac, task, state.q_arm, base, arm, stance=True, activation=self._base_out)
        return task, null, 'whole_body', 1.0
