"""Kinematics core: paper start states, every derivative against finite differences,
and clear errors on bad input."""

import numpy as np
import pinocchio as pin
import pytest

from wmm_control.errors import NonFiniteError, ShapeError, UnknownFrameError, WmmError
from wmm_control.geometry import (
    matrix_from_rpy,
    omega_rpy,
    pose_error_log,
    pose_error_rpy,
    rpy_from_matrix,
    rpy_rate_map,
    wrap_angle,
)
from wmm_control.kinematics import KinematicModel, pinocchio_model
from wmm_control.kinematics.tasks import ManipulabilityTask
from wmm_control.robot_config import load_robot

N_STATES = 20
_ROWS_OF = {'position': slice(0, 3), 'full': slice(0, 6)}
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
    task = ManipulabilityTask(model, rows)
    for base, q in random_states(model, N_STATES, seed=5):
        model.update(base, q)
        grad = task.gradient()
        hess = task.hessian()
        fd_grad = np.zeros(7)
        fd_hess = np.zeros((7, 7))
        for k in range(7):
            dq = np.zeros(7)
            dq[k] = EPS
            model.update(base, q + dq)
            hp, gp = task.value(), task.gradient()
            model.update(base, q - dq)
            hm, gm = task.value(), task.gradient()
            fd_grad[k] = (hp - hm) / (2 * EPS)
            fd_hess[:, k] = (gp - gm) / (2 * EPS)
        scale = max(1.0, np.abs(grad).max())
        np.testing.assert_allclose(grad, fd_grad, atol=1e-8 * scale)
        np.testing.assert_allclose(hess, fd_hess, atol=1e-7 * max(1.0, np.abs(hess).max()))
        np.testing.assert_allclose(hess, hess.T, atol=1e-12)


REFERENCE_STATE = ([0.5, -0.2, 0.7], [0.3, -0.7, 1.1, -1.2, 0.4, 0.9, -0.5])


def _jacobian_derivatives(model, base, q, h=1e-5, h2=1e-4):
    """∂J_m/∂q_k (k, 6, n) and ∂²J_m/∂q_l∂q_k (l, k, 6, n) by central differences of pinocchio's
    Jacobian: the explicit form the closed-form derivatives avoid."""
    n = len(q)

    def jac(dq):
        model.update(base, q + dq)
        return model.arm_jacobian_world('full')

    eye = np.eye(n) * h
    d1 = np.array([(jac(eye[k]) - jac(-eye[k])) / (2 * h) for k in range(n)])
    e2 = np.eye(n) * h2

    def second(a, b):
        return (jac(e2[a] + e2[b]) - jac(e2[a] - e2[b]) - jac(-e2[a] + e2[b]) + jac(-e2[a] - e2[b])) / (4 * h2 * h2)

    d2 = np.array([[second(a, b) for b in range(n)] for a in range(n)])
    model.update(base, q)
    return d1, d2


@pytest.mark.parametrize('rows', ['position', 'full'])
def test_manipulability_derivatives_match_the_full_second_derivative_form(model, rows):
    """Xing's appendices A and B written out with every ∂J_m/∂q_k and ∂²J_m/∂q_l∂q_k (here by
    finite differences of the Jacobian): ``∇H = H g``, ``g_k = tr(M⁻¹ ∂_k M)`` and
    ``∇²H = H (g gᵀ + A + B − C)``."""
    base, q = (np.array(v) for v in REFERENCE_STATE)
    d1, d2 = _jacobian_derivatives(model, base, q)
    model.update(base, q)
    r = _ROWS_OF[rows]
    jm = model.arm_jacobian_world(rows)
    d1, d2 = d1[:, r], d2[:, :, r]
    m = jm @ jm.T
    minv = np.linalg.inv(m)
    h = np.linalg.det(m)
    dm = d1 @ jm.T + jm @ d1.transpose(0, 2, 1)  # ∂_k M
    g = np.einsum('ij,kji->k', minv, dm)
    a = 2 * np.einsum('ij,lkjm,im->lk', minv, d2, jm)  # 2 tr(M⁻¹ ∂²_lk J_m J_mᵀ)
    b = 2 * np.einsum('ij,ljm,kim->lk', minv, d1, d1)  # 2 tr(M⁻¹ ∂_l J_m ∂_k J_mᵀ)
    c = np.einsum('ij,ljk,km,nmi->ln', minv, dm, minv, dm)
    grad, hess = h * g, h * (np.outer(g, g) + a + b - c)
    task = ManipulabilityTask(model, rows)
    np.testing.assert_allclose(task.gradient(), grad, rtol=0, atol=1e-8 * np.abs(grad).max())
    np.testing.assert_allclose(task.hessian(), hess, rtol=0, atol=1e-6 * np.abs(hess).max())


def test_manipulability_derivatives_are_fresh_copies_and_follow_update(steerable_model):
    model = steerable_model
    task = ManipulabilityTask(model, 'full')
    model.update(*REFERENCE_STATE)
    hess = task.hessian()
    grad = task.gradient()
    grad_before = grad.copy()
    np.testing.assert_allclose(hess, hess.T, rtol=0, atol=1e-15 * np.abs(hess).max())
    hess[:] = 0.0
    grad[:] = 0.0
    assert np.abs(task.hessian()).max() > 0
    assert np.abs(task.gradient()).max() > 0
    model.update(np.zeros(3), model.config.arm.dexterous)
    assert not np.allclose(task.gradient(), grad_before)
    # Exactly singular J_m J_mᵀ (arm straight up): finite derivatives, those of det at the
    # singularity (zero there: joints 1, 3, 5, 7 share one axis, a rank drop of two), no error.
    model.update(np.zeros(3), np.zeros(7))
    grad, hess = task.gradient(), task.hessian()
    assert np.all(np.isfinite(grad)) and np.all(np.isfinite(hess))
    fd = []
    for k in range(7):
        dq = np.zeros(7)
        dq[k] = 1e-6
        model.update(np.zeros(3), dq)
        up = task.value()
        model.update(np.zeros(3), -dq)
        fd.append((up - task.value()) / 2e-6)
    np.testing.assert_allclose(grad, fd, atol=1e-9)


def test_sigma_min_drops_to_zero_at_the_stretched_singularity(steerable_model):
    # The LWR arm straight up (q = 0) is singular: joints 1, 3, 5, 7 share one axis.
    task = ManipulabilityTask(steerable_model, 'full')
    steerable_model.update(np.zeros(3), np.zeros(7))
    assert task.sigma_min() < 1e-9
    assert task.value() < 1e-12
    steerable_model.update(np.zeros(3), steerable_model.config.arm.dexterous)
    assert task.sigma_min() > 0.1


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
        ManipulabilityTask(steerable_model, 'orientation')
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


def test_one_pinocchio_model_per_urdf_text_and_options_each_user_with_its_own_data(tmp_path):
    """Kinematic models of one URDF text, arm and held positions read one pinocchio model (the
    same text at another path too), each with its own data; held positions of their own, another
    root joint or the file rewritten give another model, and the shared one is the one a parse of
    its own gives."""
    cfg = load_robot('steerable')
    a, b = KinematicModel(cfg), KinematicModel(cfg)
    assert a.model is b.model and a.full_model is b.full_model and a.data is not b.data
    root = pin.JointModelComposite()
    for joint in (pin.JointModelPX(), pin.JointModelPY(), pin.JointModelRZ()):
        root.addJoint(joint)
    assert a.full_model == pin.buildModelFromUrdf(str(cfg.urdf_path), root)
    text = cfg.urdf_path.read_text()
    copy = tmp_path / 'copy.urdf'
    copy.write_text(text)
    args = (cfg.arm.joints, cfg.ee_frame, cfg.base_link)
    assert KinematicModel.from_urdf(copy, *args, {}).model is a.model
    held = KinematicModel.from_urdf(copy, *args, {'steer_fl_joint': 0.3})
    assert held.full_model is a.full_model and held.model is not a.model and held.model != a.model
    fixed = pinocchio_model(cfg.urdf_path, planar_root=False)
    assert fixed.nq == a.full_model.nq - 3 and pinocchio_model(cfg.urdf_path) is a.full_model
    limit = text.index('upper="2.967060"', text.index('<joint name="arm_joint_1"'))
    copy.write_text(text[:limit] + 'upper="2.5"' + text[limit + len('upper="2.967060"') :])
    rewritten = KinematicModel.from_urdf(copy, *args, {})
    assert rewritten.full_model is not a.full_model and rewritten.model is not a.model
    assert rewritten.model.upperPositionLimit[rewritten.model.joints[2].idx_q] == 2.5
    assert a.model.upperPositionLimit[a.model.joints[2].idx_q] == 2.96706
