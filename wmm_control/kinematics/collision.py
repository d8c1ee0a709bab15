"""How far the robot's arm is from its own body, from itself, from the floor and from
obstacles, and how fast those distances change with the arm's joint rates and the base's twist.

Built on pinocchio's collision model of the URDF's ``<collision>`` shapes (coal, in the
``pin`` wheel), each mesh taken as its convex hull (:func:`collision_geometry`), on the
:class:`~wmm_control.kinematics.model.KinematicModel`'s own reduced model: the planar root
joint (x, y, θ) carries the body's shapes and the arm's joints the arm's, so every shape is in
the world frame. The floor (a half-space at ``ground_z``, the height of the floor in the root
link's frame, which moves in the world's horizontal plane at height 0: the same height in the
world) and the obstacles (:mod:`~wmm_control.kinematics.obstacles`, fixed in the world) are
placed once, when set. One configuration a cycle: built on a method's kinematic model, a
question at the state the method's update is at reads that update's joint placements and
joint Jacobians (``data.oMi``, ``data.J``) and runs no kinematics of its own; the shapes are
placed from them once per update. Links split into

* *moving* links: the links an arm joint moves (the arm's links, the tool and what is fixed
  to them);
* *body* links: the others (chassis, wheels, steer modules, the arm's mount, and the links of
  the joints outside the arm, at the positions they are held at: head, fingers).

Checked pairs: the link pairs the robot YAML lists (``collision.pairs``, ``floor`` for the
floor: ``wmm_robot init`` writes them, chosen by :func:`choose_pairs` as MoveIt's set-up
assistant chooses them) and every link against every obstacle. Without that list: moving
against body, moving against moving, moving against the floor (a half-space at the robot
YAML's ``ground_z``), and every link against every obstacle, except

* a link and its parent link (the link it hangs from in the URDF's tree): they meet at the
  joint between them;

and in both cases robot pairs closer than ``margin`` at the robot's start state: they touch by
design (the arm's first link resting on its mount; :mod:`wmm_control.cli.robot_setup`, which
has no start state yet, takes every joint at zero).

A link and its grandparent, two joints apart, are checked: the shipped robots' collision
shapes are drawn so that they stay apart over the joint limits wherever the real arm does
(robot A's forearm shape stops short of the wrist joint, whose housing is a shape of the
next link about that joint's axis, so the flange clears the forearm at any wrist bend). On
``ur_mecanum`` they do meet, where the real arm does: the wrist runs into the shoulder and
the upper arm when the elbow folds past about 160°, which the ±π elbow limit allows.

The simulator's own check (``sim_bridge.collision.SelfCollisionChecker``, PyBullet's
geometry) uses the same rules; it judges the ground truth, this model serves the controller.
Both take a collision mesh as its convex hull: the hull holds the mesh, so its distances are
never larger than the mesh's (both err on the safe side, by the mesh's concavities), and
where two hulls overlap, coal's distance is negative, minus the penetration depth (two
triangle soups would report 0 however deep they overlap).

Each pair's distance ``d`` comes with its rate ``ḋ = j · q̇_arm + j_b · (vx, vy, ω)``:
``n · (v_b − v_a)`` at the two nearest points, ``n`` the unit vector from a's nearest point
to b's, from the joint Jacobians' columns (the planar root's over the world's (ẋ, ẏ, θ̇),
turned into the base's twist in its own frame). For two points on the robot the base's share
cancels; against the floor it is zero (the base moves parallel to it).
"""

from __future__ import annotations

import time
import xml.etree.ElementTree as ET
from dataclasses import dataclass

import numpy as np
import pinocchio as pin
from scipy.spatial import ConvexHull, QhullError

from wmm_control.errors import ConfigError
from wmm_control.geometry import rotation_z
from wmm_control.kinematics.model import N_BASE, KinematicModel
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.resources import load_geometry
from wmm_control.urdf import UrdfTree

__all__ = [
    'CollisionModel',
    'NearPairs',
    'FLOOR',
    'PairChoice',
    'choose_pairs',
    'srdf_disabled_pairs',
    'ALWAYS_FRACTION',
    'median_check_time',
    'collision_geometry',
    'convex_hulls',
]

#: The name of the floor in pair names.
FLOOR = 'floor'
#: [m] GJK's tolerance on the distances.
GJK_TOLERANCE = 1e-9


@dataclass(frozen=True)
class NearPairs:
    """The checked pairs closer than some distance, at one configuration: entry ``k`` of each
    field is one pair. The arrays are read-only.

    Attributes:
        distance: signed distances [m]; negative where the shapes overlap. Shape (m,).
        links: each pair's two link names (``'floor'`` for the floor, an obstacle's name for it).
        shapes: each pair's two collision shapes' names (a link may have several).
        rate_jacobian: rows ``j`` with ``ḋ = j · q̇_arm + j_b · (vx, vy, ω)`` [m/rad or m/m].
            Shape (m, n_arm).
        base_jacobian: rows ``j_b`` [m/m, m/rad]: zero unless one of the two is fixed in the
            world (an obstacle). Shape (m, 3).
        floor: which pairs are with the floor. Shape (m,), boolean.
        lever: how fast each arm joint moves the pair's two nearest points apart or together
            in any direction, ``|v_b − v_a|`` per unit rate of the joint [m/rad or m/m]: the
            reach of a joint's motion whatever way the pair's normal turns while it moves.
            ``|rate_jacobian| ≤ lever`` entry by entry. Shape (m, n_arm).
    """

    distance: np.ndarray
    links: tuple[tuple[str, str], ...]
    shapes: tuple[tuple[str, str], ...]
    rate_jacobian: np.ndarray
    base_jacobian: np.ndarray
    floor: np.ndarray
    lever: np.ndarray

    def __len__(self) -> int:
        return self.distance.size

    def select(self, keep) -> NearPairs:
        """The pairs where the boolean array ``keep`` (shape (m,)) is true."""
        index = np.flatnonzero(keep)
        return NearPairs(
            _frozen(self.distance[index]),
            tuple(self.links[k] for k in index.tolist()),
            tuple(self.shapes[k] for k in index.tolist()),
            _frozen(self.rate_jacobian[index]),
            _frozen(self.base_jacobian[index]),
            _frozen(self.floor[index]),
            _frozen(self.lever[index]),
        )


class CollisionModel:
    """Distances and their Jacobians between the arm, the body, the floor and obstacles.

    Args:
        urdf_path: the robot's URDF.
        arm_joints: the arm's joint names, root first.
        ground_z: height of the floor in the root link's frame [m], which the base moves in
            the world's horizontal plane: the floor is at that height in the world; None: no
            floor pairs.
        start_arm: the arm posture whose pairs closer than ``margin`` touch by design and are
            not checked (default: every joint at zero).
        margin: [m].
        obstacles: :class:`~wmm_control.kinematics.obstacles.Obstacle` s in the world frame
            (:meth:`set_obstacles` changes them).
        pairs: the link pairs to check (``'floor'`` for the floor); None: the rules of the
            module docstring.
        package_dirs: folders ``package://`` mesh paths are looked up in first
            (:mod:`wmm_control.resources`).
        held: [rad or m] the joints outside the arm (head, fingers) by name, at the positions
            they are held at (:attr:`~wmm_control.robot_config.RobotConfig.held_joints`);
            None: their defaults (:func:`~wmm_control.robot_config.held_joint_positions`).
        kinematics: the :class:`~wmm_control.kinematics.model.KinematicModel` of the same URDF,
            arm and held joints whose configuration this model reads (a method's, shared with
            its safety stage); None: a model of its own. A question at another state updates
            it to that state (building this model leaves it at the start posture, the base at
            the origin).

    Raises:
        ConfigError: pinocchio cannot load the URDF or its collision shapes, or a mesh cannot be
            found.
    """

    @classmethod
    def from_robot(cls, robot, margin: float = 0.02, obstacles=(), kinematics=None):
        """The model of a :class:`~wmm_control.robot_config.RobotConfig`: its floor, its pairs
        (``collision.pairs`` of the YAML when given), and its start state's contacts left out;
        on ``kinematics`` (the robot's :class:`~wmm_control.kinematics.model.KinematicModel`)
        when given."""
        return cls(
            robot.urdf_path,
            robot.arm.joints,
            robot.ground_z,
            robot.start.arm,
            margin,
            obstacles,
            pairs=robot.collision_pairs,
            package_dirs=robot.package_dirs,
            held=robot.held_joints,
            kinematics=kinematics,
        )

    def __init__(
        self,
        urdf_path,
        arm_joints,
        ground_z=None,
        start_arm=None,
        margin: float = 0.02,
        obstacles=(),
        pairs=None,
        package_dirs=(),
        held=None,
        kinematics=None,
    ):
        path = str(urdf_path)
        tree = UrdfTree(path)
        arm_joints = tuple(arm_joints)
        if kinematics is None:
            if tree.root_link is None:
                raise ConfigError(f'{path}: the URDF has no single root link')
            # the root link as its end effector too: this model reads no end effector
            kinematics = KinematicModel.from_urdf(path, arm_joints, tree.root_link, tree.root_link, held)
        elif tuple(kinematics.model.names)[2:] != arm_joints:  # after the universe and the planar root
            raise ConfigError(f'the kinematic model moves {list(kinematics.model.names[2:])}, not {list(arm_joints)}')
        #: the configuration this model reads: every distance and rate is of its last update
        self.kinematics = kinematics
        self.model = model = kinematics.model
        # the shapes on the kinematic model: the planar root joint carries the body's, the arm's
        # joints the arm's; the joints outside the arm are locked at their held positions
        self.geom = kinematics.reduce_geometry(collision_geometry(kinematics.full_model, path, package_dirs))
        parent_link = {j.child: j.parent for j in tree.joints.values()}
        arm_ids = [model.getJointId(n) for n in arm_joints]
        self.n_arm = len(arm_ids)
        self._idx_q = [model.joints[j].idx_q for j in arm_ids]
        idx_v = [model.joints[j].idx_v for j in arm_ids]
        #: the joint Jacobians' columns the rates read: the planar root's (x, y, θ), then the arm's
        self._columns = np.array([*range(N_BASE), *idx_v])
        moving_joints = set(arm_ids)
        for j in range(1, model.njoints):  # joints below an arm joint move with it
            if model.parents[j] in moving_joints:
                moving_joints.add(j)
        link_of = [model.frames[g.parentFrame].name for g in self.geom.geometryObjects]
        moving = [g.parentJoint in moving_joints for g in self.geom.geometryObjects]

        def near(a: str, b: str) -> bool:  # b is a's parent link
            return parent_link.get(a) == b

        wanted = None if pairs is None else {frozenset(pair) for pair in pairs}

        def checked(a: int, b: int) -> bool:  # the YAML's pairs, or the rules of the module docstring
            la, lb = link_of[a], link_of[b]
            if wanted is not None:
                return la != lb and frozenset((la, lb)) in wanted
            if lb == FLOOR:
                return moving[a]
            return (moving[a] or moving[b]) and la != lb and not (near(la, lb) or near(lb, la))

        shape_pairs = [(a, b) for a in range(len(link_of)) for b in range(a + 1, len(link_of)) if checked(a, b)]
        self._world_fixed = set()
        if ground_z is not None:
            floor = pin.GeometryObject(
                FLOOR, 0, 0, pin.SE3(np.eye(3), np.array([0.0, 0.0, float(ground_z)])), _halfspace()
            )
            floor_id = self.geom.addGeometryObject(floor)
            self._world_fixed.add(floor_id)
            link_of.append(FLOOR)
            shape_pairs += [(a, floor_id) for a in range(len(moving)) if checked(a, floor_id)]
        pairs = shape_pairs
        self._link_of = link_of
        self._n_robot = len(moving)  # geometry objects of the robot's own links
        for a, b in pairs:
            self.geom.addCollisionPair(pin.CollisionPair(a, b))
        self.geom_data = pin.GeometryData(self.geom)
        self._placed = None
        self._results = list(self.geom_data.distanceResults)
        start = self._distances(self._configuration(np.zeros(self.n_arm) if start_arm is None else start_arm))
        keep = [k for k, d in enumerate(start) if d >= margin]
        self.excluded_at_start = [
            (link_of[pairs[k][0]], link_of[pairs[k][1]]) for k in range(len(pairs)) if k not in set(keep)
        ]
        self.geom.removeAllCollisionPairs()
        for k in keep:
            self.geom.addCollisionPair(pin.CollisionPair(*pairs[k]))
        self._robot_geom = self.geom.copy()
        self._robot_link_of = list(link_of)
        # [joint, i]: arm joint i moves the joint (none moves the planar root, which carries the
        # body, nor the world's, which holds the floor and the obstacles)
        self._moved_by = np.array([[a in model.supports[j] for a in arm_ids] for j in range(model.njoints)])
        self.obstacles: tuple[Obstacle, ...] = ()
        self.set_obstacles(obstacles)

    def set_obstacles(self, obstacles) -> None:
        """Check the robot against ``obstacles`` (world frame) from now on, instead of the
        previous ones: placed here, once, in the world frame the whole model is in."""
        obstacles = tuple(obstacles)
        geom = self._robot_geom.copy()
        link_of = list(self._robot_link_of)
        self._obstacle_ids = []
        for obstacle in obstacles:
            gid = geom.addGeometryObject(
                pin.GeometryObject(obstacle.name, 0, 0, obstacle.placement, obstacle.geometry())
            )
            self._obstacle_ids.append(gid)
            link_of.append(obstacle.name)
            for a in range(self._n_robot):
                geom.addCollisionPair(pin.CollisionPair(a, gid))
        self.geom, self._link_of, self.obstacles = geom, link_of, obstacles
        self._within_memo: tuple = (None, None)  # (arguments, answer) of the last within()
        self._placed = None  # the kinematic model's revision the shapes were last placed at
        self._fixed = self._world_fixed | set(self._obstacle_ids)
        self.geom_data = pin.GeometryData(geom)
        for request in self.geom_data.distanceRequests:
            # GJK to 1e-9 m: at coal's default (1e-6) the nearest points of curved shapes (the
            # cylinders around the links) are off by degrees, and so is the rate of the distance
            request.gjk_tolerance = GJK_TOLERANCE
        # each pair's result and each shape's placement, looked up once: reading a field through
        # these costs several times less than through the vector each time (they follow the
        # vector's entries)
        self._results = list(self.geom_data.distanceResults)
        self._placements = list(self.geom_data.oMg)
        self._tabulate_pairs()

    def _tabulate_pairs(self):
        """Each checked pair's links, shapes and joints, looked up once (call again after adding pairs)."""
        objects = self.geom.geometryObjects
        self._pair_links, self._pair_shapes, joints, robot, obstacle, floor = [], [], [], [], [], []
        for pair in self.geom.collisionPairs:
            a, b = objects[pair.first], objects[pair.second]
            self._pair_links.append((self._link_of[pair.first], self._link_of[pair.second]))
            floor.append(FLOOR in self._pair_links[-1])
            self._pair_shapes.append((a.name, b.name))
            joints.append((a.parentJoint, b.parentJoint))
            robot.append((pair.first not in self._fixed, pair.second not in self._fixed))
            obstacle.append(pair.first in self._obstacle_ids or pair.second in self._obstacle_ids)
        self._pair_joints = np.array(joints, dtype=int).reshape(-1, 2)
        #: [pair, side]: the geometry objects of each pair
        self._pair_objects = np.array([(p.first, p.second) for p in self.geom.collisionPairs], dtype=int).reshape(-1, 2)
        # the broad phase: each shape's bounding sphere, its centre in the shape's own frame
        self._sphere_centre, radius = [], []
        for obj in objects:
            obj.geometry.computeLocalAABB()
            r = obj.geometry.aabb_radius  # inf for the floor: its pairs always go on
            self._sphere_centre.append(np.array(obj.geometry.aabb_center) if np.isfinite(r) else np.zeros(3))
            radius.append(r)
        self._sphere_radius = np.array(radius, dtype=float)
        #: [pair]: the two bounding spheres' radii, summed (inf with the floor)
        self._pair_radii = self._sphere_radius[self._pair_objects].sum(axis=1)
        self._sphere_offset = [k for k, c in enumerate(self._sphere_centre) if c.any()]
        #: [pair, side]: that side is on the robot (moves with the base), not the floor or an obstacle
        self._pair_on_robot = np.array(robot, dtype=float).reshape(-1, 2)
        #: [pair]: a robot shape and an obstacle
        self._pair_obstacle = np.array(obstacle, dtype=bool)
        #: [pair]: the base's twist changes its distance (a robot shape and an obstacle); it leaves
        #: a pair on the robot as it is, and a shape's height over the floor
        self._pair_base_moves = self._pair_obstacle.astype(float)
        #: [pair]: one side is the floor
        self._pair_floor = np.array(floor, dtype=bool)

    @property
    def pairs(self) -> list[tuple[str, str]]:
        """The checked pairs, by link names."""
        return list(self._pair_links)

    @property
    def data(self) -> pin.Data:
        """The kinematic model's data: its joints' placements and Jacobians at its last update."""
        return self.kinematics.data

    def _configuration(self, q_arm) -> np.ndarray:
        """The configuration ``q = (x, y, θ, q_arm)`` of arm joints ``q_arm``, the base at the origin."""
        return self._state(q_arm, np.zeros(N_BASE))

    def _state(self, q_arm, base_pose) -> np.ndarray:
        """``q = (x, y, θ, q_arm)``; without ``base_pose`` (no obstacles: no distance depends on
        it) the kinematic model's current one, the origin before its first update."""
        q = np.zeros(N_BASE + self.n_arm)
        q[N_BASE:] = q_arm
        if base_pose is not None:
            q[:N_BASE] = base_pose
        elif self.obstacles:
            raise ValueError('CollisionModel: the base pose is needed with obstacles')
        else:
            current = self.kinematics.state
            if current is not None:
                q[:N_BASE] = current[:N_BASE]
        return q

    def _place(self, q) -> None:
        """Every shape where it is at ``q = (x, y, θ, q_arm)``: the kinematic model updated to ``q``
        unless it is there already (a method's update of the cycle), then the shapes placed from
        its joints' placements, once per update."""
        kinematics = self.kinematics
        if not np.array_equal(kinematics.state, q):
            kinematics.update(q[:N_BASE], q[N_BASE:])
        if self._placed != kinematics.revision:
            pin.updateGeometryPlacements(self.model, kinematics.data, self.geom, self.geom_data)
            self._placed = kinematics.revision

    def _distances(self, q) -> np.ndarray:
        """Every checked pair's distance at the configuration ``q`` (:meth:`_configuration`)."""
        self._place(q)
        self.geom_data.setActiveCollisionPairs(self.geom, self._all_pairs_map(), True)
        pin.computeDistances(self.geom, self.geom_data)
        return np.array([r.min_distance for r in self._results])

    def _all_pairs_map(self) -> np.ndarray:
        n = len(self.geom.geometryObjects)
        everything = np.zeros((n, n), dtype=bool)
        for pair in self.geom.collisionPairs:
            everything[pair.first, pair.second] = True
        return everything

    def _distances_within(self, q, reach, subset=None) -> tuple[np.ndarray, np.ndarray]:
        """Each checked pair's distance at the configuration ``q`` (:meth:`_configuration`): exact for the pairs whose
        bounding spheres are closer than ``reach`` [m] (one for every pair, or an array of one
        per pair; the broad phase, over every pair in one numpy expression); for the others,
        the gap between their spheres, a lower bound above ``reach``, with coal's narrow phase
        skipped.
        With ``subset`` (a boolean array over the pairs), only those pairs are exact.

        Returns:
            ``(distances, exact)``: which distances coal computed (boolean). Shape (pairs,) each."""
        geom, geom_data = self.geom, self.geom_data
        self._place(q)
        placements = self._placements
        centres = np.array([m.translation for m in placements])
        for k in self._sphere_offset:  # shapes whose bounding sphere is off their frame's origin (meshes)
            centres[k] = placements[k].act(self._sphere_centre[k])
        a, b = self._pair_objects[:, 0], self._pair_objects[:, 1]
        with np.errstate(invalid='ignore'):  # the floor's infinite sphere: −inf, NaN with another: checked
            gap = np.linalg.norm(centres[a] - centres[b], axis=1) - self._pair_radii
        near = ~(gap >= reach)
        if subset is not None:
            near &= subset
        active = np.zeros((len(centres), len(centres)), dtype=bool)
        active[a[near], b[near]] = True
        geom_data.setActiveCollisionPairs(geom, active, True)
        pin.computeDistances(geom, geom_data)  # the active pairs, at the placements above
        dists = gap
        results = self._results
        dists[near] = [results[k].min_distance for k in np.flatnonzero(near).tolist()]
        return dists, near

    def closest(self, q_arm, base_pose=None) -> tuple[float, tuple[str, str] | None]:
        """``(distance [m], (link a, link b))`` of the closest checked pair at arm joints
        ``q_arm`` (and base pose ``base_pose`` (x, y, θ), needed with obstacles); ``(inf,
        None)`` when no pair is checked."""
        if not self._results:
            return float('inf'), None
        dists = self._distances(self._state(q_arm, base_pose))
        k = int(np.argmin(dists))
        return float(dists[k]), self._pair_links[k]

    def within(
        self, q_arm, influence: float, base_pose=None, robot_influence: float | None = None
    ) -> tuple[NearPairs, float, tuple[str, str] | None]:
        """The pairs closer than ``influence`` [m] at ``q_arm`` (and base pose ``base_pose`` (x,
        y, θ), needed with obstacles), with their rate Jacobians, and the closest pair's
        distance and names (``inf, None`` when no pair is checked). Only the pairs whose
        bounding spheres are closer than ``influence`` go to coal's narrow phase: the closest
        distance is exact when it is below ``influence``, else a lower bound (the gap between
        two bounding spheres). With ``robot_influence`` [m] (at most ``influence``), a pair
        without an obstacle (two shapes of the robot, or one and the floor) is in the answer
        only when closer than it; the closest distance is the same."""
        # the same question again (a method's second pass in one period: eq (14)'s compensation)
        # gets the same answer without the distances and Jacobians computed again
        key = (
            np.asarray(q_arm, dtype=float).tobytes(),
            None if base_pose is None else np.asarray(base_pose, dtype=float).tobytes(),
            float(influence),
            None if robot_influence is None else float(robot_influence),
        )
        if key != self._within_memo[0]:
            self._within_memo = (key, self._within(q_arm, influence, base_pose, robot_influence))
        return self._within_memo[1]

    def _within(self, q_arm, influence, base_pose, robot_influence):
        n_arm = self.n_arm
        if not self._results:
            return _no_pairs(n_arm), float('inf'), None
        q = self._state(q_arm, base_pose)
        reach = influence
        if robot_influence is not None:  # coal's narrow phase and the rows only for the pairs asked for
            reach = np.where(self._pair_obstacle, influence, min(float(robot_influence), influence))
        dists, exact = self._distances_within(q, reach)
        k_min = int(np.argmin(dists))
        if not exact[k_min] and dists[k_min] < influence:
            # the closest is the bound of a pair the narrow phase left out: the distances of
            # every pair within ``influence``, as the closest distance promises
            dists, exact = self._distances_within(q, influence)
            k_min = int(np.argmin(dists))
        closest = (float(dists[k_min]), self._pair_links[k_min])
        near = np.flatnonzero(dists < reach)
        if not near.size:
            return _no_pairs(n_arm), *closest
        listed = near.tolist()
        results = list(map(self._results.__getitem__, listed))
        # each pair's nearest points, on a then on b, each with coal's normal, from the first to
        # the second: rows k and m + k of pair k (one concatenation of the 3-vectors coal gives,
        # cheaper than numpy.array on them; and one cross product over 2-D rows, cheaper than
        # one that broadcasts)
        m = near.size
        points = np.concatenate([r.getNearestPoint1() for r in results] + [r.getNearestPoint2() for r in results])
        normals = np.concatenate([r.normal for r in results] * 2)
        points, normals = points.reshape(2 * m, 3), normals.reshape(2 * m, 3)
        # ḋ = n · (v_b − v_a); a point p fixed to a joint moves at v = v₀ + ω × p, (v₀, ω) the
        # spatial velocity of a column of the joint Jacobians (world frame) that the kinematic
        # model's update computed, so n · v = n · v₀ + (p × n) · ω: over the planar root's
        # columns, then the arm joints' rates
        jacobians = self.kinematics.data.J[:, self._columns]
        along = (normals @ jacobians[:3] + np.cross(points, normals) @ jacobians[3:]).reshape(2, m, -1)
        sides, along = along[:, :, :N_BASE], along[:, :, N_BASE:]
        moved_by = self._moved_by[self._pair_joints[near].T]  # only the arm joints that move p
        along *= moved_by
        rates = along[1] - along[0]
        # the whole of each point's velocity per arm joint, v₀ + ω × p, for the joints' reach
        # whatever way the normal turns: |v_b − v_a|
        (vx, vy, vz), (wx, wy, wz) = jacobians[:3, N_BASE:], jacobians[3:, N_BASE:]
        px, py, pz = points[:, 0:1], points[:, 1:2], points[:, 2:3]
        apart = []  # each component of v_b − v_a, v = v₀ + ω × p, over (m, n_arm): outer products
        for v0, first, second in ((vx, wy * pz, wz * py), (vy, wz * px, wx * pz), (vz, wx * py, wy * px)):
            component = ((v0 + first - second).reshape(2, m, -1)) * moved_by
            apart.append(component[1] - component[0])
        lever = np.sqrt(apart[0] ** 2 + apart[1] ** 2 + apart[2] ** 2)
        # the planar root's columns, over the world frame's (ẋ, ẏ, θ̇), move every point of the
        # robot; the floor and the obstacles stay put. Between two points of the robot they
        # cancel, and against the floor they are zero (the base moves parallel to it).
        sides *= self._pair_on_robot[near].T[:, :, None]
        world = (sides[1] - sides[0]) * self._pair_base_moves[near, None]
        # over the base's twist (vx, vy, ω) in its own frame: (ẋ, ẏ, θ̇) = R(θ) (vx, vy, ω)
        base = world @ rotation_z(q[2])
        pairs = NearPairs(
            _frozen(dists[near]),
            tuple(map(self._pair_links.__getitem__, listed)),
            tuple(map(self._pair_shapes.__getitem__, listed)),
            _frozen(rates),
            _frozen(base),
            _frozen(self._pair_floor[near]),
            _frozen(lever),
        )
        return pairs, *closest


@dataclass(frozen=True)
class PairChoice:
    """The robot pairs worth checking, as MoveIt's set-up assistant chooses them
    (:func:`choose_pairs`).

    Attributes:
        checked: the link pairs left to check (``'floor'`` for the floor), sorted.
        candidates: how many link pairs there were before any was left out.
        left_out: the pairs left out, by reason: ``adjacent`` (a link and the nearest link with
            shapes above it), ``rigid`` (no arm joint between them: the same arm joints move
            both), ``srdf`` (the SRDF's ``disable_collisions``), ``always`` (in contact, within
            the contact distance, at 95 % of the samples or more), ``never`` (never closer than the influence distance over the samples).
        samples: how many random arm postures were drawn.
        influence: [m] the distance of ``never``.
        contact: [m] the distance of ``always``.
    """

    checked: tuple[tuple[str, str], ...]
    candidates: int
    left_out: dict[str, tuple[tuple[str, str], ...]]
    samples: int
    influence: float
    contact: float


def srdf_disabled_pairs(path) -> set[frozenset]:
    """The ``<disable_collisions link1 link2>`` pairs of an SRDF file.

    Raises:
        ConfigError: the file cannot be read or parsed.
    """
    try:
        root = ET.parse(path).getroot()
    except (OSError, ET.ParseError) as exc:
        raise ConfigError(f'{path}: SRDF unreadable: {exc}') from exc
    return {
        frozenset((e.get('link1'), e.get('link2')))
        for e in root.iter('disable_collisions')
        if e.get('link1') and e.get('link2')
    }


#: A pair within the contact distance at this fraction of the samples or more is in contact
#: by design (MoveIt's set-up assistant takes 95 % too).
ALWAYS_FRACTION = 0.95


def choose_pairs(
    urdf_path,
    arm_joints,
    ground_z=None,
    influence: float = 0.10,
    samples: int = 1000,
    srdf=None,
    package_dirs=(),
    seed: int = 0,
    contact: float = 0.02,
) -> PairChoice:
    """The link pairs the collision model needs to check, as MoveIt's set-up assistant
    chooses them: every pair of links with collision shapes (and each link with the floor, when
    ``ground_z`` is given), less

    1. ``adjacent`` pairs: a link and the nearest link with shapes above it in the URDF's tree;
    2. ``rigid`` pairs: the same arm joints move both links (none: the body; every one: two
       links of the hand), so that their distance never changes (the joints outside the arm are
       held);
    3. ``srdf`` pairs: the ``disable_collisions`` of the SRDF file ``srdf``;
    4. ``always`` pairs: every shape pair of the two links closer than ``contact`` [m] at
       :data:`ALWAYS_FRACTION` (95 %, as in MoveIt) or more of ``samples`` seeded random arm
       postures (uniform within the joint limits, ±π for a continuous joint): in contact by
       design at the scale of the safety stage, whose safety distance (0.02 m, the default
       ``contact``) they hardly ever clear, so that it could not hold them apart (the links of
       a wrist, a shoulder in its housing). Two links of several shapes each may rest close on
       one shape pair and meet on another (TIAGo's torso top and upper arm): they are checked,
       and the shape pair that rests close is left out at run time, closer than the collision
       model's margin at the start posture (:class:`CollisionModel`);
    5. ``never`` pairs: never closer than ``influence`` [m] at those postures.

    Raises:
        ConfigError: the URDF, a mesh or the SRDF cannot be read, or an arm joint is missing.
    """
    tree = UrdfTree(urdf_path)
    shaped = [name for name, elem in tree.links.items() if elem.find('collision') is not None]
    parent = {j.child: j.parent for j in tree.joints.values()}
    arm = set(arm_joints)
    missing = sorted(arm - set(tree.joints))
    if missing:
        raise ConfigError(f'{tree.path.name}: arm joints {missing} are not in the URDF')
    moved_by = {name: frozenset(j.name for j in tree.ancestors(name) if j.name in arm) for name in shaped}
    moved_by[FLOOR] = frozenset()
    shaped_set = set(shaped)

    def shaped_parent(link):
        link = parent.get(link)
        while link is not None and link not in shaped_set:
            link = parent.get(link)
        return link

    above = {name: shaped_parent(name) for name in shaped}
    disabled = srdf_disabled_pairs(srdf) if srdf is not None else set()
    names = shaped + ([FLOOR] if ground_z is not None else [])
    left_out: dict[str, list] = {reason: [] for reason in ('adjacent', 'rigid', 'srdf', 'always', 'never')}
    remaining = []
    for i, a in enumerate(names):
        for b in names[i + 1 :]:
            pair = (a, b)
            if above.get(a) == b or above.get(b) == a:
                left_out['adjacent'].append(pair)
            elif moved_by[a] == moved_by[b]:
                left_out['rigid'].append(pair)
            elif frozenset(pair) in disabled:
                left_out['srdf'].append(pair)
            else:
                remaining.append(pair)
    candidates = len(names) * (len(names) - 1) // 2
    if remaining and samples > 0:
        model = CollisionModel(
            urdf_path, arm_joints, ground_z, margin=-np.inf, pairs=remaining, package_dirs=package_dirs
        )
        ever_near, ever_apart = _sample_pairs(model, tree, arm_joints, remaining, (influence, contact), samples, seed)
    else:
        ever_near = ever_apart = np.ones(len(remaining), dtype=bool)
    checked = []
    for k, pair in enumerate(remaining):
        if not ever_apart[k]:
            left_out['always'].append(pair)
        elif not ever_near[k]:
            left_out['never'].append(pair)
        else:
            checked.append(pair)
    return PairChoice(
        checked=tuple(sorted(checked)),
        candidates=candidates,
        left_out={reason: tuple(pairs) for reason, pairs in left_out.items()},
        samples=samples,
        influence=float(influence),
        contact=float(contact),
    )


def _sample_pairs(model, tree, arm_joints, pairs, distances, samples, seed):
    """``(ever_near, apart)`` of each link pair over ``samples`` random arm postures: closer
    than ``influence`` at one of them; one of its shape pairs farther than ``contact`` at more
    than 1 − :data:`ALWAYS_FRACTION` of them (``distances`` = (influence, contact)). A pair seen
    both ways is not computed again."""
    influence, contact = distances
    enough = (1.0 - ALWAYS_FRACTION) * samples
    joints = [tree.joint(name, 'arm joint') for name in arm_joints]
    lower = np.array([max(j.lower, -np.pi) if j.lower is not None else -np.pi for j in joints])
    upper = np.array([min(j.upper, np.pi) if j.upper is not None else np.pi for j in joints])
    index = {frozenset(pair): k for k, pair in enumerate(pairs)}
    # each shape pair's link pair (a link pair whose links have no shapes to pair has none)
    of_shape = np.array([index[frozenset(links)] for links in model._pair_links], dtype=int)
    ever_near = np.zeros(len(pairs), dtype=bool)
    shape_apart = np.zeros(len(of_shape), dtype=int)  # per shape pair
    has_shapes = np.zeros(len(pairs), dtype=bool)
    has_shapes[of_shape] = True
    rng = np.random.default_rng(seed)
    for _ in range(samples):
        # a link pair is apart as often as the most often apart of its shape pairs: two links
        # with several shapes each (a torso's column and its top) may rest close on one shape
        # pair and meet on another, and are then checked
        apart = np.zeros(len(pairs), dtype=int)
        np.maximum.at(apart, of_shape, shape_apart)
        open_pairs = ~(ever_near & (apart > enough))
        if not open_pairs[has_shapes].any():
            break
        q = model._configuration(lower + (upper - lower) * rng.random(len(joints)))
        dists, _ = model._distances_within(q, influence, subset=open_pairs[of_shape])
        nearest = np.full(len(pairs), np.inf)
        np.minimum.at(nearest, of_shape, dists)
        ever_near |= nearest < influence
        shape_apart += dists > contact
    apart = np.zeros(len(pairs), dtype=int)
    np.maximum.at(apart, of_shape, shape_apart)
    ever_apart = apart > enough
    ever_near[~has_shapes] = ever_apart[~has_shapes] = True  # nothing to check: no cost, kept
    return ever_near, ever_apart


def median_check_time(model: CollisionModel, q_arms, influence: float = 0.10) -> float:
    """The median wall time [s] of one :meth:`CollisionModel.within` at each arm posture of
    ``q_arms`` (the base at the origin), the cost of one check in a control cycle; with the
    kinematics pass (a model of its own updates its kinematic model to each posture), which a
    control cycle shares with its method."""
    times = []
    for q in q_arms:
        start = time.perf_counter()
        model.within(q, influence, np.zeros(3))
        times.append(time.perf_counter() - start)
    return float(np.median(times)) if times else 0.0


def collision_geometry(model, urdf_path, package_dirs=()):
    """pinocchio's geometry model of the URDF's ``<collision>`` shapes for ``model``, each mesh
    as its convex hull (:func:`convex_hulls`): the geometry every collision check of the
    controller reads.

    Raises:
        ConfigError: a mesh cannot be found, or pinocchio cannot load the shapes.
    """
    geometry = load_geometry(model, urdf_path, pin.GeometryType.COLLISION, package_dirs)
    convex_hulls(geometry)
    return geometry


def convex_hulls(geometry) -> int:
    """Replace, in place, each mesh shape of the pinocchio geometry model ``geometry`` (coal's
    ``BVHModel``, a soup of triangles) by the convex hull of its vertices; returns how many.

    Against a hull coal's GJK and EPA give a signed distance: negative, the penetration depth,
    where two shapes overlap, while two triangle soups report 0 however deep they overlap. A
    hull holds its mesh, so its distance to any shape is never larger than the mesh's: the
    collision model errs on the safe side, by the mesh's concavities. A description that
    splits a concave part into several ``<collision>`` meshes (TIAGo's torso) keeps that
    split: each piece gets its own hull. PyBullet, the simulator, takes a URDF's collision
    meshes as their convex hulls too. A flat mesh (its vertices in one plane) has no inside and
    stays as it is.
    """
    count = 0
    for obj in geometry.geometryObjects:
        if isinstance(obj.geometry, pin.coal.BVHModelBase):
            hull = _convex_hull(np.asarray(obj.geometry.vertices(), dtype=float))
            if hull is not None:
                obj.geometry = hull
                count += 1
    return count


def _convex_hull(vertices: np.ndarray):
    """coal's convex polytope of the hull of ``vertices`` (shape (n, 3)), its triangles turned
    outwards; None when the points span no volume (qhull through scipy)."""
    try:
        hull = ConvexHull(vertices)
    except (QhullError, ValueError):  # flat, or fewer than four points
        return None
    index = np.full(len(vertices), -1)
    index[hull.vertices] = np.arange(hull.vertices.size)
    triangles = index[hull.simplices]
    points = vertices[hull.vertices]
    a, b, c = (points[triangles[:, k]] for k in range(3))
    inward = np.einsum('ij,ij->i', np.cross(b - a, c - a), hull.equations[:, :3]) < 0.0
    triangles[inward] = triangles[inward][:, [0, 2, 1]]
    coal = pin.coal
    corners, faces = coal.StdVec_Vec3s(), coal.StdVec_Triangle()
    corners.extend(list(points))
    faces.extend([coal.Triangle(*t) for t in triangles.tolist()])
    return coal.Convex(corners, faces)


def _frozen(array: np.ndarray) -> np.ndarray:
    """``array``, read-only (answers are shared by repeated questions)."""
    array.setflags(write=False)
    return array


def _no_pairs(n_arm: int) -> NearPairs:
    return NearPairs(
        _frozen(np.zeros(0)),
        (),
        (),
        _frozen(np.zeros((0, n_arm))),
        _frozen(np.zeros((0, 3))),
        _frozen(np.zeros(0, bool)),
        _frozen(np.zeros((0, n_arm))),
    )


def _halfspace():
    """The floor's shape: z ≤ 0 in its own frame (coal, as pinocchio exposes it)."""
    return pin.coal.Halfspace(np.array([0.0, 0.0, 1.0]), 0.0)
