"""The redundancy resolvers (Sorour eqs 8–14) and the limits of their commands."""

import numpy as np
import pinocchio as pin
import pytest
from hypothesis import given, settings, strategies as st

from sim_bridge.closed_loop import ClosedLoop
from sim_bridge.world import SimWorld
from wmm_control.errors import ConfigError, NonFiniteError, ShapeError
from wmm_control.geometry import rpy_from_matrix, twist_to_world
from wmm_control.resolvers import (
    CommandLimits,
    PinvResolver,
    PoseTarget,
    RobotState,
    TaskSharingParams,
    TaskSharingResolver,
    make_resolver,
    psi_of_error,
)

DT = 0.025


@pytest.fixture(scope='module')
def robot(steerable_model):
    return steerable_model.config


def start_state(robot, q_arm=None, base=(0.0, 0.0, 0.0)):
    return RobotState(base, np.zeros(3), robot.start.arm if q_arm is None else q_arm, np.zeros(7))


def ee_of(resolver, state):
    resolver.model.update(state.base_pose, state.q_arm)
    return resolver.model.ee_placement_world()


def offset_target(resolver, state, dp, drpy=(0.0, 0.0, 0.0)):
    pos, rot = ee_of(resolver, state)
    rpy = rpy_from_matrix(rot) + np.asarray(drpy)
    return PoseTarget(pos + np.asarray(dp), pin.rpy.rpyToMatrix(*rpy))


def test_eq11_modes():
    assert psi_of_error(0.25, 0.25, 0.9) == 1.0
    assert psi_of_error(0.2501, 0.25, 0.9) == 0.5
    assert psi_of_error(0.9, 0.25, 0.9) == 0.5
    assert psi_of_error(0.9001, 0.25, 0.9) == 0.0


def test_fine_manipulation_gives_the_base_no_share(steerable_model, robot):
    """ψ = 1: the base's part of the particular solution is exactly zero (W⁻¹ is the activation)."""
    res = TaskSharingResolver(steerable_model, TaskSharingParams(lambda_dex=0.0))
    state = start_state(robot)
    cmd = res.step(state, offset_target(res, state, (0.1, 0.05, -0.05), (0.1, 0.0, 0.0)))
    assert cmd.diagnostics.psi == 1.0 and cmd.diagnostics.mode == 'fine_manipulation'
    assert np.all(cmd.base_twist == 0.0)
    assert np.linalg.norm(cmd.arm_velocity) > 1e-3


def test_gross_motion_gives_the_arm_no_share(steerable_model, robot):
    """ψ = 0: the arm takes no part in the task; at q_dex the null-space pull is zero too."""
    res = TaskSharingResolver(steerable_model)
    state = start_state(robot)
    cmd = res.step(state, offset_target(res, state, (3.0, 1.0, 0.0)))
    assert cmd.diagnostics.psi == 0.0 and cmd.diagnostics.mode == 'gross_motion'
    assert np.all(cmd.arm_velocity == 0.0)
    assert cmd.base_twist[0] > 0.0


def test_mobile_manipulation_shares_the_task(steerable_model, robot):
    res = TaskSharingResolver(steerable_model, TaskSharingParams(lambda_dex=0.0))
    state = start_state(robot)
    cmd = res.step(state, offset_target(res, state, (0.5, 0.0, 0.0)))
    assert cmd.diagnostics.psi == 0.5
    assert abs(cmd.base_twist[0]) > 0.0 and np.linalg.norm(cmd.arm_velocity) > 0.0


def test_null_space_pull_moves_towards_q_dex_and_keeps_the_end_effector_still(steerable_model, robot):
    res = TaskSharingResolver(steerable_model)
    q = robot.arm.dexterous + np.array([0.3, -0.2, 0.25, 0.2, -0.3, 0.2, 0.1])
    state = start_state(robot, q)
    cmd = res.step(state, offset_target(res, state, (0.0, 0.0, 0.0)))
    jac, _, _, _ = res.task_reference(state, offset_target(res, state, (0.0, 0.0, 0.0)))
    u = np.concatenate((cmd.base_twist, cmd.arm_velocity))
    assert np.linalg.norm(u) > 1e-3
    assert np.linalg.norm(jac @ u) < 1e-6 * np.linalg.norm(u) + 1e-9
    assert np.dot(robot.arm.dexterous - q, cmd.arm_velocity) > 0.0
    # the pull spans the base too (eq 9's projector is over the whole body)
    assert np.linalg.norm(cmd.base_twist) > 0.0


def test_pinv_follows_the_minimum_norm_direction(steerable_model, robot):
    res = PinvResolver(steerable_model)
    state = start_state(robot)
    target = offset_target(res, state, (0.3, -0.2, 0.1), (0.1, -0.1, 0.2))
    jac, p_ref, _, _ = res.task_reference(state, target)
    cmd = res.step(state, target)
    u = np.concatenate((cmd.base_twist, cmd.arm_velocity))
    expected = np.linalg.pinv(jac) @ p_ref
    cos = np.dot(u, expected) / (np.linalg.norm(u) * np.linalg.norm(expected))
    assert cos > 1.0 - 1e-6
    assert cmd.diagnostics.accel_scale < 1.0  # from rest: the acceleration limit scales it


def test_compensation_term_gives_the_arm_the_base_deficit(steerable_model, robot):
    """Eq (14): J_a Δq̇_a = M H J_b (q̇_ref(b) − q̇_bf)."""
    res = TaskSharingResolver(steerable_model)
    state = start_state(robot)
    res.step(state, offset_target(res, state, (2.0, 0.5, 0.0)))
    ref, feasible = np.array([0.4, 0.1, 0.2]), np.array([0.1, 0.0, 0.05])
    term = res.compensation_term(ref, feasible)
    jac = res._jac
    np.testing.assert_allclose(jac[:, 3:] @ term, jac[:, :3] @ (ref - feasible), atol=1e-4)  # ρ = 0.001
    assert np.allclose(res.compensation_term(ref, ref), 0.0)


def test_compensate_without_compensation_returns_the_command(steerable_model, robot):
    res = TaskSharingResolver(steerable_model, TaskSharingParams(compensation=False))
    state = start_state(robot)
    cmd = res.step(state, offset_target(res, state, (2.0, 0.5, 0.0)))
    assert res.compensate(cmd, np.zeros(3)) is cmd
    assert not res.uses_compensation


def test_psi_rate_limits_the_switch(steerable_model, robot):
    res = TaskSharingResolver(steerable_model, TaskSharingParams(psi_rate=2.0))
    state = start_state(robot)
    far = offset_target(res, state, (3.0, 0.0, 0.0))
    near = offset_target(res, state, (0.05, 0.0, 0.0))
    assert res.step(state, far).diagnostics.psi == 0.0
    psis = [res.step(state, near).diagnostics.psi for _ in range(30)]
    steps = np.diff([0.0] + psis)
    assert np.all(steps <= 2.0 * DT + 1e-12) and psis[-1] == 1.0
    assert res.step(state, near).diagnostics.mode == 'fine_manipulation'


@pytest.mark.parametrize(
    'bad',
    [
        dict(r_fm=1.0, r_mm=0.5),
        dict(orientation_error='quaternion'),
        dict(lambda_p=-1.0),
        dict(rho=float('nan')),
        dict(lambda_p='fast'),
    ],
)
def test_invalid_parameters_are_rejected(bad):
    with pytest.raises(ConfigError):
        TaskSharingParams(**bad)


def test_make_resolver_names_the_methods():
    with pytest.raises(ConfigError, match='pinv'):
        make_resolver('gradient_descent', 'steerable')
    with pytest.raises(ConfigError):
        make_resolver('pinv', 'steerable', lambda_dex=1.0)
    assert make_resolver('task_sharing', 'steerable', compensation=False).name == 'task_sharing'


def test_bad_state_and_target_raise_named_errors(robot):
    with pytest.raises(NonFiniteError):
        RobotState((0.0, np.nan, 0.0), np.zeros(3), robot.start.arm, np.zeros(7))
    with pytest.raises(ShapeError):
        RobotState((0.0, 0.0, 0.0), np.zeros(3), np.zeros(6), np.zeros(7))
    with pytest.raises(ShapeError):
        PoseTarget(np.zeros(3), np.eye(2))


@pytest.mark.parametrize('position', [(1e300, 0.0, 1.0), (-1e300, 1e300, -1e300), (0.0, 0.0, 1e12)])
def test_absurd_targets_give_finite_commands_within_limits(steerable_model, robot, position):
    res = TaskSharingResolver(steerable_model)
    state = start_state(robot)
    for _ in range(5):
        cmd = res.step(state, PoseTarget(position, np.eye(3)))
        cmd = res.compensate(cmd, np.zeros(3))
        assert np.all(np.isfinite(cmd.arm_velocity)) and np.all(np.isfinite(cmd.base_twist))
        assert np.all(np.abs(cmd.arm_velocity) <= robot.arm.velocity + 1e-12)
        assert np.all(np.abs(cmd.base_twist) <= robot.base.velocity + 1e-12)


# ---------------------------------------------------------------------- limits
def _limits(robot):
    inf3 = np.full(3, np.inf)
    return CommandLimits(
        np.concatenate((robot.base.velocity, robot.arm.velocity)),
        np.concatenate((robot.base.acceleration, robot.arm.acceleration)),
        np.concatenate((-inf3, robot.arm.position_lower)),
        np.concatenate((inf3, robot.arm.position_upper)),
        DT,
    )


@settings(max_examples=200, deadline=None)
@given(
    st.lists(st.floats(-50, 50), min_size=10, max_size=10),
    st.lists(st.floats(-5, 5), min_size=10, max_size=10),
    st.lists(st.floats(-1, 1), min_size=10, max_size=10),
    st.lists(st.floats(-1, 1), min_size=7, max_size=7),
)
def test_limited_command_keeps_every_bound(robot, primary, secondary, prev_frac, pos_frac):
    lim = _limits(robot)
    arm = robot.arm
    position = np.concatenate(
        (np.zeros(3), arm.position_lower + (np.asarray(pos_frac) + 1) / 2 * (arm.position_upper - arm.position_lower))
    )
    down, up = lim.braking_rates(position)
    prev = np.clip(np.asarray(prev_frac) * lim.velocity, -down, up)  # a command that kept its bounds
    out = lim.apply(primary, position, prev, secondary=secondary)
    u = out.command
    assert np.all(np.isfinite(u))
    assert np.all(np.abs(u) <= lim.velocity + 1e-9)
    assert np.all(np.abs(u - prev) <= lim.acceleration * DT + 1e-9)
    assert np.all(u <= up + 1e-9) and np.all(u >= -down - 1e-9)
    assert 0.0 <= out.scale <= 1.0 and 0.0 <= out.accel_scale <= 1.0


def test_uniform_scaling_keeps_the_direction(robot):
    lim = _limits(robot)
    position = np.concatenate((np.zeros(3), robot.arm.dexterous))
    desired = np.array([5.0, 2.0, 0.5, 1.0, -0.5, 0.3, 0.2, 0.1, 0.0, -0.1])
    prev = desired * 0.1  # within the acceleration reach of the scaled command
    out = lim.apply(desired, position, prev)
    assert out.scale < 1.0
    # the result moves from prev towards scale*desired along a straight line
    target = out.scale * desired
    step = out.command - prev
    cos = np.dot(step, target - prev) / (np.linalg.norm(step) * np.linalg.norm(target - prev))
    assert cos > 1 - 1e-9


@settings(max_examples=300, deadline=None)
@given(st.floats(0.0, 3.0), st.floats(0.1, 20.0))
def test_braking_rate_is_the_largest_that_stops_in_time(distance, accel):
    """Brute force: braking from v at a·dt per period covers at most the distance, and a rate 1e-9
    faster would not stop in time."""
    lim = CommandLimits([10.0], [accel], [-np.inf], [distance], DT)
    v = float(lim.braking_rates([0.0])[1][0])

    def covered(rate):
        total = 0.0
        while rate > 0.0:
            total += rate * DT
            rate -= accel * DT
        return total

    assert covered(v) <= distance * (1 + 1e-12) + 1e-15
    assert covered(v + 1e-9 + 1e-9 * v) > distance


@settings(max_examples=200, deadline=None)
@given(st.floats(0.0, 2.0), st.floats(0.0, 0.3), st.floats(0.2, 5.0), st.floats(0.0, 1.0))
def test_an_entry_given_room_keeps_within_it_and_its_acceleration_limit(room, speed, accel, shrink):
    """An entry without position limits (a base's axis), at ``speed`` with ``room`` [m] left, its
    room shrinking by what it covers and at once by ``shrink`` of it (its plan slowed): asked
    for full speed, it never changes by more than a·dt a period, and from any speed within the
    room's braking it stops within the room."""
    lim = CommandLimits([1.0], [accel], [-np.inf], [np.inf], DT)
    inf = np.array([np.inf])
    within = speed <= lim.braking_rates([0.0], (inf, np.array([room])))[1][0]
    room *= 1.0 - shrink if not within else 1.0
    covered, v = 0.0, speed
    for _ in range(2000):
        out = lim.apply(np.array([1.0]), np.zeros(1), np.array([v]), room=(inf, np.array([room - covered])))
        new = float(out.command[0])
        assert abs(new - v) <= accel * DT * (1 + 1e-9)
        v = new
        covered += v * DT
        if v == 0.0:
            break
    assert v == 0.0
    if within:
        assert covered <= room + 1e-12


def test_a_joint_next_to_its_limit_cannot_pass_it_in_one_period(robot):
    """Within a·dt² of a limit the braking rate would cover more than the distance left in one
    period; the bound is then that distance over dt."""
    lim = _limits(robot)
    position = np.concatenate((np.zeros(3), robot.arm.dexterous))
    position[3] = robot.arm.position_upper[0] - 1e-4
    down, up = lim.braking_rates(position)
    assert up[3] * DT <= 1e-4 + 1e-15 and up[3] > 0.0
    out = lim.apply(np.full(10, 5.0), position, np.zeros(10))
    assert position[3] + out.command[3] * DT <= robot.arm.position_upper[0]


@pytest.mark.parametrize('wrong', ['primary', 'position', 'previous', 'secondary', 'previous_secondary'])
def test_limits_reject_vectors_of_the_wrong_length(robot, wrong):
    lim = _limits(robot)
    args = {
        'primary': np.zeros(10),
        'position': np.concatenate((np.zeros(3), robot.arm.dexterous)),
        'previous': np.zeros(10),
        'secondary': np.zeros(10),
        'previous_secondary': np.zeros(10),
    }
    args[wrong] = np.zeros(9)
    with pytest.raises(ShapeError, match='CommandLimits.apply'):
        lim.apply(**args)


def test_many_cycles_never_pass_a_limit_even_for_unreachable_goals(steerable_model, robot):
    """Integrate the arm and an ideal base for 600 periods towards goals, two of them unreachable."""
    rng = np.random.default_rng(3)
    res = TaskSharingResolver(steerable_model)
    base = np.zeros(3)
    q = robot.start.arm.copy()
    prev_arm, prev_base = np.zeros(7), np.zeros(3)
    goals = [(2.0, 1.0, 3.5), (0.5, 0.2, -1.0), (1.0, -0.5, 1.1), tuple(rng.uniform(-1, 1, 3) + (0, 0, 1.0))]
    for k in range(600):
        goal = goals[k // 150]
        state = RobotState(base, prev_base, q, prev_arm)
        cmd = res.compensate(res.step(state, PoseTarget(goal, np.eye(3))), prev_base * 0.5)
        assert np.all(np.abs(cmd.arm_velocity) <= robot.arm.velocity + 1e-9)
        assert np.all(np.abs(cmd.arm_velocity - prev_arm) <= robot.arm.acceleration * DT + 1e-9)
        assert np.all(np.abs(cmd.base_twist) <= robot.base.velocity + 1e-9)
        assert np.all(np.abs(cmd.base_twist - prev_base) <= robot.base.acceleration * DT + 1e-9)
        q = q + cmd.arm_velocity * DT
        assert np.all(q <= robot.arm.position_upper + 1e-12) and np.all(q >= robot.arm.position_lower - 1e-12)
        base = base + DT * twist_to_world(base[2], cmd.base_twist)
        prev_arm, prev_base = cmd.arm_velocity, cmd.base_twist


# ---------------------------------------------------------------------- eq (12) trap
@pytest.mark.parametrize('literal', [False, True])
def test_rotating_the_rpy_error_by_the_base_yaw_breaks_orientation_control(literal):
    """Eq (12) as printed rotates the RPY error by ᵇR_w: once the base has turned, roll and
    pitch errors mix and the orientation diverges; the identity on the angular part converges."""
    with SimWorld('steerable', start_base_pose=(0.0, 0.0, -2.0)) as world:
        res = TaskSharingResolver('steerable', TaskSharingParams(rotate_angular_error=literal))
        loop = ClosedLoop(world, res)
        state = loop.state()
        rpy = rpy_from_matrix(state.ee_rotation) + np.array([0.3, 0.2, 0.0])
        target = PoseTarget(state.ee_position + np.array([0.05, 0.0, 0.0]), pin.rpy.rpyToMatrix(*rpy))
        errors = [np.linalg.norm(pin.log3(target.rotation @ loop.step(target).ee_rotation.T)) for _ in range(300)]
    if literal:
        assert max(errors) > 1.0
    else:
        assert errors[-1] < 1e-3 and max(errors) < errors[0] + 1e-3


_finite_or_not = st.one_of(st.floats(-50, 50), st.sampled_from([np.nan, np.inf, -np.inf]))


@settings(max_examples=300, deadline=None)
@given(
    st.lists(_finite_or_not, min_size=10, max_size=10),
    st.lists(st.floats(-5, 5), min_size=10, max_size=10),
    st.lists(st.floats(-1.2, 1.2), min_size=10, max_size=10),
    st.floats(0.0, 1.0),
    st.lists(st.floats(-0.1, 1.1), min_size=7, max_size=7),
)
def test_limits_from_any_state_keep_the_box_and_report_what_they_changed(
    robot, primary, secondary, prev_frac, prev_share, pos_frac
):
    """From any previous command (also one that broke its bounds: forced entries) and any
    position (also beyond the limits), with non-finite requests: the command is in the period's
    box, the box within the velocity and braking bounds and, where not forced, within a·dt of
    the previous command; the velocity factor is the largest that fits; and a command that no
    bound touched is the request itself."""
    lim = _limits(robot)
    arm = robot.arm
    position = np.concatenate(
        (np.zeros(3), arm.position_lower + np.asarray(pos_frac) * (arm.position_upper - arm.position_lower))
    )
    prev = np.asarray(prev_frac) * lim.velocity
    prev_s = prev_share * prev
    primary, secondary = np.asarray(primary), np.asarray(secondary)
    out = lim.apply(primary, position, prev, secondary=secondary, previous_secondary=prev_s)
    lower, upper, forced = lim.box(position, prev)
    np.testing.assert_array_equal(out.lower, lower)
    np.testing.assert_array_equal(out.upper, upper)
    down, up = lim.braking_rates(position)
    adt = lim.acceleration * DT
    u = out.command
    assert np.all(np.isfinite(u)) and np.all(np.isfinite(out.secondary))
    assert np.all(lower <= u) and np.all(u <= upper)
    assert np.all(upper <= np.minimum(lim.velocity, up)) and np.all(lower >= np.maximum(-lim.velocity, -down))
    assert np.all((upper <= prev + adt + 1e-12) | forced) and np.all((lower >= prev - adt - 1e-12) | forced)
    assert np.all(lower[forced] == upper[forced])
    limited = set(out.limited)
    bad = ~(np.isfinite(primary) & np.isfinite(secondary))
    assert set(np.flatnonzero(bad | forced).tolist()) <= limited
    for scale in (out.scale, out.accel_scale, out.secondary_scale):
        assert 0.0 <= scale <= 1.0
    # the velocity factor: the largest that brings the braking-clipped request within ±v
    p0, s0 = np.where(bad, 0.0, primary), np.where(bad, 0.0, secondary)
    clipped = np.clip(p0, -down, up)
    whole = clipped + np.clip(s0, -down - clipped, up - clipped)
    assert np.all(np.abs(out.scale * whole) <= lim.velocity * (1 + 1e-12))
    if out.scale < 1.0:
        assert np.max(np.abs(out.scale * whole) / lim.velocity) == pytest.approx(1.0, rel=1e-9)
    if not limited:
        np.testing.assert_allclose(u, primary + secondary, rtol=0, atol=1e-12)
        np.testing.assert_allclose(out.secondary, secondary, rtol=0, atol=1e-12)
        assert (out.scale, out.accel_scale, out.secondary_scale) == (1.0, 1.0, 1.0)


@settings(max_examples=100, deadline=None)
@given(st.integers(0, 2**32 - 1), st.floats(1e-2, 1.0))
def test_damped_pinv_solve_is_the_regularised_least_squares_solution(seed, rho):
    """``A Jᵀ (J A Jᵀ + ρ² I)⁻¹ r`` minimises ‖J x − r‖² + ρ² ‖x‖² over the active columns
    (normal equations ``(J_Aᵀ J_A + ρ² I) x_A = J_Aᵀ r``), and is zero on the others."""
    from wmm_control.resolvers.pose_servo import damped_pinv_solve

    rng = np.random.default_rng(seed)
    jac, rhs = rng.normal(size=(6, 10)), rng.normal(size=6)
    activation = (rng.uniform(size=10) < 0.7).astype(float)
    x = damped_pinv_solve(jac, rhs, rho, activation)
    cols = activation > 0
    assert np.all(x[~cols] == 0.0)
    ja = jac[:, cols]
    normal = ja.T @ ja + rho * rho * np.eye(cols.sum())
    residual = normal @ x[cols] - ja.T @ rhs
    assert np.linalg.norm(residual) <= 1e-10 * (np.linalg.norm(normal, 2) * np.linalg.norm(x) + np.linalg.norm(rhs))


# ---------------------------------------------------------------- entries held at their bounds
def _at_upper_limit(robot, joint):
    """An arm configuration with ``joint`` resting on its upper position limit."""
    q = np.array(robot.arm.dexterous, dtype=float)
    q[joint] = robot.arm.position_upper[joint]
    return q


def _pushing_target(res, state, joint):
    """A target whose pseudo-inverse solution drives ``joint`` further up."""
    jac, _, _, _ = res.task_reference(state, offset_target(res, state, (0.0, 0.0, 0.0)))
    push = jac[:, 3 + joint] / np.linalg.norm(jac[:3, 3 + joint])
    return offset_target(res, state, 0.05 * push[:3], 0.05 * push[3:])


@pytest.mark.parametrize('method', ['pinv', 'task_sharing'])
def test_a_joint_held_at_its_limit_gives_its_share_of_the_task_to_the_others(steerable_model, robot, method):
    """Clipped out of the solution, a joint resting on its limit takes its share of the end
    effector's motion with it; held there (``hold_joint_limits``), the others take it over."""
    state = start_state(robot, _at_upper_limit(robot, 1))
    extra = {} if method == 'pinv' else {'lambda_dex': 0.0}
    plain = make_resolver(method, steerable_model, **extra)
    held = make_resolver(method, steerable_model, hold_joint_limits=True, **extra)
    target = _pushing_target(plain, state, 1)
    jac, p_ref, _, _ = plain.task_reference(state, target)
    u_plain = plain.solve_task(jac, p_ref, state.q_arm)
    u_held = held.solve_task(jac, p_ref, state.q_arm)
    assert u_plain[3 + 1] > 0.0 and u_held[3 + 1] == 0.0  # the joint would pass its limit; held, it rests
    clipped = u_plain.copy()
    clipped[3 + 1] = 0.0  # what the limits make of the plain solution
    assert np.linalg.norm(jac @ u_held - p_ref) < 0.2 * np.linalg.norm(jac @ clipped - p_ref)
    # nothing at a limit: the plain solution
    free = start_state(robot)
    target = offset_target(plain, free, (0.05, -0.03, 0.02), (0.05, 0.0, 0.0))
    jac, p_ref, _, _ = plain.task_reference(free, target)
    assert np.allclose(plain.solve_task(jac, p_ref, free.q_arm), held.solve_task(jac, p_ref, free.q_arm), atol=1e-12)


def test_arm_takeover_keeps_the_end_effector_on_its_way_while_a_slow_base_accelerates(mecanum_model):
    """Robot B's base accelerates at 0.025 m/s²: one factor for the whole body holds the arm to
    that pace; with ``arm_takeover`` the base changes by a·t_s and the arm does the rest."""
    robot = mecanum_model.config
    state = start_state(robot)
    plain = make_resolver('pinv', mecanum_model, orientation_error='log')
    takeover = make_resolver('pinv', mecanum_model, orientation_error='log', arm_takeover=True)
    target = offset_target(plain, state, (0.15, 0.1, -0.05))
    jac, p_ref, _, _ = plain.task_reference(state, target)
    for _ in range(20):  # 0.5 s from rest, the state held (the commands ramp up)
        u_plain = np.concatenate(_command(plain.step(state, target)))
        u_take = np.concatenate(_command(takeover.step(state, target)))
    assert np.all(np.abs(u_take[:3]) <= 20 * robot.base.acceleration * DT + 1e-12)
    assert np.linalg.norm(jac @ u_plain - p_ref) > 0.9 * np.linalg.norm(p_ref)  # the whole body at the base's pace
    assert np.linalg.norm(jac @ u_take - p_ref) < 0.05 * np.linalg.norm(p_ref)  # the arm does the rest


def _command(cmd):
    return cmd.base_twist, cmd.arm_velocity
