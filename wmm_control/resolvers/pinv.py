"""The whole-body damped pseudo-inverse: Sorour eq (8), the baseline.

``u = Jᵀ (J Jᵀ + ρ² I)⁻¹ ṗ_ref`` with ṗ_ref the eq (12) pose controller: the minimum-norm
joint velocity, base and arm moving together, no null-space task and no compensation (save a
followed plan's base pull, :meth:`~wmm_control.resolvers.pose_servo.PoseServoResolver.base_pull`,
with the arm pulled towards the plan's arm posture beside it, at the gain λ_p). ρ is
Table I's 0.001 away from singularities (see :func:`~wmm_control.resolvers.pose_servo.singularity_damping`).
"""

from dataclasses import dataclass
from pathlib import Path

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

    def _resolve(self, jac, p_ref, e_pos, state, pull, stance):
        task = self.solve_task(jac, p_ref, state.q_arm)
        # a followed plan's pull (not in the paper; :meth:`base_pull`), in the null space
        null = None if pull is None else self.null_motion(jac, task, state.q_arm, pull)
        return task, null, 'whole_body', 1.0
