"""One configuration a cycle: the collision model built on a method's kinematic model reads the
joints' placements and Jacobians its update computed (no forward kinematics of its own), in the
world frame where the floor and the obstacles stay where they were placed. One pinocchio model
per robot in a process: the method's, the pursuit's and the planner's configurations read it,
each with data of its own."""

import numpy as np
import pinocchio as pin
import pytest

from wmm_control.errors import ConfigError
from wmm_control.geometry import twist_to_world
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.collision import FLOOR, CollisionModel
from wmm_control.kinematics.obstacles import parse_obstacles
from wmm_control.planning import GoalPlanner
from wmm_control.planning.pursuit import GoalPursuit
from wmm_control.resolvers import PoseTarget, RobotState, make_resolver
from wmm_control.robot_config import load_robot

OBSTACLES = parse_obstacles(
    [
        {'name': 'ball', 'shape': 'sphere', 'size': [0.15], 'pose': [0.7, 0.5, 1.1]},
        {'name': 'crate', 'shape': 'box', 'size': [0.4, 0.3, 0.5], 'pose': [0.9, -0.4, 0.25, 0.0, 0.0, 0.4]},
    ],
    'test',
)
NAMES = {o.name for o in OBSTACLES}
#: pinocchio's passes that compute joint placements from a configuration
KINEMATICS = ('forwardKinematics', 'computeJointJacobians', 'framesForwardKinematics')


@pytest.fixture(scope='module')
def mecanum():
    cfg = load_robot('mecanum')
    kinematics = KinematicModel(cfg)
    return cfg, kinematics, CollisionModel.from_robot(cfg, obstacles=OBSTACLES, kinematics=kinematics)


def _counting(monkeypatch):
    """Count the calls of pinocchio's kinematic passes and geometry placements from now on."""
    calls = {name: [] for name in (*KINEMATICS, 'updateGeometryPlacements')}
    for name in calls:
        original = getattr(pin, name)

        def counted(*args, _name=name, _original=original):
            calls[_name].append(len(args))
            return _original(*args)

        monkeypatch.setattr(pin, name, counted)
    return calls


def _state(cfg, rng):
    q = np.array(cfg.start.arm) + rng.uniform(-0.5, 0.5, len(cfg.start.arm))
    return q, np.array([rng.uniform(-0.5, 0.5), rng.uniform(-0.5, 0.5), rng.uniform(-np.pi, np.pi)])


def test_after_an_update_the_distances_read_its_configuration_without_kinematics_of_their_own(mecanum, monkeypatch):
    cfg, kinematics, collision = mecanum
    assert collision.model is kinematics.model and collision.data is kinematics.data
    q, base = _state(cfg, np.random.default_rng(5))
    kinematics.update(base, q, np.array([0.2, -0.1, 0.3]), np.full(q.size, 0.1))
    calls = _counting(monkeypatch)
    near, _, _ = collision.within(q, 1.0, base)
    assert len(near)
    assert not any(calls[name] for name in KINEMATICS)
    # the shapes placed once, from the update's joint placements (no configuration passed)
    assert calls['updateGeometryPlacements'] == [4]
    collision.within(q, 0.5, base)  # another question at the same configuration
    assert calls['updateGeometryPlacements'] == [4] and not any(calls[name] for name in KINEMATICS)
    kinematics.jdot_qdot()  # the update's rates are still there: nobody updated again
    # a configuration the kinematic model is not at: one update of it, then the shapes placed
    collision.within(q + 0.1, 1.0, base)
    assert len(calls['computeJointJacobians']) == 1 and calls['updateGeometryPlacements'] == [4, 4]
    np.testing.assert_array_equal(kinematics.state[3:], q + 0.1)


@pytest.mark.parametrize('seed', [1, 2, 3])
def test_rates_from_the_shared_configuration_are_the_derivatives_over_the_arm_and_the_base(mecanum, seed):
    """ḋ = j q̇ + j_b (vx, vy, ω) against central differences of the distances along the arm's
    rates and the base's world-frame motion (θ ≠ 0: the base's twist is in its own frame)."""
    cfg, kinematics, collision = mecanum
    rng = np.random.default_rng(seed)
    q, base = _state(cfg, rng)
    qd, twist = rng.normal(size=q.size), rng.normal(size=3)
    world = twist_to_world(base[2], twist)
    kinematics.update(base, q, world, qd)
    near, _, _ = collision.within(q, 1.0, base)
    h = 1e-5
    ahead, behind = (collision.within(q + s * h * qd, 2.0, base + s * h * world)[0] for s in (1, -1))
    obstacle_pairs = 0
    for k, shapes in enumerate(near.shapes):
        rate = (ahead.distance[ahead.shapes.index(shapes)] - behind.distance[behind.shapes.index(shapes)]) / (2 * h)
        assert near.rate_jacobian[k] @ qd + near.base_jacobian[k] @ twist == pytest.approx(rate, abs=1e-4), shapes
        obstacle_pairs += near.links[k][1] in NAMES
    assert obstacle_pairs, 'some shape within 1 m of an obstacle'


def test_only_obstacle_pairs_have_base_rates_and_the_rest_ignore_where_the_base_is(mecanum):
    """The planar root moves every shape of the robot: a pair of two of them, or one and the
    floor (at ground_z in the world, the base moving in its plane), keeps its distance wherever
    the base is, and the base's twist has no share in its rate."""
    cfg, _, collision = mecanum
    q = np.array(cfg.start.arm)
    answers = []
    for base in (np.zeros(3), np.array([0.4, -0.3, 2.0])):
        near, _, _ = collision.within(q, np.inf, base)
        answers.append(near)
        on_robot = np.array([links[1] not in NAMES for links in near.links])
        assert on_robot.any() and (~on_robot).any()
        assert not near.base_jacobian[on_robot].any()
        assert np.all(np.abs(near.base_jacobian[~on_robot]).sum(axis=1) > 0.0)
    first, second = (near.select([links[1] not in NAMES for links in near.links]) for near in answers)
    assert first.shapes == second.shapes and any(FLOOR in links for links in first.links)
    np.testing.assert_allclose(first.distance, second.distance, atol=1e-7)
    # the floor: fixed in the world, at ground_z
    data = collision.geom_data
    assert collision.geom.geometryObjects[collision.geom.getGeometryId(FLOOR)].parentJoint == 0
    assert data.oMg[collision.geom.getGeometryId(FLOOR)].translation[2] == pytest.approx(cfg.ground_z)


def test_obstacles_are_placed_once_in_the_world(mecanum):
    cfg, _, collision = mecanum
    ids = [collision.geom.getGeometryId(o.name) for o in OBSTACLES]
    rng = np.random.default_rng(9)
    for _ in range(3):
        q, base = _state(cfg, rng)
        collision.within(q, 1.0, base)
        for gid, obstacle in zip(ids, OBSTACLES):
            assert collision.geom.geometryObjects[gid].placement.isApprox(obstacle.placement)
            assert collision.geom_data.oMg[gid].isApprox(obstacle.placement)


def test_a_model_of_another_arm_is_refused(mecanum):
    cfg, kinematics, _ = mecanum
    with pytest.raises(ConfigError, match='moves'):
        CollisionModel(cfg.urdf_path, cfg.arm.joints[:-1], kinematics=kinematics)


@pytest.mark.parametrize('method', ['pinv', 'amp'])
def test_a_method_and_its_safety_stage_run_one_kinematics_pass_a_cycle(method, monkeypatch):
    cfg = load_robot('mecanum')
    resolver = make_resolver(method, cfg)
    resolver.set_obstacles(OBSTACLES)
    assert resolver.safety.collision.kinematics is resolver.model
    resolver.model.update(np.zeros(3), cfg.start.arm)
    pos, rot = resolver.model.ee_placement_world()
    target = PoseTarget(pos + np.array([0.3, 0.2, -0.1]), rot)
    base = np.array([0.1, 0.0, 0.5])
    state = RobotState(base, np.zeros(3), np.array(cfg.start.arm), np.zeros(len(cfg.start.arm)))
    resolver.step(state, target)  # the first period sets the method's memory up
    state = RobotState(base, np.zeros(3), state.q_arm + 0.01, np.zeros(len(cfg.start.arm)))  # the next period
    calls = _counting(monkeypatch)
    command = resolver.step(state, target)
    assert np.isfinite(command.diagnostics.clearance)
    assert len(calls['computeJointJacobians']) == 1  # the method's update
    assert not calls['forwardKinematics'] or method == 'amp'  # AMP's update with rates: one pass
    assert len(calls['forwardKinematics']) <= 1
    assert calls['updateGeometryPlacements'] == [4]
    # the stage's distances are those of the state the method saw, the base turned by θ
    near, _, _ = resolver.safety.collision.within(state.q_arm, np.inf, base)
    alone = CollisionModel.from_robot(cfg, obstacles=OBSTACLES)
    expected, _, _ = alone.within(state.q_arm, np.inf, base)
    np.testing.assert_allclose(near.distance, expected.distance, atol=1e-7)
    np.testing.assert_allclose(near.base_jacobian, expected.base_jacobian, atol=1e-4)  # GJK's witness points


def test_the_method_the_pursuit_and_the_planner_share_one_model_each_with_its_own_configuration():
    """The method's, the pursuit's, the planner's and its clearances' kinematic models of one robot
    read one pinocchio model (the planner's in its own thread), each with its own data: a
    configuration set in one does not show in another."""
    cfg = load_robot('mecanum')
    resolver = make_resolver('pinv', cfg)
    pursuit = GoalPursuit(cfg, OBSTACLES, 'world', 5.0, threaded=False)
    planner = GoalPlanner(cfg, OBSTACLES)
    users = [
        resolver.model,
        pursuit.model,
        planner.model,
        planner.clearance.collision.kinematics,
        planner.travel.clearance.collision.kinematics,
    ]
    assert all(u.model is resolver.model.model and u.full_model is resolver.model.full_model for u in users)
    assert len({id(u.data) for u in users}) == len(users)
    rng = np.random.default_rng(3)
    for user in users:
        user.update(np.zeros(3), cfg.start.arm)
    placements = [[m.homogeneous.copy() for m in u.data.oMi] for u in users]
    q, base = _state(cfg, rng)
    resolver.model.update(base, q)
    moved = [m.homogeneous for m in resolver.model.data.oMi]
    assert not np.allclose(moved[-1], placements[0][-1])
    for user, before in zip(users[1:], placements[1:]):
        assert np.array_equal(user.state, np.concatenate((np.zeros(3), cfg.start.arm)))
        for m, old in zip(user.data.oMi, before):
            np.testing.assert_array_equal(m.homogeneous, old)
    # the planner's clearance answers at its own configuration, whatever the method's
    planner.clearance(q, base)
    np.testing.assert_array_equal(resolver.model.data.oMi[-1].homogeneous, moved[-1])


def test_a_collision_model_s_obstacles_stay_in_its_own_geometry():
    """Collision models of one robot share its pinocchio model; the obstacles and the floor one
    of them adds go to its own geometry, not to the model nor to another's geometry."""
    cfg = load_robot('mecanum')
    plain = CollisionModel.from_robot(cfg)
    frames, shapes, pairs = plain.model.nframes, len(plain.geom.geometryObjects), plain.pairs
    q, base = _state(cfg, np.random.default_rng(4))
    closest = plain.closest(q, base)
    crowded = CollisionModel.from_robot(cfg, obstacles=OBSTACLES)
    assert crowded.model is plain.model and crowded.geom is not plain.geom
    assert NAMES <= {g.name for g in crowded.geom.geometryObjects}
    again = CollisionModel.from_robot(cfg)
    for model in (plain, again):
        assert model.model.nframes == frames and len(model.geom.geometryObjects) == shapes
        assert not NAMES & {g.name for g in model.geom.geometryObjects}
        assert model.pairs == pairs
        assert model.closest(q, base) == closest
