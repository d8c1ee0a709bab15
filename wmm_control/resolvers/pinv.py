"""The whole-body damped pseudo-inverse: Sorour eq (8), the baseline.

``u = Jᵀ (J Jᵀ + ρ² I)⁻¹ ṗ_ref`` with ṗ_ref the eq (12) pose controller: the minimum-norm
joint velocity, base and arm moving together, no null-space task and no compensation (save a
followed plan's base pull, :meth:`~wmm_control.resolvers.pose_servo.PoseServoResolver.base_pull`,
with the arm pulled towards the plan's arm posture beside it, at the gain λ_p). On a followed
plan's way (a point whose planned base is not the stance) the arm does the task and the base
follows the pull: ``u = A Jᵀ (J A Jᵀ + ρ² I)⁻¹ ṗ_ref + P_A z``, A the activation with the base's
entries zero and the arm's one, P_A the projector weighted by it
(:meth:`~wmm_control.resolvers.pose_servo.PoseServoResolver.null_motion`): the base's command is
its pull (the plan's rates and the correction onto the planned pose), the arm makes up for what
that does at the end effector. Whole-body with the pull in the null space of the task
(``I − J⁺J``), the correction that keeps the end effector still took most of a base's turn back
out of the pull (a turn of the base swings the end effector, and the minimum-norm correction
shares that with the base itself), and the task's own share turned the base the other way:
`panda_diff`'s base, which cannot move sideways, came out of its turns 0.2–0.4 rad off its
plan's heading, drifted sideways into the safety stage's hold at the pillar of `table_pillar`
and stayed there (``docs/methods.md``, the planner's section). At the stance (the final
approach) pinv is whole-body, the stance's pull in the null space, as before. ρ is
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
        #: the activation on a followed plan's way: the arm alone does the task and makes up for the pull
        self._arm_only = np.concatenate((np.zeros(self.n_base), np.ones(self.n_arm)))

    def _resolve(self, jac, p_ref, e_pos, state, pull, stance, plan_arm):  # the arm's posture is in ``pull``
        if pull is None or stance:
            task = self.solve_task(jac, p_ref, state.q_arm)
            null = None if pull is None else self.null_motion(jac, task, state.q_arm, pull)
            return task, null, 'whole_body', 1.0, None
        # a followed plan's way (not in the paper; :meth:`base_pull`): the arm does the task, the
        # base follows the pull (module docstring)
        task = self.solve_task(jac, p_ref, state.q_arm, self._arm_only)
        null = self.null_motion(jac, task, state.q_arm, pull, self._arm_only)
        return task, null, 'whole_body', 1.0, self._arm_only
