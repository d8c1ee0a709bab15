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
from wmm_control.planning.handoff import Handoff
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
