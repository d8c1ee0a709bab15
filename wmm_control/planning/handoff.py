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

These are ``/ee_reference`` points: every method tracks them as it tracks any trajectory, with
its safety stage on, and after the last one the resolver is given the goal itself for the final
whole-body approach (the stance's posture is the method's to find). The points are given at the
pace the robot keeps (:class:`~wmm_control.planning.follow.PlanFollower`), which compares the
measured base with the planned base poses kept beside them. ROS-free: the direct
engine's runs (``wmm_randomized --plan``) and a node publishing ``/ee_reference`` use the same
points.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.geometry import rotation_z
from wmm_control.kinematics.model import KinematicModel
from wmm_control.planning.timing import BaseTrajectory
from wmm_control.resolvers.interface import BaseReference, PoseTarget

__all__ = ['Handoff']


@dataclass(frozen=True)
class Handoff:
    """The end-effector trajectory of a base trajectory with the arm held (module docstring).

    Attributes:
        dt: [s] the period of the samples.
        points: one :class:`~wmm_control.resolvers.PoseTarget` per sample of the base
            trajectory, with its twist and acceleration (world axes) and its planned base
            (``base``).
        base_poses: the planned base pose (x, y, θ) of each point [m, m, rad]. Shape (K, 3).
    """

    dt: float
    points: tuple[PoseTarget, ...]
    base_poses: np.ndarray = field(compare=False)

    @classmethod
    def of(cls, model: KinematicModel, trajectory: BaseTrajectory, q_travel: ArrayLike) -> Handoff:
        """The hand-off of ``trajectory`` with the arm of ``model``'s robot at ``q_travel``."""
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
        velocity = np.array(twists)
        acceleration = np.zeros_like(velocity)
        acceleration[:-1] = np.diff(velocity, axis=0) / trajectory.dt
        base_poses = np.array(trajectory.poses, dtype=float)
        base_rates = np.array(trajectory.rates, dtype=float)
        base_acceleration = np.zeros_like(base_rates)
        base_acceleration[:-1] = np.diff(base_rates, axis=0) / trajectory.dt
        points = tuple(
            PoseTarget(p, r, velocity=v, acceleration=a, base=BaseReference(pose, rate, base_a, travel))
            for (p, r), v, a, pose, rate, base_a in zip(
                placements, velocity, acceleration, base_poses, base_rates, base_acceleration
            )
        )
        base_poses.flags.writeable = False
        return cls(float(trajectory.dt), points, base_poses)

    @property
    def duration(self) -> float:
        """[s] from the first point to the last."""
        return self.dt * (len(self.points) - 1)
