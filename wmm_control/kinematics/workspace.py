"""Where an end-effector goal can lie: above the floor, within the arm's height, outside the base.

:class:`Workspace` answers, for a world position and the base pose, whether a goal there is
impossible for a reason a user can act on:

* below the floor (the robot YAML's ``ground_z``);
* higher than the end effector can ever be: the arm's first joint, plus the lengths of every
  link after it and of the tool, stacked straight up (an upper bound, so a goal it rejects is
  surely out of reach, while some goals it lets pass may still be: the resolvers pursue
  those as far as the limits allow);
* inside the base's own body: the collision shapes of the URDF fixed to the base (chassis,
  wheel modules), each taken as its box in its own frame;
* inside an obstacle (:mod:`~wmm_control.kinematics.obstacles`).
"""

from __future__ import annotations

from collections.abc import Iterable, Sequence
from typing import TYPE_CHECKING

import numpy as np
import pinocchio as pin

from wmm_control.geometry import se2_inverse, se2_transform_points
from wmm_control.resources import load_geometry

if TYPE_CHECKING:
    from wmm_control.kinematics.model import KinematicModel
    from wmm_control.kinematics.obstacles import Obstacle

__all__ = ['Workspace']

_ROOT_JOINT = 1  # the planar base joint of the kinematic model


def _half_extents(geometry):
    """Half extents of a collision shape's box in its own frame (None for other shapes)."""
    if hasattr(geometry, 'halfSide'):
        return np.asarray(geometry.halfSide, dtype=float)
    if hasattr(geometry, 'halfLength') and hasattr(geometry, 'radius'):
        return np.array([geometry.radius, geometry.radius, geometry.halfLength], dtype=float)
    if hasattr(geometry, 'radius'):
        return np.full(3, geometry.radius, dtype=float)
    return None


class Workspace:
    """The floor, the arm's height bound and the base's body of one :class:`KinematicModel`.

    Attributes:
        floor_z: world height of the floor [m].
        max_height: no end-effector position is higher [m] (world z; the base is planar).
        boxes: ``(name, rotation (3, 3), centre (3,), half extents (3,))`` in the base frame.
        n_arm: the arm's number of joints (of a posture given with a target).
    """

    def __init__(self, model: KinematicModel) -> None:
        self.floor_z = float(model.config.ground_z)
        self.n_arm = int(model.n_arm)
        pm = model.model
        arm = list(range(2, pm.njoints))
        ee = pm.frames[model.frame_id(model.ee_frame)]
        height = pm.jointPlacements[arm[0]].translation[2]
        height += sum(float(np.linalg.norm(pm.jointPlacements[j].translation)) for j in arm[1:])
        height += float(np.linalg.norm(ee.placement.translation))
        for j in arm:  # a prismatic joint (a lift) adds its longest travel
            joint = pm.joints[j]
            if joint.shortname().startswith('JointModelP') and joint.nq == 1:
                travel = (pm.lowerPositionLimit[joint.idx_q], pm.upperPositionLimit[joint.idx_q])
                height += max((abs(float(v)) for v in travel if np.isfinite(v)), default=0.0)
        self.max_height = float(height)
        geometry = load_geometry(pm, model.config.urdf_path, pin.GeometryType.COLLISION, model.config.package_dirs)
        self.boxes = []
        for obj in geometry.geometryObjects:
            half = _half_extents(obj.geometry)
            if obj.parentJoint == _ROOT_JOINT and half is not None:
                self.boxes.append((obj.name, obj.placement.rotation.copy(), obj.placement.translation.copy(), half))

    def footprint(self) -> np.ndarray:
        """The base's footprint: the corners (counter-clockwise) of the rectangle, in the base
        frame's x-y plane, that holds every base body box (the base frame's origin alone when
        the URDF has none). Shape (4, 2) [m]."""
        corners = [np.zeros(2)]
        for _name, rot, centre, half in self.boxes:
            signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
            corners.extend((centre + (signs * half) @ rot.T)[:, :2])
        pts = np.array(corners)
        (x0, y0), (x1, y1) = pts.min(axis=0), pts.max(axis=0)
        return np.array([[x0, y0], [x1, y0], [x1, y1], [x0, y1]])

    def body_part_at(
        self, position: Sequence[float] | np.ndarray, base_pose: Sequence[float] | np.ndarray
    ) -> str | None:
        """Name of the base part whose box holds the world ``position``, or None.

        Args:
            position: world (x, y, z) [m].
            base_pose: base (x, y, θ) in the world [m, m, rad].
        """
        local = np.array([*se2_transform_points(se2_inverse(base_pose), position[:2]), position[2]])
        for name, rot, centre, half in self.boxes:
            if np.all(np.abs(rot.T @ (local - centre)) <= half):
                return name
        return None

    def impossible(
        self,
        position: Sequence[float] | np.ndarray,
        base_pose: Sequence[float] | np.ndarray | None = None,
        obstacles: Iterable[Obstacle] = (),
    ) -> str:
        """'' when a goal at world ``position`` may be reached, else why it cannot.

        Args:
            position: world (x, y, z) [m].
            base_pose: the base's current pose (x, y, θ); without it the body is not checked.
            obstacles: :class:`~wmm_control.kinematics.obstacles.Obstacle` s (world frame).
        """
        z = float(position[2])
        if z < self.floor_z:
            return f'z = {z:.4g} m is below the floor (z = {self.floor_z:g} m)'
        if z > self.max_height:
            return f'z = {z:.4g} m is above the highest the end effector can reach ({self.max_height:.3f} m)'
        if base_pose is not None:
            part = self.body_part_at(position, base_pose)
            if part is not None:
                return f'it lies inside the robot\'s own body ({part}, at the current base pose)'
        for obstacle in obstacles:
            if obstacle.signed_distance(position) < 0.0:
                return f'it lies inside the obstacle {obstacle.name!r} ({obstacle.shape})'
        return ''
