"""Joints outside the arm and the base (a head and its mimic visor; TIAGo's head and hand): held
where the robot YAML's ``held_joints`` puts them, in the kinematic, collision and workspace models,
the simulator, the viewer and ``/joint_states``; bad values fail with one line."""

import math
import re
from pathlib import Path

import numpy as np
import pybullet as p
import pytest
import yaml
from scipy.spatial.transform import Rotation

from sim_bridge.collision import SelfCollisionChecker
from sim_bridge.world import SimWorld
from urdf_factory import ARM_AXIS_XY, ARM_RADIUS, HEAD_MIMIC, HEAD_PAN, write_urdf
from wmm_control.cli import robot_setup
from wmm_control.errors import ConfigError
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.collision import CollisionModel
from wmm_control.kinematics.frames import JointTransforms
from wmm_control.kinematics.obstacles import Obstacle
from wmm_control.kinematics.workspace import Workspace
from wmm_control.robot_config import load_robot
from wmm_control.viewer.scene import RobotScene

HOME = [0.0, 0.3, 0.6, 0.0, 0.5, 0.0]
DEFAULT_PAN = HEAD_PAN['limits'][0]  # zero is below the limits: clipped up to the lower one


@pytest.fixture(scope='module')
def head_robot(tmp_path_factory):
    """The YAML ``wmm_robot init`` writes for a differential robot with a head."""
    folder = tmp_path_factory.mktemp('head')
    urdf = write_urdf(folder / 'head.urdf', 'differential', arm_joints=6, head=True)
    out = folder / 'head.yaml'
    robot_setup.init_robot(urdf, 'differential', 'arm_base_link', 'tool_link', out, home=HOME, pair_samples=50)
    return out


def _edited(robot_yaml: Path, folder: Path, **items) -> Path:
    """A copy of ``robot_yaml`` in ``folder`` with the ``robot`` items given (the URDF path made absolute)."""
    raw = yaml.safe_load(robot_yaml.read_text())
    raw['robot']['urdf'] = str(robot_yaml.parent / raw['robot']['urdf'])
    if 'package_dirs' in raw['robot']:
        raw['robot']['package_dirs'] = [str(robot_yaml.parent / d) for d in raw['robot']['package_dirs']]
    raw['robot'].update(items)
    folder.mkdir(parents=True, exist_ok=True)
    path = folder / 'robot.yaml'
    path.write_text(yaml.safe_dump(raw))
    return path


def _visor(pan):
    multiplier, offset = HEAD_MIMIC
    return multiplier * pan + offset


def _head_centre(pan):
    """The head sphere's centre (x, y) in the chassis frame at pan angle ``pan`` [m]."""
    ox, oy, _ = HEAD_PAN['origin']
    return ox + HEAD_PAN['reach'] * math.cos(pan), oy + HEAD_PAN['reach'] * math.sin(pan)


def test_init_writes_each_held_joint_at_its_zero_clipped_into_its_limits_and_check_prints_them(head_robot, capsys):
    text = head_robot.read_text()
    # the mimic visor follows the pan joint: a comment, not an entry
    assert yaml.safe_load(text)['robot']['held_joints'] == {'head_pan_joint': DEFAULT_PAN}
    assert '# head_visor_joint:' in text and 'follows head_pan_joint' in text
    cfg = load_robot(head_robot)
    assert cfg.held_joints == pytest.approx({'head_pan_joint': DEFAULT_PAN, 'head_visor_joint': _visor(DEFAULT_PAN)})
    assert robot_setup.main(['check', str(head_robot)]) == 0
    out = capsys.readouterr().out
    assert re.search(r'head_pan_joint\s+0\.250\s+rad', out), out
    assert re.search(rf'head_visor_joint\s+{_visor(DEFAULT_PAN):.3f}\s+rad \(mimic of head_pan_joint\)', out), out


BAD_HELD = {
    'unknown joint': ({'neck_joint': 0.0}, "held_joints: 'neck_joint' is not a joint of head.urdf"),
    'outside the limits': ({'head_pan_joint': 0.0}, 'held_joints.head_pan_joint: 0 is outside its limits [0.25, 2]'),
    'an arm joint': ({'arm_joint_2': 0.1}, "held_joints: 'arm_joint_2' is an arm or base joint"),
    'a wheel joint': ({'wheel_left_joint': 0.1}, "held_joints: 'wheel_left_joint' is an arm or base joint"),
    'a mimic joint': ({'head_visor_joint': 0.3}, "held_joints: 'head_visor_joint' mimics 'head_pan_joint'"),
    'a fixed joint': ({'arm_mount_joint': 0.0}, "held_joints: 'arm_mount_joint' is a fixed joint"),
    'not a number': ({'head_pan_joint': 'up'}, "held_joints.head_pan_joint: not a number: 'up'"),
    'not a mapping': ([0.3], 'held_joints: expected a mapping of joint names to positions'),
}


@pytest.mark.parametrize('kind', sorted(BAD_HELD))
def test_a_bad_held_joint_is_one_line_naming_the_file_and_the_item_and_exit_code_2(head_robot, tmp_path, capsys, kind):
    held, message = BAD_HELD[kind]
    path = _edited(head_robot, tmp_path, held_joints=held)
    with pytest.raises(ConfigError, match=re.escape(message)):
        load_robot(path)
    assert robot_setup.main(['check', str(path)]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and str(path) in err and message in err, err


def test_a_mimic_of_an_arm_joint_is_refused_in_one_line(tmp_path, capsys):
    urdf = write_urdf(tmp_path / 'r.urdf', 'differential', arm_joints=6, head=True)
    urdf.write_text(urdf.read_text().replace('<mimic joint="head_pan_joint"', '<mimic joint="arm_joint_2"'))
    args = ['init', str(urdf), '--base', 'differential', '--arm-root', 'arm_base_link', '--tool', 'tool_link']
    assert robot_setup.main([*args, '--out', str(tmp_path / 'r.yaml'), '--home', ','.join(map(str, HOME))]) == 2
    err = capsys.readouterr().err.strip()
    assert err.count('\n') == 0 and "joint 'head_visor_joint' mimics the arm joint 'arm_joint_2'" in err, err
    assert not (tmp_path / 'r.yaml').exists()


def _expected_link_poses(cfg, pan):
    """Every link's pose in the root frame by the URDF reader of TF (not pinocchio's, not
    PyBullet's): the arm at the start state, the pan joint at ``pan``, the visor following it."""
    positions = dict(zip(cfg.arm.joints, cfg.start.arm.tolist())) | {'head_pan_joint': pan}
    return JointTransforms(cfg.urdf_path).link_poses(positions)


def _pybullet_link_pose(world, link):
    cid = world.client_id
    for j in range(p.getNumJoints(world.body_id, physicsClientId=cid)):
        if p.getJointInfo(world.body_id, j, physicsClientId=cid)[12].decode() == link:
            state = p.getLinkState(world.body_id, j, computeForwardKinematics=1, physicsClientId=cid)
            return np.array(state[4]), Rotation.from_quat(state[5]).as_matrix()
    raise KeyError(link)


@pytest.mark.parametrize('pan', [None, 1.3])
def test_the_held_value_places_the_head_in_the_kinematic_model_the_simulator_and_the_viewer(head_robot, tmp_path, pan):
    path = head_robot if pan is None else _edited(head_robot, tmp_path, held_joints={'head_pan_joint': pan})
    cfg = load_robot(path)
    angle = DEFAULT_PAN if pan is None else pan
    expected = _expected_link_poses(cfg, angle)
    model = KinematicModel(cfg)
    model.update(cfg.start.base_pose, cfg.start.arm)  # the base at the origin: world = root frame
    world = SimWorld(cfg)
    try:
        for link in ('head_link', 'head_visor_link'):
            want = expected[link].matrix()
            for where, (position, rotation) in (
                ('kinematic model', model.frame_placement_world(link)),
                ('simulator', _pybullet_link_pose(world, link)),
            ):
                np.testing.assert_allclose(position, want[:3, 3], atol=1e-6, err_msg=f'{where}: {link}')
                np.testing.assert_allclose(rotation, want[:3, :3], atol=1e-6, err_msg=f'{where}: {link}')
        # the head turned by the held angle about z; the visor by the mimic's about its y after that
        head_rotation = model.frame_placement_world('head_link')[1]
        assert Rotation.from_matrix(head_rotation).as_euler('xyz')[2] == pytest.approx(angle)
        visor = head_rotation.T @ model.frame_placement_world('head_visor_link')[1]
        assert Rotation.from_matrix(visor).as_rotvec() == pytest.approx([0.0, _visor(angle), 0.0], abs=1e-9)
        names, held, rates = world.held_joint_state()
        assert dict(zip(names, held)) == pytest.approx({'head_pan_joint': angle, 'head_visor_joint': _visor(angle)})
        assert not rates.any()
    finally:
        world.close()
    scene = RobotScene(cfg.urdf_path, cfg.base_link, cfg.ee_frame, cfg.package_dirs, cfg.held_joints)
    scene.set_joints(cfg.arm.joints, cfg.start.arm)
    poses = scene.poses(np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))
    head = next(i for i, s in enumerate(scene.shapes) if s.name.startswith('head_link'))
    centre = expected['head_link'].matrix() @ np.array([HEAD_PAN['reach'], 0.0, HEAD_PAN['height'], 1.0])
    np.testing.assert_allclose(poses.positions[head], centre[:3], atol=1e-9)


def test_the_simulator_holds_the_head_under_physics(head_robot, tmp_path):
    """The base turns on the spot and the head is knocked aside: its servo takes it back."""
    cfg = load_robot(_edited(head_robot, tmp_path, held_joints={'head_pan_joint': 1.3}))
    world = SimWorld(cfg, base_mode='physics')
    try:
        world.set_command('wheel', [4.0, -4.0])
        for _ in range(20):
            world.step()
        names, held, _ = world.held_joint_state()
        np.testing.assert_allclose(held, [1.3, _visor(1.3)], atol=2e-3)
        cid = world.client_id
        pan = next(
            j
            for j in range(p.getNumJoints(world.body_id, physicsClientId=cid))
            if p.getJointInfo(world.body_id, j, physicsClientId=cid)[1] == b'head_pan_joint'
        )
        p.resetJointState(world.body_id, pan, 0.8, physicsClientId=cid)
        for _ in range(40):
            world.step()
        names, held, _ = world.held_joint_state()
        np.testing.assert_allclose(held, [1.3, _visor(1.3)], atol=2e-3)
        assert abs(world.base_pose()[2]) > 0.5
    finally:
        world.close()


@pytest.mark.parametrize('pan', [None, 1.0, 1.8])
def test_the_collision_model_measures_the_head_where_it_is_held(head_robot, tmp_path, pan):
    """The distance from the head's sphere to the arm's first link (a vertical cylinder) is the
    distance of the sphere's centre from the cylinder's axis less both radii."""
    items = {'collision': {'pairs': [['head_link', 'arm_link_1']]}}
    if pan is not None:
        items['held_joints'] = {'head_pan_joint': pan}
    cfg = load_robot(_edited(head_robot, tmp_path, **items))
    x, y = _head_centre(DEFAULT_PAN if pan is None else pan)
    expected = math.hypot(ARM_AXIS_XY[0] - x, ARM_AXIS_XY[1] - y) - HEAD_PAN['radius'] - ARM_RADIUS
    distance, pair = CollisionModel.from_robot(cfg).closest(cfg.start.arm, cfg.start.base_pose)
    assert set(pair) == {'head_link', 'arm_link_1'}
    assert distance == pytest.approx(expected, abs=1e-6)
    if pan is None:  # a model of the URDF alone holds the head at its defaults too
        alone = CollisionModel(cfg.urdf_path, cfg.arm.joints, margin=-np.inf, pairs=cfg.collision_pairs)
        assert alone.closest(cfg.start.arm)[0] == pytest.approx(expected, abs=1e-6)


def test_the_simulators_own_collision_check_sees_the_head_where_it_is_held(head_robot, tmp_path):
    """A small ball 0.1 m above the head's centre at pan 1.8 is 0.03 m from the head held there,
    and far from it held at 0.5."""
    ball = 0.02
    x, y = _head_centre(1.8)
    z = HEAD_PAN['origin'][2] + HEAD_PAN['height'] + 0.1
    found = {}
    for pan in (1.8, 0.5):
        cfg = load_robot(_edited(head_robot, tmp_path, held_joints={'head_pan_joint': pan}))
        centre = _expected_link_poses(cfg, pan)['chassis_link'].matrix() @ np.array([x, y, z, 1.0])
        obstacle = Obstacle('ball', 'sphere', (ball,), centre[:3], np.eye(3))
        with SelfCollisionChecker(cfg, margin=0.05, obstacles=[obstacle]) as checker:
            found[pan] = {a: d for a, b, d in checker.collisions(cfg.start.arm, np.zeros(3)) if b == 'ball'}
    assert found[1.8].keys() == {'head_link'}
    assert found[1.8]['head_link'] == pytest.approx(0.1 - HEAD_PAN['radius'] - ball, abs=1e-4)
    assert 'head_link' not in found[0.5]


def test_the_workspace_refuses_a_goal_inside_the_head_where_it_is_held(head_robot, tmp_path):
    """A goal at the head's centre lies inside the body at the pan angle the head is held at, and
    not at another one (the head has turned away)."""
    base = np.zeros(3)
    inside = {}
    for pan, other in ((0.5, 1.8), (1.8, 0.5)):
        cfg = load_robot(_edited(head_robot, tmp_path, held_joints={'head_pan_joint': pan}))
        workspace = Workspace(KinematicModel(cfg))
        poses = _expected_link_poses(cfg, pan)
        for angle in (pan, other):
            height = HEAD_PAN['origin'][2] + HEAD_PAN['height']
            centre = poses['chassis_link'].matrix() @ np.array([*_head_centre(angle), height, 1.0])
            inside[pan, angle] = workspace.body_part_at(centre[:3], base)
    assert inside[0.5, 0.5] and inside[0.5, 0.5].startswith('head_link')
    assert inside[1.8, 1.8] and inside[1.8, 1.8].startswith('head_link')
    assert inside[0.5, 1.8] is None and inside[1.8, 0.5] is None


def test_joint_states_and_tf_carry_the_held_joints(ros, head_robot, tmp_path):
    from ros_helpers import ScriptedController, overrides
    from sim_bridge.node import SimNode

    path = _edited(head_robot, tmp_path, held_joints={'head_pan_joint': 1.2})
    sim = ros.add(SimNode(context=ros.context, parameter_overrides=overrides(robot=str(path), timing='lockstep')))
    ctrl = ros.add(
        ScriptedController(ros.context, ('arm', 'wheel'), lambda t, js: {'arm': np.zeros(6), 'wheel': [1.0, 1.0]})
    )
    assert ros.spin_until(lambda: len(ctrl.joint_states) >= 5)
    positions = ctrl.positions()
    assert positions['head_pan_joint'] == pytest.approx(1.2)
    assert positions['head_visor_joint'] == pytest.approx(_visor(1.2))
    assert set(sim.world.robot.arm.joints) <= set(positions) and positions['wheel_left_joint'] > 0.0
    msg = ctrl.joint_states[-1]
    tfs = sim.frames.dynamic_transforms(msg.header.stamp, positions, sim.world.odom_pose(), sim.world.base_pose())
    head = next(m.transform.rotation for m in tfs if m.child_frame_id == 'head_link')
    assert Rotation.from_quat([head.x, head.y, head.z, head.w]).as_rotvec() == pytest.approx([0.0, 0.0, 1.2])


# ---------------------------------------------------------------- TIAGo (example-robot-data)
TIAGO_HOME = [0.15, 0.2, -1.34, -0.2, 1.94, -1.57, 1.37, 0.0]


def test_tiago_init_holds_its_head_and_fingers_and_a_held_value_turns_the_head(tiago_robots, tmp_path, monkeypatch):
    share = tiago_robots.parents[3]
    monkeypatch.delenv('ROS_PACKAGE_PATH', raising=False)
    urdf = tiago_robots / 'tiago.urdf'
    out = tmp_path / 'tiago.yaml'
    robot_setup.init_robot(
        urdf,
        'differential',
        'torso_fixed_link',
        'arm_tool_link',
        out,
        home=TIAGO_HOME,
        package_dirs=[share],
        pair_samples=0,
    )
    held = yaml.safe_load(out.read_text())['robot']['held_joints']
    assert {'head_1_joint', 'head_2_joint', 'hand_index_joint', 'hand_thumb_abd_joint'} <= set(held)
    assert not {'torso_lift_joint', 'arm_1_joint', 'wheel_left_joint'} & set(held)
    assert all(value == 0.0 for value in held.values())  # zero is within every one's limits
    cfg = load_robot(out)
    assert set(cfg.held_joints) == set(held)
    default = KinematicModel(cfg)
    default.update(np.zeros(3), cfg.start.arm)
    turned = KinematicModel(load_robot(_edited(out, tmp_path / 'turned', held_joints={**held, 'head_2_joint': -0.3})))
    turned.update(np.zeros(3), cfg.start.arm)
    relative = default.frame_placement_world('head_2_link')[1].T @ turned.frame_placement_world('head_2_link')[1]
    assert np.linalg.norm(Rotation.from_matrix(relative).as_rotvec()) == pytest.approx(0.3)
    np.testing.assert_allclose(default.ee_pose_world(), turned.ee_pose_world(), atol=1e-12)  # the arm is not the head's
