"""Shared fixtures: one kinematic model per robot, built once per session; a ROS harness per test."""

import pytest

from wmm_control.kinematics import KinematicModel


@pytest.fixture(scope='session', params=['steerable', 'mecanum'])
def model(request):
    """A KinematicModel of each robot (the test runs once per robot)."""
    return KinematicModel(request.param)


@pytest.fixture(scope='session')
def steerable_model():
    return KinematicModel('steerable')


@pytest.fixture(scope='session')
def mecanum_model():
    return KinematicModel('mecanum')


@pytest.fixture
def ros():
    """An isolated rclpy context with an executor (:class:`ros_helpers.RosHarness`), closed after the test."""
    from ros_helpers import RosHarness

    harness = RosHarness()
    yield harness
    harness.close()
