"""The check of the planner's "no way" (:func:`~wmm_control.planning.no_way_check.confirm_no_way`)
on goals whose answer is known by construction: inside the table, far above every reach, off
the floor where no posture is clear of it, reachable (a stance it finds is checked on the
simulator's geometry, apart from the planner's), and a robot walled in, or not quite.
"""

import math

import numpy as np
import pytest

from sim_bridge.collision import SelfCollisionChecker
from wmm_control.experiments.randomized import sample_goals
from wmm_control.geometry import matrix_from_rpy, rotation_angle
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.obstacles import load_obstacles, parse_obstacles
from wmm_control.planning import GoalPlanner, NoWay
from wmm_control.planning.no_way_check import Verdict, confirm_no_way
from wmm_control.robot_config import load_robot

OBSTACLES = load_obstacles('table_pillar')
#: [m] how much nearer PyBullet's geometry may put the robot than the planner's (coal's)
ENGINES = 0.005


@pytest.fixture(scope='module')
def steerable():
    cfg = load_robot('steerable')
    return cfg, GoalPlanner(cfg, OBSTACLES)


def _table_top():
    table = next(o for o in OBSTACLES if o.name == 'table')
    return table.position + np.array([0.0, 0.0, 0.5 * table.size[2]])


def test_a_goal_inside_the_table_is_confirmed_and_one_above_it_refuted(steerable):
    cfg, planner = steerable
    check = confirm_no_way(planner, _table_top() - [0.0, 0.0, 0.05], np.eye(3), NoWay.INSIDE_OBSTACLE, [0, 0, 0])
    assert check.verdict is Verdict.CONFIRMED and "'table'" in check.evidence
    # 2 cm above the top: within the stance margin (3 cm), as the planner says
    check = confirm_no_way(planner, _table_top() + [0.0, 0.0, 0.02], np.eye(3), NoWay.INSIDE_OBSTACLE, [0, 0, 0])
    assert check.verdict is Verdict.CONFIRMED
    check = confirm_no_way(planner, _table_top() + [0.0, 0.0, 0.3], np.eye(3), NoWay.INSIDE_OBSTACLE, [0, 0, 0])
    assert check.verdict is Verdict.REFUTED and '0.300 m' in check.evidence


@pytest.mark.parametrize('z', [3.0, -1.0])
def test_a_goal_far_above_or_below_the_floor_is_confirmed_out_of_reach(steerable, z):
    cfg, planner = steerable
    check = confirm_no_way(planner, [2.7, 0.0, z], np.eye(3), NoWay.OUT_OF_REACH, cfg.start.base_pose)
    assert check.verdict is Verdict.CONFIRMED and check.poses == 0
    assert ('below the floor' in check.evidence) == (z < cfg.ground_z)


def test_a_reachable_goal_said_to_have_no_stance_is_refuted_by_a_stance_clear_of_everything(steerable):
    cfg, planner = steerable
    goal = sample_goals(cfg, 1, seed=0, obstacles='table_pillar')[0]
    rotation = matrix_from_rpy(goal.pose[3:])
    check = confirm_no_way(planner, goal.pose[:3], rotation, NoWay.NO_STANCE, cfg.start.base_pose)
    assert check.verdict is Verdict.REFUTED, check.evidence
    # the stance reaches the goal (forward kinematics) within the limits ...
    model = KinematicModel(cfg)
    model.update(check.base_pose, check.q_arm)
    position, ee_rotation = model.ee_placement_world()
    params = planner.stances.params
    assert np.linalg.norm(position - goal.pose[:3]) <= params.position_tolerance
    assert rotation_angle(rotation, ee_rotation) <= params.orientation_tolerance
    assert np.all((check.q_arm >= cfg.arm.position_lower) & (check.q_arm <= cfg.arm.position_upper))
    # ... clear of the obstacles, its own body and the floor on the simulator's geometry
    with SelfCollisionChecker(cfg, margin=params.body_margin - ENGINES, obstacles=OBSTACLES) as checker:
        assert not checker.collisions(check.q_arm, check.base_pose)
    with SelfCollisionChecker(cfg, margin=params.stance_margin - ENGINES, obstacles=OBSTACLES) as checker:
        names = {o.name for o in OBSTACLES}
        assert not [c for c in checker.collisions(check.q_arm, check.base_pose) if c[1] in names]
    # and the base got there in its travel posture
    assert planner.travel.obstacle_clearance(check.base_pose) >= planner.travel.margin


def test_a_goal_no_posture_reaches_clear_of_the_floor_is_confirmed_no_stance(steerable):
    """2 cm above the floor, the end effector pointing up: every base pose of the grid tried."""
    cfg, planner = steerable
    goal = [2.7, 0.0, cfg.ground_z + 0.02]
    assert planner.plan(goal, np.eye(3), cfg.start.base_pose).no_way is NoWay.NO_STANCE
    check = confirm_no_way(planner, goal, np.eye(3), NoWay.NO_STANCE, cfg.start.base_pose)
    assert check.verdict is Verdict.CONFIRMED and check.base_pose is None
    assert check.poses > 300 and 'none of' in check.evidence


def _walls(gap):
    """Walls round the start, 3.2 m apart; with ``gap`` the one towards +x left out."""
    walls = [
        ([0.2, 3.4, 1.0], [1.6, 0.0, 0.5]),
        ([0.2, 3.4, 1.0], [-1.6, 0.0, 0.5]),
        ([3.4, 0.2, 1.0], [0.0, 1.6, 0.5]),
        ([3.4, 0.2, 1.0], [0.0, -1.6, 0.5]),
    ][1 if gap else 0 :]
    return parse_obstacles(
        [{'name': f'wall_{i}', 'shape': 'box', 'size': size, 'pose': pose} for i, (size, pose) in enumerate(walls)],
        'walls',
    )


@pytest.mark.parametrize('gap', [False, True])
def test_a_robot_walled_in_is_confirmed_no_path_and_one_with_a_way_out_refuted(gap):
    cfg = load_robot('steerable')
    planner = GoalPlanner(cfg, _walls(gap))
    goal = np.array([3.0, 0.0, 0.5])
    check = confirm_no_way(planner, goal, np.eye(3), NoWay.NO_PATH, cfg.start.base_pose)
    if not gap:
        assert check.verdict is Verdict.CONFIRMED, check.evidence
        return
    assert check.verdict is Verdict.REFUTED, check.evidence
    # the stance is outside the walls, where the base can stand
    assert check.base_pose[0] > 1.6 + planner.travel.radius
    assert planner.travel.obstacle_clearance(check.base_pose) >= planner.travel.margin
    assert check.clearance >= planner.stances.params.stance_margin


def test_a_blocked_start_is_unchecked_with_its_clearance(steerable):
    cfg, planner = steerable
    check = confirm_no_way(planner, [2.7, 0.0, 0.8], np.eye(3), NoWay.START_BLOCKED, cfg.start.base_pose)
    assert check.verdict is Verdict.UNCHECKED and 'not checked' in check.evidence
    assert math.isfinite(check.seconds) and check.as_dict()['verdict'] == 'unchecked'
