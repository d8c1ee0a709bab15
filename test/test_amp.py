"""Xing et al.'s adaptive motion planner (AMP), the traditional planner, and SNS (eq 9)."""

import numpy as np
import pytest

from sim_bridge.closed_loop import ClosedLoop
from sim_bridge.world import SimWorld
from wmm_control.resolvers import AmpParams, AmpResolver, PoseTarget, RobotState, TraditionalResolver, make_resolver
from wmm_control.resolvers.interface import BaseReference
from wmm_control.resolvers.setpoint_trajectory import SetpointTrajectory
from wmm_control.resolvers.sns import sns_accelerations

DT = 0.025
W = np.pi / 20.0


def test_sns_saturates_a_joint_and_gives_its_share_to_the_others():
    jac = np.array([[1.0, 1.0, 1.0]])
    lo, hi = np.array([-1.0, -1.0, -1.0]), np.array([0.5, 1.0, 1.0])
    qdd, alpha, active, saturated, _ = sns_accelerations(
        jac, np.array([2.5]), np.zeros(1), lo, hi, np.ones(3, bool), np.zeros(3)
    )
    np.testing.assert_allclose(qdd, [0.5, 1.0, 1.0])
    assert alpha == 1.0 and saturated.tolist() == [True, False, False]


def test_sns_scales_an_infeasible_task():
    jac = np.array([[1.0, 1.0, 1.0]])
    lo, hi = -np.ones(3), np.ones(3)
    qdd, alpha, *_ = sns_accelerations(jac, np.array([5.0]), np.zeros(1), lo, hi, np.ones(3, bool), np.zeros(3))
    assert alpha == pytest.approx(0.6)
    np.testing.assert_allclose(jac @ qdd, [3.0])
    assert np.all(qdd <= hi + 1e-12)


def test_sns_keeps_held_joints_at_their_given_acceleration():
    jac = np.array([[1.0, 1.0, 1.0]])
    qdd, alpha, *_ = sns_accelerations(
        jac,
        np.array([1.0]),
        np.zeros(1),
        -np.ones(3),
        np.ones(3),
        np.array([False, True, True]),
        np.array([-0.4, 0.0, 0.0]),
    )
    assert qdd[0] == -0.4 and alpha == 1.0
    np.testing.assert_allclose(jac @ qdd, [1.0])


@pytest.mark.parametrize('rows', [3, 6])
def test_tertiary_projector_is_the_printed_one(rows):
    """Eqs (10)–(11): ``P_A = [I − ((I − S) P_N)⁺] P_N`` as printed, against the projector the
    planner applies (over the active columns, ``I − (J S)⁺ (J S)``), for random Jacobians and
    active sets: the base out, saturated arm joints out, everything in."""
    rng = np.random.default_rng(rows)
    resolver = AmpResolver('mecanum')
    for active in ([False] * 3 + [True] * 7, [False] * 3 + [True, False, True, True, False, True, True], [True] * 10):
        active = np.array(active)
        jac = rng.normal(size=(rows, 10))
        q_a = rng.normal(size=10)
        q_a[:3] = 0.0
        resolver.manipulability_acceleration = lambda qd, q_a=q_a: q_a
        p_n = np.eye(10) - np.linalg.pinv(jac) @ jac
        # rcond: the exact zeros of (I − S) P_N come out at round-off, which pinv must not invert.
        p_a = (np.eye(10) - np.linalg.pinv(np.diag((~active).astype(float)) @ p_n, rcond=1e-10)) @ p_n
        task = {
            'jac': jac,
            'qd': np.zeros(10),
            'lower': -1e9 * np.ones(10),
            'upper': 1e9 * np.ones(10),
            'arm_follow': None,  # no plan
        }
        q_t, beta = resolver._tertiary(task, np.zeros(10), active, np.linalg.pinv(jac[:, active]))
        assert beta == 1.0
        np.testing.assert_allclose(q_t, p_a @ q_a, atol=1e-10)
        np.testing.assert_allclose(jac @ q_t, 0.0, atol=1e-10)
        assert np.all(q_t[~active] == 0.0)
        assert (np.linalg.norm(q_t) > 0.1) == (active.sum() > rows)  # else no null space is left


def test_setpoint_trajectory_is_smooth_and_within_its_limits():
    goal = PoseTarget(np.array([0.3, 0.0, 0.0]), np.eye(3))
    traj = SetpointTrajectory(np.zeros(3), np.eye(3), goal, 0.1, 0.1, 0.3, 0.3)
    samples = [traj.sample(t) for t in np.arange(0.0, traj.duration + 0.5, 0.01)]
    speed = max(np.linalg.norm(s.velocity[:3]) for s in samples)
    accel = max(np.linalg.norm(s.acceleration[:3]) for s in samples)
    assert speed <= 0.1 + 1e-9 and accel <= 0.1 + 1e-9 and speed > 0.09
    np.testing.assert_allclose(samples[-1].position, goal.position)
    assert not np.any(samples[-1].velocity)


def circle_run(method, radius, seconds, **params):
    """Xing §4.2–4.3: x_d(t) = x0 + [−R(cos(πt/20) − 1), −R sin(πt/20), 0] on robot B, the
    position tracked (r = 3)."""
    resolver = make_resolver(method, 'mecanum', **{'rows': 'position', **params})
    with SimWorld('mecanum') as world:
        loop = ClosedLoop(world, resolver)
        start = loop.state()
        x0, r0 = start.ee_position.copy(), start.ee_rotation.copy()
        rows = []
        for k in range(int(round(seconds / DT))):
            t = k * DT
            pos = x0 + radius * np.array([1.0 - np.cos(W * t), -np.sin(W * t), 0.0])
            vel = radius * W * np.array([np.sin(W * t), -np.cos(W * t), 0.0, 0.0, 0.0, 0.0])
            acc = radius * W * W * np.array([np.cos(W * t), np.sin(W * t), 0.0, 0.0, 0.0, 0.0])
            rec = loop.step(PoseTarget(pos, r0, velocity=vel, acceleration=acc))
            rows.append((np.linalg.norm(pos - rec.ee_position), rec.command, rec.q_arm, rec.base_velocity))
    return rows


def test_within_reach_amp_keeps_the_base_still_where_traditional_moves_it():
    """R = 0.1 m for 12 s, before σ_min nears σ_m,min: AMP's base commands are exactly zero."""
    amp = circle_run('amp', 0.1, 12.0)
    traditional = circle_run('traditional', 0.1, 12.0)
    assert all(not np.any(c.base_twist) for _, c, _, _ in amp)
    assert max(e for e, _, _, _ in amp[40:]) < 1e-3
    moving = sum(np.any(np.abs(c.base_twist) > 1e-6) for _, c, _, _ in traditional)
    assert moving > 0.9 * len(traditional)


def test_a_lower_singularity_threshold_keeps_the_base_still_all_round_the_small_circle():
    rows = circle_run('amp', 0.1, 40.0, sigma_min=0.09)
    assert all(not np.any(c.base_twist) for _, c, _, _ in rows)
    assert max(e for e, _, _, _ in rows[40:]) < 1e-3


@pytest.fixture(scope='module')
def big_circle():
    return circle_run('amp', 0.25, 40.0)


def test_beyond_reach_the_base_helps_only_part_of_the_time_and_the_circle_is_tracked(big_circle):
    active = [np.any(c.base_twist) for _, c, _, _ in big_circle]
    assert 0.05 < np.mean(active) < 0.5
    first = active.index(True) * DT
    assert 5.0 < first < 8.0  # the paper's base starts at 6.40 s
    assert max(e for e, _, _, _ in big_circle[40:]) < 2e-3


def test_no_limit_of_table_1_is_passed(big_circle):
    robot = make_resolver('amp', 'mecanum').model.config
    arm, base = robot.arm, robot.base
    q = np.array([r[2] for r in big_circle])
    dq = np.array([r[1].arm_velocity for r in big_circle])
    assert np.all(q <= arm.position_upper + 1e-9) and np.all(q >= arm.position_lower - 1e-9)
    assert np.all(np.abs(dq) <= arm.velocity + 1e-9)
    assert np.all(np.abs(np.diff(dq, axis=0)) <= arm.acceleration * DT + 1e-9)
    vb = np.array([r[1].base_twist for r in big_circle])
    assert np.all(np.abs(vb) <= base.velocity * np.sqrt(2.0) + 1e-9)  # world-frame limits, seen in the base frame
    assert np.all(np.isfinite(dq)) and np.all(np.isfinite(vb))


def test_the_base_stops_within_its_braking_time_after_deactivation(big_circle):
    robot = make_resolver('amp', 'mecanum').model.config
    modes = [r[1].diagnostics.mode for r in big_circle]
    vb = [r[1].base_twist for r in big_circle]
    stops = [
        k
        for k in range(1, len(modes))
        if modes[k - 1].startswith('base active') and not modes[k].startswith('base active')
    ]
    assert stops
    for k in stops:
        v0 = np.abs(vb[k - 1])
        allowed = int(np.ceil(np.max(v0 / robot.base.acceleration) / DT)) + 1
        at_rest = next((j for j in range(k, len(vb)) if not np.any(vb[j]) or modes[j].startswith('base active')), None)
        assert at_rest is not None and at_rest - k <= allowed


def test_without_singularity_avoidance_the_arm_runs_into_the_singularity():
    rows = circle_run('amp', 0.25, 20.0, singularity_avoidance=False)
    assert min(c.diagnostics.sigma_min for _, c, _, _ in rows) < 0.05
    assert max(e for e, _, _, _ in rows[40:]) > 0.01


def test_a_goal_within_reach_never_moves_the_base():
    resolver = AmpResolver('mecanum', AmpParams())
    with SimWorld('mecanum') as world:
        loop = ClosedLoop(world, resolver)
        start = loop.state()
        goal = PoseTarget(start.ee_position + np.array([0.05, -0.03, 0.02]), start.ee_rotation)
        rows = [loop.step(goal) for _ in range(int(4.0 / DT))]
    assert all(not np.any(r.command.base_twist) for r in rows)
    assert np.linalg.norm(goal.position - rows[-1].ee_position) < 1e-3
    accel = np.abs(np.diff([r.command.arm_velocity for r in rows], axis=0)) / DT
    assert np.max(accel) < 1.0, 'a set-point is a smooth trajectory, not a step'


def test_traditional_is_a_named_method():
    assert isinstance(make_resolver('traditional', 'mecanum'), TraditionalResolver)


@pytest.mark.parametrize('method', ['amp', 'traditional'])
def test_the_base_twist_keeps_its_own_frame_limits_when_the_base_is_turned(method):
    """The velocity bounds hold the world-frame rates ẋ_b, ẏ_b; with the base turned by π/4 a
    goal along the world diagonal takes both to their bound, √2 times the limit on the base's
    own x axis, unless the twist is held within the base-frame limits too."""
    resolver = make_resolver(method, 'mecanum', setpoint_speed=1.0, setpoint_accel=1.0)
    with SimWorld('mecanum', start_base_pose=(0.0, 0.0, np.pi / 4)) as world:
        loop = ClosedLoop(world, resolver)
        start = loop.state()
        goal = PoseTarget(start.ee_position + np.array([3.0, 3.0, 0.0]), start.ee_rotation)
        twists = np.array([loop.step(goal).command.base_twist for _ in range(int(30.0 / DT))])
    limit = resolver.limits.velocity[:3]
    assert np.max(np.abs(twists[:, 0])) > 0.9 * limit[0], 'the run must drive the base near its limit'
    assert np.all(np.abs(twists) <= limit + 1e-12)


def test_traditional_with_a_joint_on_its_limit_does_not_coast():
    """A joint resting on its position limit with the task pulling it further: scaled as a whole
    into the bounds, the accelerations would all be zero and the robot would go on at its rates
    of the moment (a turning base would keep turning). Kept joint by joint, that joint stays
    at rest and the others follow the task (taking its part too, so the push scales down to
    about half of it)."""
    resolver = make_resolver('traditional', 'steerable', rows='full')
    arm = resolver.model.config.arm
    q = np.array(arm.dexterous, dtype=float)
    q[1] = arm.position_upper[1]
    state = RobotState((0.0, 0.0, 0.0), np.array([0.0, 0.0, 0.1]), q, np.zeros(7))
    resolver.model.update(state.base_pose, q)
    pos, rot = (np.array(x) for x in resolver.model.ee_placement_world())
    push = resolver.model.jacobian_world()[:, 3 + 1].copy()
    target = PoseTarget(pos, rot, velocity=0.2 * push, acceleration=1.0 * push)
    cmd = resolver.step(state, target)
    assert cmd.diagnostics.position_error < 1e-9 and cmd.diagnostics.orientation_error < 1e-9
    assert cmd.arm_velocity[1] <= 0.0  # the joint stays on its limit
    assert cmd.diagnostics.limit_scale > 0.25
    assert not np.allclose(cmd.base_twist, state.base_twist, atol=1e-6)  # the base follows the task
    assert np.linalg.norm(cmd.arm_velocity) > 1e-3


@pytest.mark.parametrize('held', [(6,), (6, 1)])
def test_traditional_shares_the_part_of_a_joint_on_its_limit_among_the_others(held):
    """Following a plan (the arm alone takes the task), joints resting on a position limit with
    the task pulling them further are held there and the other joints take their part: the
    task's acceleration is met whole (``J q̈ = ẍ − J̇q̇``), those joints at rest. Clipped out of
    ``J⁺``'s solution without sharing, their part was left undone (`panda_diff`'s randomized goal
    70 stalled so, the orientation 0.06 rad off). With two held (joint 7 on its upper limit,
    joint 2 on its lower), the arm's five other joints cannot span the pose: the base joins in
    (goal 60 stalled so, 15 mm and 0.03 rad off, its base 3 cm beside the stance)."""
    resolver = make_resolver('traditional', 'panda_diff')
    arm = resolver.model.config.arm
    q = np.array(arm.dexterous, dtype=float)
    q[6] = arm.position_upper[6]
    q[1] = arm.position_lower[1] if 1 in held else q[1]
    base = np.zeros(3)
    state = RobotState(base, np.zeros(3), q, np.zeros(7))
    resolver.model.update(base, q)
    pos, rot = (np.array(x) for x in resolver.model.ee_placement_world())
    columns = resolver.model.jacobian_world()[:, 3:]
    push = columns[:, 6] - (columns[:, 1] if 1 in held else 0.0)  # the motion the held joints alone make
    target = PoseTarget(pos, rot, velocity=0.05 * push, acceleration=0.1 * push, base=BaseReference(base))
    task = resolver.task_acceleration(state, target)
    qdd, fields = resolver._accelerations(task)
    np.testing.assert_allclose(task['jac'] @ qdd, task['xdd'] - task['drift'], atol=1e-9)
    assert qdd[2 + 6] <= 0.0 and (1 not in held or qdd[2 + 1] >= 0.0)  # the joints stay on their limits
    assert fields['limit_scale'] == 1.0 and {2 + j for j in held} <= set(fields['limited'])
