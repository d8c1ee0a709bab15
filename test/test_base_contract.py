"""The base-controller contract (wmm_control.base.contract) and the cycle object (wmm_control.cycle):
every base family behind one interface, the phases of Sorour Fig 4 in order. ROS-free."""

import numpy as np
import pytest

from wmm_control.base import (
    BaseCommand,
    BaseController,
    SteerableBaseController,
    SwmrController,
    WheelBaseController,
    WheelController,
    make_base_controller,
)
from urdf_factory import SIX_MECANUM_WHEELS, SIX_ROLLER_ANGLES, write_mecanum_robot
from wmm_control.errors import ConfigError
from wmm_control.robot_config import load_robot

ROBOTS = ('steerable', 'mecanum', 'panda_diff', 'six_mecanum')


def expected_groups(robot):
    if robot.base.family == 'steerable':
        return {'steer': tuple(robot.base.steer_joints), 'drive': tuple(robot.base.drive_joints)}
    return {'wheel': tuple(robot.base.wheel_joints)}


def wheel_twist(base, command, before):
    """The twist the wheel kinematics give for the command's rates over the period they apply,
    from the joint positions ``before`` it."""
    c = base.controller
    if isinstance(base, SteerableBaseController):
        steer, drive = command.rates['steer'], command.rates['drive']
        mid = before['steer'] + 0.5 * c.params.dt * steer  # the steer angles in the middle of the period
        return c.geometry.twist_from_wheels(mid, steer, drive)
    return c.kinematics.twist_from_wheels(command.rates['wheel'])


def run(base, references):
    """Step ``base`` through ``references``, the joints following their commands exactly:
    ``[(command, positions before it)]``."""
    positions = {g: np.zeros(len(j)) for g, j in base.command_groups.items()}
    base.reset(positions)
    out = []
    for ref in references:
        command = base.step(ref, positions)
        out.append((command, positions))
        positions = {g: positions[g] + base.controller.params.dt * command.rates[g] for g in positions}
    return out


@pytest.fixture(scope='module', params=ROBOTS)
def robot(request, tmp_path_factory):
    if request.param == 'six_mecanum':  # a made-up Mecanum base of six wheels
        return load_robot(write_mecanum_robot(tmp_path_factory.mktemp('six'), SIX_MECANUM_WHEELS, SIX_ROLLER_ANGLES))
    return load_robot(request.param)


def test_every_family_meets_the_contract_with_the_simulators_groups(robot):
    base = make_base_controller(robot, robot.period)
    assert isinstance(base, BaseController)
    assert base.family == robot.base.family
    assert base.command_groups == expected_groups(robot)
    assert list(base.command_groups) == [g for g in ('steer', 'drive', 'wheel') if g in base.command_groups]
    assert set(base.required_groups) <= set(base.command_groups)
    assert set(base.rate_limits) == set(base.command_groups)
    np.testing.assert_array_equal(base.velocity_limit, robot.base.velocity)
    assert base.resync_from_rates is (robot.base.family != 'steerable')  # the steerable base re-reads its angles


def test_rates_per_group_are_finite_and_realise_the_feasible_twist(robot):
    base = make_base_controller(robot, robot.period)
    ref = 0.5 * np.asarray(robot.base.velocity) * np.array([0.6, 0.3, 0.5])
    commands = run(base, [ref] * 400)
    moving = 0
    for command, before in commands:
        assert isinstance(command, BaseCommand)
        assert set(command.rates) == set(base.command_groups)
        for g, rates in command.rates.items():
            assert rates.shape == (len(base.command_groups[g]),)
            assert np.all(np.isfinite(rates))
            assert np.all(np.abs(rates) <= base.rate_limits[g] + 1e-9)
        assert command.feasible_twist.shape == (3,)
        np.testing.assert_allclose(command.feasible_twist, wheel_twist(base, command, before), atol=1e-9)
        moving += bool(np.any(command.feasible_twist))
    assert moving > 300
    followed = commands[-1][0].feasible_twist
    if robot.base.family == 'differential':
        ref = ref * np.array([1.0, 0.0, 1.0])  # no sideways motion
    np.testing.assert_allclose(followed, ref, atol=2e-3)  # reached within the limits


def test_a_reference_beyond_the_limits_is_scaled_into_them_direction_kept(robot):
    base = make_base_controller(robot, robot.period)
    huge = np.array([1e308, 0.0, 0.0])
    commands = run(base, [huge] * 600)
    limit = np.asarray(robot.base.velocity)
    for command, _ in commands:
        assert np.all(np.isfinite(command.feasible_twist))
        assert np.all(np.abs(command.feasible_twist) <= limit + 1e-9)
    last = commands[-1][0].feasible_twist
    assert last[0] > 0.5 * limit[0]  # driven at its limits, along the reference
    assert abs(last[1]) < 1e-6 and abs(last[2]) < 1e-6


def test_no_reference_brakes_the_base_to_rest(robot):
    base = make_base_controller(robot, robot.period)
    ref = 0.8 * np.asarray(robot.base.velocity) * np.array([1.0, 0.0, 0.0])
    moving = run(base, [ref] * 200)[-1][0].feasible_twist
    assert moving[0] > 0.1
    positions = {g: np.zeros(len(j)) for g, j in base.command_groups.items()}
    speeds = [abs(base.step(None, positions).feasible_twist[0]) for _ in range(400)]
    assert speeds[-1] == pytest.approx(0.0, abs=1e-9)
    assert all(b <= a + 1e-9 for a, b in zip(speeds, speeds[1:]))  # monotone braking


def test_the_adapters_give_the_wrapped_controllers_numbers_exactly():
    robot = load_robot('steerable')
    base = make_base_controller(robot, robot.period)
    twin = SwmrController(base.controller.geometry, base.controller.params)
    rng = np.random.default_rng(3)
    beta = np.zeros(4)
    for k in range(120):
        ref = rng.uniform(-0.5, 0.5, 3)
        brake = k % 17 == 16
        got = base.step(None if brake else ref, {'steer': beta})
        want = twin.step(np.zeros(3) if brake else ref, beta_meas=beta, brake=brake)
        np.testing.assert_array_equal(got.rates['steer'], want.beta_dot_ref)
        np.testing.assert_array_equal(got.rates['drive'], want.phi_dot_ref)
        np.testing.assert_array_equal(got.feasible_twist, want.twist_executed)
        beta = beta + 0.025 * want.beta_dot_ref + rng.normal(0.0, 1e-4, 4)  # a steering that lags a little
    robot = load_robot('mecanum')
    base = make_base_controller(robot, robot.period)
    twin = WheelController.from_robot_config(robot, robot.period)
    for k in range(120):
        ref = rng.uniform(-0.5, 0.5, 3)
        got = base.step(None if k % 13 == 12 else ref)
        want = twin.stop() if k % 13 == 12 else twin.step(ref)
        np.testing.assert_array_equal(got.rates['wheel'], want.wheel_rates)
        np.testing.assert_array_equal(got.feasible_twist, want.twist)
        assert got.status == want.status


def test_reset_starts_at_rest_or_goes_on_from_the_measured_rates():
    robot = load_robot('mecanum')
    base = make_base_controller(robot, robot.period)
    rates = base.controller.kinematics.wheel_rates(np.array([0.1, -0.05, 0.2]))
    base.reset(rates={'wheel': rates})
    np.testing.assert_allclose(base.controller.twist, [0.1, -0.05, 0.2], atol=1e-12)
    base.reset()
    np.testing.assert_array_equal(base.controller.twist, np.zeros(3))
    robot = load_robot('steerable')
    base = make_base_controller(robot, robot.period)
    beta = np.array([0.1, 0.2, -0.1, 0.3])
    base.reset({'steer': beta})
    np.testing.assert_array_equal(base.controller.beta, beta)
    np.testing.assert_array_equal(base.controller.twist, np.zeros(3))
    steer, drive = np.full(4, 0.2), np.full(4, 3.0)
    base.reset({'steer': np.zeros(4)}, {'steer': steer, 'drive': drive})
    np.testing.assert_array_equal(base.controller.beta_dot, steer)
    np.testing.assert_allclose(
        base.controller.twist, base.controller.geometry.twist_from_wheels(np.zeros(4), steer, drive)
    )
    assert base.controller.twist[0] > 0.1


def test_the_factory_takes_the_steerable_gains_and_nothing_for_wheels():
    robot = load_robot('steerable')
    assert make_base_controller(robot, 0.02, kp=3.0).controller.params.kp == 3.0
    assert make_base_controller(robot, 0.02).controller.params.dt == 0.02
    assert isinstance(make_base_controller(load_robot('mecanum'), 0.02), WheelBaseController)
    with pytest.raises(ConfigError):
        make_base_controller(load_robot('mecanum'), 0.02, kp=3.0)
