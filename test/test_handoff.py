"""The planner's hand-off to the resolver: the planned base trajectory as end-effector trajectory
points, tracked by the method before its final approach to the goal (``wmm_randomized --plan``).

The points are checked against forward kinematics of the planned base poses with the arm in the
travel posture (pinocchio, one configuration at a time), their twists against finite differences
of those poses; the closed-loop runs against the simulator's own contact check.
"""

import numpy as np
import pytest

from wmm_control.cli.randomized import format_no_way, format_summary
from wmm_control.experiments.randomized import CONTACT_DEPTH, RandomGoal, run_goal, sample_goals, summarize
from wmm_control.geometry import matrix_from_rpy, rotation_angle
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.obstacles import load_obstacles
from wmm_control.planning import GoalPlanner
from wmm_control.planning.follow import PlanFollower
from wmm_control.planning.handoff import ARM_EE_SPEED, ARM_FRACTION, Handoff
from wmm_control.resolvers.interface import PoseTarget
from wmm_control.robot_config import load_robot

OBSTACLES = load_obstacles('table_pillar')


@pytest.fixture(scope='module')
def behind_the_table():
    """(robot, goal): the first table_pillar goal of robot A's draw (beyond the table)."""
    cfg = load_robot('steerable')
    return cfg, sample_goals(cfg, 1, seed=0, obstacles='table_pillar')[0]


def test_the_points_are_the_forward_kinematics_of_the_planned_base_poses(behind_the_table):
    cfg, goal = behind_the_table
    planner = GoalPlanner(cfg, OBSTACLES, budget=30.0)
    plan = planner.plan(goal.pose[:3], matrix_from_rpy(goal.pose[3:]), cfg.start.base_pose)
    assert plan.trajectory is not None, plan.reason
    q_travel = planner.travel.q_arm
    handoff = Handoff.of(planner.model, plan.trajectory, q_travel)
    traj = plan.trajectory
    assert len(handoff.points) == len(traj.poses) and handoff.duration == pytest.approx(traj.duration)
    model = KinematicModel(cfg)
    positions = []
    for pose, point in zip(traj.poses, handoff.points):
        model.update(pose, q_travel)
        position, rotation = model.ee_placement_world()
        assert np.allclose(point.position, position, atol=1e-9)
        assert rotation_angle(point.rotation, rotation) < 1e-9
        positions.append(position)
    # the first point is where the end effector is at the start
    model.update(cfg.start.base_pose, cfg.start.arm)
    assert np.allclose(handoff.points[0].position, model.ee_placement_world()[0], atol=1e-9)
    # each twist takes the end effector to the next point over the period (the base's twist is
    # held over it: the difference is second order in the period)
    fd = np.diff(np.array(positions), axis=0) / traj.dt
    velocity = np.array([p.velocity for p in handoff.points])
    speed = float(np.max(np.linalg.norm(velocity[:, :3], axis=1)))
    assert speed > 0.1  # the base drives
    assert np.max(np.abs(fd - velocity[:-1, :3])) < 0.02 * speed
    turn = np.diff(np.unwrap(traj.poses[:, 2])) / traj.dt
    assert np.allclose(velocity[:-1, 5], turn, atol=1e-6) and np.allclose(velocity[:, 3:5], 0.0)
    # the accelerations are the twists' forward differences; the last point is at rest
    acceleration = np.array([p.acceleration for p in handoff.points])
    assert np.allclose(acceleration[:-1], np.diff(velocity, axis=0) / traj.dt)
    assert not np.any(velocity[-1]) and not np.any(acceleration[-1])


def test_after_the_path_the_arm_moves_to_the_stances_posture_with_the_base_at_rest(behind_the_table):
    """With the stance's posture the hand-off goes on after the path: the base at rest at the
    stance, the arm on the straight joint-space motion from the travel posture to the stance's,
    within ``ARM_FRACTION`` of its limits and the end effector within ``ARM_EE_SPEED``, each point the forward kinematics of the two; the final
    approach gives the goal with the stance and that posture."""
    cfg, goal = behind_the_table
    planner = GoalPlanner(cfg, OBSTACLES, budget=30.0)
    rotation = matrix_from_rpy(goal.pose[3:])
    plan = planner.plan(goal.pose[:3], rotation, cfg.start.base_pose)
    assert plan.trajectory is not None and plan.stance is not None, plan.reason
    q_travel, q_stance = planner.travel.q_arm, plan.stance.q_arm
    path = Handoff.of(planner.model, plan.trajectory, q_travel)
    handoff = Handoff.of(planner.model, plan.trajectory, q_travel, q_stance)
    k = len(path.points)
    assert len(handoff.points) > k and np.array_equal(handoff.stance_arm, q_stance)
    for a, b in zip(path.points[:-1], handoff.points):  # the way there as without it
        assert np.array_equal(a.position, b.position) and np.array_equal(a.velocity, b.velocity)
    rest = handoff.points[k - 1 :]
    arms = np.array([p.base.arm for p in rest])
    assert np.allclose(arms[0], q_travel) and np.allclose(arms[-1], q_stance)
    assert np.allclose(handoff.base_poses[k - 1 :], plan.trajectory.poses[-1])
    assert all(not np.any(p.base.rates) and not np.any(p.base.acceleration) for p in rest)
    # a straight motion in joint space, within the fraction of the arm's limits
    along = (arms - q_travel) @ (q_stance - q_travel) / np.dot(q_stance - q_travel, q_stance - q_travel)
    assert np.allclose(arms, q_travel + along[:, None] * (q_stance - q_travel), atol=1e-9)
    assert np.all(np.diff(along) >= 0.0)
    rates = np.diff(arms, axis=0) / handoff.dt
    assert np.all(np.abs(rates) <= ARM_FRACTION * cfg.arm.velocity + 1e-9)
    assert np.all(np.abs(np.diff(rates, axis=0)) / handoff.dt <= ARM_FRACTION * cfg.arm.acceleration + 1e-6)
    # the end effector at the pace of a set-point's trajectory (its twist bounded on a few samples)
    twists = np.array([p.velocity for p in rest])
    assert np.max(np.linalg.norm(twists[:, :3], axis=1)) <= 1.05 * ARM_EE_SPEED[0]
    assert np.max(np.linalg.norm(twists[:, 3:], axis=1)) <= 1.05 * ARM_EE_SPEED[1]
    model = KinematicModel(cfg)
    for point, q in zip(rest, arms):
        model.update(plan.trajectory.poses[-1], q)
        position, orientation = model.ee_placement_world()
        assert np.allclose(point.position, position, atol=1e-9) and rotation_angle(point.rotation, orientation) < 1e-9
    # the last point reaches the goal within the stance's tolerances, at rest
    assert np.linalg.norm(rest[-1].position - goal.pose[:3]) <= planner.stances.params.position_tolerance + 1e-9
    assert not np.any(rest[-1].velocity) and not np.any(rest[-1].acceleration)
    approach = PlanFollower(handoff, PoseTarget(goal.pose[:3], rotation)).approach
    assert approach.base is not None and approach.base.stance and np.array_equal(approach.base.arm, q_stance)


def test_the_wrist_takes_the_branch_of_the_stance():
    """`panda_diff`'s goal 1 of the randomized `clutter` draw: the stance's posture has the
    wrist turned over (joint 5 near −2.35 rad, joint 6 near 0.16); from the travel posture
    (joint 6 at 1.57) the end effector's task alone drove joint 6 onto its limit, 0.2 m from the
    goal, and a pull towards the stance's posture in the null space could not turn it over. The
    arm's motion to the stance's posture takes it there, and the goal is reached."""
    cfg = load_robot('panda_diff')
    goal = sample_goals(cfg, 2, seed=0, obstacles='clutter')[1]
    result = run_goal(cfg, 'pinv', goal, obstacles='clutter', duration=20.0, plan=True)
    assert result['outcome'] == 'converged', (result['final_position_error_m'], result['why'])
    assert result['contact_depth_m'] <= CONTACT_DEPTH and result['replans'] == 0


def test_a_goal_behind_the_table_is_reached_with_the_plan_and_not_without(behind_the_table):
    cfg, goal = behind_the_table
    without = run_goal(cfg, 'pinv', goal, obstacles='table_pillar', duration=30.0)
    assert without['outcome'] != 'converged' and without['final_position_error_m'] > 0.5
    planned = run_goal(cfg, 'pinv', goal, obstacles='table_pillar', duration=30.0, plan=True)
    assert planned['outcome'] == 'converged', planned['why']
    assert planned['contact_depth_m'] <= CONTACT_DEPTH and planned['no_way'] is None
    assert planned['planning_time_s'] > 0.0


def test_a_goal_inside_the_table_is_no_way_with_its_reason_not_a_failure():
    cfg = load_robot('steerable')
    table = next(o for o in OBSTACLES if o.name == 'table')
    position = table.position + np.array([0.0, 0.0, 0.5 * table.size[2] - 0.05])
    goal = RandomGoal(0, np.zeros(3), cfg.start.arm, np.concatenate((position, np.zeros(3))), 1)
    result = run_goal(cfg, 'pinv', goal, obstacles='table_pillar', plan=True)
    assert result['outcome'] == 'no_way' and result['no_way'] == 'inside_obstacle'
    assert "'table'" in result['no_way_reason'] and result['why'] == ''
    # checked apart from the planner, counted by the check's verdict, shown with it
    check = result['no_way_check']
    assert check['verdict'] == 'confirmed' and "'table'" in check['evidence']
    assert result['no_way_from'] == pytest.approx(list(cfg.start.base_pose))
    row = summarize([result])[(cfg.name, 'pinv')]
    assert row['no_way'] == row['no_way_confirmed'] == 1 and row['no_way_refuted'] == row['no_way_unchecked'] == 0
    assert '| 1 (1 / 0 / 0) |' in format_summary(summarize([result]))
    assert 'check confirmed' in format_no_way([result])


def test_the_nodes_engine_plans_with_goal_planner_round_the_table_and_reports_no_way(behind_the_table):
    """``--engine nodes --plan``: the goal_planner node between the goal and the resolver, as
    ``robot.launch.py planner:=true`` wires it. The goal behind the table is reached round it; a
    goal inside the table is no way, with its reason, and the robot is held."""
    cfg, goal = behind_the_table
    planned = run_goal(cfg, 'pinv', goal, engine='nodes', obstacles='table_pillar', duration=40.0, plan=True)
    assert planned['outcome'] == 'converged', planned['why']
    assert planned['contact_depth_m'] <= CONTACT_DEPTH and planned['no_way'] is None
    assert planned['planning_time_s'] > 0.0
    table = next(o for o in OBSTACLES if o.name == 'table')
    position = table.position + np.array([0.0, 0.0, 0.5 * table.size[2] - 0.05])
    inside = RandomGoal(0, np.zeros(3), cfg.start.arm, np.concatenate((position, np.zeros(3))), 1)
    result = run_goal(cfg, 'pinv', inside, engine='nodes', obstacles='table_pillar', duration=5.0, plan=True)
    assert result['outcome'] == 'no_way' and result['no_way'] == 'inside_obstacle'
    assert "'table'" in result['no_way_reason'] and result['why'] == ''
    assert result['no_way_check']['verdict'] == 'confirmed'


def test_a_plan_through_the_table_stalls_and_the_replan_from_where_the_robot_stopped_gets_there(behind_the_table):
    """A plan that did not know the table: the straight way to the stance. The safety stage holds
    the robot in front of the table, the follower reports the stall, and the plan made from the
    measured base pose (by a planner that knows the table) takes the robot round it to the goal."""
    from sim_bridge.world import SimWorld
    from wmm_control.experiments.direct import run_scenario
    from wmm_control.experiments.randomized import METHOD_RUNS, _scenario, run_contact
    from wmm_control.experiments.scenario import Goal, resolver_parameters
    from wmm_control.planning.follow import PlanFollower
    from wmm_control.planning.pursuit import GoalPursuit
    from wmm_control.resolvers.period import ResolverSettings
    from wmm_control.planning.timing import LinearPiece, time_path
    from wmm_control.resolvers import make_resolver

    cfg, goal = behind_the_table
    target = Goal(0.0, 0.0, goal.pose).target
    planner = GoalPlanner(cfg, OBSTACLES, budget=30.0)
    plan = planner.plan(target.position, target.rotation, cfg.start.base_pose)
    assert plan.stance is not None, plan.reason
    straight = time_path([LinearPiece(np.asarray(cfg.start.base_pose), plan.stance.base_pose)], cfg.base, cfg.period)
    blind = Handoff.of(planner.model, straight, planner.travel.q_arm)
    replanned = []

    class Pursuit(GoalPursuit):
        def _replan(self, events, why, base):
            replanned.append(np.array(base))
            return super()._replan(events, why, base)

    settings = ResolverSettings.defaults()
    pursuit = Pursuit(
        cfg, OBSTACLES, settings.world_frame, settings.max_goal_distance, planner={'budget': 30.0}, threaded=False
    )
    pursuit.follow_plan(PlanFollower(blind, target))
    resolver = make_resolver('pinv', cfg, **resolver_parameters(METHOD_RUNS['pinv']))
    with SimWorld(cfg, base_mode='kinematic') as world:
        log = run_scenario(world, resolver, _scenario(cfg, goal, 90.0, 'table_pillar'), pursuit=pursuit)
    # it stalled first in front of the table, short of the stance (and may stall again on the
    # way round, where the robot lags the plan at the table's corner: it plans again from there)
    assert replanned and pursuit.counters.no_way == 0
    table = next(o for o in OBSTACLES if o.name == 'table')
    assert replanned[0][0] < table.position[0]
    # and got there round it, never in contact
    error = np.linalg.norm(log.ee_position[-1] - target.position)
    assert error < 0.01 and rotation_angle(target.rotation, log.ee_rotation[-1]) < 0.02
    assert run_contact(cfg, log.q_arm, log.base_pose, OBSTACLES)[0] <= CONTACT_DEPTH


def test_a_box_moved_onto_the_rest_of_the_path_is_driven_round_on_the_direct_engine(behind_the_table):
    """The direct engine pursues a goal as goal_planner does (test_goal_planner puts a box on
    the path on the node path): a box that appears on the rest of the planned path while the
    robot follows it makes the pursuit plan again round it; the goal is reached, the robot
    never in contact with the table, the pillar or the box."""
    from sim_bridge.world import SimWorld
    from wmm_control.experiments.direct import run_scenario
    from wmm_control.experiments.randomized import METHOD_RUNS, _scenario, run_contact
    from wmm_control.experiments.scenario import Goal, resolver_parameters
    from wmm_control.kinematics.obstacles import Obstacle
    from wmm_control.planning.pursuit import GoalPursuit, PursuitState
    from wmm_control.resolvers import make_resolver
    from wmm_control.resolvers.period import ResolverSettings

    cfg, goal = behind_the_table
    target = Goal(0.0, 0.0, goal.pose).target
    options = {'budget': 30.0}  # every search done whatever the load: the pursuit plans this path too
    plan = GoalPlanner(cfg, OBSTACLES, **options).plan(target.position, target.rotation, cfg.start.base_pose)
    assert plan.trajectory is not None, plan.reason
    poses = plan.trajectory.poses
    x, y = poses[len(poses) * 2 // 3, :2]  # on the path, well ahead of the base at 2 s
    box = Obstacle('box', 'box', (0.3, 0.3, 0.6), np.array([x, y, 0.3]), np.eye(3))
    moved = (*OBSTACLES, box)
    settings = ResolverSettings.defaults()
    pursuit = GoalPursuit(
        cfg, OBSTACLES, settings.world_frame, settings.max_goal_distance, planner=options, threaded=False
    )
    resolver = make_resolver('pinv', cfg, **resolver_parameters(METHOD_RUNS['pinv']))
    with SimWorld(cfg, base_mode='kinematic') as world:
        log = run_scenario(
            world,
            resolver,
            _scenario(cfg, goal, 60.0, 'table_pillar'),
            until=lambda d: d.position_error < 0.005 and d.orientation_error < 0.01,
            pursuit=pursuit,
            obstacle_changes=[(2.0, moved)],
        )
    assert pursuit.counters.replans >= 1 and pursuit.state is PursuitState.APPROACH, pursuit.status()
    assert np.linalg.norm(log.ee_position[-1] - target.position) < 0.01
    assert rotation_angle(target.rotation, log.ee_rotation[-1]) < 0.02
    assert run_contact(cfg, log.q_arm, log.base_pose, moved)[0] <= CONTACT_DEPTH
    # the base never came within the travel margin's reach of where the box stands
    assert np.min(np.hypot(log.base_pose[:, 0] - x, log.base_pose[:, 1] - y)) > 0.3
