"""The hand-off: a timed base trajectory as the end-effector trajectory the resolver tracks.

While the base drives the planned path the arm is meant to stay in the travel posture the path
was checked with (:class:`~wmm_control.planning.GoalPlanner`), so the end effector is carried
rigidly by the base: at each sample k of the :class:`~wmm_control.planning.BaseTrajectory`,

* pose: ``T_world_ee(k) = T_world_base(pose_k) · T_base_ee(q_travel)`` (forward kinematics of
  the planned base pose and the travel posture);
* twist (world axes): linear ``(ẋ, ẏ, 0) + θ̇ ẑ × (p_ee − p_base)``, angular ``(0, 0, θ̇)``,
  (ẋ, ẏ, θ̇) the trajectory's world rates at the sample (the base's twist carried to the end
  effector);
* acceleration: the forward difference of those twists over the period (zero at the last
  sample, where the base has stopped);
* base: the planned base pose itself, its world rates and their forward difference, and the
  travel posture (:class:`~wmm_control.resolvers.interface.BaseReference`): the methods hold
  the base to the plan below the end effector's task.

With the stance's arm posture (``q_stance``, the stance's inverse kinematics) the points go on
after the path: the base at rest at the stance, the arm on the straight joint-space motion from
the travel posture to the stance's (:func:`~wmm_control.planning.timing.joint_motion`, within
:data:`ARM_FRACTION` of its velocity and acceleration limits, and the end effector within
:data:`ARM_EE_SPEED` and :data:`ARM_EE_ACCEL`), each point the forward kinematics of the stance
and the arm's posture of its sample, its twist the arm's Jacobian times the joint rates held to
the next sample, and that posture as the point's ``base.arm``. The end effector then comes to
the goal on the branch of the arm (elbow, wrist) the stance was found for: the goal's task alone
from the travel posture may take another, and end on a joint limit (`panda_diff`, `clutter`
goal 1 of the randomized draw: joint 6 on its limit, 0.2 m off). The end effector's bound: at
half the arm's limits alone it moved at up to ~0.5 m/s, a whole-body method gave the base its
share of that, and robot B's base (0.025 m/s²) drifted 0.24 m off the stance within 5 s and
could not stop (the traditional planner's `table_pillar` goals 0–5 reported).

These are ``/ee_reference`` points: every method tracks them as it tracks any trajectory, with
its safety stage on, and after the last one the resolver is given the goal itself for the final
whole-body approach, with the stance and the arm's posture there (:attr:`Handoff.stance_arm`,
the stance's inverse kinematics: the branch of the arm the stance was chosen for). The points are given at the
pace the robot keeps (:class:`~wmm_control.planning.follow.PlanFollower`), which compares the
measured base with the planned base poses kept beside them. ROS-free: the direct
engine's runs (``wmm_randomized --plan``) and a node publishing ``/ee_reference`` use the same
points.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.geometry import rotation_z
from wmm_control.kinematics.model import KinematicModel
from wmm_control.planning.timing import BaseTrajectory, joint_motion
from wmm_control.resolvers.acceleration_level import AccelerationParams
from wmm_control.resolvers.interface import BaseReference, PoseTarget

__all__ = ['ARM_EE_ACCEL', 'ARM_EE_SPEED', 'ARM_FRACTION', 'Handoff']

#: the fraction of the arm's velocity and acceleration limits its motion to the stance's posture
#: uses (:meth:`Handoff.of`): room for the whole-body method that tracks it
ARM_FRACTION = 0.5
#: the end effector's largest (linear [m/s], angular [rad/s]) speed in that motion: the pace of the
#: acceleration-level methods' own trajectory to a set-point (their defaults), which a whole-body
#: method shares with a base that may accelerate slowly (robot B's, 0.025 m/s²)
ARM_EE_SPEED = (AccelerationParams.setpoint_speed, AccelerationParams.setpoint_angular_speed)
#: the same for its accelerations [m/s², rad/s²]
ARM_EE_ACCEL = (AccelerationParams.setpoint_accel, AccelerationParams.setpoint_angular_accel)
#: steps of λ over which the end effector's twist in that motion is bounded
ARM_EE_SAMPLES = 16


def _end_effector_bounds(
    model: KinematicModel, base_pose: np.ndarray, q_from: np.ndarray, q_to: np.ndarray
) -> tuple[float, float]:
    """(speed [1/s], acceleration [1/s²]) of λ along ``q_from + λ (q_to − q_from)``, the base at
    ``base_pose``, that keep the end effector within :data:`ARM_EE_SPEED` and
    :data:`ARM_EE_ACCEL`: its twist per unit λ, ``J (q_to − q_from)``, bounded by its largest
    over :data:`ARM_EE_SAMPLES` steps of λ (the acceleration as if J were constant)."""
    delta = q_to - q_from
    linear = angular = 0.0
    for lam in np.linspace(0.0, 1.0, ARM_EE_SAMPLES + 1):
        model.update(base_pose, q_from + lam * delta)
        twist = model.arm_jacobian_world('full') @ delta
        linear, angular = max(linear, float(np.linalg.norm(twist[:3]))), max(angular, float(np.linalg.norm(twist[3:])))
    speed, accel = math.inf, math.inf
    for bound, v, a in zip((linear, angular), ARM_EE_SPEED, ARM_EE_ACCEL):
        if bound > 0.0:
            speed, accel = min(speed, v / bound), min(accel, a / bound)
    return speed, accel


@dataclass(frozen=True)
class Handoff:
    """The end-effector trajectory of a base trajectory with the arm held (module docstring).

    Attributes:
        dt: [s] the period of the samples.
        points: one :class:`~wmm_control.resolvers.PoseTarget` per sample of the base
            trajectory, with its twist and acceleration (world axes) and its planned base
            (``base``).
        base_poses: the planned base pose (x, y, θ) of each point [m, m, rad]. Shape (K, 3).
        stance_arm: the arm's posture at the stance (its inverse kinematics for the goal), for
            the final approach [rad or m], or None. Shape (n,).
        path_end: the sample where the base path ends (the arm's motion to the stance's posture,
            if any, starts there).
    """

    dt: float
    points: tuple[PoseTarget, ...]
    base_poses: np.ndarray = field(compare=False)
    stance_arm: np.ndarray | None = field(compare=False)
    path_end: int

    @classmethod
    def of(
        cls,
        model: KinematicModel,
        trajectory: BaseTrajectory,
        q_travel: ArrayLike,
        q_stance: ArrayLike | None = None,
        fraction: float = ARM_FRACTION,
    ) -> Handoff:
        """The hand-off of ``trajectory`` with the arm of ``model``'s robot at ``q_travel``; with
        ``q_stance`` (the arm's posture at the stance, :attr:`stance_arm`) the arm's straight
        joint-space motion there after the path, the base at rest at its end, within
        ``fraction`` of the arm's velocity and acceleration limits (module docstring)."""
        travel = np.asarray(q_travel, dtype=float)
        model.update(np.zeros(3), travel)
        offset, rotation = (np.asarray(v, dtype=float) for v in model.ee_placement_world())
        twists = []
        placements = []
        for pose, rate in zip(trajectory.poses, trajectory.rates):
            turn = rotation_z(float(pose[2]))
            arm = turn @ offset
            position = arm + np.array((pose[0], pose[1], 0.0))
            linear = np.array((rate[0] - rate[2] * arm[1], rate[1] + rate[2] * arm[0], 0.0))
            twists.append(np.concatenate((linear, (0.0, 0.0, rate[2]))))
            placements.append((position, turn @ rotation))
        base_poses = np.array(trajectory.poses, dtype=float)
        base_rates = np.array(trajectory.rates, dtype=float)
        postures = [travel] * len(base_poses)
        stance = None
        if q_stance is not None:
            stance = np.array(q_stance, dtype=float)
            stance.flags.writeable = False
            limits = model.config.arm
            speed, accel = _end_effector_bounds(model, base_poses[-1], travel, stance)
            motion = joint_motion(
                travel, stance, limits.velocity, limits.acceleration, trajectory.dt, fraction, speed, accel
            )
            rates = np.zeros_like(motion)
            rates[:-1] = np.diff(motion, axis=0) / trajectory.dt  # held to the next sample
            here = base_poses[-1]
            twists.pop()  # the path's last sample is the motion's first
            placements.pop()
            for q, q_rate in zip(motion, rates):
                model.update(here, q)
                position, orientation = (np.array(v, dtype=float) for v in model.ee_placement_world())
                placements.append((position, orientation))
                twists.append(model.arm_jacobian_world('full') @ q_rate)
            postures = postures[:-1] + list(motion)
            base_poses = np.vstack((base_poses, np.repeat(here[None, :], len(motion) - 1, axis=0)))
            base_rates = np.vstack((base_rates, np.zeros((len(motion) - 1, 3))))
        velocity = np.array(twists)
        acceleration = np.zeros_like(velocity)
        acceleration[:-1] = np.diff(velocity, axis=0) / trajectory.dt
        base_acceleration = np.zeros_like(base_rates)
        base_acceleration[:-1] = np.diff(base_rates, axis=0) / trajectory.dt
        points = tuple(
            PoseTarget(p, r, velocity=v, acceleration=a, base=BaseReference(pose, rate, base_a, q))
            for (p, r), v, a, pose, rate, base_a, q in zip(
                placements, velocity, acceleration, base_poses, base_rates, base_acceleration, postures
            )
        )
        base_poses.flags.writeable = False
        return cls(float(trajectory.dt), points, base_poses, stance, len(trajectory.poses) - 1)

    @property
    def duration(self) -> float:
        """[s] from the first point to the last."""
        return self.dt * (len(self.points) - 1)
