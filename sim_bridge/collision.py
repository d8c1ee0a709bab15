"""Self-collision check of an arm configuration against the robot's own body and the floor.

The robot's URDF is loaded into a PyBullet world of its own (no simulation, no stepping),
and the collision shapes of the links are compared pair by pair with
``getClosestPoints``. The links split into

* *moving* links: those an arm joint moves (``arm_link_1`` … the end-effector link);
* *body* links: the others (chassis, wheels, steering modules, the arm mount).

A configuration is clear when every checked pair is at least ``margin`` apart and no moving
link comes within ``margin`` of the floor. Checked pairs: moving–body and moving–moving,
except a link and its parent link (they meet at the joint between them) and the pairs that
are already closer than ``margin`` at the robot's start state (they touch by design, e.g. the
first arm link resting on its mount). A link and its grandparent are checked: the shipped
robots' collision shapes keep them apart over the joint limits wherever the real arm does
(on ``ur_mecanum`` the wrist meets the shoulder and the upper arm with the elbow folded past
about 160°, as the real arm would). The base pose does not matter: the floor is a plane
under the wheels. :mod:`wmm_control.kinematics.collision` uses the same rules.
"""

import itertools

import pybullet as p

from sim_bridge.client import OwnedClient
from wmm_control.robot_config import RobotConfig, load_robot

__all__ = ['SelfCollisionChecker']


class SelfCollisionChecker(OwnedClient):
    """Distances between the robot's own links, and to the floor, for an arm configuration.

    Args:
        robot: robot name, alias, YAML path or :class:`~wmm_control.robot_config.RobotConfig`.
        margin: clearance required between checked pairs [m], >= 0.

    Use as a context manager, or call :meth:`close`.
    """

    def __init__(self, robot, margin=0.02):
        self.robot = robot if isinstance(robot, RobotConfig) else load_robot(robot)
        self.margin = float(margin)
        self._cid = p.connect(p.DIRECT)
        cid = self._cid
        self._body = p.loadURDF(str(self.robot.urdf_path), useFixedBase=True, physicsClientId=cid)
        plane = p.createCollisionShape(p.GEOM_PLANE, physicsClientId=cid)
        self._ground = p.createMultiBody(0.0, plane, basePosition=[0.0, 0.0, self.robot.ground_z],
                                         physicsClientId=cid)
        names, parents, joint_of = {}, {}, {}
        for j in range(p.getNumJoints(self._body, physicsClientId=cid)):
            info = p.getJointInfo(self._body, j, physicsClientId=cid)
            joint_of[info[1].decode()] = j
            names[j] = info[12].decode()
            parents[j] = info[16]
        self.link_names = names
        self._arm = [joint_of[n] for n in self.robot.arm.joints]
        moving = set(self._arm)
        for j in sorted(names):                 # descendants of an arm joint move too
            if parents[j] in moving:
                moving.add(j)
        shaped = {j for j in names if p.getCollisionShapeData(self._body, j, physicsClientId=cid)}
        self._moving = sorted(moving & shaped)
        body = sorted(shaped - moving)
        pairs = [(a, b) for a in self._moving for b in body]
        pairs += list(itertools.combinations(self._moving, 2))
        def near(a, b):           # b is a's parent link
            return parents[a] == b

        pairs = [(a, b) for a, b in pairs if not (near(a, b) or near(b, a))]
        self._set(self.robot.start.arm)
        self._pairs = [(a, b) for a, b in pairs if self._distance(a, b) >= self.margin]

    def _set(self, q_arm):
        for j, q in zip(self._arm, q_arm):
            p.resetJointState(self._body, j, float(q), physicsClientId=self._cid)

    def _distance(self, a, b, body_b=None, bound=None):
        """Distance between links ``a`` and ``b`` (of ``body_b``, default the robot), or
        ``bound`` when they are farther apart than that."""
        bound = self.margin if bound is None else bound
        pts = p.getClosestPoints(self._body, self._body if body_b is None else body_b, bound, linkIndexA=a,
                                 linkIndexB=b, physicsClientId=self._cid)
        return min((pt[8] for pt in pts), default=bound)

    def collisions(self, q_arm):
        """The pairs closer than ``margin`` at arm configuration ``q_arm`` [rad].

        Returns:
            list of (link name, link name or ``'floor'``, distance [m]); empty when clear.
        """
        self._set(q_arm)
        out = [(self.link_names[a], self.link_names[b], d) for a, b in self._pairs
               if (d := self._distance(a, b)) < self.margin]
        out += [(self.link_names[a], 'floor', d) for a in self._moving
                if (d := self._distance(a, -1, self._ground)) < self.margin]
        return out
