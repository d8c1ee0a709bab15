"""nodes.conversions: ROS messages to and from the core's arrays, both ways."""

import math

import numpy as np
from geometry_msgs.msg import Pose, PoseStamped, Transform, Twist
from nav_msgs.msg import Odometry

from wmm_control.kinematics.orientation import matrix_from_rpy
from wmm_control.nodes.conversions import (
    float_array,
    odometry_pose,
    odometry_values,
    planar_twist,
    pose_rotation,
    pose_values,
    set_planar_pose,
    set_planar_twist,
    set_pose,
    set_rotation,
    set_twist,
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
