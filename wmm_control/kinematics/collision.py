"""How far the arm is from the robot's own body, from itself and from the floor, and how fast
that distance changes with the arm's joint rates.

Built on pinocchio's collision model of the URDF's ``<collision>`` shapes (coal, in the
``pin`` wheel), in the frame of the URDF's root link (``base_link``): the body does not move
in it, and neither does the floor, since the base moves in its own plane. Links split into

* *moving* links: the links an arm joint moves (the arm's links, the tool and what is fixed
  to them);
* *body* links: the others (chassis, wheels, steer modules, the arm's mount).

Checked pairs: moving against body, moving against moving, and moving against the floor (a
half-space at the robot YAML's ``ground_z``), except

* a link and its parent or grandparent link: one joint apart they share that joint; two
  joints apart the primitive shapes of a URDF (cylinders around each link) meet as soon as
  the joint between them bends, which the real arm allows;
* pairs closer than ``margin`` at the robot's start state: they touch by design (the arm's
  first link resting on its mount; :mod:`wmm_control.cli.robot_setup`, which has no start
  state yet, takes every joint at zero).

The simulator's own check (``sim_bridge.collision.SelfCollisionChecker``, PyBullet's
geometry) uses the same rules; it judges the ground truth, this model serves the controller.

Each pair's distance ``d`` comes with its rate ``ḋ = j · q̇_arm``: ``n · (v_b − v_a)`` at the
two nearest points, ``n`` the unit vector from a's nearest point to b's.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pinocchio as pin

from wmm_control.errors import ConfigError
from wmm_control.urdf import UrdfTree

__all__ = ['CollisionModel', 'PairDistance', 'FLOOR']

#: The name of the floor in pair names.
FLOOR = 'floor'
#: [m] GJK's tolerance on the distances.
GJK_TOLERANCE = 1e-9


@dataclass(frozen=True)
class PairDistance:
    """One checked pair at one configuration.

    Attributes:
        distance: signed distance [m]; negative when the shapes overlap.
        links: the two link names (``'floor'`` for the floor).
        shapes: the two collision shapes' names (a link may have several).
        rate_jacobian: ``j`` with ``ḋ = j · q̇_arm`` [m/rad or m/m]. Shape (n_arm,).
    """

    distance: float
    links: tuple[str, str]
    shapes: tuple[str, str]
    rate_jacobian: np.ndarray


class CollisionModel:
    """Distances and their Jacobians between the arm, the body and the floor.

    Args:
        urdf_path: the robot's URDF.
        arm_joints: the arm's joint names, root first.
        ground_z: height of the floor in the root link's frame [m]; None: no floor pairs.
        start_arm: the arm posture whose pairs closer than ``margin`` touch by design and are
            not checked (default: every joint at zero).
        margin: [m].

    Raises:
        ConfigError: pinocchio cannot load the URDF or its collision shapes.
    """

    @classmethod
    def from_robot(cls, robot, margin: float = 0.02):
        """The model of a :class:`~wmm_control.robot_config.RobotConfig`: its floor, and its start
        state's contacts left out."""
        return cls(robot.urdf_path, robot.arm.joints, robot.ground_z, robot.start.arm, margin)

    def __init__(self, urdf_path, arm_joints, ground_z=None, start_arm=None, margin: float = 0.02):
        path = str(urdf_path)
        try:
            self.model = pin.buildModelFromUrdf(path)
            self.geom = pin.buildGeomFromUrdf(self.model, path, pin.GeometryType.COLLISION)
        except (RuntimeError, ValueError) as exc:
            raise ConfigError(f'pinocchio could not load the collision shapes of {path}: {exc}') from exc
        model = self.model
        tree = UrdfTree(path)
        parent_link = {j.child: j.parent for j in tree.joints.values()}
        arm_ids = [model.getJointId(n) for n in arm_joints]
        self.n_arm = len(arm_ids)
        self._idx_q = [model.joints[j].idx_q for j in arm_ids]
        self._continuous = [model.joints[j].nq == 2 for j in arm_ids]
        self._idx_v = np.array([model.joints[j].idx_v for j in arm_ids])
        moving_joints = set(arm_ids)
        for j in range(1, model.njoints):              # joints below an arm joint move with it
            if model.parents[j] in moving_joints:
                moving_joints.add(j)
        link_of = [model.frames[g.parentFrame].name for g in self.geom.geometryObjects]
        moving = [g.parentJoint in moving_joints for g in self.geom.geometryObjects]

        def near(a, b):                                # b is a's parent or grandparent link
            up = parent_link.get(a)
            return up == b or (up is not None and parent_link.get(up) == b)

        pairs = []
        for a in range(len(link_of)):
            for b in range(a + 1, len(link_of)):
                la, lb = link_of[a], link_of[b]
                if (moving[a] or moving[b]) and la != lb and not (near(la, lb) or near(lb, la)):
                    pairs.append((a, b))
        if ground_z is not None:
            floor = pin.GeometryObject(FLOOR, 0, 0, pin.SE3(np.eye(3), np.array([0.0, 0.0, float(ground_z)])),
                                       _halfspace())
            floor_id = self.geom.addGeometryObject(floor)
            link_of.append(FLOOR)
            pairs += [(a, floor_id) for a in range(len(moving)) if moving[a]]
        self._link_of = link_of
        self.data = model.createData()
        for a, b in pairs:
            self.geom.addCollisionPair(pin.CollisionPair(a, b))
        self.geom_data = pin.GeometryData(self.geom)
        start = self._distances(self._configuration(np.zeros(self.n_arm) if start_arm is None else start_arm))
        keep = [k for k, d in enumerate(start) if d >= margin]
        self.excluded_at_start = [(link_of[pairs[k][0]], link_of[pairs[k][1]]) for k in range(len(pairs))
                                  if k not in set(keep)]
        self.geom.removeAllCollisionPairs()
        for k in keep:
            self.geom.addCollisionPair(pin.CollisionPair(*pairs[k]))
        self.geom_data = pin.GeometryData(self.geom)
        for request in self.geom_data.distanceRequests:
            # GJK to 1e-9 m: at coal's default (1e-6) the nearest points of curved shapes (the
            # cylinders around the links) are off by degrees, and so is the rate of the distance
            request.gjk_tolerance = GJK_TOLERANCE
        # [joint, i]: arm joint i moves the joint (none moves the root, the body's joints, the floor's)
        self._moved_by = np.array([[a in model.supports[j] for a in arm_ids] for j in range(model.njoints)])
        self._tabulate_pairs()

    def _tabulate_pairs(self):
        """Each checked pair's links, shapes and joints, looked up once (call again after adding pairs)."""
        objects = self.geom.geometryObjects
        self._pair_links, self._pair_shapes, joints = [], [], []
        for pair in self.geom.collisionPairs:
            a, b = objects[pair.first], objects[pair.second]
            self._pair_links.append((self._link_of[pair.first], self._link_of[pair.second]))
            self._pair_shapes.append((a.name, b.name))
            joints.append((a.parentJoint, b.parentJoint))
        self._pair_joints = np.array(joints, dtype=int).reshape(-1, 2)

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """The checked pairs, by link names."""
        return list(self._pair_links)

    def _configuration(self, q_arm) -> np.ndarray:
        q = pin.neutral(self.model)
        for iq, cont, val in zip(self._idx_q, self._continuous, np.asarray(q_arm, dtype=float).tolist()):
            if cont:
                q[iq], q[iq + 1] = np.cos(val), np.sin(val)
            else:
                q[iq] = val
        return q

    def _distances(self, q) -> np.ndarray:
        """Every checked pair's distance at the full configuration ``q``."""
        pin.computeDistances(self.model, self.data, self.geom, self.geom_data, q)
        return np.array([r.min_distance for r in self.geom_data.distanceResults])

    def closest(self, q_arm) -> tuple[float, tuple[str, str] | None]:
        """``(distance [m], (link a, link b))`` of the closest checked pair at arm joints
        ``q_arm``; ``(inf, None)`` when no pair is checked."""
        if not self.geom.collisionPairs:
            return float('inf'), None
        dists = self._distances(self._configuration(q_arm))
        k = int(np.argmin(dists))
        return float(dists[k]), self._pair_links[k]

    def within(self, q_arm, influence: float) -> tuple[list[PairDistance], float, tuple[str, str] | None]:
        """The pairs closer than ``influence`` [m] at ``q_arm``, each with its rate Jacobian, and
        the closest pair's distance and names (``inf, None`` when no pair is checked)."""
        if not self.geom.collisionPairs:
            return [], float('inf'), None
        model, data = self.model, self.data
        q = self._configuration(q_arm)
        dists = self._distances(q)
        k_min = int(np.argmin(dists))
        closest = (float(dists[k_min]), self._pair_links[k_min])
        near = np.flatnonzero(dists < influence)
        if not near.size:
            return [], *closest
        results = self.geom_data.distanceResults
        points, normals = np.empty((2, near.size, 3)), np.empty((near.size, 3))
        for i, k in enumerate(near.tolist()):          # each pair's nearest points, on a and on b
            result = results[k]
            points[0, i], points[1, i] = result.getNearestPoint1(), result.getNearestPoint2()
            normals[i] = result.normal                  # coal's: from the first shape to the second
        # ḋ = n · (v_b − v_a); a point p fixed to a joint moves at v = v₀ + ω × p, (v₀, ω) the
        # joint's spatial velocity in the root frame, so n · v = n · v₀ + (p × n) · ω
        pin.computeJointJacobians(model, data, q)
        twists = data.J[:, self._idx_v]                 # (v₀, ω) per arm joint rate
        along = normals @ twists[:3] + np.cross(points, normals) @ twists[3:]
        along *= self._moved_by[self._pair_joints[near].T]   # only the arm joints that move p
        rates = along[1] - along[0]
        out = [PairDistance(float(dists[k]), self._pair_links[k], self._pair_shapes[k], j)
               for k, j in zip(near.tolist(), rates)]
        return out, *closest


def _halfspace():
    """The floor's shape: z ≤ 0 in its own frame (coal, as pinocchio exposes it)."""
    return pin.coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.0)
