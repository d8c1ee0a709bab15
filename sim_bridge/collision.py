"""Self-collision check of an arm configuration against the robot's own body and the floor.

The robot's URDF is loaded into a PyBullet world of its own (no simulation, no stepping),
and the collision shapes of the links are compared pair by pair with
``getClosestPoints``. The links split into

* *moving* links: those an arm joint moves (``arm_link_1`` … the end-effector link);
* *body* links: the others (chassis, wheels, steering modules, the arm mount, and the head and
  fingers at the robot YAML's ``held_joints``).

A configuration is clear when every checked pair is at least ``margin`` apart and no moving
link comes within ``margin`` of the floor. Checked pairs: moving–body and moving–moving,
except a link and its parent link (they meet at the joint between them) and the pairs that
are already closer than ``margin`` at the robot's start state (they touch by design, e.g. the
first arm link resting on its mount). A link and its grandparent are checked: the shipped
robots' collision shapes keep them apart over the joint limits wherever the real arm does
(on ``ur_mecanum`` the wrist meets the shoulder and the upper arm with the elbow folded past
about 160°, as the real arm would). The base pose does not matter for those: the floor is a
plane under the wheels. :mod:`wmm_control.kinematics.collision` uses the same rules.
Obstacles (:mod:`wmm_control.kinematics.obstacles`) are checked against every link, and for
them it does: they are placed around the robot from the base's pose.

A collision mesh is the convex hull of its vertices here: PyBullet's URDF importer takes every
STL or COLLADA collision mesh so, and an OBJ file as one hull per object in it, unless the URDF
marks the mesh ``concave="yes"`` (Bullet has no distance between two concave triangle meshes).
The controller's model takes the same hulls
(:func:`wmm_control.kinematics.collision.collision_geometry`; an OBJ file's objects make one
hull there, never smaller than PyBullet's). A hull holds its mesh, so this check errs on the
safe side: whenever two meshes touch, their hulls do; a contact it reports may be one of the
hulls only, never one of the meshes it misses.
"""

import itertools
from collections.abc import Iterable, Sequence
from pathlib import Path
from typing import Any

import numpy as np
import pybullet as p
from numpy.typing import ArrayLike

from sim_bridge.client import OwnedClient
from wmm_control.kinematics.obstacles import Obstacle, around_base
from wmm_control.geometry import quaternion_from_matrix
from wmm_control.resources import loadable_urdf
from wmm_control.robot_config import RobotConfig, load_robot

__all__ = ['SelfCollisionChecker', 'add_obstacle', 'OBSTACLE_RGBA']

#: Colour of the obstacles in the simulator's GUI and images.
OBSTACLE_RGBA = (0.85, 0.55, 0.25, 1.0)


def add_obstacle(obstacle: Obstacle, cid: int, visual: bool = True) -> int:
    """A static PyBullet body for ``obstacle`` (:class:`~wmm_control.kinematics.obstacles.Obstacle`)
    at its world pose in client ``cid``; returns its body id."""
    size = obstacle.size
    collision: dict[str, Any]
    drawing: dict[str, Any] | None
    if obstacle.shape == 'box':
        kind, collision, drawing = p.GEOM_BOX, {'halfExtents': [0.5 * v for v in size]}, None
    elif obstacle.shape == 'sphere':
        kind, collision, drawing = p.GEOM_SPHERE, {'radius': size[0]}, None
    else:  # PyBullet names a cylinder's length "height" in one call and "length" in the other
        kind, collision, drawing = (
            p.GEOM_CYLINDER,
            {'radius': size[0], 'height': size[1]},
            {'radius': size[0], 'length': size[1]},
        )
    shape = p.createCollisionShape(kind, **collision, physicsClientId=cid)
    vis = (
        p.createVisualShape(kind, **(drawing or collision), rgbaColor=OBSTACLE_RGBA, physicsClientId=cid)
        if visual
        else -1
    )
    return p.createMultiBody(
        0.0,
        shape,
        vis,
        basePosition=obstacle.position.tolist(),
        baseOrientation=_quaternion(obstacle.rotation),
        physicsClientId=cid,
    )


def _quaternion(rotation):
    """(x, y, z, w) of a rotation matrix, PyBullet's order."""
    return quaternion_from_matrix(rotation).tolist()


class SelfCollisionChecker(OwnedClient):
    """Distances between the robot's own links, and to the floor, for an arm configuration.

    Args:
        robot: robot name, alias, YAML path or :class:`~wmm_control.robot_config.RobotConfig`.
        margin: clearance required between checked pairs [m], >= 0.
        obstacles: :class:`~wmm_control.kinematics.obstacles.Obstacle` s in the world frame.

    Use as a context manager, or call :meth:`close`.
    """

    def __init__(
        self, robot: str | Path | RobotConfig, margin: float = 0.02, obstacles: Iterable[Obstacle] = ()
    ) -> None:
        self.robot = robot if isinstance(robot, RobotConfig) else load_robot(robot)
        self.margin = float(margin)
        self._cid = p.connect(p.DIRECT)
        cid = self._cid
        urdf = loadable_urdf(self.robot.urdf_path, self.robot.package_dirs)
        self._body = p.loadURDF(str(urdf), useFixedBase=True, physicsClientId=cid)
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
        self._ground = p.createMultiBody(0.0, plane, basePosition=[0.0, 0.0, self.robot.ground_z], physicsClientId=cid)
        names, parents, joint_of = {}, {}, {}
        for j in range(p.getNumJoints(self._body, physicsClientId=cid)):
            info = p.getJointInfo(self._body, j, physicsClientId=cid)
            joint_of[info[1].decode()] = j
            names[j] = info[12].decode()
            parents[j] = info[16]
        self.link_names = names
        for name, value in self.robot.held_joints.items():  # the head, the fingers: where they are held
            p.resetJointState(self._body, joint_of[name], value, physicsClientId=cid)
        self._arm = [joint_of[n] for n in self.robot.arm.joints]
        moving = set(self._arm)
        for j in sorted(names):  # descendants of an arm joint move too
            if parents[j] in moving:
                moving.add(j)
        shaped = {j for j in names if p.getCollisionShapeData(self._body, j, physicsClientId=cid)}
        self._moving = sorted(moving & shaped)
        body = sorted(shaped - moving)
        pairs = [(a, b) for a in self._moving for b in body]
        pairs += list(itertools.combinations(self._moving, 2))

        def near(a: int, b: int) -> bool:  # b is a's parent link
            return parents[a] == b

        pairs = [(a, b) for a, b in pairs if not (near(a, b) or near(b, a))]
        self._set(self.robot.start.arm)
        self._pairs = [(a, b) for a, b in pairs if self._distance(a, b) >= self.margin]
        self._links = sorted(shaped) + ([-1] if p.getCollisionShapeData(self._body, -1, physicsClientId=cid) else [])
        self.obstacles = tuple(obstacles)
        self._obstacles = [add_obstacle(o, cid, visual=False) for o in self.obstacles]

    def _place_obstacles(self, base_pose):
        """Obstacles around the robot (fixed at the origin) as they are around the base at
        ``base_pose`` (x, y, θ) in the world."""
        for body, local in zip(self._obstacles, around_base(self.obstacles, base_pose)):
            p.resetBasePositionAndOrientation(
                body, local.translation.tolist(), _quaternion(local.rotation), physicsClientId=self._cid
            )

    def _set(self, q_arm):
        for j, q in zip(self._arm, q_arm):
            p.resetJointState(self._body, j, float(q), physicsClientId=self._cid)

    def _distance(self, a, b, body_b=None, bound=None):
        """Distance between links ``a`` and ``b`` (of ``body_b``, default the robot), or
        ``bound`` when they are farther apart than that."""
        bound = self.margin if bound is None else bound
        pts = p.getClosestPoints(
            self._body,
            self._body if body_b is None else body_b,
            bound,
            linkIndexA=a,
            linkIndexB=b,
            physicsClientId=self._cid,
        )
        return min((pt[8] for pt in pts), default=bound)

    def _nearest(self, body_b):
        """The distance of every robot link closer than ``margin`` to ``body_b`` (the floor, an
        obstacle), one PyBullet query for all of them: ``{(link, -1): distance}``."""
        pts = p.getClosestPoints(self._body, body_b, self.margin, physicsClientId=self._cid)
        out = {}
        for pt in pts:  # several points per pair where a link has several shapes: the nearest
            if pt[8] < self.margin:
                key = (pt[3], pt[4])
                out[key] = min(out.get(key, pt[8]), pt[8])
        return out

    def collisions(
        self, q_arm: ArrayLike, base_pose: Sequence[float] | np.ndarray | None = None
    ) -> list[tuple[str, str, float]]:
        """The pairs closer than ``margin`` at arm configuration ``q_arm`` [rad] (and, with
        obstacles, base pose ``base_pose`` (x, y, θ) [m, m, rad]).

        Returns:
            list of (link name, link name, ``'floor'`` or an obstacle's name, distance [m]);
            empty when clear.
        """
        self._set(q_arm)
        # pair by pair: one query over the robot's own links would compute every pair of them
        out = [
            (self.link_names[a], self.link_names[b], d)
            for a, b in self._pairs
            if (d := self._distance(a, b)) < self.margin
        ]
        floor = self._nearest(self._ground)
        out += [(self.link_names[a], 'floor', floor[a, -1]) for a in self._moving if (a, -1) in floor]
        if self._obstacles:
            if base_pose is None:
                raise ValueError('SelfCollisionChecker: the base pose is needed to place the obstacles')
            self._place_obstacles(base_pose)
            for body, obstacle in zip(self._obstacles, self.obstacles):
                near = self._nearest(body)
                out += [
                    (self.link_names.get(a, 'base_link'), obstacle.name, near[a, -1])
                    for a in self._links
                    if (a, -1) in near
                ]
        return out
