"""Workspace: goals below the floor, above the arm's reach or inside the base are impossible."""

import numpy as np
import pytest

from wmm_control.experiments.scenario import load_scenario
from wmm_control.kinematics.workspace import Workspace
from wmm_control.paths import config_path


@pytest.fixture(scope='module')
def workspaces(steerable_model, mecanum_model):
    return {
        'steerable': (steerable_model, Workspace(steerable_model)),
        'mecanum': (mecanum_model, Workspace(mecanum_model)),
    }


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_the_height_bound_is_never_passed_by_any_arm_configuration(workspaces, robot):
    model, ws = workspaces[robot]
    rng = np.random.default_rng(3)
    arm = model.config.arm
    heights = []
    for _ in range(3000):
        model.update(
            [0.0, 0.0, 0.0], rng.uniform(np.maximum(arm.position_lower, -np.pi), np.minimum(arm.position_upper, np.pi))
        )
        heights.append(model.ee_placement_world()[0][2])
    # An upper bound, and not a loose one: random postures come within a quarter of the arm's length.
    assert max(heights) <= ws.max_height
    assert max(heights) > ws.max_height - 0.3


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_the_start_pose_and_every_scenario_goal_are_possible(workspaces, robot):
    model, ws = workspaces[robot]
    cfg = model.config
    model.update(cfg.start.base_pose, cfg.start.arm)
    assert ws.impossible(model.ee_placement_world()[0], cfg.start.base_pose) == ''
    for path in sorted(config_path('scenarios').glob('*.yaml')):
        scenario = load_scenario(str(path))
        if scenario.robot in (robot, cfg.name):
            for goal in scenario.goals:
                assert ws.impossible(goal.pose[:3]) == '', (path.name, goal.pose)


def test_points_inside_the_chassis_follow_the_base_pose(workspaces):
    _, ws = workspaces['steerable']
    assert 'chassis' in ws.impossible([0.0, 0.0, 0.35], [0.0, 0.0, 0.0])
    assert ws.impossible([0.0, 0.0, 0.35], [2.0, 0.0, 0.0]) == ''
    # The chassis is 0.6 m long and 0.5 m wide: turned by 90°, its x extent is 0.25 m.
    assert ws.body_part_at([2.28, 0.0, 0.35], [2.0, 0.0, 0.0]) is not None
    assert ws.body_part_at([2.28, 0.0, 0.35], [2.0, 0.0, np.pi / 2]) is None
    assert ws.body_part_at([2.0, 0.28, 0.35], [2.0, 0.0, np.pi / 2]) is not None


def test_floor_and_height_reasons_name_the_numbers(workspaces):
    _, ws = workspaces['mecanum']
    assert 'below the floor (z = -0.4 m)' in ws.impossible([1.0, 0.0, -0.5])
    assert 'above the highest' in ws.impossible([1.0, 0.0, 5.0])


def test_the_footprint_holds_every_base_box_and_no_more(model):
    from wmm_control.kinematics.workspace import Workspace

    workspace = Workspace(model)
    corners = workspace.footprint()
    assert corners.shape == (4, 2) and np.all(np.isfinite(corners))
    (x0, y0), (x1, y1) = corners[0], corners[2]
    assert x0 < 0.0 < x1 and y0 < 0.0 < y1
    touched = set()
    for _name, rot, centre, half in workspace.boxes:
        signs = np.array([[sx, sy, sz] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])
        xy = (centre + (signs * half) @ rot.T)[:, :2]
        assert np.all(xy >= [x0 - 1e-12, y0 - 1e-12]) and np.all(xy <= [x1 + 1e-12, y1 + 1e-12])
        touched |= {i for i, v in enumerate((x0, y0)) if np.any(np.isclose(xy[:, i], v))}
        touched |= {i + 2 for i, v in enumerate((x1, y1)) if np.any(np.isclose(xy[:, i], v))}
    assert touched == {0, 1, 2, 3}, 'each side of the rectangle touches a box'
