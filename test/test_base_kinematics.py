"""Wheel-level kinematics of the two bases: Mecanum (Xing eq 16) and steerable (Sorour §IV)."""

import xml.etree.ElementTree as ET

import numpy as np
import pytest

from urdf_factory import SIX_MECANUM_WHEELS, SIX_ROLLER_ANGLES
from wmm_control.base import MecanumKinematics, SteerableGeometry
from wmm_control.errors import ConfigError, NonFiniteError, ShapeError
from wmm_control.robot_config import load_robot

HIPS = np.array([[0.24, 0.19], [0.24, -0.19], [-0.24, 0.19], [-0.24, -0.19]])


@pytest.fixture
def mecanum():
    return MecanumKinematics.rectangle(wheel_radius=0.1, d1=0.3, d2=0.2)


def test_mecanum_eq16_by_hand(mecanum):
    # R/4 = 0.025, k = d1 + d2 = 0.5.
    np.testing.assert_allclose(mecanum.twist_from_wheels([1, 1, 1, 1]), [0.1, 0.0, 0.0], atol=1e-12)
    np.testing.assert_allclose(mecanum.twist_from_wheels([-1, 1, 1, -1]), [0.0, 0.1, 0.0], atol=1e-12)
    np.testing.assert_allclose(mecanum.twist_from_wheels([-1, 1, -1, 1]), [0.0, 0.0, 0.2], atol=1e-12)
    np.testing.assert_allclose(mecanum.twist_from_wheels([2, 0, 0, 0]), [0.05, -0.05, -0.1], atol=1e-12)


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
    kin = MecanumKinematics.from_config(load_robot('mecanum').base)
    assert kin.wheel_radius == 0.076 and kin.n_wheels == 4
    with pytest.raises(ConfigError, match='wheel_radius must be finite and > 0'):
        MecanumKinematics.rectangle(0.0, 0.3, 0.2)
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
    geometry = SteerableGeometry.from_config(robot.base)
    swmr = SwmrController(geometry, SwmrParams.from_robot_config(robot))
    beta = np.array([0.3, 0.3, 0.3, 0.3])
    twist = np.array([0.4, 0.1, 0.0])
    phi_dot = geometry.wheel_rates(beta, np.zeros(4), twist)
    swmr.restart(beta, np.array([3.0, -3.0, 0.0, 0.0]), phi_dot)
    limit = swmr.params.steer_rate_limit
    np.testing.assert_allclose(swmr.beta_dot, [limit, -limit, 0.0, 0.0])
    np.testing.assert_allclose(swmr.beta, beta)
    mecanum = WheelController.from_robot_config(load_robot('mecanum'), 0.025)
    kinematics = MecanumKinematics.from_config(load_robot('mecanum').base)
    mecanum.restart(kinematics.wheel_rates((0.1, -0.05, 0.2)))
    np.testing.assert_allclose(mecanum.twist, (0.1, -0.05, 0.2), atol=1e-12)


# ---------------------------------------------------------------- Mecanum of any number of wheels


def _rollers_agree(kinematics, twist, rates):
    """The roller constraint of each wheel, written from the physics: along the axis a_i =
    (−sin γ_i, cos γ_i) of its roller on the floor, the floor under the wheel, (vx − ω y_i,
    vy + ω x_i), moves as the wheel's rim, (R φ̇_i, 0). Residuals [m/s]. Shape (N,)."""
    vx, vy, w = twist
    x, y = kinematics.positions.T
    floor = np.column_stack((vx - w * y, vy + w * x))
    rim = np.column_stack((kinematics.wheel_radius * np.asarray(rates), np.zeros(len(x))))
    axis = np.column_stack((-np.sin(kinematics.roller_angles), np.cos(kinematics.roller_angles)))
    return np.einsum('ij,ij->i', axis, floor - rim)


@pytest.mark.parametrize('robot', ['mecanum', 'ur_mecanum'])
def test_the_shipped_four_wheel_bases_are_xing_eq_16(robot):
    """J_V from the wheels' positions and roller angles equals Xing's eq (16) with d1, d2 the
    URDF's wheel origins, and its inverse is the rows of the roller constraint."""
    cfg = load_robot(robot)
    joints = {j.get('name'): j for j in ET.parse(cfg.urdf_path).getroot().iter('joint')}
    origins = np.array(
        [[float(v) for v in joints[n].find('origin').get('xyz').split()[:2]] for n in cfg.base.wheel_joints]
    )
    d1, d2 = np.abs(origins[0])
    np.testing.assert_allclose(np.abs(origins), [[d1, d2]] * 4)  # a rectangle, in the order fl, fr, rl, rr
    np.testing.assert_array_equal(np.sign(origins), [[1, 1], [1, -1], [-1, 1], [-1, -1]])
    k, r = d1 + d2, cfg.base.wheel_radius
    xing = r / 4 * np.array([[1, 1, 1, 1], [-1, 1, 1, -1], [-1 / k, 1 / k, -1 / k, 1 / k]])
    kin = MecanumKinematics.from_config(cfg.base)
    np.testing.assert_allclose(kin.jv, xing, rtol=0, atol=1e-12)
    np.testing.assert_allclose(kin.jv @ kin.inverse, np.eye(3), rtol=0, atol=1e-12)
    twist = np.array([0.2, -0.1, 0.3])
    np.testing.assert_allclose(_rollers_agree(kin, twist, kin.wheel_rates(twist)), 0.0, atol=1e-12)


# Any N ≥ 3 wheels of rank 3: three with rollers at ±45°, six with a middle pair at ±60°.
THREE = ([(0.3, 0.0), (-0.15, 0.26), (-0.15, -0.26)], [np.pi / 4, -np.pi / 4, np.pi / 4])
SIX = ([(x, y) for _, x, y in SIX_MECANUM_WHEELS], SIX_ROLLER_ANGLES)


@pytest.mark.parametrize('positions, angles', [THREE, SIX], ids=['three', 'six'])
def test_mecanum_of_n_wheels_round_trips_a_twist_and_fits_disagreeing_wheels(positions, angles):
    kin = MecanumKinematics(0.05, positions, angles)
    assert kin.inverse.shape == (len(angles), 3) and kin.jv.shape == (3, len(angles))
    rng = np.random.default_rng(3)
    for _ in range(50):
        twist = rng.normal(size=3)
        rates = kin.wheel_rates(twist)
        np.testing.assert_allclose(_rollers_agree(kin, twist, rates), 0.0, atol=1e-12)
        np.testing.assert_allclose(kin.twist_from_wheels(rates), twist, rtol=0, atol=1e-12)
        noisy = rates + rng.normal(size=len(rates))  # wheels that disagree: the least-squares twist
        expected = np.linalg.lstsq(kin.inverse, noisy, rcond=None)[0]
        np.testing.assert_allclose(kin.twist_from_wheels(noisy), expected, rtol=0, atol=1e-10)


@pytest.mark.parametrize(
    'positions, angles, message',
    [
        (THREE[0], [np.pi / 4] * 3, 'rank 2'),  # every roller alike: no sideways twist of its own
        (SIX[0], [np.pi / 2] * 6, 'rank 2'),  # omni wheels all on y axles: nothing moves sideways
        ([(0.3, 0.2), (-0.3, -0.2)], [np.pi / 4, np.pi / 4], 'rank 2'),  # two wheels
        (THREE[0], [np.pi / 4, 0.0, np.pi / 4], 'gives no traction'),  # rollers along the axle
        (THREE[0], [np.pi / 4] * 2, 'N roller angles'),
    ],
    ids=['alike', 'omni', 'two', 'along the axle', 'lengths'],
)
def test_mecanum_wheels_that_cannot_make_every_twist_are_rejected(positions, angles, message):
    with pytest.raises(ConfigError, match=message):
        MecanumKinematics(0.05, positions, angles)
