"""Mesh collision shapes as their convex hulls (``convex_hulls``, which every collision model of
the controller takes through ``collision_geometry``): two overlapping hulls are minus their
penetration depth apart, a hull is never farther from anything than its mesh; on a real
description (TIAGo's) no triangle soup is left, the broad phase's bounding spheres still hold
every hull, and the simulator's ground truth (PyBullet) sees the same hulls."""

import xml.etree.ElementTree as ET

import numpy as np
import pinocchio as pin
import pybullet as p
import pytest
from scipy.spatial.transform import Rotation

from wmm_control.kinematics.collision import GJK_TOLERANCE, CollisionModel, convex_hulls
from wmm_control.resources import loadable_urdf

TIAGO_ARM = ['torso_lift_joint'] + [f'arm_{k}_joint' for k in range(1, 8)]


def _box(size, centre=(0.0, 0.0, 0.0)):
    """The vertices and triangles of a box of ``size`` (x, y, z) about ``centre``."""
    half = 0.5 * np.asarray(size, dtype=float)
    vertices = [np.asarray(centre) + half * (sx, sy, sz) for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)]
    triangles = [(0, 1, 3), (0, 3, 2), (4, 6, 7), (4, 7, 5), (0, 4, 5), (0, 5, 1)]
    triangles += [(2, 3, 7), (2, 7, 6), (0, 2, 6), (0, 6, 4), (1, 5, 7), (1, 7, 3)]
    return np.array(vertices), np.array(triangles)


def _mesh(*parts):
    """coal's triangle soup (a ``BVHModel``, as pinocchio loads a mesh) of the ``_box`` parts."""
    vertices = np.vstack([v for v, _ in parts])
    offsets = np.cumsum([0] + [len(v) for v, _ in parts[:-1]])
    triangles = np.vstack([t + k for (_, t), k in zip(parts, offsets)])
    mesh = pin.coal.BVHModelOBBRSS()
    mesh.beginModel(len(triangles), len(vertices))
    mesh.addVertices(vertices)
    mesh.addTriangles(triangles)
    mesh.endModel()
    return mesh


#: A cube of 0.05 m, the probe.
PROBE = (_box((0.05, 0.05, 0.05)),)
#: An L, 0.1 m thick: its notch (x, y in [0.1, 0.4]) is outside it and inside its hull.
ELL = (_box((0.4, 0.1, 0.1), (0.2, 0.05, 0.05)), _box((0.1, 0.3, 0.1), (0.05, 0.25, 0.05)))


class Pair:
    """Two shapes as a pinocchio geometry model, as triangle soups and with ``convex_hulls``."""

    def __init__(self, a, b):
        self.meshes = pin.GeometryModel()
        for name, parts in (('a', a), ('b', b)):
            self.meshes.addGeometryObject(pin.GeometryObject(name, 0, 0, pin.SE3.Identity(), _mesh(*parts)))
        self.meshes.addCollisionPair(pin.CollisionPair(0, 1))
        self.hulls = self.meshes.copy()
        for obj in self.hulls.geometryObjects:  # its own shapes, not the triangle soups'
            obj.geometry = obj.geometry.clone()
        assert convex_hulls(self.hulls) == 2

    @staticmethod
    def distance(geometry, place_a, place_b) -> float:
        """Coal's distance between the two shapes of ``geometry`` at these placements."""
        geometry.geometryObjects[0].placement = place_a
        geometry.geometryObjects[1].placement = place_b
        model = pin.Model()
        data = pin.GeometryData(geometry)
        data.distanceRequests[0].gjk_tolerance = GJK_TOLERANCE
        pin.computeDistances(model, model.createData(), geometry, data, np.zeros(0))
        return data.distanceResults[0].min_distance


def _placement(rotation, translation):
    return pin.SE3(np.asarray(rotation, dtype=float), np.asarray(translation, dtype=float))


@pytest.mark.parametrize('depth', [0.004, 0.02, 0.05])
def test_overlapping_hulls_are_minus_their_penetration_depth_apart(depth):
    """Two boxes overlapping by ``depth`` along x (and by more along y and z), anywhere and
    turned any way: their hulls are −depth apart, their triangle soups 0."""
    pair = Pair((_box((0.4, 0.3, 0.2)),), (_box((0.2, 0.2, 0.2)),))
    rng = np.random.default_rng(3)
    for _ in range(5):
        world = _placement(Rotation.random(random_state=rng).as_matrix(), rng.uniform(-1.0, 1.0, 3))
        place_b = world * _placement(np.eye(3), [0.3 - depth, 0.03, -0.02])
        assert Pair.distance(pair.hulls, world, place_b) == pytest.approx(-depth, abs=1e-6)
        assert Pair.distance(pair.meshes, world, place_b) == 0.0


def test_a_hull_is_never_farther_than_its_mesh():
    """A small cube against an L-shaped mesh and against a box mesh, 300 random placements: the
    hull's distance is at most the mesh's; equal for the convex box wherever the hulls are apart
    (a triangle soup also reports a cube wholly inside it as apart: its hull does not); and a
    cube in the L's notch, 0.075 m from the L, is inside the L's hull."""
    ell, cube = Pair(ELL, PROBE), Pair((_box((0.3, 0.3, 0.1), (0.15, 0.15, 0.05)),), PROBE)
    rng = np.random.default_rng(5)
    gaps = []
    for _ in range(300):
        place = _placement(Rotation.random(random_state=rng).as_matrix(), rng.uniform(-0.3, 0.7, 3))
        for pair in (ell, cube):
            mesh = Pair.distance(pair.meshes, pin.SE3.Identity(), place)
            hull = Pair.distance(pair.hulls, pin.SE3.Identity(), place)
            assert hull <= mesh + 1e-9
            if pair is cube and hull > 0.0:
                assert hull == pytest.approx(mesh, abs=1e-7)
            if pair is ell:
                gaps.append(mesh - hull)
    assert max(gaps) > 0.05 and np.median(gaps) < 1e-7  # the notch matters at some placements only
    in_notch = _placement(np.eye(3), [0.2, 0.2, 0.05])
    assert Pair.distance(ell.meshes, pin.SE3.Identity(), in_notch) == pytest.approx(0.075, abs=1e-7)
    assert Pair.distance(ell.hulls, pin.SE3.Identity(), in_notch) < 0.0


def test_a_hull_is_a_closed_outward_polytope_and_a_flat_mesh_stays_as_it_is():
    """The L's hull has the volume of the L's hull (its triangles all face outwards) and every
    vertex of the L's outline but the notch's corner; a flat mesh (a square) spans no volume and
    keeps its triangles."""
    ell = Pair(ELL, PROBE).hulls.geometryObjects[0].geometry
    outline = [(0, 0), (0.4, 0), (0.4, 0.1), (0.1, 0.4), (0, 0.4)]  # the hull's section, 0.1 m thick
    x, y = np.array(outline).T
    area = 0.5 * abs(np.dot(x, np.roll(y, 1)) - np.dot(y, np.roll(x, 1)))
    assert ell.computeVolume() == pytest.approx(0.1 * area, rel=1e-9)
    assert ell.num_points == 2 * len(outline)
    square = pin.GeometryModel()
    flat = _mesh((np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0.0]]), np.array([[0, 1, 2], [0, 2, 3]])))
    square.addGeometryObject(pin.GeometryObject('square', 0, 0, pin.SE3.Identity(), flat))
    assert convex_hulls(square) == 0
    assert isinstance(square.geometryObjects[0].geometry, pin.coal.BVHModelBase)


def test_the_broad_phase_holds_the_hulls_of_a_real_description(tiago_robots):
    """TIAGo's collision model: every mesh a hull, each inside its bounding sphere; at random arm
    postures the broad phase gives the exact distance of every pair within reach and a lower
    bound for the others; some postures put the arm's hull into the body (negative distances)."""
    urdf, share = tiago_robots / 'tiago_no_hand.urdf', tiago_robots.parents[3]
    model = CollisionModel(urdf, TIAGO_ARM, ground_z=0.0, margin=-np.inf, package_dirs=[share])
    objects = model.geom.geometryObjects
    hulls = [obj.geometry for obj in objects if isinstance(obj.geometry, pin.coal.ConvexBase)]
    meshes = ET.parse(urdf).getroot().findall('link/collision/geometry/mesh')
    assert len(hulls) == len(meshes) > 10
    assert not any(isinstance(obj.geometry, pin.coal.BVHModelBase) for obj in objects)
    for hull in hulls:
        hull.computeLocalAABB()
        reach = np.linalg.norm(np.asarray(hull.points()) - np.asarray(hull.aabb_center), axis=1)
        assert reach.max() <= hull.aabb_radius + 1e-12
    lower, upper = model.model.lowerPositionLimit, model.model.upperPositionLimit
    idx = np.array(model._idx_q)
    rng = np.random.default_rng(11)
    deepest = np.inf
    for _ in range(30):
        q = model._configuration(lower[idx] + (upper[idx] - lower[idx]) * rng.random(idx.size))
        exact = model._distances(q)
        within, _ = model._distances_within(q, 0.10)
        near = exact < 0.10
        # to EPA's tolerance (1e-6 m): an overlap's depth varies that much from one call to the next
        np.testing.assert_allclose(within[near], exact[near], atol=1e-6)
        assert np.all(within <= exact + 1e-6)
        deepest = min(deepest, exact.min())
    assert deepest < -0.005


def test_the_simulator_judges_contact_on_the_same_hulls(tiago_robots):
    """PyBullet, the simulator's ground truth, takes TIAGo's collision meshes as their hulls too:
    at random arm postures each link pair within 0.1 m is as far apart there as in the
    collision model, less PyBullet's collision margins (1 mm a shape), contacts included; the
    triangle soups would be up to a tenth of a metre off, reporting a link inside another as
    apart."""
    urdf, share = tiago_robots / 'tiago_no_hand.urdf', tiago_robots.parents[3]
    model = CollisionModel(urdf, TIAGO_ARM, margin=-np.inf, package_dirs=[share])
    cid = p.connect(p.DIRECT)
    try:
        body = p.loadURDF(str(loadable_urdf(urdf, [share])), useFixedBase=True, physicsClientId=cid)
        joints = [
            p.getJointInfo(body, j, physicsClientId=cid) for j in range(p.getNumJoints(body, physicsClientId=cid))
        ]
        link_index = {info[12].decode(): info[0] for info in joints}
        joint_index = {info[1].decode(): info[0] for info in joints}
        lower, upper = (
            limits[np.array(model._idx_q)]
            for limits in (model.model.lowerPositionLimit, model.model.upperPositionLimit)
        )
        rng = np.random.default_rng(2)
        differences, contacts = [], 0
        for _ in range(20):
            q_arm = lower + (upper - lower) * rng.random(len(TIAGO_ARM))
            for name, value in zip(TIAGO_ARM, q_arm):
                p.resetJointState(body, joint_index[name], float(value), physicsClientId=cid)
            nearest: dict[tuple[str, str], float] = {}
            for links, d in zip(model.pairs, model._distances(model._configuration(q_arm))):
                nearest[links] = min(nearest.get(links, np.inf), d)
            for (a, b), d in nearest.items():
                if d < 0.1:
                    points = p.getClosestPoints(
                        body, body, 0.2, linkIndexA=link_index[a], linkIndexB=link_index[b], physicsClientId=cid
                    )
                    differences.append(d - min(point[8] for point in points))
                    contacts += d < 0.0
    finally:
        p.disconnect(cid)
    assert contacts > 10 and len(differences) > 100
    assert 0.0 <= min(differences) and max(differences) <= 0.002 + 1e-6
