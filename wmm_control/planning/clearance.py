"""How far the robot is from the obstacles and from its own body, for the planner.

Two questions, both on :class:`~wmm_control.kinematics.collision.CollisionModel`'s public
queries (the pairs, the shapes and the floor are the controller's own):

* :class:`Clearance`: at one configuration (base pose, arm joints), the distance from the
  nearest obstacle and, apart, from the robot's own body and the floor (the controller's
  self-collision pairs). Apart, because an arm at rest already holds some of its own links a few
  centimetres apart, which must not hide how far the obstacles are.
* :class:`Travel`: the robot driving with its arm held still (the travel posture): its
  clearance from the obstacles at a base pose, and a motion of the base that keeps it at least
  ``margin`` from every obstacle all the way, by conservative advancement: from a pose at
  clearance d, no point of the robot comes nearer than ``margin`` before it has moved d − margin,
  and a base motion moves no point of the robot by more than ``|Δ(x, y)| + r |Δθ|``, r the
  largest distance of the robot's shapes from the base's vertical axis (:func:`swept_radius`).
  Each checked pose must be at least ``margin + step`` clear, and the next one is at most
  max(d − margin, step) of motion further on, so every pose in between, not only the checked
  ones, keeps ``margin`` (up to the accuracy of the distances).
"""

from __future__ import annotations

import copy
import dataclasses
import math
from collections.abc import Callable, Iterable, Sequence

import numpy as np
import pinocchio as pin
from numpy.typing import ArrayLike

from wmm_control.geometry import wrap_angle
from wmm_control.kinematics.collision import CollisionModel
from wmm_control.kinematics.model import KinematicModel
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.resources import load_geometry
from wmm_control.robot_config import RobotConfig

__all__ = ['Clearance', 'Travel', 'swept_radius']

#: [m] the distance within which the pairs' distances are computed exactly; beyond it a pair
#: only counts as that far (the bound the advancement steps by)
INFLUENCE = 0.5


class Clearance:
    """The robot's distances from the obstacles and from its own body at one configuration.

    Args:
        collision: the robot's collision model, with the obstacles.
        influence: [m] distances are exact below it and reported as ``influence`` above it.
    """

    def __init__(self, collision: CollisionModel, influence: float = INFLUENCE) -> None:
        self.collision = collision
        self.influence = float(influence)
        self._obstacles = {o.name for o in collision.obstacles}
        self._body = any(a not in self._obstacles and b not in self._obstacles for a, b in collision.pairs)

    @classmethod
    def of_robot(
        cls, robot: RobotConfig, obstacles: Iterable[Obstacle], influence: float = INFLUENCE, body: bool = True
    ) -> Clearance:
        """The clearance of the robot ``robot`` among ``obstacles``; with ``body=False`` only
        from the obstacles (the robot's own pairs and the floor's left out, so each query costs
        less: for a base moving an arm held still, whose own distances do not change)."""
        if not body:
            robot = dataclasses.replace(robot, collision_pairs=())
        return cls(CollisionModel.from_robot(robot, obstacles=tuple(obstacles)), influence)

    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """The obstacles, world frame."""
        return self.collision.obstacles

    def __call__(
        self, q_arm: Sequence[float] | np.ndarray, base_pose: Sequence[float] | np.ndarray
    ) -> tuple[float, float]:
        """``(obstacles, body)`` [m]: the distance of the nearest pair with an obstacle (inf
        without obstacles) and of the nearest other pair (the robot's own links, the floor; inf
        without them), each capped at ``influence``."""
        near, _, _ = self.collision.within(q_arm, self.influence, base_pose)
        obstacle = self.influence if self._obstacles else math.inf
        body = self.influence if self._body else math.inf
        for distance, (a, b) in zip(near.distance.tolist(), near.links):
            if a in self._obstacles or b in self._obstacles:
                obstacle = min(obstacle, distance)
            else:
                body = min(body, distance)
        return obstacle, body


def swept_radius(model: KinematicModel, q_arm: Sequence[float] | np.ndarray) -> float:
    """The largest horizontal distance [m] of any collision shape of the robot, arm at ``q_arm``,
    from the base's vertical axis: each shape taken as its bounding sphere. A turn of the base
    by Δθ moves no point of the robot by more than this times |Δθ|."""
    cfg = model.config
    geom = load_geometry(model.model, cfg.urdf_path, pin.GeometryType.COLLISION, cfg.package_dirs)
    data = pin.GeometryData(geom)
    q, _ = model.configuration(np.zeros(3), q_arm)
    pin_data = model.model.createData()
    pin.updateGeometryPlacements(model.model, pin_data, geom, data, q)
    radius = 0.0
    for obj, placement in zip(geom.geometryObjects, data.oMg):
        obj.geometry.computeLocalAABB()
        centre = placement.act(np.asarray(obj.geometry.aabb_center, dtype=float))
        radius = max(radius, math.hypot(centre[0], centre[1]) + float(obj.geometry.aabb_radius))
    return radius


class Travel:
    """The robot driving its base with the arm held at ``q_arm``, among the obstacles.

    Args:
        clearance: the robot's :class:`Clearance`.
        model: its kinematic model (for :func:`swept_radius`).
        q_arm: the travel posture [rad or m].
        margin: [m] the clearance kept from every obstacle all along a motion.
        step: [m] the least motion of the robot's points between two checked poses; a checked
            pose must be ``margin + step`` clear.
    """

    def __init__(
        self,
        clearance: Clearance,
        model: KinematicModel,
        q_arm: ArrayLike,
        margin: float,
        step: float = 0.01,
    ) -> None:
        if not (margin > 0.0 and step > 0.0):
            raise ValueError(f'margin and step must be > 0 [m], got {margin}, {step}')
        self.clearance = clearance
        self.model = model
        self.q_arm = np.array(q_arm, dtype=float)
        self.margin = float(margin)
        self.step = float(step)
        self.radius = swept_radius(model, self.q_arm)
        self.queries = 0

    def with_posture(self, q_arm: ArrayLike) -> Travel:
        """The same robot and margins, the arm held at ``q_arm`` instead."""
        return Travel(self.clearance, self.model, q_arm, self.margin, self.step)

    def with_margin(self, margin: float) -> Travel:
        """The same robot and posture, keeping ``margin`` [m] instead."""
        if not margin > 0.0:
            raise ValueError(f'margin must be > 0 [m], got {margin}')
        out = copy.copy(self)
        out.margin = float(margin)
        return out

    def obstacle_clearance(self, base_pose: Sequence[float] | np.ndarray) -> float:
        """[m] the distance from the nearest obstacle of the robot at ``base_pose`` (x, y, θ),
        arm in the travel posture (capped at the clearance's ``influence``)."""
        self.queries += 1
        return self.clearance(self.q_arm, base_pose)[0]

    def valid(self, base_pose: Sequence[float] | np.ndarray) -> bool:
        """Whether the robot at ``base_pose`` is ``margin + step`` clear of every obstacle."""
        return self.obstacle_clearance(base_pose) >= self.margin + self.step

    def motion_valid(self, pose_at: Callable[[float], Sequence[float]], sweep: float) -> bool:
        """Whether the motion ``pose_at(λ)``, λ from 0 to 1, keeps ``margin`` from every
        obstacle all the way (the module docstring's conservative advancement).

        Args:
            pose_at: the base pose (x, y, θ) at λ ∈ [0, 1].
            sweep: [m] a bound on how far any point of the robot moves per unit of λ.
        """
        lam = 0.0
        while True:
            d = self.obstacle_clearance(pose_at(lam))
            if d < self.margin + self.step:
                return False
            if lam >= 1.0 or sweep <= 0.0:
                return True
            lam = min(1.0, lam + max(d - self.margin, self.step) / sweep)

    def linear_sweep(self, a: Sequence[float], b: Sequence[float]) -> float:
        """[m] how far any point of the robot moves, at most, when the base goes from ``a`` to
        ``b`` (x, y, θ) along the straight line in (x, y) while θ turns the short way."""
        dth = abs(wrap_angle(float(b[2]) - float(a[2])))
        return math.hypot(float(b[0]) - float(a[0]), float(b[1]) - float(a[1])) + self.radius * dth
