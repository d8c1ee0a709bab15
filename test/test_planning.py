"""The planner's ROS-free core: where to stand, a base path round the table (OMPL), timed.

Every plan is checked on its own terms and against the simulator's geometry (PyBullet,
:class:`~sim_bridge.collision.SelfCollisionChecker`), independently of the planner's distance
model: the stance's arm reaches the goal (forward kinematics), the robot keeps its margins there
and all along the path, and the timed path stays within the base's limits and ends at the stance.
"""

import dataclasses
import math
import time
from typing import ClassVar

import numpy as np
import pytest

from sim_bridge.collision import SelfCollisionChecker
from wmm_control.experiments.randomized import sample_goals
from wmm_control.geometry import matrix_from_rpy, rotation_angle, se2_integrate, twist_to_world, wrap_angle
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.collision import CollisionModel
from wmm_control.kinematics.obstacles import load_obstacles, parse_obstacles
from wmm_control.planning import BasePathPlanner, Clearance, GoalPlanner, NoWay, Travel, time_path
from wmm_control.robot_config import load_robot

OBSTACLES = load_obstacles('table_pillar')
NAMES = {o.name for o in OBSTACLES}
#: [m] how much nearer PyBullet's geometry may put the robot than the planner's (coal's)
ENGINES = 0.005
#: [s] a search budget no plan here comes near (they take under a second), so that a loaded
#: machine cuts none short
BUDGET = 30.0


@pytest.fixture(scope='module', params=['steerable', 'panda_diff'])
def planned(request):
    """(robot, planner, goal, plan) for the first table_pillar goal whose straight way is blocked."""
    cfg = load_robot(request.param)
    planner = GoalPlanner(cfg, OBSTACLES, budget=BUDGET)
    goals = sample_goals(cfg, 3, seed=0, obstacles='table_pillar')
    with SelfCollisionChecker(cfg, margin=planner.travel.margin, obstacles=OBSTACLES) as checker:
        for goal in goals:
            plan = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), cfg.start.base_pose)
            assert plan.no_way is None, plan.reason
            straight = [
                cfg.start.base_pose + s * (plan.stance.base_pose - cfg.start.base_pose) for s in np.linspace(0, 1, 60)
            ]
            if any(_obstacle_distances(checker, cfg.start.arm, pose) for pose in straight):
                return cfg, planner, goal, plan
    pytest.fail('no goal of the draw lies behind the table or the pillar')


def _obstacle_distances(checker, q_arm, base_pose):
    return [d for _a, b, d in checker.collisions(q_arm, base_pose) if b in NAMES]


def _nearest_along(cfg, travel, traj, obstacles=OBSTACLES):
    """``(sample, distance)``: the robot's distance from the nearest obstacle (PyBullet; inf
    beyond the travel margin), arm in the travel posture, as the base moves through each period:
    every point of the robot checked within 1 cm."""
    names = {o.name for o in obstacles}
    with SelfCollisionChecker(cfg, margin=travel.margin, obstacles=obstacles) as checker:
        for k, (pose, twist) in enumerate(zip(traj.poses[:-1], traj.twists[:-1])):
            sweep = (math.hypot(twist[0], twist[1]) + travel.radius * abs(twist[2])) * traj.dt
            steps = max(1, math.ceil(sweep / 0.01))
            for s in range(steps):
                at = se2_integrate(pose, twist, s * traj.dt / steps)
                near = [d for _a, b, d in checker.collisions(travel.q_arm, at) if b in names]
                yield k, min(near, default=math.inf)


def test_the_stance_reaches_a_goal_beyond_the_table_clear_of_everything(planned):
    cfg, planner, goal, plan = planned
    stance = plan.stance
    model = KinematicModel(cfg)
    model.update(stance.base_pose, stance.q_arm)
    position, rotation = model.ee_placement_world()
    assert np.linalg.norm(position - goal.pose[:3]) <= 0.005
    assert rotation_angle(matrix_from_rpy(goal.pose[3:]), rotation) <= 0.01
    lower, upper = cfg.arm.position_lower, cfg.arm.position_upper
    assert np.all((stance.q_arm >= lower) & (stance.q_arm <= upper))
    margin = planner.stances.params.stance_margin
    with SelfCollisionChecker(cfg, margin=margin - ENGINES, obstacles=OBSTACLES) as checker:
        assert not _obstacle_distances(checker, stance.q_arm, stance.base_pose)
    # the others come after it: ranked by their score (the robot's own pose is no stance here)
    scores = [s.score for s in plan.search.stances]
    assert scores == sorted(scores, reverse=True)


def test_the_base_path_keeps_the_margin_from_every_obstacle_all_along(planned):
    cfg, planner, _goal, plan = planned
    traj = plan.trajectory
    assert np.allclose(traj.poses[0], cfg.start.base_pose)
    assert np.array_equal(planner.travel.q_arm, cfg.start.arm)
    for k, distance in _nearest_along(cfg, planner.travel, traj):
        assert distance >= planner.travel.margin - ENGINES, f'{distance} m from an obstacle at {traj.poses[k]}'


def test_another_travel_posture_is_the_one_the_path_keeps_clear():
    """Panda's arm held out to its side while the base drives: a wider robot."""
    cfg = load_robot('panda_diff')
    planner = GoalPlanner(cfg, OBSTACLES, budget=BUDGET)
    held_out = cfg.start.arm.copy()
    held_out[[0, 1, 3]] = 1.4, 0.3, -1.2  # turned to the left, leaning out, elbow opened
    planner.set_travel_posture(held_out)
    assert planner.travel.radius > GoalPlanner(cfg, OBSTACLES).travel.radius + 0.1
    goal = sample_goals(cfg, 1, seed=0, obstacles='table_pillar')[0]
    plan = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), cfg.start.base_pose)
    assert plan.no_way is None, plan.reason
    for k, distance in _nearest_along(cfg, planner.travel, plan.trajectory):
        assert distance >= planner.travel.margin - ENGINES, f'{distance} m from an obstacle at sample {k}'


def test_the_timed_path_is_within_the_base_limits_and_ends_at_the_stance(planned):
    cfg, _planner, _goal, plan = planned
    traj = plan.trajectory
    assert traj.dt == cfg.period
    assert np.allclose(np.diff(traj.t), cfg.period)
    end = traj.poses[-1] - plan.stance.base_pose
    assert np.hypot(end[0], end[1]) < 1e-6 and abs(wrap_angle(end[2])) < 1e-6
    # the twists move the base from each sample to the next, and the world rates are the same twists
    for k in range(len(traj.t) - 1):
        moved = np.array(se2_integrate(traj.poses[k], traj.twists[k], traj.dt)) - traj.poses[k + 1]
        assert np.hypot(moved[0], moved[1]) < 1e-6 and abs(wrap_angle(moved[2])) < 1e-6
    assert np.allclose(traj.rates, [twist_to_world(th, tw) for th, tw in zip(traj.poses[:, 2], traj.twists)])
    assert np.all(traj.twists[-1] == 0.0)
    velocity, acceleration = cfg.base.velocity, cfg.base.acceleration
    assert np.all(np.abs(traj.twists) <= velocity + 1e-6)  # a differential base: vy within 1e-6 of 0
    # from rest and back to rest
    rates = np.diff(np.vstack([np.zeros(3), traj.twists]), axis=0) / traj.dt
    assert np.all(np.abs(rates) <= acceleration * (1 + 1e-6) + 1e-6)
    assert np.max(np.abs(traj.twists[:, [0, 2]])) > 0.1 * np.min(velocity[[0, 2]])  # it does move


def test_the_same_seed_plans_the_same_path(planned):
    cfg, planner, _goal, plan = planned
    again = planner.paths.plan(cfg.start.base_pose, plan.stance.base_pose)
    assert np.array_equal(again.waypoints, plan.path.waypoints)
    assert plan.path.planner == 'RRTConnect'  # searched, not the straight way: the seed matters
    other = BasePathPlanner(cfg.base, planner.travel, budget=BUDGET, seed=planner.paths.seed + 1)
    assert not np.array_equal(other.plan(cfg.start.base_pose, plan.stance.base_pose).waypoints, plan.path.waypoints)


class _SlowChecks:
    """A :class:`Travel` whose motion checks each take ``delay`` [s] longer: the planner on a
    slower or loaded machine."""

    def __init__(self, travel, delay):
        self._travel, self._delay = travel, delay

    def __getattr__(self, name):
        return getattr(self._travel, name)

    def motion_valid(self, *args):
        time.sleep(self._delay)
        return self._travel.motion_valid(*args)


def test_a_slower_machine_plans_the_same_path(planned):
    """Every search runs, each to a path or to its iterations, with the default budget only a
    cap: the path kept does not depend on how long the checks take (about 2 s more here)."""
    cfg, planner, _goal, plan = planned
    slow = BasePathPlanner(cfg.base, _SlowChecks(planner.travel, 0.01), seed=planner.paths.seed)
    path = slow.plan(cfg.start.base_pose, plan.stance.base_pose)
    assert path.planner == 'RRTConnect'
    assert np.array_equal(path.waypoints, plan.path.waypoints)


def test_a_base_already_at_the_stance_stays_there(planned):
    cfg, planner, goal, plan = planned
    again = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), plan.stance.base_pose)
    assert again.path.planner == 'direct' and len(again.trajectory.t) == 1
    assert np.allclose(again.trajectory.poses[0], plan.stance.base_pose) and not again.trajectory.twists.any()


def test_a_goal_inside_the_table_is_refused_with_its_reason():
    cfg = load_robot('steerable')
    planner = GoalPlanner(cfg, OBSTACLES)
    table = next(o for o in OBSTACLES if o.name == 'table')
    goal = table.position + np.array([0.0, 0.0, 0.5 * table.size[2] - 0.05])  # 5 cm under its top
    plan = planner.plan(goal, np.eye(3), cfg.start.base_pose)
    assert plan.no_way is NoWay.INSIDE_OBSTACLE and plan.trajectory is None
    assert "'table'" in plan.reason
    # just above the top, nearer than the stance margin: refused too
    plan = planner.plan(goal + [0.0, 0.0, 0.06], np.eye(3), cfg.start.base_pose)
    assert plan.no_way is NoWay.INSIDE_OBSTACLE


@pytest.mark.parametrize('robot', ['steerable', 'panda_diff'])
def test_a_goal_out_of_every_stance_s_reach_is_refused_with_its_reason(robot):
    cfg = load_robot(robot)
    planner = GoalPlanner(cfg, OBSTACLES)
    plan = planner.plan([2.7, 0.0, 3.0], np.eye(3), cfg.start.base_pose)
    assert plan.no_way is NoWay.OUT_OF_REACH and plan.stance is None
    assert 'reach' in plan.reason
    # below the floor
    plan = planner.plan([2.7, 0.0, cfg.ground_z - 0.1], np.eye(3), cfg.start.base_pose)
    assert plan.no_way is NoWay.OUT_OF_REACH


def test_a_goal_the_arm_reaches_from_nowhere_gets_no_stance():
    """Above the floor and below the arm's highest, yet 2 cm off the floor: no posture gets the
    end effector there clear of the floor: every candidate is tried."""
    cfg = load_robot('steerable')
    planner = GoalPlanner(cfg, OBSTACLES)
    plan = planner.plan([2.7, 0.0, cfg.ground_z + 0.02], np.eye(3), cfg.start.base_pose)
    assert plan.no_way is NoWay.NO_STANCE and plan.search.candidates > 0
    assert plan.reason.startswith('no stance')


def test_a_goal_the_arm_reaches_clear_only_back_over_the_base_gets_a_stance():
    """Robot C's first clutter goal: every stance facing it, or turned from it by up to 60°,
    brings the arm within 2 cm of its own links; facing away, the arm reaching back over the
    base, it is clear."""
    cfg = load_robot('ur_mecanum')
    planner = GoalPlanner(cfg, load_obstacles('clutter'))
    goal = sample_goals(cfg, 1, seed=0, obstacles='clutter')[0]
    search = planner.stances.find(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), cfg.start.base_pose)
    assert search.no_way is None, search.reason
    params = planner.stances.params
    for stance in search.stances:
        assert stance.clearance >= params.stance_margin and stance.body_clearance >= params.body_margin
    facing = np.arctan2(*(goal.pose[1::-1] - search.stances[0].base_pose[1::-1]))
    assert abs(wrap_angle(search.stances[0].base_pose[2] - facing)) > math.pi / 2


def test_a_stance_between_the_first_rings_among_boxes_is_found_by_the_second_pass():
    """Robot A's clutter goal 92 sits 1.6 m high among boxes: 11 of the first pass's base poses
    are clear for travel and the arm reaches the goal from none of them. The planner said "no
    stance" and the check refuted it (a stance 0.70 of the reach out, between the rings at 0.6
    and 0.75). The second pass finds stances: checked here on the simulator's geometry (PyBullet,
    not the planner's distance model) and by forward kinematics."""
    cfg = load_robot('steerable')
    obstacles = load_obstacles('clutter')
    planner = GoalPlanner(cfg, obstacles)
    goal = sample_goals(cfg, 100, seed=0, obstacles='clutter')[92]
    rotation = matrix_from_rpy(goal.pose[3:])
    search = planner.stances.find(goal.pose[:3], rotation, cfg.start.base_pose)
    assert search.no_way is None, search.reason
    params = planner.stances.params
    first = planner.stances.candidates(goal.pose[:3], cfg.start.base_pose)
    model = KinematicModel(cfg)
    names = {o.name for o in obstacles}
    with SelfCollisionChecker(cfg, margin=params.stance_margin, obstacles=obstacles) as checker:
        for stance in search.stances:
            assert not any(np.allclose(stance.base_pose, c) for c in first), 'found by the second pass'
            model.update(stance.base_pose, stance.q_arm)
            position, orientation = model.ee_placement_world()
            assert np.linalg.norm(position - goal.pose[:3]) <= params.position_tolerance
            assert rotation_angle(rotation, orientation) <= params.orientation_tolerance
            near = [d for _a, b, d in checker.collisions(stance.q_arm, stance.base_pose) if b in names]
            assert min(near, default=math.inf) >= params.stance_margin - ENGINES


@pytest.mark.parametrize('robot', ['steerable', 'panda_diff'])
def test_a_robot_stopped_near_the_table_backs_away_then_keeps_the_margin(robot):
    """Where a reactive controller leaves it: facing the table 5 cm from it. The path first takes
    a way out that comes no nearer (less the check step), then keeps the margin."""
    from scipy.optimize import brentq

    cfg = load_robot(robot)
    planner = GoalPlanner(cfg, OBSTACLES, budget=BUDGET)
    travel = planner.travel
    goal, start, plan = _plan_from_beside_the_table(cfg, planner, 0.0, 0.05)
    # touching (within the check step): no way out that keeps its clearance
    x = brentq(lambda x: travel.obstacle_clearance([x, -0.2, 0.0]) - 0.005, 0.0, 1.2, xtol=1e-5)
    plan = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), [x, -0.2, 0.0])
    assert plan.no_way is NoWay.START_BLOCKED and 'where it stands' in plan.reason


def test_a_robot_walled_in_gets_no_path():
    cfg = load_robot('steerable')
    walls = parse_obstacles(
        [
            {'name': f'wall_{i}', 'shape': 'box', 'size': size, 'pose': pose}
            for i, (size, pose) in enumerate(
                [
                    ([0.2, 3.4, 1.0], [1.6, 0.0, 0.5]),
                    ([0.2, 3.4, 1.0], [-1.6, 0.0, 0.5]),
                    ([3.4, 0.2, 1.0], [0.0, 1.6, 0.5]),
                    ([3.4, 0.2, 1.0], [0.0, -1.6, 0.5]),
                ]
            )
        ],
        'walls',
    )
    model = KinematicModel(cfg)
    travel = Travel(Clearance.of_robot(cfg, walls, body=False), model, cfg.start.arm, margin=0.1)
    planner = BasePathPlanner(cfg.base, travel, budget=BUDGET)
    path = planner.plan(cfg.start.base_pose, [3.0, 0.0, 0.0])
    assert path.no_way is NoWay.NO_PATH and not path.found and len(path.waypoints) == 0
    assert f'in {planner.iterations} iterations' in path.reason
    # a budget too short for the iterations: the safety cap, no path rather than a guess
    hurried = BasePathPlanner(cfg.base, travel, budget=1e-4)
    path = hurried.plan(cfg.start.base_pose, [3.0, 0.0, 0.0])
    assert path.no_way is NoWay.TIMED_OUT and not path.found and len(path.waypoints) == 0
    assert 'budget' in path.reason


def test_a_holonomic_move_is_refused_to_a_differential_base():
    from wmm_control.planning.timing import LinearPiece

    cfg = load_robot('panda_diff')
    sideways = LinearPiece(np.zeros(3), np.array([0.0, 1.0, 0.0]))
    with pytest.raises(Exception, match='vy'):
        time_path([sideways], cfg.base, cfg.period)


def test_the_path_space_follows_whether_the_base_moves_sideways():
    """A base without a sideways axis plans Reeds–Shepp curves of ρ = v_max / ω_max, whatever its
    family is called (here a differential one renamed); a base with one plans straight SE(2)
    motions. A step to the side: the curves time within the base's limits (no vy), a straight
    sideways motion would need vy."""
    from wmm_control.planning.timing import LinearPiece, TwistPiece
    from wmm_control.robot_config import DifferentialBase

    @dataclasses.dataclass(frozen=True)
    class Renamed(DifferentialBase):
        family: ClassVar[str] = 'skid'

    diff, holonomic = load_robot('panda_diff'), load_robot('mecanum')
    renamed = Renamed(**{f.name: getattr(diff.base, f.name) for f in dataclasses.fields(diff.base)})
    assert not renamed.sideways and renamed.path_turning_radius == diff.base.path_turning_radius == 0.75 / 3.0
    assert holonomic.base.sideways and holonomic.base.path_turning_radius is None
    goal = np.array([0.0, 1.0, 0.0])
    for cfg, base in ((diff, renamed), (holonomic, holonomic.base)):
        travel = Travel(Clearance.of_robot(cfg, (), body=False), KinematicModel(cfg), cfg.start.arm, margin=0.1)
        planner = BasePathPlanner(base, travel, budget=BUDGET)
        assert planner.rho == base.path_turning_radius
        path = planner.plan(np.zeros(3), goal)
        assert path.found, path.reason
        traj = time_path(path.pieces, base, cfg.period)
        np.testing.assert_allclose(traj.poses[-1], goal, rtol=0, atol=1e-6)
        if base.sideways:
            assert [type(piece) for piece in path.pieces] == [LinearPiece]
        else:
            assert len(path.pieces) > 1 and all(isinstance(piece, TwistPiece) for piece in path.pieces)
            np.testing.assert_allclose(traj.twists[:, 1], 0.0, rtol=0, atol=1e-6)


def test_a_straight_se2_piece_bounds_its_twist_and_the_twist_s_change_tightly():
    """u(λ), the twist per unit λ in the base's frame, by finite differences along random pieces
    (turning up to half a turn): within the piece's bounds, and reaching them (not loose)."""
    from wmm_control.geometry import se2_twist
    from wmm_control.planning.timing import LinearPiece

    rng = np.random.default_rng(3)
    h = 1e-5
    for _ in range(20):
        start = rng.uniform([-2, -2, -math.pi], [2, 2, math.pi])
        end = start + rng.uniform([-2, -2, -math.pi], [2, 2, math.pi])
        piece = LinearPiece(start, end)
        bound, slope = piece.rate_bounds()
        lams = np.linspace(0.0, 1.0 - h, 801)
        u = np.array([se2_twist(piece.pose(lam), piece.pose(lam + h), h) for lam in lams])
        du = np.diff(u, axis=0) / np.diff(lams)[:, None]
        assert np.all(np.abs(u) <= bound * (1 + 1e-4) + 1e-6)
        assert np.all(np.abs(du) <= slope * (1 + 1e-3) + 1e-3)
        assert np.all(np.max(np.abs(u), axis=0) >= 0.99 * bound - 1e-6)


def test_timed_se2_pieces_keep_every_axis_within_its_own_limits():
    """Robot B's base: 0.25 m/s and 0.025 m/s² on x and y, 1 rad/s and 1.5 rad/s² on the turn."""
    from wmm_control.planning.timing import LinearPiece

    cfg = load_robot('mecanum')
    rng = np.random.default_rng(4)
    poses = np.cumsum(rng.uniform([-0.6, -0.6, -2.0], [0.6, 0.6, 2.0], size=(4, 3)), axis=0)
    traj = time_path([LinearPiece(a, b) for a, b in zip(poses[:-1], poses[1:])], cfg.base, cfg.period)
    assert np.allclose(traj.poses[-1], [*poses[-1, :2], wrap_angle(poses[-1, 2])])
    assert np.all(np.abs(traj.twists) <= cfg.base.velocity + 1e-9)
    rates = np.diff(np.vstack([np.zeros(3), traj.twists]), axis=0) / traj.dt
    assert np.all(np.abs(rates) <= cfg.base.acceleration * (1 + 1e-6))
    # the turn and the translation use their limits: the slowest axis sets the pace, not a common one
    use = np.max(np.abs(rates), axis=0) / cfg.base.acceleration
    assert np.max(use) > 0.5


def test_a_steerable_base_path_is_timed_within_its_wheels_steering_limits():
    """Robot A's modules steer at 1 rad/s: a straight piece that turns the base's heading by
    2.2 rad over 1.4 m swings a module's heading faster than that at the base's own limits; the
    timing slows it until every module's heading (its hip's velocity direction, modulo π) keeps
    within the steer rate and acceleration limits."""
    from wmm_control.planning.timing import LinearPiece

    cfg = load_robot('steerable')
    base = cfg.base
    pieces = [LinearPiece(np.array([1.435, -1.812, -0.713]), np.array([2.354, -0.75, 1.488]))]
    rng = np.random.default_rng(7)
    poses = np.cumsum(rng.uniform([-1.0, -1.0, -2.5], [1.0, 1.0, 2.5], size=(5, 3)), axis=0)
    pieces += [LinearPiece(a, b) for a, b in zip(poses[:-1], poses[1:])]
    for piece in pieces:
        traj = time_path([piece], base, cfg.period)
        moving = np.linalg.norm(traj.twists, axis=1) > 1e-9
        headings = base.steer_headings(traj.twists[moving])
        swing = wrap_angle(2.0 * np.diff(headings, axis=0)) / 2.0 / traj.dt  # modulo π
        assert np.abs(swing).max() <= base.steer_rate_limit * 1.02, np.abs(swing).max()
        assert np.all(np.abs(traj.twists) <= base.velocity + 1e-9)
    # the first piece needs it: timed at the twist limits alone, a module swings faster
    free = dataclasses.replace(base, steer_rate_limit=1e9, steer_accel_limit=1e9)
    traj = time_path(pieces[:1], free, cfg.period)
    headings = base.steer_headings(traj.twists[np.linalg.norm(traj.twists, axis=1) > 1e-9])
    assert np.abs(wrap_angle(2.0 * np.diff(headings, axis=0)) / 2.0 / traj.dt).max() > 1.3 * base.steer_rate_limit
    assert load_robot('mecanum').base.steer_headings(traj.twists).shape == (len(traj.twists), 0)


def test_a_robot_held_along_the_table_with_no_straight_way_out_turns_its_way_out(monkeypatch):
    """Robot A stopped 4 cm beside the table, heading along it: no straight motion with the
    heading kept reaches the margin without coming nearer; a way out that turns as it goes
    does, and the path then keeps the margin. (Seen after a stall in a realtime run: "no way"
    where there was one.)"""
    import wmm_control.planning.base_path as base_path

    cfg = load_robot('steerable')
    planner = GoalPlanner(cfg, OBSTACLES, budget=BUDGET)
    goal, start, plan = _plan_from_beside_the_table(cfg, planner, math.pi / 2, 0.04)
    assert abs(wrap_angle(plan.path.waypoints[1][2] - start[2])) > 0.1  # the way out turns
    monkeypatch.setattr(base_path, 'ESCAPE_TURNS', ())  # straight ways out only
    plan = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), start)
    assert plan.no_way is NoWay.START_BLOCKED, plan.reason


def _plan_from_beside_the_table(cfg, planner, heading, clearance):
    """A plan to the first table_pillar goal from a base ``clearance`` [m] beside the table's
    near side (y = −0.2, ``heading``), checked: it starts there, its way out comes no nearer
    than that (less the check step), and the path keeps the margin after it. (goal, start, plan)."""
    from scipy.optimize import brentq

    travel = planner.travel
    x = brentq(lambda x: travel.obstacle_clearance([x, -0.2, heading]) - clearance, 0.0, 1.25, xtol=1e-5)
    start = np.array([x, -0.2, heading])
    goal = sample_goals(cfg, 1, seed=0, obstacles='table_pillar')[0]
    plan = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), start)
    assert plan.no_way is None, plan.reason
    traj = plan.trajectory
    assert np.allclose(traj.poses[0], start)
    out = next(k for k, pose in enumerate(traj.poses) if np.allclose(pose, plan.path.waypoints[1]))
    for k, distance in _nearest_along(cfg, travel, traj):
        assert distance >= (clearance - travel.step if k < out else travel.margin) - ENGINES
    return goal, start, plan


def test_a_detour_round_a_wall_gives_way_to_a_path_through_the_doorway():
    """Robot A in `doorway`: the travel margin (0.10 m) leaves a lane through the 0.9 m gap a few
    centimetres wide, which the searches do not find, and the path goes round a wall's end
    (more than 10 m). Where a path is such a detour the planner also searches with the narrow
    margin (0.07 m), and the path through the gap, shorter by far, keeps that margin from every
    obstacle all along (PyBullet's geometry)."""
    cfg = load_robot('steerable')
    doorway = load_obstacles('doorway')
    goal = sample_goals(cfg, 1, seed=0, obstacles='doorway')[0]
    where = goal.pose[:3], matrix_from_rpy(goal.pose[3:]), cfg.start.base_pose
    wide = GoalPlanner(cfg, doorway, budget=BUDGET, narrow_margin=0.0, stances_tried=1).plan(*where)
    plan = GoalPlanner(cfg, doorway, budget=BUDGET, stances_tried=1).plan(*where)
    assert wide.path.length > 8.0 and plan.path.length < 5.0, (wide.path.length, plan.path.length)
    narrow = GoalPlanner(cfg, doorway).travel.with_margin(0.07)
    for k, distance in _nearest_along(cfg, narrow, plan.trajectory, doorway):
        assert distance >= 0.07 - ENGINES, f'{distance} m from a wall at {plan.trajectory.poses[k]}'


def test_a_robot_stopped_where_the_travel_margin_has_no_way_out_leaves_with_the_narrow_margin():
    """Robot A stopped 5 cm beside `doorway`'s wall, past it (where a stalled run left it): no
    pose within reach keeps the travel margin with a way out that comes no nearer, and the plan
    was "no way" ('start_blocked'). With the narrow margin it leaves without coming nearer
    (less the check step), then keeps 0.07 m from every obstacle (PyBullet's geometry)."""
    from scipy.optimize import brentq

    cfg = load_robot('steerable')
    doorway = load_obstacles('doorway')
    goal = sample_goals(cfg, 100, seed=0, obstacles='doorway')[45]
    travel = GoalPlanner(cfg, doorway, budget=BUDGET).travel
    x = brentq(lambda x: travel.obstacle_clearance([x, -3.21, -1.04]) - 0.05, 1.7, 2.6, xtol=1e-5)
    where = goal.pose[:3], matrix_from_rpy(goal.pose[3:]), [x, -3.21, -1.04]
    wide = GoalPlanner(cfg, doorway, budget=BUDGET, narrow_margin=0.0).plan(*where)
    assert wide.no_way is NoWay.START_BLOCKED, wide.reason
    plan = GoalPlanner(cfg, doorway, budget=BUDGET).plan(*where)
    assert plan.no_way is None, plan.reason
    traj = plan.trajectory
    out = next(k for k, pose in enumerate(traj.poses) if np.allclose(pose, plan.path.waypoints[1]))
    narrow = travel.with_margin(0.07)
    for k, distance in _nearest_along(cfg, narrow, traj, doorway):
        assert distance >= (0.05 - travel.step if k < out else 0.07) - ENGINES, (k, distance)


def test_where_the_best_stance_is_only_reached_round_a_wall_another_stance_is_taken():
    """Robot A in `doorway`, goal 53: the best-scored stance stands just behind the wall's end,
    and every path to it, at either margin, goes round the wall (more than 8 m); the next
    stance is reached through the doorway. The plan takes the first stance whose path is not a
    detour, and its path keeps the margins all along (PyBullet's geometry)."""
    cfg = load_robot('steerable')
    doorway = load_obstacles('doorway')
    goal = sample_goals(cfg, 100, seed=0, obstacles='doorway')[53]
    where = goal.pose[:3], matrix_from_rpy(goal.pose[3:]), cfg.start.base_pose
    first = GoalPlanner(cfg, doorway, budget=BUDGET, stances_tried=1).plan(*where)
    assert first.path.detour and first.path.length > 8.0, first.path.length
    plan = GoalPlanner(cfg, doorway, budget=BUDGET).plan(*where)
    assert plan.no_way is None and not plan.path.detour and plan.path.length < 4.0, plan.path.length
    assert not np.allclose(plan.stance.base_pose, first.stance.base_pose)
    assert plan.stance.base_pose.tolist() in [s.base_pose.tolist() for s in plan.search.stances[1:]]
    narrow = GoalPlanner(cfg, doorway).travel.with_margin(0.07)
    for k, distance in _nearest_along(cfg, narrow, plan.trajectory, doorway):
        assert distance >= 0.07 - ENGINES, f'{distance} m from a wall at {plan.trajectory.poses[k]}'


def test_the_stance_chosen_is_one_the_arm_can_move_to_without_passing_through_its_own_margin():
    """`ur_mecanum`'s arm travels folded, 24 mm from its own body. In `doorway` goal 7 of the
    randomized draw the stance with a straight base path through the doorway has a posture whose
    straight joint-space motion from the travel posture brings the forearm within 13 mm of the
    wrist (arm_link_3, arm_link_5): the safety stage holds that pair at 20 mm, and the run stalled
    there. The planner now takes a stance whose motion keeps the margin, and says which stances
    found have none. Checked on the controller's collision model, the one the safety stage
    holds pairs on, at every hundredth of the motion (PyBullet's geometry has this arm's wrist
    links overlapping already in the travel posture, and the simulator leaves such pairs out)."""
    cfg = load_robot('ur_mecanum')
    obstacles = load_obstacles('doorway')
    planner = GoalPlanner(cfg, obstacles, budget=BUDGET)
    goal = sample_goals(cfg, 8, seed=0, obstacles='doorway')[7]
    plan = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), cfg.start.base_pose)
    assert plan.no_way is None, plan.reason
    stance, params = plan.stance, planner.stances.params
    assert stance.motion_clear
    assert any(not s.motion_clear for s in plan.search.stances)  # the choice mattered
    own = CollisionModel.from_robot(cfg)
    travel = planner.travel.q_arm
    nearest = min(own.closest(travel + s * (stance.q_arm - travel))[0] for s in np.linspace(0.0, 1.0, 101))
    assert nearest >= params.body_margin, nearest
