"""Kinematics core: paper start states, every derivative against finite differences,
and clear errors on bad input."""

import numpy as np
import pinocchio as pin
import pytest

from wmm_control.errors import NonFiniteError, ShapeError, UnknownFrameError, WmmError
from wmm_control.kinematics import (
    KinematicModel,
    matrix_from_rpy,
    omega_rpy,
    pose_error_log,
    pose_error_rpy,
    rpy_from_matrix,
    rpy_rate_map,
    wrap_angle,
)

N_STATES = 20
EPS = 1e-6


def random_states(model, n, seed):
    """Random base poses and arm configurations inside the position limits."""
    rng = np.random.default_rng(seed)
    lo = np.maximum(model.config.arm.position_lower, -np.pi)
    hi = np.minimum(model.config.arm.position_upper, np.pi)
    for _ in range(n):
        base = np.array([rng.uniform(-3, 3), rng.uniform(-3, 3), rng.uniform(-np.pi, np.pi)])
        yield base, rng.uniform(lo, hi)


def world_position(model, base, q):
    model.update(base, q)
    return model.ee_placement_world()


def test_steerable_start_state_matches_sorour_table_ii(steerable_model):
    cfg = steerable_model.config
    steerable_model.update(cfg.start.base_pose, cfg.start.arm)
    pose = steerable_model.ee_pose_world()
    np.testing.assert_allclose(pose[:3], [0.708, 0.004, 1.08], atol=1e-2)
    assert np.max(np.abs(wrap_angle(pose[3:] - [np.pi / 2, 0, 0]))) <= 0.02
    np.testing.assert_allclose(cfg.start.arm, [np.pi / 2, np.pi / 2, np.pi / 2, -np.pi / 2, 0, 0, 0])
    np.testing.assert_allclose(cfg.arm.dexterous, cfg.start.arm)


def test_mecanum_start_state_matches_xing(mecanum_model):
    cfg = mecanum_model.config
    np.testing.assert_allclose(
        np.concatenate((cfg.start.base_pose, cfg.start.arm)), [0, 0, 0, 0, np.pi / 6, 0, np.pi / 2, 0, -np.pi / 6, 0]
    )
    mecanum_model.update(cfg.start.base_pose, cfg.start.arm)
    pos, _ = mecanum_model.ee_placement_world()
    assert np.linalg.norm(pos - [0.65, -0.0246, 0.4921]) <= 1e-2


def test_world_jacobian_matches_finite_differences(model):
    # Linear rows: d(position)/dq. Angular rows: log3(R(q+h) R(q)ᵀ)/h.
    for base, q in random_states(model, N_STATES, seed=1):
        model.update(base, q)
        jac = model.jacobian_world()
        x0 = np.concatenate((base, q))
        p0, r0 = model.ee_placement_world()
        fd = np.zeros((6, 10))
        for k in range(10):
            xp = x0.copy()
            xp[k] += EPS
            xm = x0.copy()
            xm[k] -= EPS
            pp, rp = world_position(model, xp[:3], xp[3:])
            pm, rm = world_position(model, xm[:3], xm[3:])
            fd[:3, k] = (pp - pm) / (2 * EPS)
            fd[3:, k] = (pin.log3(rp @ r0.T) - pin.log3(rm @ r0.T)) / (2 * EPS)
        np.testing.assert_allclose(jac, fd, atol=1e-7)


def test_arm_jacobian_and_h_give_base_frame_end_effector_velocity(model):
    # Sorour eqs (1) and (4): the EE velocity w.r.t. the world, in base axes, equals
    # H J_b q̇_b + J_a q̇_a with q̇_b = [ẋ ẏ 0 0 0 ω] in base axes.
    rng = np.random.default_rng(2)
    for base, q in random_states(model, N_STATES, seed=2):
        twist_b = rng.normal(size=3)  # (vx, vy, ω) base frame
        dq = rng.normal(size=7)
        c, s = np.cos(base[2]), np.sin(base[2])
        base_rate = np.array([c * twist_b[0] - s * twist_b[1], s * twist_b[0] + c * twist_b[1], twist_b[2]])
        model.update(base, q)
        qb6 = np.array([twist_b[0], twist_b[1], 0, 0, 0, twist_b[2]])
        predicted = model.h_matrix() @ qb6 + model.arm_jacobian_base() @ dq
        p0, r0 = model.ee_placement_world()
        p1, r1 = world_position(model, base + EPS * base_rate, q + EPS * dq)
        p2, r2 = world_position(model, base - EPS * base_rate, q - EPS * dq)
        rwb = np.array([[c, -s, 0], [s, c, 0], [0, 0, 1]])
        v_world = (p1 - p2) / (2 * EPS)
        w_world = (pin.log3(r1 @ r0.T) - pin.log3(r2 @ r0.T)) / (2 * EPS)
        np.testing.assert_allclose(predicted, np.concatenate((rwb.T @ v_world, rwb.T @ w_world)), atol=1e-7)


def test_jmm_maps_joint_rates_to_base_frame_rpy_rates(model):
    # Sorour eq (7): columns 6.. of J_mm (the arm) give the rates of the base-frame
    # RPY pose; checked away from the pitch singularity.
    checked = 0
    for base, q in random_states(model, 3 * N_STATES, seed=3):
        model.update(base, q)
        rpy = model.ee_pose_base()[3:]
        if abs(np.cos(rpy[1])) < 0.2:
            continue
        jmm = model.jmm()
        assert jmm.shape == (6, 13)
        for k in range(7):
            dq = np.zeros(7)
            dq[k] = EPS
            model.update(base, q + dq)
            pp = model.ee_pose_base()
            model.update(base, q - dq)
            pm = model.ee_pose_base()
            fd = (pp - pm) / (2 * EPS)
            fd[3:] = wrap_angle(fd[3:] * 2 * EPS) / (2 * EPS)
            np.testing.assert_allclose(jmm[:, 6 + k], fd, atol=1e-6)
        checked += 1
    assert checked >= 10


def test_jdot_qdot_matches_finite_differences(model):
    # J̇q̇ = d/dt (J(q) q̇) along q̇ with q̈ = 0.
    rng = np.random.default_rng(4)
    for base, q in random_states(model, N_STATES, seed=4):
        v = rng.normal(size=10)
        model.update(base, q, base_rate=v[:3], dq_arm=v[3:])
        jdqd = model.jdot_qdot()
        x0 = np.concatenate((base, q))
        xp, xm = x0 + EPS * v, x0 - EPS * v
        model.update(xp[:3], xp[3:])
        jp = model.jacobian_world() @ v
        model.update(xm[:3], xm[3:])
        jm = model.jacobian_world() @ v
        np.testing.assert_allclose(jdqd, (jp - jm) / (2 * EPS), atol=1e-6)


@pytest.mark.parametrize('rows', ['position', 'full'])
def test_manipulability_gradient_and_hessian_match_finite_differences(model, rows):
    for base, q in random_states(model, N_STATES, seed=5):
        model.update(base, q)
        grad = model.manipulability_gradient(rows)
        hess = model.manipulability_hessian(rows)
        fd_grad = np.zeros(7)
        fd_hess = np.zeros((7, 7))
        for k in range(7):
            dq = np.zeros(7)
            dq[k] = EPS
            model.update(base, q + dq)
            hp, gp = model.manipulability(rows), model.manipulability_gradient(rows)
            model.update(base, q - dq)
            hm, gm = model.manipulability(rows), model.manipulability_gradient(rows)
            fd_grad[k] = (hp - hm) / (2 * EPS)
            fd_hess[:, k] = (gp - gm) / (2 * EPS)
        scale = max(1.0, np.abs(grad).max())
        np.testing.assert_allclose(grad, fd_grad, atol=1e-8 * scale)
        np.testing.assert_allclose(hess, fd_hess, atol=1e-7 * max(1.0, np.abs(hess).max()))
        np.testing.assert_allclose(hess, hess.T, atol=1e-12)


# ∇H and ∇²H at one generic state (base (0.5, −0.2, 0.7), q_m below), as given by the
# earlier implementation, which built every ∂²J_m/∂q_l∂q_k (7, 7, 6, 7) explicitly.
REFERENCE_STATE = ([0.5, -0.2, 0.7], [0.3, -0.7, 1.1, -1.2, 0.4, 0.9, -0.5])
REFERENCE_DERIVATIVES = {
    ('steerable', 'position'): (
        [
            7.808278102983e-18,
            -1.569564861194e-02,
            1.443290630504e-03,
            2.418564508970e-03,
            -4.096004741488e-04,
            -1.996433198930e-03,
            -5.594267887809e-19,
        ],
        [
            [
                2.498648992955e-17,
                -1.742567047541e-17,
                1.602374489211e-18,
                -9.808098960374e-18,
                -4.547478772974e-19,
                -3.778141725175e-18,
                2.152969140938e-33,
            ],
            [
                -1.742567047541e-17,
                2.180934619364e-02,
                -1.658904080397e-02,
                -1.376039431918e-02,
                -3.648302064847e-03,
                7.848813523941e-03,
                4.707399756940e-18,
            ],
            [
                1.602374489211e-18,
                -1.658904080397e-02,
                2.082568215577e-02,
                1.101760312788e-02,
                5.192917105028e-03,
                7.657654434989e-04,
                -3.643496483405e-18,
            ],
            [
                -9.808098960374e-18,
                -1.376039431918e-02,
                1.101760312788e-02,
                -1.093598712482e-02,
                1.049551360089e-03,
                4.712297317945e-03,
                7.262796044265e-20,
            ],
            [
                -4.547478772974e-19,
                -3.648302064847e-03,
                5.192917105028e-03,
                1.049551360089e-03,
                8.842156480096e-04,
                7.776865742759e-04,
                -6.393593060234e-19,
            ],
            [
                -3.778141725175e-18,
                7.848813523941e-03,
                7.657654434989e-04,
                4.712297317945e-03,
                7.776865742759e-04,
                -5.583851788223e-03,
                -1.313519346735e-18,
            ],
            [
                2.152969140938e-33,
                4.707399756940e-18,
                -3.643496483405e-18,
                7.262796044265e-20,
                -6.393593060234e-19,
                -1.313519346735e-18,
                -1.104011483665e-18,
            ],
        ],
    ),
    ('steerable', 'full'): (
        [
            4.970701526738e-17,
            -1.540621255351e-02,
            6.203968626639e-04,
            -2.485485987656e-03,
            -1.339616732347e-03,
            3.361992222017e-03,
            -9.197645472540e-33,
        ],
        [
            [
                -3.092880949970e-16,
                1.861369053229e-16,
                -3.922480562539e-17,
                -3.070640833618e-16,
                -4.384637822931e-17,
                3.170706693349e-17,
                3.679058189016e-32,
            ],
            [
                1.861369053229e-16,
                1.001391708867e-02,
                -3.504404904867e-03,
                4.443208561585e-03,
                3.180898047318e-03,
                -9.000088460940e-03,
                -2.136115055383e-32,
            ],
            [
                -3.922480562539e-17,
                -3.504404904867e-03,
                3.501149148062e-03,
                1.411989461916e-03,
                6.220609964636e-18,
                9.846332849694e-04,
                -1.563387056358e-32,
            ],
            [
                -3.070640833618e-16,
                4.443208561585e-03,
                1.411989461916e-03,
                -1.829667895951e-02,
                1.362812483675e-03,
                2.675113096682e-03,
                2.697701947527e-32,
            ],
            [
                -4.384637822931e-17,
                3.180898047318e-03,
                6.220609964636e-18,
                1.362812483675e-03,
                -2.882666860997e-03,
                2.013462087876e-03,
                3.207798857413e-33,
            ],
            [
                3.170706693349e-17,
                -9.000088460940e-03,
                9.846332849694e-04,
                2.675113096682e-03,
                2.013462087876e-03,
                -8.188482783473e-03,
                -3.746417697090e-33,
            ],
            [
                3.679058189016e-32,
                -2.136115055383e-32,
                -1.563387056358e-32,
                2.697701947527e-32,
                3.207798857413e-33,
                -3.746417697090e-33,
                4.797068555896e-33,
            ],
        ],
    ),
    ('mecanum', 'position'): (
        [
            1.812129695967e-17,
            -1.260315993057e-02,
            -7.570609941387e-03,
            -1.196164519831e-02,
            4.775765617047e-03,
            -5.862866993838e-03,
            -9.870742512117e-19,
        ],
        [
            [
                1.656804293456e-16,
                4.254091533145e-17,
                2.965301568205e-17,
                4.353802952840e-17,
                -2.931995906536e-18,
                -9.112725897624e-18,
                -1.536053058437e-19,
            ],
            [
                4.254091533145e-17,
                -9.898363890298e-03,
                -3.794354118978e-03,
                7.065796012437e-03,
                5.322836584316e-04,
                8.123485910366e-03,
                1.411496804581e-18,
            ],
            [
                2.965301568205e-17,
                -3.794354118978e-03,
                -3.119399746206e-03,
                1.661014445514e-02,
                -2.114386069490e-03,
                9.626424265321e-03,
                1.558472101446e-18,
            ],
            [
                4.353802952840e-17,
                7.065796012437e-03,
                1.661014445514e-02,
                -1.808972094386e-02,
                6.411945814049e-04,
                7.551973333287e-03,
                1.225280522686e-18,
            ],
            [
                -2.931995906536e-18,
                5.322836584316e-04,
                -2.114386069490e-03,
                6.411945814049e-04,
                4.699697557078e-03,
                2.411599675887e-03,
                3.109917130813e-19,
            ],
            [
                -9.112725897624e-18,
                8.123485910366e-03,
                9.626424265321e-03,
                7.551973333287e-03,
                2.411599675887e-03,
                3.075095391087e-03,
                5.053982446146e-19,
            ],
            [
                -1.536053058437e-19,
                1.411496804581e-18,
                1.558472101446e-18,
                1.225280522686e-18,
                3.109917130813e-19,
                5.053982446146e-19,
                9.261064469874e-19,
            ],
        ],
    ),
    ('mecanum', 'full'): (
        [
            1.555740349959e-18,
            -5.880633430868e-03,
            -2.084195381309e-03,
            -1.607365020211e-03,
            -9.719840878031e-05,
            5.024927659022e-03,
            2.159023446078e-34,
        ],
        [
            [
                6.908875027449e-34,
                -2.128041005323e-17,
                -1.129388738771e-16,
                4.906987773691e-17,
                1.551423873503e-17,
                3.956928455265e-17,
                5.527100021960e-33,
            ],
            [
                -2.128041005323e-17,
                -1.020253938787e-03,
                -9.703886850379e-04,
                1.668456743874e-03,
                2.370175092823e-04,
                -8.019459720769e-03,
                -2.435084524762e-33,
            ],
            [
                -1.129388738771e-16,
                -9.703886850379e-04,
                9.337404465471e-05,
                2.054612442699e-03,
                -8.001961945132e-06,
                -3.304371823658e-03,
                4.362320310408e-33,
            ],
            [
                4.906987773691e-17,
                1.668456743874e-03,
                2.054612442699e-03,
                -8.673504888036e-03,
                6.426263219010e-04,
                9.554656855220e-04,
                -6.317049042272e-33,
            ],
            [
                1.551423873503e-17,
                2.370175092823e-04,
                -8.001961945132e-06,
                6.426263219010e-04,
                -7.791825304440e-05,
                1.068336559482e-03,
                -7.076101781488e-35,
            ],
            [
                3.956928455265e-17,
                -8.019459720769e-03,
                -3.304371823658e-03,
                9.554656855220e-04,
                1.068336559482e-03,
                2.248807928786e-03,
                -3.835639939769e-33,
            ],
            [
                5.527100021960e-33,
                -2.435084524762e-33,
                4.362320310408e-33,
                -6.317049042272e-33,
                -7.076101781488e-35,
                -3.835639939769e-33,
                7.108499635902e-34,
            ],
        ],
    ),
}


@pytest.mark.parametrize('rows', ['position', 'full'])
def test_manipulability_derivatives_match_the_full_second_derivative_form(model, rows):
    model.update(*REFERENCE_STATE)
    grad_ref, hess_ref = (np.array(a) for a in REFERENCE_DERIVATIVES[model.config.name, rows])
    np.testing.assert_allclose(
        model.manipulability_gradient(rows), grad_ref, rtol=0, atol=1e-11 * np.abs(grad_ref).max()
    )
    np.testing.assert_allclose(
        model.manipulability_hessian(rows), hess_ref, rtol=0, atol=1e-11 * np.abs(hess_ref).max()
    )


def test_manipulability_derivatives_are_fresh_copies_and_follow_update(steerable_model):
    model = steerable_model
    model.update(*REFERENCE_STATE)
    hess = model.manipulability_hessian('full')
    grad = model.manipulability_gradient('full')
    np.testing.assert_array_equal(hess, hess.T)
    hess[:] = 0.0
    grad[:] = 0.0
    assert np.abs(model.manipulability_hessian('full')).max() > 0
    assert np.abs(model.manipulability_gradient('full')).max() > 0
    model.update(np.zeros(3), model.config.arm.dexterous)
    assert not np.allclose(model.manipulability_gradient('position'), REFERENCE_DERIVATIVES['steerable', 'position'][0])
    # Exactly singular J_m J_mᵀ (arm straight up): finite derivatives, those of det at the
    # singularity (zero there: joints 1, 3, 5, 7 share one axis, a rank drop of two), no error.
    model.update(np.zeros(3), np.zeros(7))
    grad, hess = model.manipulability_gradient('full'), model.manipulability_hessian('full')
    assert np.all(np.isfinite(grad)) and np.all(np.isfinite(hess))
    fd = []
    for k in range(7):
        dq = np.zeros(7)
        dq[k] = 1e-6
        model.update(np.zeros(3), dq)
        up = model.manipulability('full')
        model.update(np.zeros(3), -dq)
        fd.append((up - model.manipulability('full')) / 2e-6)
    np.testing.assert_allclose(grad, fd, atol=1e-9)


def test_sigma_min_drops_to_zero_at_the_stretched_singularity(steerable_model):
    # The LWR arm straight up (q = 0) is singular: joints 1, 3, 5, 7 share one axis.
    steerable_model.update(np.zeros(3), np.zeros(7))
    assert steerable_model.sigma_min('full') < 1e-9
    assert steerable_model.manipulability('full') < 1e-12
    steerable_model.update(np.zeros(3), steerable_model.config.arm.dexterous)
    assert steerable_model.sigma_min('full') > 0.1


def test_rpy_helpers_round_trip_and_omega_matches_definition():
    rng = np.random.default_rng(6)
    for _ in range(50):
        rpy = np.array([rng.uniform(-np.pi, np.pi), rng.uniform(-1.5, 1.5), rng.uniform(-np.pi, np.pi)])
        rot = matrix_from_rpy(rpy)
        np.testing.assert_allclose(rpy_from_matrix(rot), rpy, atol=1e-12)
        rates = rng.normal(size=3)
        r1 = matrix_from_rpy(rpy + EPS * rates)
        r2 = matrix_from_rpy(rpy - EPS * rates)
        omega = pin.log3(r1 @ r2.T) / (2 * EPS)
        np.testing.assert_allclose(omega_rpy(rpy) @ rates, omega, atol=1e-7)
        np.testing.assert_allclose(rpy_rate_map(rpy)[3:, 3:] @ omega_rpy(rpy), np.eye(3), atol=1e-9)
    # At the pitch singularity the damped map stays finite.
    assert np.all(np.isfinite(rpy_rate_map([0.1, np.pi / 2, 0.3])))


def test_pose_errors_wrap_and_log_map_agree_for_small_rotations():
    err = pose_error_rpy([0, 0, 0, np.pi - 0.1, 0, 0], [0, 0, 0, -np.pi + 0.1, 0, 0])
    np.testing.assert_allclose(err[3:], [-0.2, 0, 0], atol=1e-12)
    rot = matrix_from_rpy([0.3, 0.2, -0.1])
    small = matrix_from_rpy([0.31, 0.2, -0.1])
    e_log = pose_error_log([1, 2, 3], small, [1, 2, 2.5], rot)
    np.testing.assert_allclose(e_log[:3], [0, 0, 0.5])
    assert abs(np.linalg.norm(e_log[3:]) - 0.01) < 1e-4
    assert wrap_angle(np.pi) == np.pi and wrap_angle(-np.pi) == np.pi


def test_bad_input_raises_named_errors(steerable_model):
    with pytest.raises(ShapeError, match=r'q_arm: expected shape \(7,\), got \(6,\)'):
        steerable_model.update(np.zeros(3), np.zeros(6))
    with pytest.raises(ShapeError, match='base_pose'):
        steerable_model.update(np.zeros(2), np.zeros(7))
    with pytest.raises(NonFiniteError, match=r'q_arm: non-finite entries at indices \[2\]'):
        steerable_model.update(np.zeros(3), [0, 0, np.nan, 0, 0, 0, 0])
    with pytest.raises(NonFiniteError, match='base_rate'):
        steerable_model.update(np.zeros(3), np.zeros(7), base_rate=[np.inf, 0, 0], dq_arm=np.zeros(7))
    with pytest.raises(UnknownFrameError, match="unknown frame 'gripper'.*ee_link"):
        steerable_model.frame_id('gripper')
    with pytest.raises(UnknownFrameError, match='tool0'):
        KinematicModel('steerable', ee_frame='tool0')
    with pytest.raises(WmmError, match="rows must be 'position' or 'full'"):
        steerable_model.manipulability('orientation')
    fresh = KinematicModel('mecanum')
    with pytest.raises(WmmError, match='call update'):
        fresh.arm_jacobian_base()
    fresh.update(np.zeros(3), np.zeros(7))
    with pytest.raises(WmmError, match='jdot_qdot needs'):
        fresh.jdot_qdot()


def test_a_failed_update_keeps_the_previous_state(steerable_model):
    steerable_model.update(np.zeros(3), steerable_model.config.arm.dexterous)
    before = steerable_model.ee_pose_world()
    with pytest.raises(NonFiniteError):
        steerable_model.update([np.nan, 0, 0], np.zeros(7))
    np.testing.assert_array_equal(steerable_model.ee_pose_world(), before)
