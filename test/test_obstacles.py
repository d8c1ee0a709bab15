"""Obstacles: the file format, the distances and their rates against the simulator's geometry,
the safety stage on the base, goals inside an obstacle, the /obstacles topic, the simulator's
contact report, and the recorded runs."""

import math
import re

import numpy as np
import pytest
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from rclpy.node import Node
from std_msgs.msg import Float64
from visualization_msgs.msg import Marker, MarkerArray

from ros_helpers import RosHarness, overrides
from sim_bridge.collision import SelfCollisionChecker
from sim_bridge.node import SimNode
from wmm_control.base import make_base_controller
from wmm_control.cycle import Cycle
from wmm_control.errors import ConfigError
from wmm_control.geometry import twist_to_world
from wmm_control.experiments.randomized import CONTACT_DEPTH, RandomGoal, run_goal, sample_goals
from wmm_control.experiments.scenario import load_scenario
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.collision import CollisionModel
from wmm_control.kinematics.obstacles import load_obstacles, parse_obstacles
from wmm_control.kinematics.workspace import Workspace
from wmm_control.nodes.obstacle_topic import Applied, ObstacleSet, obstacle_from_marker
from wmm_control.nodes.qos import LATCHED_QOS
from wmm_control.nodes.redundancy_resolver import RedundancyResolverNode
from wmm_control.nodes.swmr_controller import SwmrControllerNode
from wmm_control.resolvers import make_resolver
from wmm_control.resolvers.limits import CommandLimits
from wmm_control.resolvers.safety import SafetyStage
from wmm_control.robot_config import load_robot

BALLS = parse_obstacles(
    [
        {'name': 'ball', 'shape': 'sphere', 'size': [0.15], 'pose': [0.7, 0.5, 1.1]},
        {'name': 'low', 'shape': 'sphere', 'size': [0.2], 'pose': [0.9, -0.3, 0.2]},
    ],
    'test',
)


@pytest.mark.parametrize(
    'entry, message',
    [
        ({'shape': 'cone', 'size': [1.0], 'pose': [0, 0, 0]}, 'shape must be one of'),
        ({'shape': 'box', 'size': [1.0, 1.0], 'pose': [0, 0, 0]}, 'takes 3 size entries'),
        ({'shape': 'sphere', 'size': [0.0], 'pose': [0, 0, 0]}, 'finite, > 0 and at most 1000'),
        ({'shape': 'box', 'size': [1.0, 2e3, 1.0], 'pose': [0, 0, 0]}, 'finite, > 0 and at most 1000'),
        ({'shape': 'sphere', 'size': [0.1], 'pose': [0, 1e15, 0]}, 'within ±1000 m'),
        ({'shape': 'sphere', 'size': [0.1], 'pose': [0, 0]}, 'expected 3 or 6 numbers'),
        ({'shape': 'sphere', 'size': [0.1], 'pose': [0, 0, float('nan')]}, 'finite'),
        ({'shape': 'sphere', 'size': [0.1], 'pose': [0, 0, 0], 'colour': 'red'}, 'unknown keys'),
    ],
)
def test_a_bad_obstacle_entry_is_refused_with_its_reason(entry, message):
    with pytest.raises(ConfigError, match=message):
        parse_obstacles([entry], 'test.yaml')


def test_obstacle_files_are_checked(tmp_path):
    with pytest.raises(ConfigError, match='not found'):
        load_obstacles(tmp_path / 'missing.yaml')
    twice = tmp_path / 'twice.yaml'
    twice.write_text(
        'obstacles:\n  - {name: a, shape: sphere, size: [0.1], pose: [0, 0, 0]}\n'
        '  - {name: a, shape: sphere, size: [0.1], pose: [1, 0, 0]}\n'
    )
    with pytest.raises(ConfigError, match='used twice'):
        load_obstacles(twice)
    assert [o.name for o in load_obstacles('table_pillar')] == ['table', 'pillar']


def test_signed_distances_of_the_three_shapes():
    box, ball, post = parse_obstacles(
        [
            {'shape': 'box', 'size': [2.0, 1.0, 0.5], 'pose': [1.0, 0.0, 0.0, 0.0, 0.0, np.pi / 2]},
            {'shape': 'sphere', 'size': [0.5], 'pose': [0.0, 0.0, 1.0]},
            {'shape': 'cylinder', 'size': [0.1, 2.0], 'pose': [0.0, 2.0, 1.0]},
        ],
        'test',
    )
    assert box.signed_distance([1.0, 0.0, 0.0]) == pytest.approx(-0.25)  # the centre: 0.25 to the top
    assert box.signed_distance([1.0, 1.5, 0.0]) == pytest.approx(0.5)  # turned: its x is the world's y
    assert ball.signed_distance([0.0, 0.0, 2.0]) == pytest.approx(0.5)
    assert post.signed_distance([0.0, 2.05, 1.5]) == pytest.approx(-0.05)
    assert post.signed_distance([0.0, 2.0, 2.5]) == pytest.approx(0.5)


@pytest.mark.parametrize('name', ['steerable', 'mecanum'])
def test_obstacle_distances_agree_with_the_simulator_and_their_rates_are_their_derivatives(name):
    robot = load_robot(name)
    model = CollisionModel.from_robot(robot, obstacles=BALLS)
    rng = np.random.default_rng(3)
    h = 1e-4
    with SelfCollisionChecker(robot, margin=1.0, obstacles=BALLS) as checker:
        for _ in range(15):
            q = np.array(robot.start.arm) + rng.uniform(-0.5, 0.5, len(robot.start.arm))
            base = np.array([rng.uniform(-0.4, 0.4), rng.uniform(-0.4, 0.4), rng.uniform(-np.pi, np.pi)])
            near, _, _ = model.within(q, 1.0, base)
            truth = {(a, b): d for a, b, d in checker.collisions(q, base) if b in ('ball', 'low')}
            mine = near.select([links[1] in ('ball', 'low') for links in near.links])
            assert len(mine), 'some link within 1 m of an obstacle'
            nearest = {}  # a link may have several shapes: PyBullet's is the nearest
            for links, distance in zip(mine.links, mine.distance):
                nearest[links] = min(nearest.get(links, np.inf), distance)
            for links, distance in nearest.items():
                assert distance == pytest.approx(truth[links], abs=2e-3), links
            # a joint's reach on a pair, whichever way its normal turns, bounds its rate along the normal
            assert np.all(np.abs(mine.rate_jacobian) <= mine.lever + 1e-12)
            # ḋ = j q̇ + j_b (vx, vy, ω), the base's twist in its own frame
            qd, twist = rng.normal(size=q.size), rng.normal(size=3)
            world = twist_to_world(base[2], twist)
            ahead, behind = (model.within(q + s * h * qd, 2.0, base + s * h * world)[0] for s in (1, -1))
            for k, shapes in enumerate(mine.shapes):
                rate = (ahead.distance[ahead.shapes.index(shapes)] - behind.distance[behind.shapes.index(shapes)]) / (
                    2 * h
                )
                assert mine.rate_jacobian[k] @ qd + mine.base_jacobian[k] @ twist == pytest.approx(rate, abs=1e-4), (
                    shapes
                )


def test_distances_asked_again_follow_new_obstacles_and_a_moved_base():
    """A method asks for the distances twice a period (eq (14)'s compensation), and the second
    answer is the first one again: obstacles set meanwhile, or another base pose, are a new
    question."""
    model = CollisionModel.from_robot(load_robot('mecanum'))
    q = np.array(load_robot('mecanum').start.arm)
    base = np.zeros(3)
    first = model.within(q, 1.0, base)[0]
    assert model.within(q, 1.0, base)[0].links == first.links
    assert not any('pillar' in links for links in first.links)
    model.set_obstacles(
        parse_obstacles([{'name': 'pillar', 'shape': 'cylinder', 'size': [0.1, 2.0], 'pose': [0.9, 0.0, 0.0]}], 't')
    )

    def to_pillar(base_pose):
        near = model.within(q, 1.0, base_pose)[0]
        return {links: d for links, d in zip(near.links, near.distance) if 'pillar' in links}

    near = to_pillar(base)
    assert near
    moved = to_pillar(base + [0.2, 0.0, 0.0])
    for links, distance in moved.items():
        assert distance == pytest.approx(near[links] - 0.2, abs=0.05)


@pytest.mark.parametrize('name', ['steerable', 'mecanum'])
def test_robot_pairs_come_within_their_own_reach_and_the_closest_distance_is_kept(name):
    """The safety stage looks metres ahead at obstacles for a lagging base but only its arm's
    look-ahead at the robot's own pairs: asked with that shorter reach for the pairs without an
    obstacle, the answer holds the same obstacle pairs at the same distances, the robot's pairs
    within that reach only, and the same closest distance."""
    robot = load_robot(name)
    obstacles = load_obstacles('table_pillar')
    names = {o.name for o in obstacles}
    model = CollisionModel.from_robot(robot, obstacles=obstacles)
    rng = np.random.default_rng(5)
    left_out = 0
    for _ in range(10):
        q = np.array(robot.start.arm) + rng.uniform(-0.5, 0.5, len(robot.start.arm))
        base = rng.uniform((0.2, -1.6, -np.pi), (2.8, 1.6, np.pi))
        every, closest, pair = model.within(q, 3.0, base)
        asked, closest_asked, pair_asked = model.within(q, 3.0, base, robot_influence=0.3)
        assert closest_asked == pytest.approx(closest, abs=1e-6) and pair_asked == pair
        kept = [k for k, links in enumerate(every.links) if names & set(links) or every.distance[k] < 0.3]
        left_out += len(every) - len(kept)
        assert asked.shapes == tuple(every.shapes[k] for k in kept)
        np.testing.assert_allclose(asked.distance, every.distance[kept], atol=1e-6)
        # (their rows are those pairs' rows: a face against a face has many nearest points, and
        # GJK, started from its last answer, may pick another one each time it is asked)
        assert asked.rate_jacobian.shape == (len(kept), len(q)) and asked.base_jacobian.shape == (len(kept), 3)
    assert left_out, 'some robot pair between 0.3 and 3 m'


def test_a_base_driving_at_an_obstacle_is_slowed_to_what_it_can_brake():
    robot = load_robot('mecanum')
    # its base brakes at 0.025 m/s² per axis, of which the turn may take a quarter: 3.33 m from
    # full speed on the diagonal (0.25 m/s on each axis)
    pillar = parse_obstacles(
        [{'name': 'pillar', 'shape': 'cylinder', 'size': [0.1, 2.0], 'pose': [0.9, 0.0, 0.0]}], 'test'
    )
    stage = SafetyStage.for_robot(robot)
    stage.set_obstacles(pillar)
    assert stage.obstacle_lookahead == pytest.approx(0.02 + 2 * 0.25**2 / (2 * 0.75 * 0.025))
    q = np.array(robot.start.arm)
    n = q.size
    command = np.concatenate(([0.25, 0.0, 0.0], np.zeros(n)))  # full speed ahead, the arm still
    box = np.concatenate((robot.base.velocity, robot.arm.velocity))
    out = stage.filter(q, command, -box, box, base_pose=np.zeros(3), base_axes=(0, 1, 2))
    assert out.changed
    # the base's front is about half a metre from the pillar: braking at 0.025 m/s² stops from
    # √(2 · 0.025 · (d − d_s)) ≈ 0.15 m/s at most (the arm, nearer, can pull back faster)
    within, _, _ = stage.collision.within(q, 2.0, np.zeros(3))
    nearest = min(
        d
        for d, links, j in zip(within.distance, within.links, within.rate_jacobian)
        if 'pillar' in links and not j.any()
    )
    assert 0.4 < nearest < 0.6
    assert 0.0 < out.command[0] <= np.sqrt(2 * 0.025 * (nearest - 0.02)) + 1e-6
    away = stage.filter(q, -command, -box, box, base_pose=np.zeros(3), base_axes=(0, 1, 2))
    assert not away.changed, 'backing away passes'
    # the same base behind the pillar's far side (turned round) is not held back
    far = stage.filter(q, command, -box, box, base_pose=np.array([2.0, 0.0, 0.0]), base_axes=(0, 1, 2))
    assert not far.changed


@pytest.mark.parametrize('pose, twist', [((0.0, 0.0, 0.0), (0.2, 0.0, 0.0)), ((0.5, 0.0, 0.0), (0.15, 0.0, 0.0))])
def test_the_arm_alone_is_let_through_what_the_whole_command_was_with_the_base_at_its_twist(pose, twist):
    """Eq (14)'s call: the base controller has answered with the twist the stage let through,
    and only the arm is left to choose. Robot B drives at the table within its look-ahead (its
    base brakes at 0.025 m/s², so that reaches metres): the arm command the stage let through
    with that twist passes again unchanged. (Counting on the arm alone to brake the pairs the
    base carries, the stage allowed the arm's first links no approach at all and drove joint 1
    to the edge of its box, period after period: task sharing wound the arm round its shoulder
    while following a plan past the table.)"""
    robot = load_robot('mecanum')
    stage = SafetyStage.for_robot(robot, obstacles=load_obstacles('table_pillar'))
    q, pose = np.array(robot.start.arm), np.array(pose)
    limits = CommandLimits.for_robot(robot, robot.period)
    command = np.concatenate((twist, np.zeros(q.size)))
    lower, upper, _ = limits.box(np.concatenate((np.zeros(3), q)), command)
    whole = stage.filter(q, command, lower, upper, base_pose=pose, base_axes=(0, 1, 2), base_velocity=np.array(twist))
    base, arm = whole.command[:3], whole.command[3:]
    assert base[0] > 0.1, 'the base drives on at the table, braking as it can'
    alone = stage.filter(q, arm, lower[3:], upper[3:], base_pose=pose, base_twist=base)
    np.testing.assert_allclose(alone.command, arm, atol=1e-9)


@pytest.mark.parametrize('method, index', [('task_sharing', 1), ('amp', 6)])
def test_robot_a_turning_past_the_table_keeps_off_it(method, index):
    """Robot A's base lags its reference and turns on while it does. Two randomized
    runs (``table_pillar``, seed 0) in which it swung into the table as it turned past a corner:
    ``task_sharing`` goal 1 (its reference in the base's frame: the chassis 6.7 cm into the
    table) and ``amp`` goal 6 (in the world frame: a wheel 3.7 cm in). The stage now holds the
    reference to the rows the base will see after the turn it cannot stop at once, and the turn
    to the linear path the base is still on. No period in contact, and the run ends converged
    or reported stalled."""
    goal = sample_goals('steerable', index + 1, seed=0, obstacles='table_pillar')[index]
    out = run_goal('steerable', method, goal, obstacles='table_pillar')
    assert out['contact_depth_m'] <= CONTACT_DEPTH, (out['contact_pair'], out['contact_depth_m'])
    assert out['outcome'] in ('converged', 'reported'), out['why']


def test_robot_a_re_steering_beside_the_table_keeps_off_it():
    """``amp`` goal 7 of the randomized draw (``table_pillar``, seed 0): robot A drives past the
    table's near face while its wheels steer from one ICR to another, and its twist grows along
    their heading, not the reference's. Counted as a lag of 1/K_p alone, its approach overtook
    the rows 0.17 m from the table and a wheel went 5 mm into it; with the ICR controller's lag
    in series (1/K_p + 1/λ) no period is in contact, and the run ends converged or reported
    stalled."""
    goal = sample_goals('steerable', 8, seed=0, obstacles='table_pillar')[7]
    out = run_goal('steerable', 'amp', goal, obstacles='table_pillar')
    assert out['contact_depth_m'] <= CONTACT_DEPTH, (out['contact_pair'], out['contact_depth_m'])
    assert out['outcome'] in ('converged', 'reported'), out['why']


def test_robot_a_crept_up_to_the_table_is_taken_away_from_it():
    """``pinv`` goal 24 of the randomized draw (``table_pillar``, seed 0): robot A stops with its
    chassis at the table, inside the safety distance, and crawls at about 1 mm/s. Held to its
    own path (s v₀) no faster backwards than it came (s ≥ −1), the reference could not take it
    away faster than it crept: the chassis crept 8 mm into the table over a minute. Sent back
    along its path as fast as the pair must separate, no period is in contact, and the run ends
    converged or reported stalled."""
    goal = sample_goals('steerable', 25, seed=0, obstacles='table_pillar')[24]
    out = run_goal('steerable', 'pinv', goal, obstacles='table_pillar')
    assert out['contact_depth_m'] <= CONTACT_DEPTH, (out['contact_pair'], out['contact_depth_m'])
    assert out['outcome'] in ('converged', 'reported'), out['why']


def test_robot_a_spinning_beside_the_pillar_keeps_its_margin_off_it():
    """``task_sharing`` goal 38 of the randomized draw (``table_pillar``, seed 0): robot A spins
    at up to 0.58 rad/s beside the pillar while its wheels steer from one ICR to another; its
    chassis approached the pillar faster and faster for 0.3 s while its reference asked it away,
    and went 5.2 mm in with its body held to d_s alone. A lag of τ on each axis does not
    describe that sweep; the body keeps ``collision_lag_margin`` more, and no period is in
    contact."""
    goal = sample_goals('steerable', 100, seed=0, obstacles='table_pillar')[38]
    out = run_goal('steerable', 'task_sharing', goal, obstacles='table_pillar')
    assert out['contact_depth_m'] <= CONTACT_DEPTH, (out['contact_pair'], out['contact_depth_m'])
    assert out['outcome'] in ('converged', 'reported'), out['why']


def test_a_lagging_base_already_too_fast_for_an_obstacle_is_braked_along_its_own_path():
    """Robot A's base follows its reference with a lag of 1/K_p + 1/λ = 0.75 s (its ICR, then its
    twist; :func:`~wmm_control.resolvers.safety.base_lag`). Its reference is held to
    what it can stop from after that lag; and where its measured twist is already too fast (it
    lagged, or its wheels swept round while it changed its ICR), it is sent a twist on its own
    path, slower, whatever the method asked."""
    robot = load_robot('steerable')
    table = parse_obstacles(
        [{'name': 'table', 'shape': 'box', 'size': [0.5, 1.2, 0.8], 'pose': [0.9, 0.0, 0.0]}], 'test'
    )
    stage = SafetyStage.for_robot(robot)
    stage.set_obstacles(table)
    tau = stage.base_lag
    assert tau == pytest.approx(1.0 / 2.0 + 1.0 / 4.0)  # K_p = 2 /s (Sorour Table I), λ = 4 /s
    speed = math.sqrt(2.0)  # 1 m/s on each linear axis
    margin = stage.params.collision_lag_margin  # the room its body keeps beyond d_s
    assert stage.obstacle_lookahead == pytest.approx(0.02 + margin + speed * tau + speed**2 / (2 * 0.5))
    q = np.array(robot.start.arm)
    box = np.concatenate((robot.base.velocity, robot.arm.velocity))
    pose = np.zeros(3)
    within, _, _ = stage.collision.within(q, 2.0, pose)
    near = within.distance[within.base_jacobian.any(axis=1)].min()
    assert 0.2 < near < 0.4
    allowed = 0.5 * (np.sqrt(tau**2 + 2 * (near - 0.02) / 0.5) - tau)  # after the lag
    assert allowed < np.sqrt(2 * 0.5 * (near - 0.02)) - 0.1  # well below the rows without it
    command = np.concatenate(([0.6, 0.0, 0.0], np.zeros(q.size)))  # the method's: at the table
    slow = stage.filter(
        q, command, -box, box, base_pose=pose, base_axes=(0, 1, 2), base_velocity=np.array([0.05, 0.0, 0.0])
    )
    assert slow.changed and 0.0 < slow.command[0] <= allowed + 1e-6
    # measured at 0.5 m/s, sideways and turning (not the method's direction): the base is sent a
    # twist along its own, slower, while the method asked for the table at 0.6 m/s
    measured = np.array([0.5, 0.2, 0.3])
    fast = stage.filter(q, command, -box, box, base_pose=pose, base_axes=(0, 1, 2), base_velocity=measured)
    assert fast.changed
    base = fast.command[:3]
    scale = base @ measured / (measured @ measured)
    np.testing.assert_allclose(base, scale * measured, atol=1e-12)
    assert scale < 0.7
    # without a lag (a wheeled base) the same call only holds the reference to its rows
    wheeled = SafetyStage(
        stage.collision, stage.params, robot.arm.acceleration, robot.base.velocity, robot.base.acceleration
    )
    plain = wheeled.filter(q, command, -box, box, base_pose=pose, base_axes=(0, 1, 2), base_velocity=measured)
    assert plain.command[0] > allowed and abs(plain.command[1]) < 0.05


def test_an_obstacle_is_looked_at_from_where_the_dampers_let_the_base_on_at_full_speed():
    """The stage looks as far as the pair at which its dampers first let the base approach at
    full speed (its diagonal): nearer, they slow it; with and without the base's lag."""
    for name, lag in (('steerable', None), ('steerable', 0.0), ('mecanum', None)):
        robot = load_robot(name)
        stage = SafetyStage.for_robot(robot)
        if lag is not None:
            stage.set_base_lag(lag)
        dampers = stage.dampers
        speed = math.hypot(*robot.base.velocity[:2])
        distance = stage.obstacle_lookahead - stage.body_margin
        _, brake = dampers.linear_braking(robot.base.axes)
        assert dampers.allowed_approach(distance, brake, stage.base_lag) == pytest.approx(speed)
        assert dampers.allowed_approach(0.9 * distance, brake, stage.base_lag) < 0.95 * speed


def test_a_slow_braking_base_is_not_let_on_at_an_obstacle_because_its_turn_swings_a_corner_away():
    """Robot B brakes at 0.025 m/s² along x and y, but turns at 1.5 rad/s². Driving at a pillar
    beside its front corner faster than it can stop from, while turning, the turn keeps the
    distance's rate within the row for the moment; the stage must brake the linear approach
    anyway, as hard as the base's acceleration box allows."""
    robot = load_robot('mecanum')
    pillar = parse_obstacles(
        [{'name': 'pillar', 'shape': 'cylinder', 'size': [0.06, 3.0], 'pose': [0.65, -0.4, 0.0]}], 'test'
    )
    stage = SafetyStage.for_robot(robot)
    stage.set_obstacles(pillar)
    q, pose = np.array(robot.start.arm), np.zeros(3)
    twist = np.array([0.185, 0.1, -0.3])  # the base's twist now
    step = np.asarray(robot.base.acceleration) * robot.period
    arm = np.asarray(robot.arm.velocity)
    lower, upper = np.concatenate((twist - step, -arm)), np.concatenate((twist + step, arm))
    within, _, _ = stage.collision.within(q, stage.obstacle_lookahead, pose)
    body = np.flatnonzero(within.base_jacobian.any(axis=1) & ~within.rate_jacobian.any(axis=1))  # chassis, wheels
    k = body[np.argmin(within.distance[body])]
    j, distance = within.base_jacobian[k], within.distance[k]
    slowest = float(np.min(robot.base.acceleration[:2]))
    # the linear approach is beyond what the base can stop from; with the turn, the row holds
    assert j[:2] @ twist[:2] < -stage.dampers.allowed_approach(distance, np.linalg.norm(j[:2]) * slowest)
    assert j @ twist >= -stage.dampers.allowed_approach(distance, np.linalg.norm(j[:2]) * slowest)
    out = stage.filter(q, np.concatenate((twist, np.zeros(q.size))), lower, upper, base_pose=pose, base_axes=(0, 1, 2))
    assert out.changed
    braked = j[:2] @ out.command[:2] - j[:2] @ twist[:2]
    assert braked >= 0.99 * np.abs(j[:2]) @ step[:2]


def test_a_goal_inside_an_obstacle_is_impossible():
    model = KinematicModel('steerable')
    workspace = Workspace(model)
    table = load_obstacles('table_pillar')
    assert 'inside the obstacle \'table\'' in workspace.impossible([1.5, 0.0, 0.3], None, table)
    assert workspace.impossible([1.5, 0.0, 0.9], None, table) == ''


def _marker(
    kind,
    action=Marker.ADD,
    frame='world',
    marker_id=0,
    scale=(0.2, 0.2, 0.2),
    position=(1.0, 0.0, 0.5),
    quat=(0.0, 0.0, 0.0, 1.0),
):
    m = Marker()
    m.header.frame_id = frame
    m.ns, m.id, m.type, m.action = 'test', marker_id, kind, action
    m.scale.x, m.scale.y, m.scale.z = scale
    m.pose.position.x, m.pose.position.y, m.pose.position.z = position
    m.pose.orientation.x, m.pose.orientation.y, m.pose.orientation.z, m.pose.orientation.w = quat
    return m


def test_markers_add_replace_and_delete_obstacles_and_bad_ones_are_rejected():
    obstacles = ObstacleSet('table_pillar', 'world')
    fixed = len(obstacles.obstacles)
    applied = obstacles.apply(
        MarkerArray(
            markers=[
                _marker(Marker.CUBE, scale=(0.4, 0.6, 0.8)),
                _marker(Marker.SPHERE, marker_id=1),
                _marker(Marker.CYLINDER, marker_id=2, scale=(0.3, 0.3, 1.0)),
                _marker(Marker.ARROW, marker_id=3),
                _marker(Marker.CUBE, marker_id=4, frame='map'),
                _marker(Marker.CUBE, marker_id=5, quat=(0.0, 0.0, 0.0, 0.0)),
                _marker(Marker.SPHERE, marker_id=6, scale=(float('nan'), 0.1, 0.1)),
            ]
        )
    )
    assert applied.changed and len(obstacles.obstacles) == fixed + 3
    errors = applied.rejected
    assert len(errors) == 4 and 'not an obstacle' in errors[0] and "'map'" in errors[1]
    box, ball, post = obstacles.obstacles[fixed:]
    assert (box.shape, box.size, ball.size, post.size) == ('box', (0.4, 0.6, 0.8), (0.1,), (0.15, 1.0))
    assert obstacles.apply(MarkerArray(markers=[_marker(Marker.SPHERE, marker_id=1)])) == Applied(False)
    applied = obstacles.apply(MarkerArray(markers=[_marker(Marker.SPHERE, Marker.DELETE, marker_id=1)]))
    assert applied.changed and len(obstacles.obstacles) == fixed + 2
    obstacles.apply(MarkerArray(markers=[_marker(Marker.SPHERE, Marker.DELETEALL)]))
    assert len(obstacles.obstacles) == fixed, 'the file\'s obstacles stay'


NAN = float('nan')


@pytest.mark.parametrize(
    'kind, changes, reason',
    [
        (Marker.CUBE, {'scale': (NAN, 0.2, 0.2)}, 'scale [nan, 0.2, 0.2] must be finite and > 0'),
        # max() of the diameters would pass over a NaN or a negative entry that is not the first
        (Marker.SPHERE, {'scale': (0.2, NAN, 0.2)}, 'must be finite and > 0'),
        (Marker.CYLINDER, {'scale': (0.2, 0.2, -1.0)}, 'must be finite and > 0'),
        (Marker.SPHERE, {'scale': (0.2, -0.3, 0.2)}, 'must be finite and > 0'),
        (Marker.CUBE, {'scale': (0.2, 0.0, 0.2)}, 'must be finite and > 0'),
        (Marker.CUBE, {'scale': (0.2, float('inf'), 0.2)}, 'must be finite and > 0'),
        (Marker.CUBE, {'scale': (1e308, 1.0, 1.0)}, 'at most 1000'),
        (Marker.SPHERE, {'scale': (1e5, 1e5, 1e5)}, 'at most 1000'),
        (Marker.CUBE, {'position': (1e15, 0.0, 0.5)}, 'within ±1000 m'),
        (Marker.CUBE, {'position': (0.0, NAN, 0.5)}, 'position must be 3 finite numbers'),
        (Marker.CUBE, {'quat': (0.0, 0.0, 0.0, 0.0)}, 'finite, non-zero quaternion'),
        (Marker.CUBE, {'quat': (0.0, 0.0, NAN, 1.0)}, 'finite, non-zero quaternion'),
        (Marker.CUBE, {'frame': 'map'}, "frame 'map', expected 'world'"),
        (Marker.CUBE, {'frame': ''}, "frame '', expected 'world'"),
        (Marker.ARROW, {}, 'type 0 is not an obstacle'),
        (42, {}, 'type 42 is not an obstacle'),
    ],
)
def test_a_bad_marker_is_rejected_with_its_reason(kind, changes, reason):
    with pytest.raises(ConfigError, match=re.escape(reason)):
        obstacle_from_marker(_marker(kind, marker_id=7, **changes), 'world')


def test_a_quaternion_off_unit_norm_is_normalised_with_a_note_and_the_obstacle_kept():
    """Dropping the obstacle would leave the robot free to drive into it; the pose is what the
    publisher meant up to the norm (a goal's quaternion is taken the same way)."""
    half = math.sqrt(0.5)
    obstacle, note = obstacle_from_marker(_marker(Marker.CUBE, quat=(0.0, 0.0, 2 * half, 2 * half)), 'world')
    assert note == 'marker test/0: quaternion has norm 2: normalised'
    np.testing.assert_allclose(obstacle.rotation, [[0, -1, 0], [1, 0, 0], [0, 0, 1]], atol=1e-12)
    _, note = obstacle_from_marker(_marker(Marker.CUBE, quat=(0.0, 0.0, 0.0, 1.0 + 1e-4)), 'world')
    assert note == ''  # round-off: not worth a warning


class _Log:
    """A node logger's warn and info, recorded."""

    def __init__(self):
        self.warnings, self.infos = [], []

    def warn(self, message, throttle_duration_sec=None):
        assert throttle_duration_sec, 'every warning about /obstacles is throttled'
        self.warnings.append(message)

    def info(self, message):
        self.infos.append(message)


def test_an_empty_or_oversized_message_is_refused_with_a_warning_and_the_obstacles_stay():
    obstacles = ObstacleSet('table_pillar', 'world')
    log = _Log()
    assert obstacles.take(MarkerArray(markers=[_marker(Marker.CUBE, marker_id=1)]), log, 3)
    kept = obstacles.obstacles
    assert not obstacles.take(MarkerArray(), log, 3)
    assert log.warnings == ['ignored an empty /obstacles message: nothing to add or remove']
    # four markers over a limit of three: none applied, not even the DELETEALL among them
    four = [_marker(Marker.SPHERE, marker_id=i) for i in (2, 3, 4)] + [_marker(Marker.CUBE, Marker.DELETEALL)]
    assert not obstacles.take(MarkerArray(markers=four), log, 3)
    assert log.warnings[1] == (
        'rejected /obstacles: 4 markers, more than max_obstacles 3; the obstacles stay as they were'
    )
    assert len(obstacles.obstacles) == len(kept) and all(a is b for a, b in zip(obstacles.obstacles, kept))
    # at the limit it is taken
    assert obstacles.take(MarkerArray(markers=four[:3]), log, 3)
    assert len(obstacles.obstacles) == len(kept) + 3 and log.infos[-1].startswith('now 6 obstacles')


def test_the_rejected_markers_of_a_message_make_one_warning_naming_the_first_three():
    obstacles = ObstacleSet('', 'world')
    log = _Log()
    bad = [_marker(Marker.CUBE, marker_id=i, scale=(NAN, 1.0, 1.0)) for i in range(5)]
    good = _marker(Marker.CUBE, marker_id=9, quat=(0.0, 0.0, 0.0, 3.0))
    assert obstacles.take(MarkerArray(markers=[*bad, good]), log, 200)
    rejected, normalised = log.warnings
    assert rejected.startswith('rejected /obstacles marker test/0: scale [nan, 1.0, 1.0]')
    assert 'marker test/2' in rejected and 'marker test/3' not in rejected and rejected.endswith('(and 2 more markers)')
    assert normalised == '/obstacles marker test/9: quaternion has norm 3: normalised'
    assert [o.name for o in obstacles.obstacles] == ['test/9']


def test_every_node_that_takes_obstacles_declares_max_obstacles_with_the_same_default():
    from sim_bridge.node_params import PARAMS as SIM
    from wmm_control.nodes.goal_planner_params import PARAMS as PLANNER
    from wmm_control.nodes.parameters import load_defaults
    from wmm_control.nodes.redundancy_resolver_params import PARAMS as RESOLVER
    from wmm_control.nodes.viewer_params import PARAMS as VIEWER

    defaults = {}
    for node, params in {
        'wmm_sim': SIM,
        'redundancy_resolver': RESOLVER,
        'goal_planner': PLANNER,
        'wmm_viewer': VIEWER,
    }.items():
        names = [spec.name for spec in params]
        assert 'obstacles' in names and 'max_obstacles' in names, node
        defaults[node] = load_defaults(f'{node}.yaml', node)['max_obstacles']
    assert len(set(defaults.values())) == 1, defaults


def test_the_nodes_take_obstacles_live_reject_goals_inside_them_and_the_simulator_reports_contact():
    ros = RosHarness()
    try:
        resolver = ros.add(
            RedundancyResolverNode(context=ros.context, parameter_overrides=overrides(diagnostics_period=1e-9))
        )
        sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(diagnostics_period=0.05)))
        driver = ros.add(Node('obstacle_driver', context=ros.context))
        pub = driver.create_publisher(MarkerArray, '/obstacles', 10)
        goals = driver.create_publisher(PoseStamped, '/goal_pose', 10)
        reports = []
        driver.create_subscription(
            DiagnosticArray,
            '/diagnostics',
            lambda m: reports.extend(
                {kv.key: kv.value for kv in s.values} | {'level': s.level}
                for s in m.status
                if s.name.endswith('obstacles')
            ),
            10,
        )
        # a box over the robot's arm: the simulator reports the contact
        pub.publish(MarkerArray(markers=[_marker(Marker.CUBE, scale=(0.3, 0.3, 0.3), position=(0.6, 0.0, 1.0))]))
        assert ros.spin_until(
            lambda: len(resolver.obstacles.obstacles) == 1 and len(sim.world.obstacles) == 1 and reports, timeout=20.0
        )
        assert ros.spin_until(lambda: any(r['contact_periods'] != '0' for r in reports), timeout=20.0)
        last = reports[-1]
        assert float(last['clearance_m']) < 0.0 and last['closest_obstacle'] == 'test/0' and last['level'] == b'\x02'
        goal = PoseStamped()
        goal.header.frame_id = 'world'
        goal.pose.position.x, goal.pose.position.z, goal.pose.orientation.w = 0.6, 1.0, 1.0
        goals.publish(goal)
        assert ros.spin_until(lambda: resolver.counters['goals_rejected'] == 1, timeout=10.0)
        assert resolver.target is None
    finally:
        ros.close()


def test_a_recorded_run_holds_the_documented_arrays(tmp_path):
    goal = sample_goals('steerable', 1, seed=0, obstacles='table_pillar')[0]
    out = run_goal('steerable', 'pinv', goal, duration=1.0, obstacles='table_pillar', record=tmp_path)
    data = np.load(tmp_path / 'steerable_pinv_0.npz')
    k = len(data['t'])
    assert k == 40 and out['contact_depth_m'] == 0.0
    names = list(data['joint_names'])
    robot = load_robot('steerable')
    assert names[:7] == list(robot.arm.joints) and 'steer_fl_joint' in names and data['q'].shape == (k, len(names))
    assert data['base_pose'].shape == (k, 3) and np.all(np.isfinite(data['q']))
    np.testing.assert_allclose(data['q'][0, :7], robot.start.arm)
    assert 'pillar' in str(data['obstacles']) and data['goal_pose'].shape == (6,)


@pytest.mark.parametrize('method', ['pinv', 'task_sharing', 'amp', 'traditional'])
def test_table_reach_every_method_reaches_over_the_table_or_reports_a_stall_without_touching_it(method):
    scenario = load_scenario('table_reach')
    goal = RandomGoal(0, np.zeros(3), np.zeros(7), scenario.goals[0].pose, 1)
    out = run_goal(scenario.robot, method, goal, obstacles=scenario.obstacles_file)
    assert out['contact_depth_m'] == 0.0, out['contact_pair']
    # the straight way runs through the table's near edge: the stage kept the robot off it
    assert out['outcome'] == ('reported' if method == 'task_sharing' else 'converged'), out['why']


def _drive(stage, pose, twist, q, want, seconds):
    """Robot B's stage in closed loop on its own commands: the base from ``pose`` (x, y, θ) at
    ``twist`` (base frame), the arm at ``q``, and a method that asks for ``want`` throughout.
    The base follows its reference within its acceleration limits; returns the closest any
    pair came [m]."""
    robot = load_robot('mecanum')
    dt = robot.period
    pose, twist, q = (np.array(v, dtype=float) for v in (pose, twist, q))
    step, limit = np.asarray(robot.base.acceleration) * dt, np.asarray(robot.base.velocity)
    arm_step, arm_limit = np.asarray(robot.arm.acceleration) * dt, np.asarray(robot.arm.velocity)
    dq, closest = np.zeros(q.size), np.inf
    for _ in range(round(seconds / dt)):
        lower = np.concatenate((np.maximum(twist - step, -limit), np.maximum(dq - arm_step, -arm_limit)))
        upper = np.concatenate((np.minimum(twist + step, limit), np.minimum(dq + arm_step, arm_limit)))
        out = stage.filter(
            q, np.clip(want, lower, upper), lower, upper, base_pose=pose, base_axes=(0, 1, 2), base_velocity=twist
        )
        twist, dq = out.command[:3], out.command[3:]
        pose = pose + dt * twist_to_world(pose[2], twist)
        q = q + dt * dq
        closest = min(closest, stage.collision.closest(q, pose)[0])
    return closest


def _drive_past_the_table(stage, seconds=12.0):
    """The base at (2.41, −0.61, −1.26) beside the table of ``table_pillar``, driving at
    (0.11, −0.17) m/s, and a method that asks for (0.16, −0.13) m/s and a turn of −0.45 rad/s
    throughout, the arm still (:func:`_drive`)."""
    q = np.array([-1.0823, -2.1645, 2.1069, -1.6751, -0.0515, 1.0037, 1.2814])
    want = np.concatenate(([0.16, -0.13, -0.45], np.zeros(q.size)))
    return _drive(stage, [2.4094, -0.6065, -1.2613], [0.1125, -0.1663, -0.1594], q, want, seconds)


def test_a_base_spinning_on_a_diagonal_is_braked_before_an_obstacle_it_swings_round_to():
    """Robot B spinning at −1 rad/s while it drives at (−0.25, 0.19) m/s (0.31 m/s, faster than
    either axis's limit) swings its path round onto the table. From that speed it needs 2.6 m
    to stop at the deceleration the stage counts on; looking out only as far as one axis at
    full speed stops (1.27 m), the stage saw the table too late and the base went into it (a
    randomized run found it: a wheel 9.9 cm into the table). The state is that run's at 33 s."""
    robot = load_robot('mecanum')
    stage = SafetyStage.for_robot(robot, obstacles=load_obstacles('table_pillar'))
    assert stage.obstacle_lookahead == pytest.approx(0.02 + 2 * 0.25**2 / (2 * 0.75 * 0.025))
    q = np.array([0.2218, 2.1623, 0.4481, -0.9595, 0.918, 0.0046, 0.6831])
    want = np.concatenate(([-0.25, 0.19, -1.0], np.zeros(q.size)))
    closest = _drive(stage, [-0.4408, -0.3569, 0.1606], [-0.193, 0.135, -0.449], q, want, seconds=30.0)
    assert closest >= stage.params.collision_safety - 1e-3


def test_a_wrist_spun_at_full_rate_near_a_wall_is_braked_before_its_turn_swings_the_gripper_into_it():
    """Robot B's ``pinv`` on ``doorway`` goal 7 (a randomized run, under an earlier stance rule)
    spun wrist joints 5–7 at about their full 3.14 rad/s 9.7 cm from the wall. Braking from
    there, each turns about 1 rad, and the gripper's nearest point, 0.05–0.15 m from their
    axes, swung round onto the wall at 0.3–0.44 m/s within 0.3 s: the rows on the distance's
    first-order rate saw it too late, and the gripper went 2.8 cm in. That period's state:
    the stage now brakes every wrist joint as hard as its box allows, where it let them speed
    up to the full rate, and says the arm's stopping turn is what binds."""
    robot = load_robot('mecanum')
    stage = SafetyStage.for_robot(robot, obstacles=load_obstacles('doorway'))
    q = np.array([-4.0935, -2.2, -27.2361, -2.5, -32.4044, -0.5359, -4.1634])
    command = np.array([0.0335, -0.0101, 0.1659, 0.0956, 0.0101, 1.5201, 0.001, -3.015, -2.7607, -3.0261])
    lower = np.array([0.033, -0.0114, 0.1385, 0.0709, -0.0, 1.5007, -0.0, -3.14, -3.0028, -3.14])
    upper = np.array([0.0342, -0.0101, 0.2135, 0.2209, 0.0657, 1.6507, 0.075, -3.015, -2.7528, -3.015])
    target = np.concatenate(([0.0004, -0.0035, 1.0], command[3:]))
    out = stage.filter(
        q,
        command,
        lower,
        upper,
        base_pose=np.array([2.016, 0.6118, 1.602]),
        base_axes=(0, 1, 2),
        base_velocity=np.array([0.0336, -0.0107, 0.176]),
        target=target,
    )
    wrist = slice(7, 10)
    np.testing.assert_allclose(out.command[wrist], upper[wrist], atol=1e-6)
    assert out.binding()['arm stopping'] >= 1


def test_a_slow_braking_base_does_not_turn_its_path_into_a_table_it_drives_past():
    """Turning at ω while driving at v turns a base's velocity in the world at v ω: towards the
    table, faster than robot B's linear axes brake (0.025 m/s²), the chassis went 3.8 cm into
    it (a randomized run found it). The stage lets the turn bend the path towards an obstacle
    by no more than a share of the linear braking, so every pair stays at d_s."""
    robot = load_robot('mecanum')
    stage = SafetyStage.for_robot(robot, obstacles=load_obstacles('table_pillar'))
    assert _drive_past_the_table(stage) >= stage.params.collision_safety - 1e-3


def test_the_stage_brakes_the_base_with_the_lag_of_the_controller_the_cycle_runs():
    """Robot A 0.7 m before the table, driving at it at 0.8 m/s: with Table I's gains (τ = 1/K_p
    + 1/λ = 0.75 s) the stage lets it go on at a crawl; with a controller ten times as quick (τ =
    0.1 s) it may go on much faster, and each stage answers as one built with that lag."""
    robot = load_robot('steerable')
    obstacles = load_obstacles('table_pillar')
    n = len(robot.arm.joints)
    command = np.concatenate(([0.8, 0.0, 0.0], np.zeros(n)))
    box = np.concatenate(([1.0, 1.0, 1.0], np.ones(n)))
    forward = {}
    for kp, icr_gain in ((2.0, 4.0), (20.0, 20.0)):
        resolver = make_resolver('pinv', robot)
        resolver.set_obstacles(obstacles)
        Cycle(resolver, make_base_controller(robot, robot.period, kp=kp, icr_gain=icr_gain), robot.period)
        stage = resolver.safety
        assert stage.base_lag == pytest.approx(1.0 / kp + 1.0 / icr_gain)
        args = (np.array(robot.start.arm), command, -box, box)
        kwargs = dict(base_pose=np.array([0.55, -0.2, 0.0]), base_axes=(0, 1, 2), base_velocity=np.array([0.8, 0, 0]))
        answer = stage.filter(*args, **kwargs)
        alone = SafetyStage.for_robot(robot, resolver.params, obstacles)
        alone.set_base_lag(1.0 / kp + 1.0 / icr_gain)
        np.testing.assert_allclose(alone.filter(*args, **kwargs).command, answer.command, atol=1e-9)
        forward[kp] = answer.command[0]
    assert forward[2.0] < 0.2 < 0.4 < forward[20.0] <= 0.8


def test_the_resolver_node_takes_the_running_base_controllers_lag():
    """swmr_controller started with other gains publishes its τ (latched); a resolver started
    after it brakes the base with that τ, not with the robot YAML's defaults."""
    ros = RosHarness()
    try:
        ros.add(SwmrControllerNode(context=ros.context, parameter_overrides=overrides(kp=8.0, icr_gain=10.0)))
        ros.spin_for(0.2)
        resolver = ros.add(RedundancyResolverNode(context=ros.context))
        assert resolver.resolver.safety.base_lag == pytest.approx(0.75)  # the YAML's, until it hears
        assert ros.spin_until(lambda: resolver.resolver.safety.base_lag == pytest.approx(1.0 / 8.0 + 1.0 / 10.0))
        # a lag that is no time constant is rejected, and the last good one kept
        probe = ros.probe('lag_probe')
        publisher = probe.create_publisher(Float64, 'base/lag', LATCHED_QOS)
        for bad in (math.nan, -1.0, math.inf):
            publisher.publish(Float64(data=bad))
            ros.spin_for(0.1)
            assert resolver.resolver.safety.base_lag == pytest.approx(0.225)
    finally:
        ros.close()
