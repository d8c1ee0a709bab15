"""The traditional planner of Xing §4.3, for comparison: the whole-body pseudo-inverse at
acceleration level with the manipulability objective in its null space,
``q̈ = J⁺(ẍ − J̇q̇) + (I − J⁺J) q̈_A`` (q̈_A of eq 13). The base always takes part. A joint that
``J⁺`` would drive past the braking bound of its position limit is held at that bound and its
part of the task shared among the others, ``J⁺`` taken again over the joints still free
(:func:`~wmm_control.resolvers.sns.saturate_in_null_space`, every joint past its bound in a
round, the task not scaled), and ``q̈_A`` leaves the held joints alone; the result is then
scaled uniformly into the joint acceleration bounds (from the nearest point of the bounds to
rest, keeping its direction), as every method of this package keeps the limits. (Scaled as a
whole for a joint that rests on its position limit with the task pulling it further, the
accelerations would all be zero, and the whole robot would coast on at its rates of the
moment.) Not in the paper, whose runs keep off the position limits: clipped out of ``J⁺``'s
solution without sharing its part, a joint on its limit left the end effector's task
undone where the other joints could do it (`panda_diff`, `table_pillar` goal 70 of the
randomized runs: joint 7 on its limit, the position met and the orientation 0.06 rad off for
the rest of the run; now converged).

Following a plan (a :class:`~wmm_control.resolvers.interface.BaseReference` on the target; not
in the paper, and nothing changes without one): the base's accelerations towards its planned
pose (``task['base_follow']``) and the arm's towards the plan's arm posture (the travel posture,
then the stance's; ``task['arm_follow']``), each clipped into this period's bounds and less that entry's share of
the task's solution, join q̈_A in the null space, so what the task leaves free brings the base
back onto the plan and the arm into the posture the plan was checked with. Within the bounds:
eq (23)'s gains ask a base off its plan for more than it can do (robot B's, 0.025 m/s², for
hundreds of times that), and the whole command, scaled into the bounds as one, would take the
end effector's task down with it while the robot coasted on. The arm's pull: without it the
null space held the base's pull and the manipulability objective alone, and the arm wandered
while the base lagged (robot A, the randomized `table_pillar` goals: a joint on its limit, the
elbow through its straight singularity), into a posture from which the approach stalled.
While a plan is followed the arm alone takes the end effector's task wherever its Jacobian
spans the task's rows (smallest singular value above ``ARM_SPAN``), J⁺ zero on the base, so
the base's pull passes the null space whole: with the whole-body J⁺ the base took its
minimum-norm share of the arm's motion to the stance's posture, which robot B's base
(0.025 m/s²) cannot stop once begun, and left the stance by 0.15–0.69 m before the final
approach, which then swung it about the goal for the rest of the run (`mecanum`, `table_pillar`
goals 17, 20, 28). Where the arm's joints that its position limits leave free no longer span
the task's rows, the base joins it (the whole-body J⁺, its joints held the same way): a
differential base that comes to rest beside its stance cannot close that offset, and the arm
alone may then need a joint past its limit (`panda_diff` goal 60: the base 3 cm beside the
stance, whose posture is 0.06 rad from joint 6's limit; joints 7 and 2 came to rest on theirs,
and the run stalled 15 mm and 0.03 rad off; now converged). The paper's runs follow no plan.
"""

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wmm_control.resolvers.acceleration_level import AccelerationParams, AccelerationResolver
from wmm_control.resolvers.sns import saturate_in_null_space
from wmm_control.geometry import largest_step
from wmm_control.kinematics import KinematicModel
from wmm_control.robot_config import RobotConfig

__all__ = ['TraditionalParams', 'TraditionalResolver']

#: The smallest singular value of the arm's Jacobian (over the task's rows) at which, following a
#: plan, the arm alone takes the task (module docstring); below it the whole body does.
ARM_SPAN = 1e-3


@dataclass(frozen=True)
class TraditionalParams(AccelerationParams):
    """Parameters of :class:`TraditionalResolver`: those of :class:`AccelerationParams`."""


class TraditionalResolver(AccelerationResolver):
    """J⁺ at acceleration level with manipulability enhancement in the null space (Xing §4.3)."""

    name = 'traditional'

    def __init__(
        self, robot: str | Path | RobotConfig | KinematicModel, params: TraditionalParams | None = None
    ) -> None:
        super().__init__(robot, params if params is not None else TraditionalParams())

    def _accelerations(self, task):
        jac = task['jac']
        n = jac.shape[1]
        follow = task['base_follow']
        rcond = self.params.rcond

        def spans(cols: np.ndarray) -> bool:
            part = jac[:, cols]
            return part.shape[0] <= part.shape[1] and np.linalg.svd(part, compute_uv=False)[-1] > ARM_SPAN

        def solve(free: np.ndarray):
            # J⁺ over the joints free, a joint it drives past its braking bound held there (module docstring)
            return saturate_in_null_space(
                lambda cols: np.linalg.pinv(jac[:, cols], rcond=rcond),
                jac,
                task['xdd'],
                task['drift'],
                task['brake_lower'],
                task['brake_upper'],
                free,
                np.zeros(n),
                one_at_a_time=False,
                scale=False,
            )

        whole = np.ones(n, dtype=bool)
        arm = whole.copy()
        if follow is not None:
            arm[: len(follow)] = False
        if follow is not None and spans(arm):
            # a plan followed and the arm alone spans the task: the arm's task, J⁺ zero on the base,
            # unless the arm's joints its limits leave free do not span it: then the base joins in
            solved = solve(arm)
            if not spans(solved.active):
                solved = solve(whole)
        else:
            solved = solve(whole)
        qdd = solved.qdd
        j_pinv = np.zeros(jac.shape[::-1])
        if solved.pinv is not None:
            j_pinv[solved.active] = solved.pinv
        lo, hi = task['lower'], task['upper']
        if self.params.manipulability or follow is not None:
            q_a = self.manipulability_acceleration(task['qd']) if self.params.manipulability else np.zeros(len(qdd))
            if follow is not None:
                nb = len(follow)
                q_a[:nb] += np.clip(follow, lo[:nb], hi[:nb]) - qdd[:nb]
                if task['arm_follow'] is not None:
                    q_a[nb:] += np.clip(task['arm_follow'], lo[nb:], hi[nb:]) - qdd[nb:]
            q_a[solved.saturated] = 0.0  # a joint held at its braking bound stays there
            qdd = qdd + q_a - j_pinv @ (jac @ q_a)  # + (I − J⁺J) q̈_A
        # position limits joint by joint (q̈_A's share too): a joint resting on its limit would
        # otherwise take the whole body's scale to zero, and with zero accelerations the robot coasts on
        qdd = np.clip(qdd, task['brake_lower'], task['brake_upper'])
        anchor = np.clip(0.0, lo, hi)
        scale, per = largest_step(anchor, qdd - anchor, lo, hi)
        limited = solved.saturated | ((per <= scale + 1e-12) if scale < 1.0 else False)
        limited = tuple(int(i) for i in np.flatnonzero(limited))
        return anchor + scale * (qdd - anchor), {
            'mode': 'whole_body',
            'psi': 0.0,
            'limit_scale': scale,
            'accel_scale': 1.0,
            'null_scale': 1.0,
            'limited': limited,
        }
