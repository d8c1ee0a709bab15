"""Shared fixtures: one kinematic model per robot, built once per session; a ROS harness per test."""

from importlib.metadata import PackageNotFoundError, distribution
from pathlib import Path

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


@pytest.fixture(scope='session')
def tiago_robots():
    """The folder of TIAGo's URDFs in the example-robot-data wheel
    (``tiago.urdf``, ``tiago_no_hand.urdf``); its ``parents[3]`` is the ``share`` folder that holds
    ``example-robot-data/``. Skips where the wheel is not installed (scripts/requirements-test.txt
    installs it)."""
    try:
        share = Path(str(distribution('example-robot-data').locate_file('cmeel.prefix/share')))
    except PackageNotFoundError:
        pytest.skip('example-robot-data is not installed (scripts/requirements-test.txt)')
    return share / 'example-robot-data' / 'robots' / 'tiago_description' / 'robots'
