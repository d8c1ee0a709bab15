"""The viewer's ROS-free parts: the scene from a URDF, its forward kinematics, paths, the status
panel, the goal drag, the choice of the base pose, and the page drawn on a served scene."""

import math
import socket
from types import SimpleNamespace

import numpy as np
import pytest

from wmm_control.errors import ConfigError, NonFiniteError, UnknownFrameError
from wmm_control.kinematics import KinematicModel
from wmm_control.robot_config import load_robot
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.viewer.browser import BrowserScene
from wmm_control.viewer.drag import GoalDrag
from wmm_control.viewer.inputs import BaseCourse, BasePose, inputs_markdown
from wmm_control.viewer.scene import RobotScene, Trail, finite_pose, unit_wxyz, wxyz_from_xyzw, xyzw_from_wxyz
from wmm_control.viewer.status import NodeStatus, StatusBoard

# A URDF of no robot of this package: a mesh, a prismatic and a continuous joint, a base link
# that is not the root, and no colour.
URDF = """<robot name="odd">
  <material name="teal"><color rgba="0 0.5 0.5 0.6"/></material>
  <link name="root"><visual><geometry><mesh filename="part.stl" scale="2 1 1"/></geometry></visual></link>
  <link name="body"><visual><origin xyz="0 0 0.1"/><geometry><box size="0.4 0.2 0.1"/></geometry>
    <material name="teal"/></visual></link>
  <link name="slider"><visual><geometry><sphere radius="0.05"/></geometry></visual></link>
  <link name="wheel"><visual><origin rpy="1.5707963 0 0"/><geometry><cylinder radius="0.1" length="0.04"/></geometry>
    </visual></link>
  <link name="tip"/>
  <joint name="mount" type="fixed"><parent link="root"/><child link="body"/><origin xyz="0 0 0.5"/></joint>
  <joint name="slide" type="prismatic"><parent link="body"/><child link="slider"/><axis xyz="1 0 0"/>
    <limit lower="-1" upper="1" effort="1" velocity="1"/></joint>
  <joint name="spin" type="continuous"><parent link="slider"/><child link="wheel"/><axis xyz="0 0 1"/>
    <origin xyz="0 0 0.2"/></joint>
  <joint name="tip_joint" type="fixed"><parent link="wheel"/><child link="tip"/><origin xyz="0.3 0 0"/></joint>
</robot>
"""


@pytest.fixture
def odd_urdf(tmp_path):
    import trimesh

    trimesh.creation.box((0.2, 0.1, 0.05)).export(tmp_path / 'part.stl')
    path = tmp_path / 'odd.urdf'
    path.write_text(URDF)
    return path


def yaw_quat(theta):
    return np.array([math.cos(theta / 2), 0.0, 0.0, math.sin(theta / 2)])


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_every_visual_of_the_urdf_is_a_shape_in_its_colour(robot):
    cfg = load_robot(robot)
    scene = RobotScene(cfg.urdf_path, cfg.base_link, cfg.ee_frame)
    visuals = cfg.urdf_path.read_text().count('<visual')
    assert len(scene.shapes) == visuals and not scene.skipped
    assert {s.kind for s in scene.shapes} == {'box', 'cylinder', 'sphere'}
    if robot == 'steerable':
        assert (255, 115, 0) in {s.color for s in scene.shapes}  # the URDF's orange, 1 0.45 0
        chassis = next(s for s in scene.shapes if s.name.startswith('chassis_link') and s.kind == 'box')
        assert chassis.size == pytest.approx((0.6, 0.5, 0.3))
    # Every wheel-side joint is there, and every arm joint.
    assert set(cfg.arm.joints) | set(cfg.base.joints) <= set(scene.joint_names)


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_the_end_effector_is_where_the_kinematic_model_puts_it(robot):
    cfg = load_robot(robot)
    scene = RobotScene(cfg.urdf_path, cfg.base_link, cfg.ee_frame)
    model = KinematicModel(robot)
    rng = np.random.default_rng(3)
    for _ in range(5):
        q = rng.uniform(np.maximum(cfg.arm.position_lower, -math.pi), np.minimum(cfg.arm.position_upper, math.pi))
        base = rng.uniform([-3, -3, -math.pi], [3, 3, math.pi])
        assert scene.set_joints(cfg.arm.joints, q) == []
        poses = scene.poses((base[0], base[1], 0.0), yaw_quat(base[2]))
        model.update(base, q)
        pos, rot = model.ee_placement_world()
        assert poses.ee_position == pytest.approx(pos, abs=1e-9)
        w, x, y, z = poses.ee_wxyz
        expected = np.array(
            [
                [1 - 2 * (y * y + z * z), 2 * (x * y - w * z), 2 * (x * z + w * y)],
                [2 * (x * y + w * z), 1 - 2 * (x * x + z * z), 2 * (y * z - w * x)],
                [2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)],
            ]
        )
        assert expected == pytest.approx(rot, abs=1e-9)


def test_wheel_and_steer_joints_move_their_shapes():
    cfg = load_robot('steerable')
    scene = RobotScene(cfg.urdf_path, cfg.base_link, cfg.ee_frame)
    index = [i for i, s in enumerate(scene.shapes) if s.name.startswith('wheel_fl_link')][0]
    still = scene.poses((0, 0, 0), (1, 0, 0, 0))
    scene.set_joints(['steer_fl_joint', 'drive_fl_joint'], [0.7, 12.0])
    turned = scene.poses((0, 0, 0), (1, 0, 0, 0))
    assert abs(np.dot(still.wxyz[index], turned.wxyz[index])) < 0.99
    assert scene.joint_positions()['drive_fl_joint'] == pytest.approx(12.0 - 4 * math.pi)  # an angle
    # Only the wheel's and steer link's shapes moved.
    moved = {
        scene.shapes[i].name for i in range(len(scene.shapes)) if abs(np.dot(still.wxyz[i], turned.wxyz[i])) < 1 - 1e-12
    }
    assert moved == {'wheel_fl_link_0', 'steer_fl_link_0'}


def test_a_base_pose_moves_and_turns_the_whole_robot():
    cfg = load_robot('mecanum')
    scene = RobotScene(cfg.urdf_path, cfg.base_link, cfg.ee_frame)
    home = scene.poses((0, 0, 0), (1, 0, 0, 0))
    moved = scene.poses((1.0, 2.0, 0.0), yaw_quat(math.pi / 2))
    # (x, y) → (1 − y, 2 + x) for every shape.
    expected = np.column_stack((1.0 - home.positions[:, 1], 2.0 + home.positions[:, 0], home.positions[:, 2]))
    assert moved.positions == pytest.approx(expected, abs=1e-12)


def test_any_urdf_mesh_prismatic_continuous_and_a_base_link_that_is_not_the_root(odd_urdf):
    scene = RobotScene(odd_urdf, base_link='body', ee_frame='tip')
    kinds = {s.name.rsplit('_', 1)[0]: s for s in scene.shapes}
    assert {k: s.kind for k, s in kinds.items()} == {
        'root': 'mesh',
        'body': 'box',
        'slider': 'sphere',
        'wheel': 'cylinder',
    }
    mesh = kinds['root']
    assert mesh.vertices.shape == (8, 3) and mesh.faces.shape == (12, 3)
    assert np.ptp(mesh.vertices, axis=0) == pytest.approx([0.4, 0.1, 0.05])  # scaled by the URDF
    assert kinds['body'].color == (0, 128, 128) and kinds['body'].opacity == pytest.approx(0.6)
    assert kinds['wheel'].size == pytest.approx((0.1, 0.04))
    assert set(scene.joint_names) == {'slide', 'spin'}
    assert scene.set_joints(['slide', 'spin', 'not_a_joint'], [0.25, math.pi / 2, 3.0]) == ['not_a_joint']
    poses = scene.poses((0.0, 0.0, 0.0), (1, 0, 0, 0))
    # body at the world origin; the slider 0.25 along x; the tip 0.3 along the spun wheel's x (now y).
    assert poses.ee_position == pytest.approx([0.25, 0.3, 0.2], abs=1e-9)
    body = next(i for i, s in enumerate(scene.shapes) if s.name.startswith('body'))
    assert poses.positions[body] == pytest.approx([0.0, 0.0, 0.1])
    root = next(i for i, s in enumerate(scene.shapes) if s.name.startswith('root'))
    assert poses.positions[root] == pytest.approx([0.0, 0.0, -0.5])


def test_bad_input_is_refused_and_changes_nothing(odd_urdf):
    scene = RobotScene(odd_urdf, base_link='body', ee_frame='tip')
    scene.set_joints(['slide'], [0.1])
    with pytest.raises(NonFiniteError):
        scene.set_joints(['slide', 'spin'], [0.5, math.nan])
    assert scene.joint_positions()['slide'] == pytest.approx(0.1)
    with pytest.raises(ValueError):
        scene.set_joints(['slide'], [0.1, 0.2])
    for bad in (((0, 0, math.inf), (1, 0, 0, 0)), ((0, 0, 0), (0, 0, 0, 0)), ((0, 0, 0), (math.nan, 0, 0, 1))):
        with pytest.raises(NonFiniteError):
            scene.poses(*bad)
    with pytest.raises(UnknownFrameError, match='nowhere'):
        RobotScene(odd_urdf, base_link='nowhere', ee_frame='tip')
    broken = odd_urdf.with_name('broken.urdf')
    broken.write_text('<robot name="x"><link name="a"></robot>')
    with pytest.raises(ConfigError, match='broken.urdf'):
        RobotScene(broken)


def test_quaternion_helpers():
    assert wxyz_from_xyzw((1, 2, 3, 4)).tolist() == [4, 1, 2, 3]
    assert xyzw_from_wxyz((4, 1, 2, 3)).tolist() == [1, 2, 3, 4]
    assert unit_wxyz((2, 0, 0, 0)).tolist() == [1, 0, 0, 0]
    assert unit_wxyz((1e300, 1e300, 0, 0)) == pytest.approx([math.sqrt(0.5), math.sqrt(0.5), 0, 0])
    assert unit_wxyz((0, 0, 0, 0)) is None and unit_wxyz((math.inf, 0, 0, 0)) is None
    position, wxyz = finite_pose([1, 2, 3], (0, 0, 0, 2))
    assert position.tolist() == [1, 2, 3] and wxyz.tolist() == [0, 0, 0, 1]
    assert finite_pose((1, 2, math.nan), (1, 0, 0, 0)) is None and finite_pose((1, 2), (1, 0, 0, 0)) is None
    assert finite_pose((1, 2, 3), (0, 0, 0, 0)) is None


def test_a_trail_keeps_points_a_step_apart_and_at_most_its_length():
    trail = Trail(max_points=4, min_step=0.1)
    assert trail.add((0, 0, 0)) and not trail.add((0.05, 0, 0)) and not trail.add((math.nan, 0, 0))
    for x in (0.15, 0.3, 0.45, 0.6):
        assert trail.add((x, 0, 0))
    assert len(trail) == 4 and trail.points[:, 0] == pytest.approx([0.15, 0.3, 0.45, 0.6])
    segments = trail.segments()
    assert segments.shape == (3, 2, 3) and segments[0, 1] == pytest.approx(segments[1, 0])
    trail.clear()
    assert trail.segments().shape == (0, 2, 3)
    with pytest.raises(ValueError):
        Trail(1, 0.1)


def test_a_drag_publishes_at_release_and_at_most_once_per_period_while_it_goes_on():
    drag = GoalDrag(period=0.5)
    drag.start()
    assert drag.due(0.0) is None
    assert drag.update((1, 0, 0), (1, 0, 0, 0), now=0.0)
    assert drag.due(0.2) is None  # not yet a period
    drag.update((2, 0, 0), (1, 0, 0, 0), now=0.4)
    position, wxyz = drag.due(0.5)  # a period into the drag: the latest
    assert position.tolist() == [2, 0, 0] and wxyz.tolist() == [1, 0, 0, 0]
    assert drag.due(0.6) is None  # nothing new
    drag.update((3, 0, 0), (2, 0, 0, 0), now=0.7)
    drag.end((4, 0, 0), (0, 0, 0, 2), now=0.8)
    position, wxyz = drag.due(0.8)  # the release: at once
    assert position.tolist() == [4, 0, 0] and wxyz.tolist() == [0, 0, 0, 1] and not drag.dragging
    assert drag.due(5.0) is None
    # Not a pose: ignored, nothing to publish.
    assert not drag.update((math.nan, 0, 0), (1, 0, 0, 0), now=6.0)
    assert not drag.update((0, 0, 0), (0, 0, 0, 0), now=6.0)
    drag.end((0, 0, math.inf), (1, 0, 0, 0), now=6.1)
    assert drag.due(6.1) is None and drag.due(9.0) is None


def test_the_handles_events_start_update_and_end_a_drag():
    drag = GoalDrag(period=10.0)
    drag.event('start', (9, 9, 9), (1, 0, 0, 0), now=0.0)  # a grab takes no pose
    assert drag.dragging and drag.due(20.0) is None
    drag.event('update', (1, 0, 0), (1, 0, 0, 0), now=1.0)
    assert drag.due(2.0) is None  # within the period
    drag.event('end', (2, 0, 0), (1, 0, 0, 0), now=3.0)
    assert not drag.dragging and drag.due(3.0)[0].tolist() == [2, 0, 0]


def test_the_status_panel_shows_what_the_diagnostics_say():
    board = StatusBoard()
    assert 'No /diagnostics' in board.markdown(0.0)
    board.update(
        NodeStatus(
            'wmm_sim: arm commands',
            1,
            'no fresh command (zero velocity)',
            {'clamped': '0', 'rejected': '2', 'command_age_s': 'inf'},
            received=0.0,
        )
    )
    board.update(
        NodeStatus(
            'redundancy_resolver',
            0,
            'mobile_manipulation',
            {
                'method': 'task_sharing',
                'mode': 'mobile_manipulation',
                'psi': '0.512345678',
                'sigma_min': '0.0321',
                'position_error_m': '0.25',
                'orientation_error_rad': '0.1',
                'goal_reached': 'False',
                'goal_stalled': 'False',
                'cycle_time_us': '812.5',
                'limit_scale': '0.75',
                'arm_command': '[0, 0]',
                'clearance_m': '0.04321',
                'closest_pair': 'arm_link_7/chassis_link',
                'collision_changed': 'True',
                'binding_self': '2',
                'binding_floor': '0',
                'binding_obstacle': '37',
                'binding_base_along_path': '5',
                'relaxed_cycles': '1',
            },
            received=9.0,
        )
    )
    board.update(NodeStatus('swmr_controller', 2, 'solver_failure', {'status': 'solver_failure'}, received=9.0))
    text = board.markdown(10.0)
    # The resolver first, then the controller, then the simulator.
    assert text.index('**redundancy_resolver**') < text.index('**swmr_controller**') < text.index('**wmm_sim')
    for shown in (
        '| method | task_sharing |',
        '| ψ (task sharing) | 0.5123 |',
        '| σ_min | 0.0321 |',
        '| position error [m] | 0.25 |',
        '| goal reached | False |',
        '| cycle time [µs] | 812.5 |',
        '| task scale α / s_v | 0.75 |',
        '**swmr_controller** — ERROR: solver_failure',
        '| clearance [m] | 0.04321 |',
        '| closest pair | arm_link_7/chassis_link |',
        '| avoiding contact | True |',
        '| limits that shaped it [cycles] | obstacle 37, base along path 5, self 2 |',
        '| limits relaxed [cycles] | 1 |',
        '| command age [s] | inf |',
        'WARN, 10 s old: no fresh command (zero velocity)',
    ):
        assert shown in text, shown
    assert 'arm_command' not in text and 'floor' not in text
    # no limit bound yet: said so; a status without the counts has no such row
    board.update(NodeStatus('redundancy_resolver', 0, 'no goal', {'binding_obstacle': '0'}, received=10.0))
    assert '| limits that shaped it [cycles] | none |' in board.markdown(10.0)
    assert 'limits that shaped it' not in board.markdown(10.0).split('**swmr_controller**')[1]
    # A newer status of the same name replaces the old one.
    board.update(NodeStatus('swmr_controller', 0, 'tracking', {'status': 'tracking'}, received=10.0))
    assert 'solver_failure' not in board.markdown(10.0) and len(board) == 3


def test_the_base_is_drawn_at_the_ground_truth_while_it_is_fresh_else_at_the_odometry():
    base = BasePose(timeout=0.5)
    assert base.source(0.0) == 'none'
    position, wxyz = base.pose(0.0)
    assert position.tolist() == [0, 0, 0] and wxyz.tolist() == [1, 0, 0, 0]  # the origin
    base.take('ground_truth', np.array([1.0, 0, 0]), np.array([1.0, 0, 0, 0]), now=1.0)
    assert base.source(1.2) == 'ground_truth'
    assert base.source(2.0) == 'ground_truth'  # stale, but nothing else to draw
    base.take('odom', np.array([2.0, 0, 0]), np.array([1.0, 0, 0, 0]), now=2.0)
    assert base.source(2.0) == 'odom' and base.pose(2.0)[0].tolist() == [2, 0, 0]
    base.take('ground_truth', np.array([3.0, 0, 0]), np.array([1.0, 0, 0, 0]), now=3.0)
    assert base.pose(3.4)[0].tolist() == [3, 0, 0]
    base.set_timeout(0.1)
    assert base.source(3.4) == 'odom'


def test_the_base_course_is_the_reference_twist_turned_into_the_world_while_fresh():
    course = BaseCourse(hold=1.0)
    quarter = np.array([math.cos(math.pi / 4), 0.0, 0.0, math.sin(math.pi / 4)])  # yaw 90°
    assert course.velocity(quarter, 0.0) is None  # no twist yet
    course.take(np.array([0.2, 0.1, 0.5]), now=0.0)
    assert course.velocity(quarter, 0.5) == pytest.approx([-0.1, 0.2])
    assert course.velocity(quarter, 1.5) is None  # older than a second
    course.take(np.array([math.nan, 0.0, 0.0]), now=2.0)  # ignored
    assert course.velocity(quarter, 2.0) is None
    course.take(np.array([0.0, 0.0, 0.7]), now=2.0)
    assert course.velocity(quarter, 2.0) is None  # turning on the spot: nowhere to head


def test_the_inputs_panel_says_how_old_the_joint_states_are_and_where_the_base_comes_from():
    assert inputs_markdown(math.inf, 'none', 0, 0) == (
        '- joint states: never\n- base pose from none yet (drawn at the origin)\n'
        '- joint states rejected: 0\n- goals sent: 0'
    )
    text = inputs_markdown(0.123, 'odom', 2, 5)
    assert '0.12 s ago' in text and 'odometry (/odom)' in text and 'rejected: 2' in text and 'sent: 5' in text


def test_a_diagnostic_status_message_becomes_a_node_status():
    kv = SimpleNamespace(key='psi', value='0.5')
    for level in (b'\x02', 2):
        status = NodeStatus.of(SimpleNamespace(name='r', level=level, message='m', values=[kv]), received=4.0)
        assert status == NodeStatus('r', 2, 'm', {'psi': '0.5'}, 4.0)


def _free_port():
    with socket.socket() as sock:
        sock.bind(('127.0.0.1', 0))
        return sock.getsockname()[1]


def test_the_page_places_the_handle_draws_the_goal_course_and_obstacles_and_takes_hold():
    config = load_robot('steerable')
    scene = RobotScene(config.urdf_path, config.base_link, config.ee_frame)
    trails = (Trail(10, 0.01), Trail(10, 0.01))
    events = []
    page = BrowserScene('127.0.0.1', _free_port(), scene.shapes, 0.0, (1.0, 2.0), trails, events.append, '*none*')
    try:
        assert len(page.shape_handles) == len(scene.shapes)
        poses = scene.poses((1.0, 2.0, 0.0), (1.0, 0.0, 0.0, 0.0))
        page.draw_robot(poses, (1.0, 2.0, 0.0), joints_known=False)
        assert np.asarray(page.goal_handle.position) == pytest.approx([0, 0, 0])  # no joint states yet
        assert np.asarray(page.shape_handles[0].position) == pytest.approx(poses.positions[0])
        page.draw_robot(poses, (1.0, 2.0, 0.0), joints_known=True)
        assert np.asarray(page.goal_handle.position) == pytest.approx(poses.ee_position)
        goal = np.array([2.0, 0.5, 0.8])
        page.show_goal(goal, np.array([1.0, 0, 0, 0]), move_handle=False)  # a drag goes on
        assert page.goal_frame.visible and np.asarray(page.goal_frame.position) == pytest.approx(goal)
        assert np.asarray(page.goal_handle.position) == pytest.approx(poses.ee_position)
        page.show_goal(goal, np.array([1.0, 0, 0, 0]), move_handle=True)
        assert np.asarray(page.goal_handle.position) == pytest.approx(goal)
        assert '(2.000, 0.500, 0.800)' in page.goal_text.content
        page.draw_robot(scene.poses((1.5, 2.0, 0.0), (1.0, 0.0, 0.0, 0.0)), (1.5, 2.0, 0.0), joints_known=True)
        assert np.asarray(page.goal_handle.position) == pytest.approx(goal)  # a goal is known: it stays
        assert len(trails[1]) == 2 and trails[1].points[:, 2] == pytest.approx(0.005)
        page.draw_course((1.0, 2.0, 0.0), np.array([0.3, -0.1]))
        assert page.base_course.visible
        np.testing.assert_allclose(np.asarray(page.base_course.points)[0], [[1.0, 2.0, 0.01], [1.3, 1.9, 0.01]])
        page.draw_course((1.0, 2.0, 0.0), None)
        assert not page.base_course.visible
        box = Obstacle('table', 'box', (1.0, 0.5, 0.2), np.array([1.5, 0.0, 0.3]), np.eye(3))
        page.draw_obstacles([box, Obstacle('post', 'sphere', (0.1,), np.zeros(3), np.eye(3))])
        page.draw_obstacles([box])  # drawn anew
        assert [h.name for h in page.obstacle_handles] == ['/obstacles/table']
        assert not page.hold_pressed()
        page._hold.set()  # as the button's click does
        assert page.hold_pressed() and not page.hold_pressed()
    finally:
        page.stop()
    page.stop()  # a second stop does nothing
