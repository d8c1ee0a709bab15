"""Shared fixtures: one kinematic model per robot, built once per session; a ROS harness per test;
one colcon install tree per session."""

import subprocess
import sys
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


@pytest.fixture(scope='session')
def install_tree(tmp_path_factory):
    """The package built and installed by colcon (``<install>/wmm_control``), as ``ros2 run`` and
    ``ros2 launch`` use it; built once for every test that uses it (test_packaging, test_launch)."""
    colcon = Path(sys.executable).with_name('colcon')
    if not colcon.exists():
        pytest.fail(f'colcon not found next to {sys.executable}: run the README set-up')
    work = tmp_path_factory.mktemp('colcon')
    result = subprocess.run(
        [
            str(colcon),
            '--log-base',
            str(work / 'log'),
            'build',
            '--base-paths',
            str(Path(__file__).resolve().parent.parent),
            '--build-base',
            str(work / 'build'),
            '--install-base',
            str(work / 'install'),
        ],
        cwd=work,
        capture_output=True,
        text=True,
        timeout=600,
    )
    assert result.returncode == 0, result.stdout + result.stderr
    return work / 'install' / 'wmm_control'
