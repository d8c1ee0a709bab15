"""How far the arm's collision shapes are from the robot's body and from each other.

Built on pinocchio's collision model of the URDF's ``<collision>`` shapes (coal, in the
``pin`` wheel). The pairs checked are every arm link against every link that is not part of
the arm (chassis, wheels, mount), and arm links against each other, except links at most two
joints apart along the chain (they meet at a joint by construction); the arm's root link
counts as part of the chain. Links that carry no collision
shape take no part.
"""

from __future__ import annotations

import numpy as np
import pinocchio as pin

from wmm_control.errors import ConfigError

__all__ = ['BodyClearance']


class BodyClearance:
    """Signed distances between the arm and the rest of the robot, at given arm joint values.

    Args:
        urdf_path: the robot's URDF.
        arm_joints: the arm joint names, root first.
        arm_root: the arm's root link (fixed to the body, the chain's place −1).

    Raises:
        ConfigError: pinocchio cannot load the URDF or its collision shapes.
    """

    def __init__(self, urdf_path, arm_joints, arm_root):
        try:
            self.model = pin.buildModelFromUrdf(str(urdf_path))
            self.geom = pin.buildGeomFromUrdf(self.model, str(urdf_path), pin.GeometryType.COLLISION)
        except (RuntimeError, ValueError) as exc:
            raise ConfigError(f'pinocchio could not load the collision shapes of {urdf_path}: {exc}') from exc
        ids = [self.model.getJointId(n) for n in arm_joints]
        self._arm_idx_q = [self.model.joints[j].idx_q for j in ids]
        self._continuous = [self.model.joints[j].nq == 2 for j in ids]
        moving = {j: k for k, j in enumerate(ids)}        # joint id → its place in the arm chain
        root_frame = self.model.getFrameId(arm_root) if self.model.existFrame(arm_root) else -1
        place = [-1 if g.parentFrame == root_frame else moving.get(g.parentJoint)
                 for g in self.geom.geometryObjects]
        for a in range(len(place)):
            for b in range(a + 1, len(place)):
                pa, pb = place[a], place[b]
                if pa is None and pb is None:
                    continue                              # body against body: rigid
                if pa is not None and pb is not None and abs(pa - pb) <= 2:
                    continue                              # neighbours along the arm
                if pa is None or pb is None:
                    arm = pa if pa is not None else pb
                    if arm <= 0:
                        continue                          # the root and first arm link sit on the body
                self.geom.addCollisionPair(pin.CollisionPair(a, b))
        self.data = self.model.createData()
        self.geom_data = pin.GeometryData(self.geom)

    def _q(self, q_arm):
        q = pin.neutral(self.model)
        for iq, cont, val in zip(self._arm_idx_q, self._continuous, np.asarray(q_arm, dtype=float)):
            if cont:
                q[iq], q[iq + 1] = np.cos(val), np.sin(val)
            else:
                q[iq] = val
        return q

    def closest(self, q_arm):
        """``(distance [m], (link a, link b))`` of the closest checked pair at arm joints ``q_arm``;
        negative when they overlap. ``(inf, None)`` when no pair is checked."""
        if not self.geom.collisionPairs:
            return float('inf'), None
        pin.computeDistances(self.model, self.data, self.geom, self.geom_data, self._q(q_arm))
        dists = [r.min_distance for r in self.geom_data.distanceResults]
        k = int(np.argmin(dists))
        pair = self.geom.collisionPairs[k]
        names = (self.geom.geometryObjects[pair.first].name, self.geom.geometryObjects[pair.second].name)
        return float(dists[k]), names
