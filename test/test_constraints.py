"""Rows on a command (wmm_control.resolvers.constraints), and the safety stage as the command
nearest the method's, in the task metric, under its limits' constraints."""

import warnings

import numpy as np
import pytest
import qpsolvers
from scipy import sparse

from wmm_control.errors import NonFiniteError, ShapeError
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.obstacles import load_obstacles
from wmm_control.resolvers.collision_limits import LIMITS
from wmm_control.resolvers.constraints import Box, Constraint, nearest
from wmm_control.resolvers.safety import SELF_WEIGHT, SafetyCounts, SafetyResult, SafetyStage
from wmm_control.robot_config import load_robot

#: where the base is drawn near table_pillar's obstacles: (x, y, θ) low and high
BASE_BOX = ((0.2, -1.6, -np.pi), (2.8, 1.6, np.pi))


def _independent(metric, target, G, h, lower, upper):
    """The QP solved by another solver (OSQP, tight tolerances) on the same stacked rows; None
    where it finds no command that meets them (OSQP warns so, expected here)."""
    with warnings.catch_warnings():
        warnings.simplefilter('ignore')
        return _osqp(metric, target, G, h, lower, upper)


def _osqp(metric, target, G, h, lower, upper):
    return qpsolvers.solve_qp(
        sparse.csc_matrix(metric),
        -metric @ target,
        sparse.csc_matrix(G) if len(h) else None,
        h if len(h) else None,
        lb=lower,
        ub=upper,
        solver='osqp',
        eps_abs=1e-10,
        eps_rel=1e-10,
        polishing=True,
        verbose=False,
        max_iter=400000,
    )


def test_a_stack_keeps_each_part_its_rows_and_its_name():
    a = Constraint(np.eye(3)[:2], np.array([1.0, 2.0]), 'a')
    b = Constraint(np.ones((1, 3)), np.array([0.5]), 'b')
    stack = Constraint.stack([a, Constraint.empty(3, 'none'), b, a], 3, 'all')
    assert stack.G.shape == (5, 3) and stack.h.tolist() == [1.0, 2.0, 0.5, 1.0, 2.0]
    assert stack.parts == (('a', 2), ('b', 1), ('a', 2))
    # neighbours of one name merge: one limit's several blocks stay one part
    assert Constraint.stack([a, a], 3).parts == (('a', 4),)
    nothing = Constraint.stack([], 4, 'nothing')
    assert nothing.G.shape == (0, 4) and len(nothing) == 0 and not nothing.violated(np.zeros(4)).any()


def test_rows_kept_and_rows_binding_are_counted_per_part():
    # x ≤ 1, y ≤ 1 ('box-ish'); x + y ≤ 1 ('sum')
    rows = Constraint.stack(
        [Constraint(np.eye(2), np.ones(2), 'each'), Constraint(np.ones((1, 2)), np.ones(1), 'sum')], 2
    )
    kept = rows.select(np.array([False, True, True]))
    assert kept.parts == (('each', 1), ('sum', 1)) and kept.h.tolist() == [1.0, 1.0]
    # at (1, 0): x ≤ 1 and x + y ≤ 1 bind, y ≤ 1 does not
    assert rows.binding(np.array([1.0, 0.0])) == {'each': 1, 'sum': 1}
    assert rows.violated(np.array([1.0, 0.5])).tolist() == [False, False, True]
    assert Constraint.from_lower(np.eye(2), np.zeros(2)).violated(np.array([-1.0, 1.0])).tolist() == [True, False]
    # a row broken binds; nearness is measured along the row, in the command's units: 2x ≤ 2
    # at x = 1 - 1e-7 is 1e-7 from its boundary (its residual 2e-7)
    assert rows.binding(np.array([2.0, 0.0])) == {'each': 1, 'sum': 1}
    scaled = Constraint(np.array([[2.0, 0.0]]), np.array([2.0]), 'scaled')
    assert scaled.binding(np.array([1.0 - 1e-7, 0.0]), tolerance=1.5e-7) == {'scaled': 1}
    assert scaled.binding(np.array([1.0 - 2e-7, 0.0]), tolerance=1.5e-7) == {'scaled': 0}


def test_a_row_on_no_entry_never_binds():
    # the round-off row of a pair no entry moves (G ~ 1e-17, h ~ 1e-9) and an exact zero row
    # are met at equality to within 1e-6, yet shape nothing
    rows = Constraint.stack(
        [
            Constraint(np.array([[3e-17, -2e-17]]), np.array([5e-9]), 'rigid'),
            Constraint(np.zeros((1, 2)), np.zeros(1), 'none'),
            Constraint(np.array([[1.0, 1.0]]), np.array([1.0]), 'sum'),
        ],
        2,
    )
    assert rows.binding(np.array([0.5, 0.5])) == {'rigid': 0, 'none': 0, 'sum': 1}


def _answer(binding, qp=True, relaxed=False, held=False):
    """A stage's answer on two entries with a row of each limit of ``binding`` (name → whether
    its multiplier in the QP is positive); ``qp`` False: none ran (the command met every row)."""
    parts = [Constraint(np.array([[1.0, 0.0]]), np.array([1.0]), name) for name, _ in binding]
    multipliers = np.array([0.5 if bound else 0.0 for _, bound in binding]) if qp else None
    rows = Constraint.stack(parts, 2)
    return SafetyResult(np.array([1.0, 0.0]), 0.05, 'a/b', 1, qp or held, rows, relaxed, held, multipliers)


def test_safety_counts_count_a_cycle_once_per_limit_that_shaped_the_command():
    counts = SafetyCounts()
    assert set(counts.values()) == {f'binding_{n.replace(" ", "_")}' for n in LIMITS} | {
        'relaxed_cycles',
        'base_held_cycles',
    }
    assert not any(counts.values().values())
    counts.add(_answer([('obstacle', True), ('self', False)]))
    counts.add(_answer([('obstacle', True), ('base along path', True)], relaxed=True, held=True))
    # the compensated arm command of that cycle: the obstacle again (counted once), the floor new
    counts.add(_answer([('obstacle', True), ('floor', True)], relaxed=True), same_cycle=True)
    counts.add(_answer([('obstacle', True)], qp=False))  # no QP ran: shaped by none, whatever it meets
    counts.add(None)
    values = counts.values()
    assert values['binding_obstacle'] == 2 and values['binding_self'] == 0
    assert values['binding_base_along_path'] == 1 and values['binding_floor'] == 1
    assert values['relaxed_cycles'] == 1 and values['base_held_cycles'] == 1


@pytest.mark.parametrize(
    'G, h, error',
    [
        (np.ones(3), np.ones(1), ShapeError),  # G not 2-D
        (np.ones((2, 3)), np.ones(3), ShapeError),  # h of another length
        (np.ones((2, 3)), np.ones((2, 1)), ShapeError),  # h not 1-D
        (np.array([[1.0, np.nan]]), np.ones(1), NonFiniteError),
        (np.array([[1.0, np.inf]]), np.ones(1), NonFiniteError),
        (np.ones((1, 2)), np.array([np.nan]), NonFiniteError),
        (np.ones((1, 2)), np.array([-np.inf]), NonFiniteError),  # a row no command meets
    ],
)
def test_a_malformed_constraint_is_refused_with_its_name(G, h, error):
    with pytest.raises(error, match='elbow'):
        Constraint(G, h, 'elbow')


def test_a_row_never_binding_may_have_no_bound_and_stacks_must_agree_on_the_command():
    assert not Constraint(np.ones((1, 2)), np.array([np.inf])).violated(np.full(2, 1e300)).any()
    with pytest.raises(ShapeError, match='on 2 entries'):
        Constraint.stack([Constraint(np.ones((1, 2)), np.ones(1), 'x'), Constraint.empty(3)], 3)
    with pytest.raises(ShapeError):
        Constraint(np.ones((2, 2)), np.ones(2)).select(np.ones(3, dtype=bool))


def test_a_box_is_checked():
    with pytest.raises(ValueError, match='entries \\[1\\]'):
        Box(np.zeros(2), np.array([1.0, -1.0]))
    with pytest.raises(NonFiniteError):
        Box(np.array([np.nan]), np.ones(1))
    with pytest.raises(ShapeError):
        Box(np.zeros(2), np.ones(3))
    box = Box(np.array([-1.0, -np.inf]), np.array([1.0, np.inf]))
    # the greatest value of a row over the box; an entry a row does not involve adds nothing
    assert box.greatest(np.array([[2.0, 0.0], [-1.0, 0.0], [0.0, 1.0]])).tolist() == [2.0, 1.0, np.inf]


@pytest.mark.parametrize('seed', range(4))
def test_nearest_is_the_minimum_another_solver_finds(seed):
    rng = np.random.default_rng(seed)
    n, m = 9, 30
    jac = rng.normal(size=(6, n))
    metric = jac.T @ jac + 0.01 * np.diag(rng.uniform(0.5, 2.0, n))
    target = rng.normal(size=n)
    rows = Constraint(rng.normal(size=(m, n)), rng.uniform(0.05, 0.5, m), 'random')
    box = Box(-np.full(n, 2.0), np.full(n, 2.0))
    x, relaxed, multipliers = nearest(target, metric, rows, box)
    assert not relaxed  # 0 is strictly inside every row and the box
    assert not rows.violated(x, 1e-8).any()
    np.testing.assert_allclose(x, _independent(metric, target, rows.G, rows.h, box.lower, box.upper), atol=1e-6)
    # the rows that shape the answer: met at equality; the others dropped, it stays; the first
    # of them dropped, it moves
    shaping = multipliers > 1e-9
    assert shaping.any() and np.all(np.abs(rows.residual(x)[shaping]) < 1e-8)
    np.testing.assert_allclose(nearest(target, metric, rows.select(shaping), box).command, x, atol=1e-6)
    first = shaping & (np.cumsum(shaping) == 1)
    assert not np.allclose(nearest(target, metric, rows.select(~first), box).command, x, atol=1e-6)


def test_rows_that_conflict_within_the_box_are_met_as_far_as_it_allows():
    # x ≥ 1 and x ≤ −1 cannot both hold: with both slacks at their linear cost whatever x, the
    # answer minimises ½ (x − 0.3)² + ½ ((1 − x)² + (1 + x)²) (the slacks' quadratic term): x =
    # 0.1, between the two rows; y, which no row involves, stays where it was asked
    rows = Constraint(np.array([[-1.0, 0.0], [1.0, 0.0]]), np.array([-1.0, -1.0]), 'apart')
    x, relaxed, multipliers = nearest(np.array([0.3, 0.4]), np.eye(2), rows, Box(-np.ones(2), np.ones(2)))
    assert relaxed and (multipliers > 0.0).all(), 'both rows broken: both shape the answer'
    np.testing.assert_allclose(x, [0.1, 0.4], atol=1e-6)
    # a row the box cannot meet: met as far as the box allows
    x, relaxed, _ = nearest(
        np.zeros(2), np.eye(2), Constraint(np.array([[-1.0, 0.0]]), np.array([-5.0])), Box(-np.ones(2), np.ones(2))
    )
    assert relaxed and x == pytest.approx([1.0, 0.0])


@pytest.mark.parametrize('outvoting', [1, 5, 30])
def test_a_row_the_box_can_meet_is_kept_however_many_rows_it_cannot_meet_pull_the_other_way(outvoting):
    # x ≤ 0.1 can be met in the box x ∈ [0, 1]; x ≥ 2 (given `outvoting` times, as a link's
    # several shapes each give a row) cannot. The rows the box has to break are met as far as
    # the one it can keep allows: x = 0.1, whatever their number. One cost for every slack
    # would send x to 1 as soon as the broken rows outnumber the kept one (the chassis of a
    # base driven into an obstacle for an arm's swinging links).
    G = np.array([[1.0, 0.0]] + [[-1.0, 0.0]] * outvoting)
    h = np.array([0.1] + [-2.0] * outvoting)
    x, relaxed, multipliers = nearest(np.array([0.5, 0.5]), np.eye(2), Constraint(G, h), Box(np.zeros(2), np.ones(2)))
    assert relaxed
    np.testing.assert_allclose(x, [0.1, 0.5], atol=1e-6)
    assert (multipliers > 0.0).all(), 'the kept row and the broken ones all shape the answer'


def _near_states(cfg, stage, count, rng):
    """Arm postures near the body (base far from the obstacles) and base poses near the table
    and the pillar, where some pair is within the look-ahead and none in contact."""
    arm = cfg.arm
    lo = np.where(np.isfinite(arm.position_lower), arm.position_lower, -np.pi)
    hi = np.where(np.isfinite(arm.position_upper), arm.position_upper, np.pi)
    out = []
    while len(out) < count:
        if len(out) % 2:
            q, pose = rng.uniform(lo, hi), np.array([-5.0, -5.0, 0.0])
        else:
            q, pose = np.asarray(cfg.start.arm, dtype=float), rng.uniform(*BASE_BOX)
        near, closest, _ = stage.collision.within(q, stage.obstacle_lookahead, pose)
        if closest > 0.0 and len(near):
            out.append((q, pose))
    return out


@pytest.mark.parametrize('robot', ['steerable', 'mecanum'])
def test_the_stage_answer_meets_every_row_and_is_the_nearest_in_the_task_metric(robot):
    """At random states near the body and near obstacles, with the method's command drawn at
    random within a random box: the stage's answer lies in the box, meets every row of the
    cycle's constraints (unless they conflict in the box, then it says so), and is the minimum
    of ½ (q̇ − q̇₀)ᵀ (JᵀJ + μ W) (q̇ − q̇₀) over them that another solver finds on the stacked
    rows. Each way the base enters: the arm alone beside a moving base, the base's reference in
    its own frame with its measured twist (a steerable base lags it), the world frame's rates."""
    cfg = load_robot(robot)
    rng = np.random.default_rng(7)
    stage = SafetyStage.for_robot(cfg, obstacles=load_obstacles('table_pillar'), kinematics=KinematicModel(cfg))
    axes = tuple(cfg.base.axes)
    n_arm = cfg.arm.velocity.size
    changed = relaxed = 0
    kinds = {}
    for k, (q, pose) in enumerate(_near_states(cfg, stage, 36, rng)):
        mode = k % 3
        kwargs = dict(base_pose=pose)
        if mode == 0:
            nb = 0
            kwargs['base_twist'] = rng.uniform(-1.0, 1.0, 3) * cfg.base.velocity
        else:
            nb = len(axes)
            kwargs.update(base_axes=axes, base_velocity=rng.uniform(-1.0, 1.0, 3) * cfg.base.velocity)
            kwargs['world_rates'] = mode == 2
        velocity = np.concatenate((cfg.base.velocity[list(axes)][:nb], cfg.arm.velocity))
        command = rng.uniform(-1.0, 1.0, nb + n_arm) * velocity
        lower = command - rng.uniform(0.0, 0.5, command.size) * velocity
        upper = command + rng.uniform(0.0, 0.5, command.size) * velocity
        jac, weights = rng.normal(size=(6, command.size)), rng.uniform(0.5, 2.0, command.size)
        out = stage.filter(q, command, lower, upper, weights, task_jacobian=jac, **kwargs)
        assert stage.last is out
        rows = out.constraints
        assert rows is not None and rows.n == command.size
        for name, count in rows.parts:
            kinds[name] = kinds.get(name, 0) + count
        assert np.all(out.command >= lower - 1e-9) and np.all(out.command <= upper + 1e-9)
        changed += out.changed
        # a lagging base held on its path: its entries fixed, the rest nearest the method's
        target, lo, hi = command.copy(), lower.copy(), upper.copy()
        if out.held:
            target[:nb] = lo[:nb] = hi[:nb] = out.command[:nb]
        # a row on no entry the box leaves free (a pair of the base's body and an obstacle, the
        # base not commanded or held) is what the base makes it: no command changes it
        rows = rows.select((rows.G[:, hi > lo] != 0.0).any(axis=1))
        metric = jac.T @ jac + SELF_WEIGHT * np.diag(weights)
        reference = _independent(metric, target, rows.G, rows.h, lo, hi)
        if out.relaxed:  # only where no command in the box meets every row
            assert reference is None
            relaxed += 1
            continue
        assert not rows.violated(out.command, 1e-7).any(), rows.per_part(
            np.flatnonzero(rows.violated(out.command, 1e-7))
        )
        np.testing.assert_allclose(out.command, reference, atol=1e-5)
    assert changed >= 12 and relaxed <= 18  # the rows shaped many answers, and met most in full
    assert {'self', 'obstacle'} <= set(kinds)
    if robot == 'steerable':  # a lagging base's rows
        assert {'base along path', 'base between', 'base after turn'} <= set(kinds)
    else:  # a base that tracks its reference
        assert {'base without turn', 'base turn rate'} <= set(kinds)
