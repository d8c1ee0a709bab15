"""Wheel-level kinematics of the two bases: Mecanum (Xing eq 16) and steerable (Sorour §IV)."""

import numpy as np
import pytest

from wmm_control.base import MecanumKinematics, SteerableGeometry
from wmm_control.errors import ConfigError, NonFiniteError, ShapeError
from wmm_control.robot_config import load_robot

HIPS = np.array([[0.24, 0.19], [0.24, -0.19], [-0.24, 0.19], [-0.24, -0.19]])


@pytest.fixture
def mecanum():
    return MecanumKinematics(wheel_radius=0.1, d1=0.3, d2=0.2)


def test_mecanum_eq16_by_hand(mecanum):
    # R/4 = 0.025, k = d1 + d2 = 0.5.
    np.testing.assert_allclose(mecanum.twist_from_wheels([1, 1, 1, 1]), [0.1, 0.0, 0.0])
    np.testing.assert_allclose(mecanum.twist_from_wheels([-1, 1, 1, -1]), [0.0, 0.1, 0.0])
    np.testing.assert_allclose(mecanum.twist_from_wheels([-1, 1, -1, 1]), [0.0, 0.0, 0.2])
    np.testing.assert_allclose(mecanum.twist_from_wheels([2, 0, 0, 0]), [0.05, -0.05, -0.1])


def test_mecanum_inverse_is_exact_and_world_rates_rotate(mecanum):
    rng = np.random.default_rng(0)
    for _ in range(20):
        twist = rng.normal(size=3)
        np.testing.assert_allclose(mecanum.twist_from_wheels(mecanum.wheel_rates(twist)), twist, atol=1e-12)
    # Strafing left (+y in the base) while facing +y in the world moves along −x.
    w = mecanum.wheel_rates([0.0, 0.3, 0.0])
    np.testing.assert_allclose(w, [-3.0, 3.0, 3.0, -3.0])
    np.testing.assert_allclose(mecanum.world_rates(np.pi / 2, w), [-0.3, 0.0, 0.0], atol=1e-12)


def test_mecanum_from_robot_b_config_and_errors():
    kin = MecanumKinematics.from_config(load_robot('mecanum').mecanum)
    assert kin.wheel_radius == 0.076 and kin.d1 + kin.d2 == pytest.approx(0.47)
    with pytest.raises(ConfigError, match='d1 must be finite and > 0'):
        MecanumKinematics(0.1, 0.0, 0.2)
    with pytest.raises(ShapeError, match='wheel_rates'):
        kin.twist_from_wheels([1.0, 2.0, 3.0])
    with pytest.raises(NonFiniteError, match='twist'):
        kin.wheel_rates([np.nan, 0.0, 0.0])


def test_steerable_inverse_then_forward_recovers_the_twist():
    geom = SteerableGeometry(HIPS, 0.09, 0.045)
    rng = np.random.default_rng(1)
    for _ in range(50):
        twist = rng.normal(size=3)
        icr = np.array([-twist[1], twist[0]]) / twist[2]
        beta = geom.steer_angles_for_icr(icr) + np.pi * rng.integers(0, 2, 4)  # either twin
        beta_dot = rng.normal(size=4)
        phi = geom.wheel_rates(beta, beta_dot, twist)
        np.testing.assert_allclose(geom.slip_rows(beta) @ twist, 0.0, atol=1e-12)
        np.testing.assert_allclose(geom.twist_from_wheels(beta, beta_dot, phi), twist, atol=1e-10)


def test_batched_rolling_model_equals_twist_from_wheels():
    geom = SteerableGeometry(HIPS, 0.09, 0.045)
    rng = np.random.default_rng(5)
    beta = rng.uniform(-3.0, 3.0, (10, 4))
    beta_dot, phi_dot = rng.uniform(-1.0, 1.0, 4), rng.uniform(-10.0, 10.0, 4)
    expected = np.array([geom.twist_from_wheels(b, beta_dot, phi_dot) for b in beta])
    np.testing.assert_allclose(geom.twists_from_wheels(beta, beta_dot, phi_dot), expected, atol=1e-12)


def test_steerable_geometry_rejects_bad_values():
    with pytest.raises(ConfigError, match='hips'):
        SteerableGeometry(np.zeros((4, 3)), 0.09, 0.045)
    with pytest.raises(ConfigError, match='wheel_radius'):
        SteerableGeometry(HIPS, -0.09, 0.045)
    with pytest.raises(ConfigError, match='wheel_offset'):
        SteerableGeometry(HIPS, 0.09, -0.01)


def _rows_by_hand(beta):
    """f(β_i) and g(β_i) of Sorour §IV written out, for wheel sets that need not agree."""
    c, s = np.cos(beta), np.sin(beta)
    hx, hy, d = HIPS[:, 0], HIPS[:, 1], 0.045
    return np.column_stack((c, s, d - hy * c + hx * s)), np.column_stack((-s, c, hx * c + hy * s))


def test_rolling_model_fit_of_disagreeing_wheels_is_the_least_squares_twist():
    geom = SteerableGeometry(HIPS, 0.09, 0.045)
    rng = np.random.default_rng(8)
    for _ in range(50):
        beta, beta_dot, phi_dot = rng.uniform(-3, 3, 4), rng.uniform(-1, 1, 4), rng.uniform(-10, 10, 4)
        f, g = _rows_by_hand(beta)
        rhs = np.concatenate((0.09 * phi_dot - 0.045 * beta_dot, np.zeros(4)))
        expected = np.linalg.lstsq(np.vstack((f, g)), rhs, rcond=None)[0]
        np.testing.assert_allclose(geom.twist_from_wheels(beta, beta_dot, phi_dot), expected, atol=1e-10)


def test_icr_of_disagreeing_wheels_minimises_the_side_slip():
    """Icr.from_steer_angles is the smallest right singular vector of the no-side-slip rows."""
    from wmm_control.base import Icr

    geom = SteerableGeometry(HIPS, 0.09, 0.045)
    rng = np.random.default_rng(9)
    for _ in range(200):
        beta = geom.steer_angles_for_icr(rng.uniform(-2, 2, 2)) + rng.normal(0.0, 0.3, 4)
        _, g = _rows_by_hand(beta)
        t = np.linalg.svd(g)[2][-1]  # (vx, vy, ω), ℓ = 1
        icr = Icr.from_steer_angles(geom, beta)
        twist = icr.twist_direction
        assert abs(abs(twist @ t) - 1.0) < 1e-9


def test_a_restart_goes_on_from_the_measured_state_within_the_steer_rate_limit():
    """The last command was not applied: both base controllers go on from what the joint state
    measured, the steerable one from steer rates within its limit (an encoder glitch of 3 rad/s
    is not followed) and the twist that fits them and the drive rates."""
    from wmm_control.base import WheelController, MecanumKinematics, SteerableGeometry, SwmrController, SwmrParams

    robot = load_robot('steerable')
    geometry = SteerableGeometry.from_config(robot.steerable)
    swmr = SwmrController(geometry, SwmrParams.from_robot_config(robot))
    beta = np.array([0.3, 0.3, 0.3, 0.3])
    twist = np.array([0.4, 0.1, 0.0])
    phi_dot = geometry.wheel_rates(beta, np.zeros(4), twist)
    swmr.restart(beta, np.array([3.0, -3.0, 0.0, 0.0]), phi_dot)
    limit = swmr.params.steer_rate_limit
    np.testing.assert_allclose(swmr.beta_dot, [limit, -limit, 0.0, 0.0])
    np.testing.assert_allclose(swmr.beta, beta)
    mecanum = WheelController.from_robot_config(load_robot('mecanum'), 0.025)
    kinematics = MecanumKinematics.from_config(load_robot('mecanum').mecanum)
    mecanum.restart(kinematics.wheel_rates((0.1, -0.05, 0.2)))
    np.testing.assert_allclose(mecanum.twist, (0.1, -0.05, 0.2), atol=1e-12)
