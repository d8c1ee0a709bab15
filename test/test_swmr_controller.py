"""SWMR base controller (Sorour §IV): ICR representation, route, QP, limits, tracking, failure."""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wmm_control.base import (
    Icr,
    IcrQp,
    QpResult,
    SteerableGeometry,
    SwmrController,
    SwmrOutput,
    SwmrParams,
    choose_route,
)
from wmm_control.errors import ConfigError, NonFiniteError, ShapeError, SolverError
from wmm_control.robot_config import load_robot

HIPS = np.array([[0.24, 0.19], [0.24, -0.19], [-0.24, 0.19], [-0.24, -0.19]])
R_W, D = 0.09, 0.045
ROBOT_A = load_robot('steerable')        # the limits (SwmrParams has no default for them)
DT, RATE_MAX, ACC_MAX, DRIVE_MAX = 0.025, 1.0, 2.0, 12.0
TOL = 1e-6


@pytest.fixture(scope='module')
def geometry():
    return SteerableGeometry(HIPS, R_W, D)


def make(geometry, **kw):
    return SwmrController(geometry, SwmrParams.from_robot_config(ROBOT_A, **kw))


def run(ctrl, refs):
    """Step through ``refs`` (iterable of twists); return the outputs."""
    return [ctrl.step(r) for r in refs]


def assert_limits(outs, beta_dot0=None, beta0=None):
    """Every cycle: |β̇| ≤ β̇_max, |β̈| ≤ β̈_max (by differencing), β̇ = Δβ/dt, finite, |φ̇| ≤ max."""
    prev_rate = np.zeros(4) if beta_dot0 is None else np.asarray(beta_dot0)
    prev_beta = beta0
    for k, o in enumerate(outs):
        for name in ('beta_ref', 'beta_dot_ref', 'phi_dot_ref', 'twist_feasible'):
            assert np.all(np.isfinite(getattr(o, name))), (k, name)
        assert np.all(np.isfinite(o.icr_next.point)) and np.all(np.isfinite(o.icr_ref.point)), k
        assert np.max(np.abs(o.beta_dot_ref)) <= RATE_MAX + TOL, (k, o.beta_dot_ref)
        acc = (o.beta_dot_ref - prev_rate) / DT
        assert np.max(np.abs(acc)) <= ACC_MAX + TOL, (k, acc)
        assert np.max(np.abs(o.phi_dot_ref)) <= DRIVE_MAX + TOL, (k, o.phi_dot_ref)
        if prev_beta is not None:
            np.testing.assert_allclose((o.beta_ref - prev_beta) / DT, o.beta_dot_ref, atol=1e-9)
        prev_rate, prev_beta = o.beta_dot_ref, o.beta_ref


def executed_twist(geometry, o):
    """The twist the commanded wheels realise (forward model of the steerable geometry)."""
    return geometry.twist_from_wheels(o.beta_ref, o.beta_dot_ref, o.phi_dot_ref)


# ---------------------------------------------------------------- ICR representation

def test_icr_of_translation_is_on_the_border_and_antipodes_agree():
    icr = Icr.from_twist([0.5, 0.0, 0.0], border=20.0)       # moving along x: ICR at ±∞ on y
    assert icr.at_infinity
    np.testing.assert_allclose(np.abs(icr.point), [0.0, 20.0], atol=1e-12)
    flipped = icr.with_z(-icr.z)
    np.testing.assert_allclose(flipped.point, -icr.point)    # opposite border points
    assert icr.angle_to(flipped) == pytest.approx(0.0, abs=1e-7)
    np.testing.assert_allclose(np.abs(icr.twist_direction), [1.0, 0.0, 0.0], atol=1e-12)


def test_icr_of_arc_and_compatible_twist():
    icr = Icr.from_twist([0.4, 0.0, 0.2])                    # X = -vy/ω = 0, Y = vx/ω = 2
    assert not icr.at_infinity
    np.testing.assert_allclose(icr.point, [0.0, 2.0], atol=1e-12)
    t = icr.twist_direction
    np.testing.assert_allclose(t / t[2], [2.0, 0.0, 1.0], atol=1e-12)   # ∝ (Y, -X, 1)
    far = Icr.from_point(50.0, 10.0, border=20.0)
    assert far.at_infinity
    np.testing.assert_allclose(far.point, [20.0, 4.0])


def test_icr_from_steer_angles_recovers_the_icr(geometry):
    for x, y in [(0.0, 2.0), (1.3, -0.7), (0.24, 0.5), (-3.0, 0.0)]:
        beta = geometry.steer_angles_for_icr((x, y))
        beta[1] += np.pi                                     # a twin does not change the ICR
        icr = Icr.from_steer_angles(geometry, beta)
        np.testing.assert_allclose(icr.point, [x, y], atol=1e-9)
    icr = Icr.from_steer_angles(geometry, geometry.steer_angles_for_translation((0.0, 1.0)))
    assert icr.at_infinity and icr.z[2] == pytest.approx(0.0, abs=1e-12)


def test_zero_twist_has_no_icr():
    with pytest.raises(NonFiniteError):
        Icr.from_twist([0.0, 0.0, 0.0])


@pytest.mark.parametrize('r1, r2, expected', [
    (2.0, 2.0, 'complementary'),   # R1 R2 = 4 > ℓ² = 1: through straight-line motion
    (5.0, 0.5, 'complementary'),
    (0.5, 0.5, 'direct'),          # tight arcs: through the base centre
    (0.9, 1.0, 'direct'),
])
def test_route_rule_left_arc_to_right_arc(r1, r2, expected):
    left = Icr.from_point(0.0, r1)
    right = Icr.from_point(0.0, -r2)
    z, route = choose_route(left, right)
    assert route == expected
    assert float(z @ left.z) >= 0.0
    assert choose_route(left, Icr.from_point(0.5, 1.5))[1] == 'direct'


# ---------------------------------------------------------------- parameters

def test_params_validation():
    with pytest.raises(ConfigError):
        SwmrParams.from_robot_config(ROBOT_A, dt=-0.01)
    with pytest.raises(ConfigError):
        SwmrParams.from_robot_config(ROBOT_A, icr_gain=float('nan'))
    with pytest.raises(ConfigError):
        SwmrParams.from_robot_config(ROBOT_A, base_velocity_limit=(1.0, 1.0))
    with pytest.raises(ConfigError):
        SwmrParams.from_robot_config(ROBOT_A, icr_gain=100.0)                           # λ dt > 1
    with pytest.raises(ConfigError):
        SwmrParams.from_robot_config(ROBOT_A, steer_rate_limit=40.0)                    # > π/4 per period


def test_params_from_robot_config():
    from wmm_control.robot_config import load_robot
    robot = load_robot('steerable')
    p = SwmrParams.from_robot_config(robot, kp=2.0)
    assert p.steer_rate_limit == robot.steerable.steer_rate_limit
    assert p.steer_accel_limit == robot.steerable.steer_accel_limit
    assert p.drive_rate_limit == robot.steerable.drive_rate_limit
    np.testing.assert_allclose(p.base_velocity_limit, robot.base.velocity)
    with pytest.raises(ConfigError):
        SwmrParams.from_robot_config(load_robot('mecanum'))


def test_input_checks(geometry):
    ctrl = make(geometry)
    with pytest.raises(ShapeError):
        ctrl.step([0.1, 0.0])
    with pytest.raises(NonFiniteError):
        ctrl.step([0.1, float('nan'), 0.0])
    with pytest.raises(ShapeError):
        ctrl.reset(np.zeros(3))


@pytest.mark.parametrize('huge, bounded', [
    ((1e308, 0.0, 0.0), (1.0, 0.0, 0.0)),
    ((0.0, 1e200, 0.0), (0.0, 1.0, 0.0)),
    ((-1e308, 1e308, 1e308), (-1.0, 1.0, 1.0)),
    ((3.0, 1.0, 0.0), (1.0, 1.0 / 3.0, 0.0)),            # scaled, not clipped: the ICR is kept
], ids=['vx-1e308', 'vy-1e200', 'all-1e308', 'vx-3'])
def test_references_beyond_the_limits_are_scaled_into_them(geometry, huge, bounded):
    ctrl, ref = make(geometry), make(geometry)
    outs = run(ctrl, [huge] * 200)
    expected = run(ref, [bounded] * 200)
    assert_limits(outs)
    for o, e in zip(outs, expected):
        for name in ('beta_ref', 'beta_dot_ref', 'phi_dot_ref', 'twist_feasible', 'twist_executed'):
            np.testing.assert_allclose(getattr(o, name), getattr(e, name), rtol=0, atol=1e-12)
    assert np.all(np.isfinite(ctrl.twist)) and np.all(np.isfinite(ctrl.phi_dot))
    moving = outs[-1].twist_executed         # along the reference, at a base or drive-rate limit
    np.testing.assert_allclose(moving / np.linalg.norm(moving), np.divide(bounded, np.linalg.norm(bounded)),
                               atol=1e-6)
    assert np.linalg.norm(moving) > 0.99 or np.max(np.abs(outs[-1].phi_dot_ref)) > DRIVE_MAX - 1e-6
    np.testing.assert_allclose(ctrl.build_qp(huge).x_ref, ref.build_qp(bounded).x_ref, atol=1e-12)


# ---------------------------------------------------------------- the QP

def test_build_qp_is_inspectable_and_consistent(geometry):
    ctrl = make(geometry)
    ctrl.reset(geometry.steer_angles_for_icr((0.0, 2.0)))
    qp = ctrl.build_qp([0.0, 0.5, 0.0])
    assert isinstance(qp, IcrQp)
    assert qp.P.shape == (2, 2) and qp.q.shape == (2,)
    assert qp.A.shape == (10, 2) and qp.l.shape == (10,) and qp.u.shape == (10,)
    np.testing.assert_allclose(qp.P, np.eye(2))
    np.testing.assert_allclose(qp.q, -qp.x_ref)
    # At rest the present ICR (x = 0) satisfies every wedge; rows are unit length.
    assert np.all(qp.A @ np.zeros(2) >= qp.l - 1e-12)
    np.testing.assert_allclose(np.linalg.norm(qp.A[:8], axis=1), 1.0)
    np.testing.assert_allclose(qp.icr_curr.point, [0.0, 2.0], atol=1e-9)
    np.testing.assert_allclose(qp.rate_upper, ACC_MAX * DT)
    np.testing.assert_allclose(qp.rate_lower, -ACC_MAX * DT)
    # The solver's answer lies in the wedges: the implied steer change needs no clipping.
    out = ctrl.step([0.0, 0.5, 0.0])
    assert out.qp_status == 'solved'
    assert np.max(np.abs(out.beta_dot_ref)) <= ACC_MAX * DT + TOL
    assert out.icr_ref.angle_to(qp.icr_ref) < 1e-12


def test_wedge_rows_bound_the_steer_change(geometry):
    """An ICR on a wedge line of wheel i asks exactly the edge steer change rate*dt of wheel i."""
    from wmm_control.base.icr import wrap_half_turn
    ctrl = make(geometry)
    ctrl.reset(geometry.steer_angles_for_icr((1.0, 1.5)), beta_dot=[0.3, -0.2, 0.1, 0.0])
    qp = ctrl.build_qp([0.3, 0.1, 0.4])
    beta = ctrl.beta
    for i in range(4):
        for k, rate in ((2 * i, qp.rate_lower[i]), (2 * i + 1, qp.rate_upper[i])):
            x = qp.A[k] * qp.l[k]                             # nearest point of the edge line
            assert qp.A[k] @ x == pytest.approx(qp.l[k], abs=1e-12)
            icr = qp.icr_of(x)
            v = icr.hip_velocities(HIPS)[i]
            change = wrap_half_turn(np.arctan2(v[1], v[0]) - beta[i])
            assert change == pytest.approx(rate * DT, abs=1e-9)


def test_feasible_reference_is_returned_without_osqp(geometry):
    """x_ref inside every wedge is the QP's optimum: returned as is ('unconstrained'), OSQP agrees."""
    ctrl = make(geometry)
    run(ctrl, [(0.4, 0.0, 0.2)] * 200)                     # settled on the arc: ICR_ref ≈ ICR_curr
    qp = ctrl.build_qp([0.4, 0.0, 0.2])
    assert np.all(qp.A @ qp.x_ref >= qp.l) and np.all(qp.A @ qp.x_ref <= qp.u)
    res = ctrl.solver(qp)
    assert res.status == 'unconstrained'
    np.testing.assert_array_equal(res.x, qp.x_ref)
    x_osqp, status, _ = ctrl.solver._run(ctrl.solver._osqp, qp.q, qp.A.ravel(order='F'), qp.l, qp.u)
    assert status == 'solved'
    np.testing.assert_allclose(x_osqp, qp.x_ref, atol=1e-5)
    assert ctrl.step([0.4, 0.0, 0.2]).qp_status == 'unconstrained'


class _PublicApiOnly:
    """An OSQP solver seen through its public update()/solve() only."""

    def __init__(self, inner):
        self._inner = inner

    def update(self, **kwargs):
        return self._inner.update(**kwargs)

    def solve(self, **kwargs):
        return self._inner.solve(**kwargs)


def test_public_osqp_api_path_gives_the_same_commands(geometry):
    """The fast path through osqp's extension object and the public API agree."""
    fast, public = make(geometry), make(geometry)
    public.solver._osqp = _PublicApiOnly(public.solver._osqp)
    public.solver._elastic = _PublicApiOnly(public.solver._elastic)
    refs = [(0.5, 0.0, 0.3)] * 60 + [(0.0, 0.4, -0.3)] * 60 + [(0.3, -0.2, 0.0)] * 60
    statuses = set()
    for ref in refs:
        a, b = fast.step(ref), public.step(ref)
        statuses.add(a.qp_status)
        assert a.qp_status == b.qp_status
        np.testing.assert_allclose(a.beta_ref, b.beta_ref, atol=1e-9)
        np.testing.assert_allclose(a.phi_dot_ref, b.phi_dot_ref, atol=1e-9)
    assert 'solved' in statuses


def test_osqp_is_set_up_once_and_warm_started(geometry, monkeypatch):
    import osqp
    calls = {'setup': 0}
    orig = osqp.OSQP.setup

    def counting(self, *a, **k):
        calls['setup'] += 1
        return orig(self, *a, **k)

    monkeypatch.setattr(osqp.OSQP, 'setup', counting)
    ctrl = make(geometry)
    assert calls['setup'] == 2                               # the QP and its elastic twin
    run(ctrl, [[0.3, 0.2, 0.3]] * 30 + [[0.0, 0.4, -0.2]] * 30)
    assert calls['setup'] == 2


# ---------------------------------------------------------------- limits (property test)

SPEEDS = st.one_of(
    st.sampled_from([0.0, 0.0, 1e-4, -1e-4, 0.5, -0.5, 2.0, -2.0]),
    st.floats(-1.5, 1.5, allow_nan=False, allow_infinity=False),
)
SEGMENT = st.tuples(SPEEDS, SPEEDS, SPEEDS, st.integers(1, 25))


@settings(max_examples=1000, deadline=None, derandomize=True,
          suppress_health_check=[HealthCheck.too_slow])
@given(
    segments=st.lists(SEGMENT, min_size=1, max_size=5),
    beta0=st.lists(st.floats(-math.pi, math.pi), min_size=4, max_size=4),
    rate0=st.lists(st.floats(-RATE_MAX, RATE_MAX), min_size=4, max_size=4),
)
def test_limits_hold_for_random_reference_sequences(geometry, segments, beta0, rate0):
    ctrl = make(geometry)
    ctrl.reset(beta0, beta_dot=rate0)
    refs = [seg[:3] for seg in segments for _ in range(seg[3])]
    outs = run(ctrl, refs)
    assert_limits(outs, beta_dot0=rate0, beta0=np.asarray(beta0))
    for o in outs:
        assert o.status in ('ok', 'stopped')
        assert o.route in ('direct', 'complementary', 'hold')
        assert np.all(np.abs(o.twist_feasible) <= np.array([1.0, 1.0, 1.0]) + TOL)
        assert all(0 <= i < 4 for i in o.active_constraints)


def test_measured_state_resyncs(geometry):
    ctrl = make(geometry)
    run(ctrl, [(0.4, 0.0, 0.0)] * 50)
    measured = ctrl.beta + 0.01
    out = ctrl.step([0.4, 0.0, 0.0], beta_meas=measured, beta_dot_meas=np.zeros(4))
    np.testing.assert_allclose(out.beta_ref, measured + DT * out.beta_dot_ref, atol=1e-12)
    assert np.max(np.abs(out.beta_dot_ref)) <= ACC_MAX * DT + TOL
    outs = run(ctrl, [(0.4, 0.0, 0.0)] * 200)
    assert_limits(outs, beta_dot0=out.beta_dot_ref, beta0=out.beta_ref)
    np.testing.assert_allclose(outs[-1].beta_ref, 0.0, atol=1e-3)        # back to straight


# ---------------------------------------------------------------- tracking

@pytest.mark.parametrize('ref', [
    (0.5, 0.0, 0.0),        # x
    (0.0, 0.5, 0.0),        # y
    (0.35, 0.35, 0.0),      # diagonal
    (-0.3, 0.4, 0.0),
    (0.0, 0.0, 0.5),        # pure rotation
    (0.4, 0.0, 0.2),        # arc left
    (0.3, -0.2, -0.3),      # arc right, sideways
])
def test_executed_twist_converges_to_the_reference(geometry, ref):
    ctrl = make(geometry)
    outs = run(ctrl, [ref] * 300)
    assert_limits(outs)
    ref = np.asarray(ref)
    for o in outs[-20:]:
        tw = executed_twist(geometry, o)
        assert np.linalg.norm(tw - ref) <= 0.01 * np.linalg.norm(ref), (tw, ref)
        np.testing.assert_allclose(tw, o.twist_feasible, atol=1e-9)   # wheels agree: no slip
    # Error of the executed twist never grows over the last 150 cycles (monotone convergence).
    errs = [np.linalg.norm(executed_twist(geometry, o) - ref) for o in outs[150:]]
    assert all(b <= a + 1e-9 for a, b in zip(errs, errs[1:]))


# ---------------------------------------------------------------- route

def test_left_arc_to_right_arc_goes_through_straight_motion(geometry):
    ctrl = make(geometry)
    left, right = (0.5, 0.0, 0.25), (0.5, 0.0, -0.25)      # ICR (0, 2) then (0, -2)
    run(ctrl, [left] * 200)
    beta_left = ctrl.beta
    outs = run(ctrl, [right] * 200)
    assert_limits(outs, beta_dot0=np.zeros(4), beta0=beta_left)
    assert outs[0].route == 'complementary'
    pts = np.array([o.icr_next.point for o in outs])
    # The ICR leaves through the border (pure translation) and never comes near the centre.
    assert any(o.icr_next.at_infinity for o in outs)
    assert np.min(np.abs(pts[:, 1])) > 1.9
    speeds = [np.linalg.norm(o.twist_feasible[:2]) for o in outs]
    assert min(speeds) > 0.4                                 # keeps driving, no spin on the spot
    # ω changes sign exactly once, while the ICR is beyond the border (straight-line motion).
    w = np.array([o.twist_feasible[2] for o in outs])
    flips = np.flatnonzero(np.sign(w[1:]) != np.sign(w[:-1]))
    assert len(flips) == 1
    k = flips[0]
    assert outs[k].icr_next.at_infinity and outs[k + 1].icr_next.at_infinity
    # Small steer changes: |Δβ| < 0.25 rad for every wheel (through the centre it would be ~π).
    assert np.max(np.abs(np.array([o.beta_ref for o in outs]) - beta_left)) < 0.25
    np.testing.assert_allclose(executed_twist(geometry, outs[-1]), right, atol=5e-3)


def test_tight_arc_switch_goes_through_the_centre(geometry):
    ctrl = make(geometry)
    run(ctrl, [(0.1, 0.0, 0.5)] * 200)                       # ICR (0, 0.2)
    outs = run(ctrl, [(0.1, 0.0, -0.5)] * 300)               # ICR (0, -0.2): R1 R2 < ℓ²
    assert outs[0].route == 'direct'
    assert not any(o.icr_next.at_infinity for o in outs)
    np.testing.assert_allclose(outs[-1].icr_next.point, [0.0, -0.2], atol=1e-3)


def test_reversal_keeps_wheel_angles_and_reverses_the_drive(geometry):
    ctrl = make(geometry)
    ref = np.array([0.4, 0.1, 0.2])
    run(ctrl, [ref] * 200)
    beta0, phi0 = ctrl.beta, ctrl.phi_dot
    outs = run(ctrl, [-ref] * 200)
    assert_limits(outs, beta_dot0=np.zeros(4), beta0=beta0)
    drift = np.max(np.abs(np.array([o.beta_ref for o in outs]) - beta0))
    assert drift < 1e-3                                      # no wheel turns by π
    np.testing.assert_allclose(outs[-1].phi_dot_ref, -phi0, rtol=1e-3)
    np.testing.assert_allclose(executed_twist(geometry, outs[-1]), -ref, atol=1e-3)


def test_stop_holds_the_steer_angles(geometry):
    ctrl = make(geometry)
    run(ctrl, [(0.3, 0.2, 0.4)] * 200)
    beta0 = ctrl.beta
    outs = run(ctrl, [(0.0, 0.0, 0.0)] * 200)
    assert_limits(outs, beta_dot0=np.zeros(4), beta0=beta0)
    assert all(o.status == 'stopped' and o.route == 'hold' for o in outs)
    np.testing.assert_allclose(outs[-1].beta_ref, beta0, atol=1e-9)   # wheels not straightened
    assert np.max(np.abs(outs[-1].phi_dot_ref)) < 1e-3
    phi = np.array([np.max(np.abs(o.phi_dot_ref)) for o in outs])
    assert np.all(np.diff(phi) <= 1e-12)                              # monotone ramp-down


def test_stop_while_steering_decelerates_within_limits(geometry):
    ctrl = make(geometry)
    outs = run(ctrl, [(0.0, 0.5, 0.0)] * 20)                 # steering at full rate
    assert np.max(np.abs(ctrl.beta_dot)) > 0.4
    outs2 = run(ctrl, [(0.0, 0.0, 0.0)] * 40)
    assert_limits(outs + outs2)
    assert np.max(np.abs(outs2[-1].beta_dot_ref)) == 0.0


# ---------------------------------------------------------------- singular cases

def test_icr_crossing_a_steer_hip(geometry):
    """The straight ICR route X = 0.24 from Y = 1 to Y = -1 crosses the fl and fr hips."""
    ctrl = make(geometry)
    w = 0.3
    above, below = w * np.array([1.0, -0.24, 1.0]), w * np.array([-1.0, -0.24, 1.0])
    run(ctrl, [above] * 300)
    beta0 = ctrl.beta
    outs = run(ctrl, [below] * 400)
    assert_limits(outs, beta_dot0=np.zeros(4), beta0=beta0)
    assert outs[0].route == 'direct'
    pts = np.array([o.icr_next.point for o in outs])
    assert np.min(np.linalg.norm(pts - HIPS[0], axis=1)) < 0.02            # passes by the fl hip
    assert all(o.status == 'ok' for o in outs)
    np.testing.assert_allclose(executed_twist(geometry, outs[-1]), below, atol=1e-3)


def test_reference_icr_exactly_on_a_hip(geometry):
    ctrl = make(geometry)
    on_hip = 0.4 * np.array([HIPS[0, 1], -HIPS[0, 0], 1.0])  # rotation about the fl hip
    outs = run(ctrl, [on_hip] * 300)
    assert_limits(outs)
    np.testing.assert_allclose(outs[-1].icr_next.point, HIPS[0], atol=1e-3)
    np.testing.assert_allclose(executed_twist(geometry, outs[-1]), on_hip, atol=5e-3)


# ---------------------------------------------------------------- failure

@pytest.mark.parametrize('bad_solver', [
    lambda problem: QpResult(np.array([np.nan, 0.0]), 'solved'),
    lambda problem: QpResult(np.array([1e-3, 0.0]), 'unsolved'),
    lambda problem: (_ for _ in ()).throw(SolverError('injected')),
])
def test_injected_solver_failure_gives_a_safe_stop(geometry, bad_solver):
    ctrl = make(geometry, drive_accel_limit=20.0)
    good = ctrl.solver
    warm = run(ctrl, [(0.5, 0.0, 0.0)] * 100 + [(0.0, 0.5, 0.0)] * 10)   # driving and steering
    assert np.max(np.abs(ctrl.beta_dot)) > 0.2
    beta_before, phi_before = ctrl.beta, ctrl.phi_dot
    ctrl.solver = bad_solver
    outs = run(ctrl, [(0.0, 0.5, 0.0)] * 60)
    assert_limits(warm + outs)
    assert all(o.status == 'solver_failure' and o.route == 'hold' for o in outs)
    phis = np.array([phi_before] + [o.phi_dot_ref for o in outs])
    assert np.max(np.abs(np.diff(phis, axis=0))) <= 20.0 * DT + 1e-9      # drive ramp within φ̈_max
    np.testing.assert_allclose(outs[-1].phi_dot_ref, 0.0, atol=0.0)
    np.testing.assert_allclose(outs[-1].twist_feasible, 0.0, atol=0.0)
    assert np.all(outs[-1].beta_dot_ref == 0.0)                            # steering held
    assert np.max(np.abs(outs[-1].beta_ref - beta_before)) < 0.3           # braked, not turned
    ctrl.solver = good                                                     # recovery
    after = run(ctrl, [(0.0, 0.5, 0.0)] * 300)
    assert after[-1].status == 'ok'
    np.testing.assert_allclose(executed_twist(geometry, after[-1]), [0.0, 0.5, 0.0], atol=5e-3)


def test_solver_hook_in_constructor(geometry):
    ctrl = SwmrController(geometry, SwmrParams.from_robot_config(ROBOT_A), solver=lambda p: QpResult(np.full(2, np.inf), 'solved'))
    out = ctrl.step([0.3, 0.0, 0.0])
    assert isinstance(out, SwmrOutput)
    assert out.status == 'solver_failure' and 'non-finite' in out.qp_status


def test_infeasible_qp_falls_back_to_clipping(geometry):
    """A solver reporting infeasibility is not a failure: rates are clipped per wheel."""
    ctrl = SwmrController(geometry, SwmrParams.from_robot_config(ROBOT_A),
                          solver=lambda p: QpResult(np.zeros(2), 'primal_infeasible'))
    outs = run(ctrl, [(0.0, 0.5, 0.0)] * 200)
    assert_limits(outs)
    assert all(o.status == 'ok' for o in outs)
    np.testing.assert_allclose(outs[-1].beta_ref % np.pi, np.pi / 2, atol=1e-3)


# ---------------------------------------------------------------- hand-computed wheel rates

def test_hand_computed_wheel_rates(geometry):
    """r_w φ̇_i = f(β_i)·ξ̇ + d β̇_i with f(β) = [cos β, sin β, d − hy cos β + hx sin β].

    Numbers worked by hand (r_w = 0.09, d = 0.045, hips (±0.24, ±0.19)):
    * x translation 0.45 m/s, β = 0: φ̇ = 0.45/0.09 = 5.0 for every wheel.
    * y translation 0.45 m/s, β = π/2: f = [0, 1, d + hx], ω = 0 → 5.0; the twin β = −π/2
      gives f = [0, −1, …] → −5.0.
    * spin ω = 0.5 about the centre, β_i = atan2(hy, hx) − π/2 (heading ⟂ hip radius ρ):
      d − hy cos β + hx sin β = d − (hy² + hx²)/ρ = d − ρ, ρ = √(0.24² + 0.19²) = 0.3061046,
      φ̇ = 0.5 (0.045 − 0.3061046)/0.09 = −1.4505809; the twin gives d + ρ → 1.9505809.
    * arc ξ̇ = (0.4, 0, 0.2), ICR (0, 2): heading along the hip velocity, f·ξ̇ = ω (ρ_i + d)
      with ρ_i the hip's distance to the ICR: front-left/rear-left √(0.24² + 1.81²) = 1.8258423
      → φ̇ = 0.2·1.8708423/0.09 = 4.1574273; right wheels √(0.24² + 2.19²) = 2.2031114
      → 0.2·2.2481114/0.09 = 4.9958032.
    """
    cases = [
        (np.zeros(4), (0.45, 0.0, 0.0), [5.0, 5.0, 5.0, 5.0]),
        (np.full(4, np.pi / 2), (0.0, 0.45, 0.0), [5.0, 5.0, 5.0, 5.0]),
        (np.array([np.pi / 2, -np.pi / 2, np.pi / 2, -np.pi / 2]), (0.0, 0.45, 0.0),
         [5.0, -5.0, 5.0, -5.0]),
        (np.arctan2(HIPS[:, 1], HIPS[:, 0]) - np.pi / 2, (0.0, 0.0, 0.5), [-1.4505809] * 4),
        (np.arctan2(HIPS[:, 1], HIPS[:, 0]) + np.array([np.pi / 2, -np.pi / 2, -np.pi / 2, -np.pi / 2]),
         (0.0, 0.0, 0.5), [1.9505809, -1.4505809, -1.4505809, -1.4505809]),
        (geometry.steer_angles_for_icr((0.0, 2.0)), (0.4, 0.0, 0.2),
         [4.1574273, 4.9958032, 4.1574273, 4.9958032]),
    ]
    for beta, ref, expected in cases:
        ctrl = make(geometry)
        ctrl.reset(beta, twist=ref)                          # already at the reference
        out = ctrl.step(ref)
        np.testing.assert_allclose(out.beta_dot_ref, 0.0, atol=1e-9)
        np.testing.assert_allclose(out.phi_dot_ref, expected, atol=1e-6)
        np.testing.assert_allclose(out.twist_feasible, ref, atol=1e-9)


def test_steer_rate_term_of_the_drive(geometry):
    """While steering, φ̇_i − f(β_i)·ξ̇/r_w = (d/r_w) β̇_i = 0.5 β̇_i (d/r_w = 0.045/0.09)."""
    ctrl = make(geometry)
    for o in run(ctrl, [(0.3, 0.3, 0.0)] * 30):
        rolling = geometry.rolling_rows(o.beta_ref) @ o.twist_feasible / R_W
        np.testing.assert_allclose(o.phi_dot_ref - rolling, 0.5 * o.beta_dot_ref, atol=1e-12)


def test_a_stale_reference_brakes_at_the_acceleration_limit():
    """brake=True: rest within max |v_i|/a_i + one period, never decelerating beyond the limits."""
    from wmm_control.base import SteerableGeometry, SwmrController, SwmrParams
    from wmm_control.robot_config import load_robot
    robot = load_robot('steerable')
    ctrl = SwmrController(SteerableGeometry.from_config(robot.steerable), SwmrParams.from_robot_config(robot))
    for _ in range(400):
        out = ctrl.step([0.8, 0.0, 0.0])
    v0 = out.twist_feasible.copy()
    assert v0[0] > 0.79
    amax = np.array(ctrl.params.base_accel_limit)
    allowed = int(np.ceil(np.max(np.abs(v0) / amax) / ctrl.params.dt)) + 1
    twists = [v0]
    for _ in range(allowed):
        twists.append(ctrl.step([0.0, 0.0, 0.0], brake=True).twist_feasible.copy())
    steps = np.abs(np.diff(twists, axis=0))
    assert np.all(steps <= amax * ctrl.params.dt + 1e-12)
    assert np.allclose(twists[-1], 0.0)
    # the K_p law alone (no brake) is still moving after the same time
    ctrl2 = SwmrController(SteerableGeometry.from_config(robot.steerable), SwmrParams.from_robot_config(robot))
    for _ in range(400):
        ctrl2.step([0.8, 0.0, 0.0])
    for _ in range(allowed):
        out2 = ctrl2.step([0.0, 0.0, 0.0])
    assert np.linalg.norm(out2.twist_feasible) > 0.05


def test_measured_steer_rates_beyond_the_limit_never_give_commands_beyond_it():
    from wmm_control.base import SteerableGeometry, SwmrController, SwmrParams
    from wmm_control.robot_config import load_robot
    robot = load_robot('steerable')
    ctrl = SwmrController(SteerableGeometry.from_config(robot.steerable), SwmrParams.from_robot_config(robot))
    limit = ctrl.params.steer_rate_limit
    rates = []
    for k in range(60):
        glitch = np.array([3.0, -3.0, 3.0, -3.0]) if k == 0 else None
        out = ctrl.step([0.2, 0.3, 0.4], beta_meas=ctrl.beta, beta_dot_meas=glitch)
        rates.append(out.beta_dot_ref)
    assert np.max(np.abs(rates)) <= limit + 1e-12
