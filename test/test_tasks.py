"""The tasks (wmm_control.kinematics.tasks): each one's Jacobian moves its error's coordinates as
the configuration moves, checked by finite differences, for a base that moves sideways (world
rates) and one that does not ((v, ω))."""

import numpy as np
import pinocchio as pin
import pytest

from wmm_control.errors import WmmError
from wmm_control.geometry import rotation_z, twist_to_world, wrap_angle
from wmm_control.kinematics import KinematicModel
from test_kinematics import random_states
from wmm_control.kinematics.tasks import ManipulabilityTask, PoseTask, PostureTask, base_rates, twist_columns

EPS = 1e-6


def _states(model, n, seed):
    """States inside the arm's limits (``test_kinematics.random_states``) with random rates of
    the base's entries and the arm's."""
    rng = np.random.default_rng(seed + 100)
    n_base = base_rates(model.config.base.axes).n
    for base, q in random_states(model, n, seed):
        yield base, q, rng.normal(size=n_base), rng.normal(size=model.n_arm)


def _placement(model, base, q):
    model.update(base, q)
    return model.ee_placement_world()


@pytest.mark.parametrize('robot', ['steerable', 'panda_diff'])
def test_the_world_jacobian_over_the_bases_own_rates_moves_the_pose_as_the_robot_does(robot):
    """``J u`` is the end effector's twist when the base moves at ``T(θ) u_b`` and the arm at
    ``q̇_a``; the drift is ``d/dt (J T u)`` at fixed u (``J̇ q̇ + J_b Ṫ u_b``): a base without a
    sideways axis turns its forward speed with its heading."""
    model = KinematicModel(robot)
    rates = base_rates(model.config.base.axes)
    pose = PoseTask(model)
    assert rates.world == (robot == 'steerable')
    for base, q, u_b, dq in _states(model, 5, seed=3):
        world = rates.to_world(base[2], u_b)
        plus = (base + EPS * world, q + EPS * dq)
        minus = (base - EPS * world, q - EPS * dq)
        (pp, rp), (pm, rm) = _placement(model, *plus), _placement(model, *minus)
        fd = np.concatenate(((pp - pm) / (2 * EPS), pin.log3(rp @ rm.T) / (2 * EPS)))
        model.update(base, q, world, dq)
        u = np.concatenate((u_b, dq))
        np.testing.assert_allclose(pose.jacobian_world(rates, base[2]) @ u, fd, atol=1e-7)

        twist_along = []
        for state in (plus, minus):
            model.update(*state)
            twist_along.append(pose.jacobian_world(rates, state[0][2]) @ u)
        fd_drift = (twist_along[0] - twist_along[1]) / (2 * EPS)
        model.update(base, q, world, dq)
        np.testing.assert_allclose(pose.drift(rates, base[2], u_b), fd_drift, atol=1e-6)


@pytest.mark.parametrize('orientation', ['rpy', 'log'])
def test_the_base_frame_jacobian_moves_the_error_coordinates_of_its_variant(orientation):
    """Sorour eq (7): over the base's twist (vx, vy, ω) and q̇_a, base-frame rows; the RPY
    variant moves the base-frame RPY angles of the end effector, the log one its twist."""
    model = KinematicModel('steerable')
    pose = PoseTask(model, orientation, rpy_damping=1e-9)
    cols = twist_columns(model.config.base.axes)
    for base, q, twist, dq in _states(model, 5, seed=4):
        world = twist_to_world(base[2], twist)
        plus, minus = (base + EPS * world, q + EPS * dq), (base - EPS * world, q - EPS * dq)
        (pw_p, rw_p), (pw_m, rw_m) = _placement(model, *plus), _placement(model, *minus)
        rpy_p = model.ee_pose_base()[3:]  # at ``minus``, the last update
        model.update(*plus)
        rpy_p, rpy_m = model.ee_pose_base()[3:], rpy_p
        model.update(base, q)
        b_r_w = rotation_z(base[2]).T
        fd_lin = b_r_w @ ((pw_p - pw_m) / (2 * EPS))
        if orientation == 'rpy':
            # J_mm's RPY rows are Ω⁻¹ of the end effector's angular velocity in the base's axes:
            # the base-frame RPY angles' rates plus the base's own turn on the yaw (Ω⁻¹ e_z = e_z)
            fd_ang = wrap_angle(rpy_p - rpy_m) / (2 * EPS) + np.array([0.0, 0.0, twist[2]])
        else:
            fd_ang = b_r_w @ (pin.log3(rw_p @ rw_m.T) / (2 * EPS))
        u = np.concatenate((twist, dq))
        np.testing.assert_allclose(pose.jacobian_base(cols) @ u, np.concatenate((fd_lin, fd_ang)), atol=1e-6)


def test_a_posture_tasks_pull_moves_the_arm_alone_towards_the_posture():
    task = PostureTask(3, 4)
    q, posture = np.array([0.1, -0.2, 0.3, 0.0]), np.array([0.5, -0.2, 0.0, 1.0])
    z = task.pull(q, posture, 2.0)
    np.testing.assert_allclose(z, [0, 0, 0, 0.8, 0.0, -0.6, 2.0])
    np.testing.assert_allclose(task.jacobian() @ z, 2.0 * task.error(q, posture))
    np.testing.assert_allclose(task.jacobian().T @ task.error(q, posture) * 2.0, z)


def test_the_bases_sent_twist_stays_within_its_own_axes_limits_and_its_rates_agree():
    """World rates turned into the base's own twist: each axis within a·T of the last twist and
    within its speed; the integrator's rates are that twist's (what is sent is what is integrated)."""
    world, unicycle = base_rates((0, 1, 2)), base_rates((0, 2))
    theta, last = 0.7, np.array([0.1, 0.0, 0.0])
    step, speed = np.array([0.01, 0.01, 0.02]), np.array([0.3, 0.3, 0.5])
    twist, u_b = world.twist(theta, np.array([1.0, -1.0, 0.5]), last, step, speed)
    assert np.all(np.abs(twist - last) <= step + 1e-15) and np.all(np.abs(twist) <= speed)
    np.testing.assert_allclose(world.of_twist(theta, twist), u_b)
    twist, u_b = unicycle.twist(theta, np.array([0.2, -0.1]), last, step, speed)
    np.testing.assert_allclose(twist, [0.2, 0.0, -0.1])
    np.testing.assert_allclose(unicycle.of_twist(theta, twist), u_b)
    np.testing.assert_allclose(unicycle.to_world(theta, u_b), [0.2 * np.cos(theta), 0.2 * np.sin(theta), -0.1])
    with pytest.raises(WmmError, match=r'got axes \(0, 1\)'):
        base_rates((0, 1))


def test_the_manipulability_tasks_rows_are_named_and_checked():
    model = KinematicModel('steerable')
    model.update(np.zeros(3), model.config.arm.dexterous)
    full, position = ManipulabilityTask(model, 'full'), ManipulabilityTask(model, 'position')
    jm = model.arm_jacobian_world('full')
    assert full.value() == pytest.approx(np.linalg.det(jm @ jm.T))
    assert position.value() == pytest.approx(np.linalg.det(jm[:3] @ jm[:3].T))
    with pytest.raises(WmmError, match="rows must be 'position' or 'full'"):
        ManipulabilityTask(model, 'orientation')
