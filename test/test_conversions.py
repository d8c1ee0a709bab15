"""nodes.conversions: ROS messages to and from the core's arrays, both ways."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import Pose, PoseStamped, Transform, Twist
from nav_msgs.msg import Odometry

from wmm_control.geometry import matrix_from_rpy
from wmm_control.nodes.conversions import (
    float_array,
    odometry,
    odometry_pose,
    odometry_values,
    planar_twist,
    planar_covariance,
    pose_stamped,
    pose_rotation,
    planned_base_values,
    pose_values,
    reference_message,
    set_planar_pose,
    set_planar_twist,
    set_pose,
    set_rotation,
    set_twist,
    stamp_from_seconds,
    twist_stamped,
    twist_values,
)


def test_a_pose_and_a_transform_round_trip():
    quat = np.array([0.1, -0.2, 0.3, 0.9]) / np.linalg.norm([0.1, -0.2, 0.3, 0.9])
    for msg in (Pose(), Transform()):
        set_pose(msg, (1.0, -2.0, 0.5), quat)
        np.testing.assert_allclose(pose_values(msg), [1.0, -2.0, 0.5, *quat])
    rotation = matrix_from_rpy([0.3, -0.4, 2.0])
    msg = PoseStamped()
    set_rotation(msg.pose.orientation, rotation)
    position, back = pose_rotation(msg.pose)
    np.testing.assert_allclose(back, rotation, atol=1e-12)
    assert msg.pose.orientation.w >= 0.0


def test_a_planar_pose_and_twist_round_trip_through_odometry():
    msg = Odometry()
    set_planar_pose(msg.pose.pose, (1.5, -0.5, 3.0))
    set_planar_twist(msg.twist.twist, (0.2, -0.1, 0.4))
    pose, twist = odometry_pose(msg)
    np.testing.assert_allclose(pose, [1.5, -0.5, 3.0], atol=1e-12)
    np.testing.assert_allclose(twist, [0.2, -0.1, 0.4])
    xy, quat, _ = odometry_values(msg)
    np.testing.assert_allclose(xy, [1.5, -0.5])
    np.testing.assert_allclose(quat, [0.0, 0.0, math.sin(1.5), math.cos(1.5)], atol=1e-12)
    assert msg.pose.pose.position.z == 0.0


def test_twists_and_arrays():
    twist = Twist()
    set_twist(twist, [1, 2, 3, 4, 5, 6])
    np.testing.assert_allclose(twist_values(twist), [1, 2, 3, 4, 5, 6])
    np.testing.assert_allclose(planar_twist(twist), [1, 2, 6])
    msg = twist_stamped((3, 500), 'base_link', (0.1, 0.2, 0.3))
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (3, 500, 'base_link')
    np.testing.assert_allclose(planar_twist(msg.twist), [0.1, 0.2, 0.3])
    assert float_array(np.arange(3)).data.tolist() == [0.0, 1.0, 2.0]


def test_seconds_become_a_stamp_never_rounded_into_the_next_second():
    stamp = stamp_from_seconds(12.25)
    assert (stamp.sec, stamp.nanosec) == (12, 250_000_000)
    stamp = stamp_from_seconds(3.9999999999)
    assert (stamp.sec, stamp.nanosec) == (3, 999_999_999)


def test_an_odometry_carries_its_frames_and_a_planar_covariance_in_the_ros_layout():
    cov3 = np.array([[1.0, 0.1, 0.2], [0.1, 2.0, 0.3], [0.2, 0.3, 3.0]])
    full = np.array(planar_covariance(cov3, 1e-9)).reshape(6, 6)
    np.testing.assert_array_equal(full[np.ix_([0, 1, 5], [0, 1, 5])], cov3)
    np.testing.assert_array_equal(np.diag(full)[2:5], 1e-9)  # z, roll, pitch: the floor
    assert np.count_nonzero(full) == 9 + 3
    twist_cov = planar_covariance(np.diag([4.0, 5.0, 6.0]), 1e-9)
    msg = odometry(
        stamp_from_seconds(1.5),
        'r1/odom',
        'r1/base_link',
        (1.0, 2.0, 0.5),
        (0.1, 0.0, 0.2),
        (full.ravel().tolist(), twist_cov),
    )
    assert (msg.header.frame_id, msg.child_frame_id, msg.header.stamp.sec) == ('r1/odom', 'r1/base_link', 1)
    pose, twist = odometry_pose(msg)
    np.testing.assert_allclose(pose, [1.0, 2.0, 0.5], atol=1e-12)
    np.testing.assert_allclose(twist, [0.1, 0.0, 0.2])
    np.testing.assert_array_equal(np.asarray(msg.pose.covariance), full.ravel())
    assert msg.twist.covariance[35] == 6.0
    assert not np.any(odometry(msg.header.stamp, 'world', 'base_link', pose, twist).pose.covariance)


def test_a_pose_stamped_carries_its_stamp_frame_and_pose():
    msg = pose_stamped(stamp_from_seconds(2.5), 'world', (1.0, 2.0, 3.0), (0.0, 0.0, 1.0, 0.0))
    assert (msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id) == (2, 500_000_000, 'world')
    np.testing.assert_allclose(pose_values(msg.pose), [1.0, 2.0, 3.0, 0.0, 0.0, 1.0, 0.0])


def test_an_ee_reference_carries_a_followed_plan_s_base_and_gives_it_back():
    from wmm_control.resolvers.interface import BaseReference, PoseTarget

    base = BaseReference(np.array((1.2, -0.4, 2.9)), np.array((0.3, -0.1, 0.5)), np.array((0.05, 0.0, -0.2)))
    target = PoseTarget(np.array((1.5, 0.3, 1.0)), matrix_from_rpy((0.1, 0.2, 0.3)), velocity=np.ones(6), base=base)
    msg = reference_message(target, 'world', stamp_from_seconds(1.5), 0.25)
    assert list(msg.joint_names) == ['end_effector', 'base'] and len(msg.points[0].transforms) == 2
    pose, rates, acceleration = planned_base_values(msg)
    assert (
        np.allclose(pose, base.pose) and np.allclose(rates, base.rates) and np.allclose(acceleration, base.acceleration)
    )
    # the end effector's point is as it was
    assert np.allclose(pose_values(msg.points[0].transforms[0])[:3], target.position)
    assert np.allclose(twist_values(msg.points[0].velocities[0]), 1.0)
    # without a base: one joint, and none given back
    alone = reference_message(PoseTarget(target.position, target.rotation), 'world', stamp_from_seconds(1.5), 0.25)
    assert list(alone.joint_names) == ['end_effector'] and planned_base_values(alone) is None
    # a zero quaternion gives a heading of NaN, which the resolver rejects as non-finite
    msg.points[0].transforms[1].rotation.w = 0.0
    msg.points[0].transforms[1].rotation.z = 0.0
    assert math.isnan(planned_base_values(msg)[0][2])


def test_an_ee_reference_carries_the_plan_s_travel_posture_by_joint_name():
    from wmm_control.resolvers.interface import BaseReference, PoseTarget

    joints = ('j1', 'j2', 'j3')
    posture = np.array((0.3, -1.2, 6.0))  # beyond ±π: a position, not an angle of a rotation
    base = BaseReference(np.array((1.2, -0.4, 2.9)), np.array((0.3, -0.1, 0.5)), np.zeros(3), posture)
    target = PoseTarget(np.array((1.5, 0.3, 1.0)), np.eye(3), base=base)
    msg = reference_message(target, 'world', stamp_from_seconds(1.5), 0.25, joints)
    assert list(msg.joint_names) == ['end_effector', 'base', *joints]
    assert len(msg.points[0].transforms) == len(msg.points[0].velocities) == len(msg.points[0].accelerations) == 5
    pose, rates, _, arm = planned_base_values(msg, joints)
    assert np.allclose(pose, base.pose) and np.allclose(rates, base.rates) and np.allclose(arm, posture)
    # read by name: in the arm's order whatever the message's
    msg.joint_names = ['end_effector', 'base', 'j3', 'j1', 'j2']
    assert np.allclose(planned_base_values(msg, joints)[3], (-1.2, 6.0, 0.3))
    # a joint missing or named twice gives fewer positions than the arm has (the resolver rejects it)
    msg.joint_names = ['end_effector', 'base', 'j1', 'j1', 'j2']
    assert planned_base_values(msg, joints)[3].shape == (1,)
    # a joint named without its transform: NaN (rejected as non-finite)
    msg.joint_names = ['end_effector', 'base', *joints, 'j4']
    assert math.isnan(planned_base_values(msg, (*joints, 'j4'))[3][3])
    # a posture of another size than the joints named is a bug of the caller
    with pytest.raises(ValueError, match='travel posture of 3 joints'):
        reference_message(target, 'world', stamp_from_seconds(1.5), 0.25, joints[:2])
    # no travel posture (the final approach): base alone
    approach = PoseTarget(target.position, target.rotation, base=BaseReference(base.pose))
    assert len(planned_base_values(reference_message(approach, 'world', stamp_from_seconds(1.5), 0.0, joints))) == 3
