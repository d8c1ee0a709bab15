"""The whole-body damped pseudo-inverse: Sorour eq (8), the baseline.

``u = Jᵀ (J Jᵀ + ρ² I)⁻¹ ṗ_ref`` with ṗ_ref the eq (12) pose controller: the minimum-norm
joint velocity, base and arm moving together, no null-space task and no compensation (save a
followed plan's base pull, :meth:`~wmm_control.resolvers.pose_servo.PoseServoResolver.base_pull`,
with the arm pulled towards the dexterous posture beside it, at the gain λ_p). ρ is
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

    def __init__(self, robot: str | Path | RobotConfig | KinematicModel, params: PinvParams | None = None) -> None:
        super().__init__(robot, params if params is not None else PinvParams())
        self._q_dex = np.asarray(self.model.config.arm.dexterous, dtype=float)

    def _resolve(self, jac, p_ref, e_pos, state, pull):
        task = self.solve_task(jac, p_ref, state.q_arm)
        if pull is None:  # no plan followed: eq (8) alone
            return task, None, 'whole_body', 1.0
        # a followed plan (not in the paper): its base pull, and the arm pulled towards the
        # dexterous posture (the plan's travel posture on the shipped robots), in the null space
        z = pull.copy()
        z[self.n_base :] += self.params.lambda_p * (self._q_dex - state.q_arm)
        return task, self.null_motion(jac, task, state.q_arm, z), 'whole_body', 1.0
