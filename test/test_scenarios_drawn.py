"""The planner's scenarios beside table_pillar: ``doorway`` (a wall with a 0.9 m doorway, goals in
the next room) and ``clutter`` (ten boxes drawn by the seed, none near the start pose), and the
goals ``wmm_randomized`` draws in them."""

import math

import numpy as np
import pytest

from sim_bridge.collision import SelfCollisionChecker
from wmm_control.errors import ConfigError
from wmm_control.experiments.randomized import sample_goals
from wmm_control.kinematics.obstacles import draw_boxes, is_drawn, load_obstacles, obstacle_text
from wmm_control.robot_config import load_robot

SPEC = {
    'count': 10,
    'size': [0.3, 0.8],
    'area': [0.8, 3.8, -1.8, 1.8],
    'keep_clear': {'centre': [0.0, 0.0], 'radius': 1.0},
    'floor': -0.4,
}


def _corners(box):
    """The box's footprint corners (x, y) in the world."""
    hx, hy = 0.5 * box.size[0], 0.5 * box.size[1]
    local = np.array([(hx, hy, 0.0), (hx, -hy, 0.0), (-hx, hy, 0.0), (-hx, -hy, 0.0)])
    return (local @ box.rotation.T + box.position)[:, :2]


@pytest.mark.parametrize('seed', [0, 1, 7])
def test_clutter_is_ten_boxes_of_its_sizes_drawn_by_the_seed_clear_of_the_start(seed):
    boxes = load_obstacles('clutter', seed)
    assert len(boxes) == 10 and all(b.shape == 'box' for b in boxes)
    for box in boxes:
        height = box.position[2] + 0.5 * box.size[2]  # its top above z = 0
        assert 0.3 <= box.size[0] <= 0.8 and 0.3 <= box.size[1] <= 0.8 and 0.3 <= height <= 0.8
        assert box.position[2] - 0.5 * box.size[2] == pytest.approx(-0.4)  # on the lowest floor
        assert 0.8 <= box.position[0] <= 3.8 and -1.8 <= box.position[1] <= 1.8
        assert np.min(np.linalg.norm(_corners(box), axis=1)) >= 1.0  # nothing near the start pose
    again = load_obstacles('clutter', seed)
    assert all(np.array_equal(a.position, b.position) and a.size == b.size for a, b in zip(boxes, again))
    other = load_obstacles('clutter', seed + 1)
    assert not np.allclose([b.position for b in boxes], [b.position for b in other])


def test_a_draw_written_as_a_file_is_the_same_obstacles(tmp_path):
    assert is_drawn('clutter') and not is_drawn('table_pillar') and not is_drawn('')
    path = tmp_path / 'clutter_3.yaml'
    path.write_text(obstacle_text('clutter', 3))
    assert not is_drawn(path)
    for a, b in zip(load_obstacles('clutter', 3), load_obstacles(path), strict=True):
        assert a.name == b.name and np.allclose(a.size, b.size, atol=1e-6)
        assert np.allclose(a.position, b.position, atol=1e-6) and np.allclose(a.rotation, b.rotation, atol=1e-5)


@pytest.mark.parametrize(
    'change',
    [
        {'count': -1},
        {'count': 2.5},
        {'size': [0.8, 0.3]},
        {'area': [3.8, 0.8, -1.8, 1.8]},
        {'keep_clear': {'centre': [0.0, 0.0]}},
        {'floor': 1.0},
        {'size': [0.3, math.nan]},
        {'extra': 1},
    ],
)
def test_a_bad_random_boxes_entry_is_refused(change):
    with pytest.raises(ConfigError, match='random_boxes'):
        draw_boxes({**SPEC, **change}, 0)


def test_an_area_with_no_room_clear_of_the_start_is_refused():
    with pytest.raises(ConfigError, match='keep_clear'):
        draw_boxes({**SPEC, 'area': [-0.5, 0.5, -0.5, 0.5], 'keep_clear': {'centre': [0.0, 0.0], 'radius': 3.0}}, 0)


def test_the_doorway_is_0_9_m_wide_and_the_goals_are_beyond_it():
    walls = load_obstacles('doorway')
    inner = sorted(abs(b.position[1]) - 0.5 * b.size[1] for b in walls)
    assert inner == pytest.approx([0.45, 0.45])  # each wall stops 0.45 m from the doorway's middle
    x_wall = max(b.position[0] + 0.5 * b.size[0] for b in walls)
    cfg = load_robot('steerable')
    goals = sample_goals(cfg, 5, seed=0, obstacles='doorway')
    assert all(g.base_pose[0] > x_wall for g in goals)  # the goals' bases in the next room


@pytest.mark.parametrize('obstacles', ['doorway', 'clutter'])
def test_the_goals_drawn_are_of_configurations_clear_of_the_obstacles(obstacles):
    cfg = load_robot('panda_diff')
    goals = sample_goals(cfg, 5, seed=0, obstacles=obstacles)
    with SelfCollisionChecker(cfg, margin=0.0, obstacles=load_obstacles(obstacles)) as checker:
        for goal in goals:
            assert not checker.collisions(goal.q_arm, goal.base_pose)
