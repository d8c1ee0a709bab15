"""The robot's TF frames from joint values (ROS-free): every link's pose composed from the
per-joint transforms equals pinocchio's forward kinematics of the same URDF, for every robot the
package ships and for made-up ones (3 and 6 steer modules, a prismatic lift, a differential base)."""

import math

import numpy as np
import pinocchio as pin
import pytest

from urdf_factory import write_urdf
from wmm_control.errors import ConfigError, NonFiniteError
from wmm_control.geometry import continuous_to_q
from wmm_control.kinematics.frames import (
    FrameTransform,
    JointTransforms,
    compose,
    planar_transform,
    quaternion_from_matrix,
    world_to_odom,
)
from wmm_control.robot_config import load_robot, robot_names


def _pinocchio_link_poses(urdf, positions):
    """Every body frame's placement in the root link's frame, by pinocchio (fixed base)."""
    model = pin.buildModelFromUrdf(str(urdf))
    data = model.createData()
    q = pin.neutral(model)
    for joint_id in range(1, model.njoints):
        joint = model.joints[joint_id]
        value = positions.get(model.names[joint_id], 0.0)
        if joint.nq == 2:  # continuous: cos, sin
            q[joint.idx_q : joint.idx_q + 2] = continuous_to_q(value)
        else:
            q[joint.idx_q] = value
    pin.framesForwardKinematics(model, data, q)
    return {f.name: data.oMf[i] for i, f in enumerate(model.frames) if f.type == pin.FrameType.BODY}


def _urdfs(tmp_path_factory):
    shipped = [load_robot(name).urdf_path for name in robot_names()]
    work = tmp_path_factory.mktemp('urdfs')
    made = [
        write_urdf(work / 'three.urdf', 'steerable', modules=3, arm_joints=6),
        write_urdf(work / 'six_lift.urdf', 'steerable', modules=6, arm_joints=7, prismatic_lift=True),
        write_urdf(work / 'diff.urdf', 'differential', arm_joints=7),
        write_urdf(work / 'mecanum.urdf', 'mecanum', arm_joints=6),
    ]
    return shipped + made


@pytest.fixture(scope='module')
def urdfs(tmp_path_factory):
    return _urdfs(tmp_path_factory)


def test_every_link_pose_equals_pinocchio_forward_kinematics(urdfs):
    rng = np.random.default_rng(3)
    for urdf in urdfs:
        frames = JointTransforms(urdf)
        assert frames.moving_joints, urdf
        for _ in range(5):
            positions = {name: float(rng.uniform(-3.0, 3.0)) for name in frames.moving_joints}
            ours = frames.link_poses(positions)
            theirs = _pinocchio_link_poses(urdf, positions)
            assert set(theirs) <= set(ours), (urdf, sorted(set(theirs) - set(ours)))
            for link, placement in theirs.items():
                m = ours[link].matrix()
                np.testing.assert_allclose(m[:3, 3], placement.translation, atol=1e-9, err_msg=f'{urdf} {link}')
                np.testing.assert_allclose(m[:3, :3], placement.rotation, atol=1e-9, err_msg=f'{urdf} {link}')


def test_fixed_joints_are_static_and_moving_ones_follow_the_joint_state():
    robot = load_robot('steerable')
    frames = JointTransforms(robot.urdf_path)
    fixed_children = {tf.child for tf in frames.fixed}
    assert robot.ee_frame in fixed_children  # the tool is a fixed joint: static
    assert set(robot.arm.joints) | set(robot.base.joints) <= set(frames.moving_joints)
    half = frames.moving({robot.arm.joints[0]: 0.5})
    assert [tf.child for tf in half] == [next(t.child for t in frames.moving({robot.arm.joints[0]: 0.0}))]
    assert frames.moving({'no_such_joint': 1.0}) == []
    with pytest.raises(NonFiniteError):
        frames.moving({robot.arm.joints[0]: math.nan})
    for tf in (*frames.fixed, *half):
        assert np.linalg.norm(tf.quaternion) == pytest.approx(1.0) and np.all(np.isfinite(tf.translation))


def test_a_mimic_joint_follows_its_leader_with_multiplier_and_offset(tmp_path):
    path = tmp_path / 'gripper.urdf'
    path.write_text(
        '<robot name="g"><link name="base"/><link name="left"/><link name="right"/>'
        '<joint name="finger" type="prismatic"><parent link="base"/><child link="left"/>'
        '<axis xyz="0 2 0"/><limit lower="0" upper="0.04" effort="1" velocity="1"/></joint>'
        '<joint name="finger_mirror" type="prismatic"><parent link="base"/><child link="right"/>'
        '<origin xyz="0 0 0.1"/><axis xyz="0 1 0"/><mimic joint="finger" multiplier="-1" offset="0.01"/>'
        '<limit lower="-0.04" upper="0" effort="1" velocity="1"/></joint></robot>'
    )
    frames = JointTransforms(path)
    poses = frames.link_poses({'finger': 0.03})
    np.testing.assert_allclose(poses['left'].translation, [0.0, 0.03, 0.0], atol=1e-12)  # axis normalised
    np.testing.assert_allclose(poses['right'].translation, [0.0, -0.02, 0.1], atol=1e-12)
    bad = tmp_path / 'bad.urdf'
    bad.write_text(
        '<robot name="b"><link name="a"/><link name="b"/><joint name="j" type="revolute">'
        '<parent link="a"/><child link="b"/><axis xyz="0 0 0"/></joint></robot>'
    )
    with pytest.raises(ConfigError, match='zero axis'):
        JointTransforms(bad)


@pytest.mark.parametrize(
    'angle, axis',
    [
        (0.0, (0, 0, 1)),
        (math.pi, (1, 0, 0)),
        (math.pi, (0, 1, 0)),
        (math.pi, (0, 0, 1)),
        (2.5, (1, 2, 3)),
        (-3.1, (-1, 0.5, 0.2)),
    ],
)
def test_quaternion_from_matrix_round_trips(angle, axis):
    axis = np.asarray(axis, dtype=float) / np.linalg.norm(axis)
    rot = pin.AngleAxis(angle, axis).toRotationMatrix()
    quat = quaternion_from_matrix(rot)
    back = FrameTransform('a', 'b', np.zeros(3), quat).matrix()[:3, :3]
    np.testing.assert_allclose(back, rot, atol=1e-12)
    assert quat[3] >= 0.0 and np.linalg.norm(quat) == pytest.approx(1.0)


def test_world_to_odom_puts_the_base_at_its_true_pose():
    true_pose, odom_pose = (2.0, -1.0, 0.7), (1.8, -0.7, 0.5)
    world_base = compose(
        world_to_odom('world', 'odom', true_pose, odom_pose), planar_transform('odom', 'base_link', odom_pose)
    )
    expected = planar_transform('world', 'base_link', true_pose)
    assert (world_base.parent, world_base.child) == ('world', 'base_link')
    np.testing.assert_allclose(world_base.matrix(), expected.matrix(), atol=1e-12)
    np.testing.assert_allclose(world_to_odom('world', 'odom', odom_pose, odom_pose).matrix(), np.eye(4), atol=1e-12)
    with pytest.raises(NonFiniteError):
        planar_transform('odom', 'base_link', (0.0, math.nan, 0.0))
    with pytest.raises(ValueError):
        compose(expected, expected)
