"""SWMR controller on steerable bases of N = 2, 3 and 6 modules (nothing assumes 4 wheels).

Each geometry is built directly (no robot YAML): two modules front and back on the centre
line, three 120° apart, six 60° apart. Over random reference twists the steer rates and
accelerations, the drive rates and the base velocity stay within their limits; the drive
commands realise the feasible twist on every wheel's rolling constraint, and the commanded
wheel states give it back through the geometry's least-squares fit; a constant reachable
reference is tracked within a stated time.
"""

import math

import numpy as np
import pytest
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from wmm_control.base import Icr, SteerableGeometry, SwmrController, SwmrParams

R_W, D = 0.09, 0.045
DT, RATE_MAX, ACC_MAX, DRIVE_MAX = 0.025, 1.0, 2.0, 12.0
VELOCITY, ACCEL = (1.0, 1.0, 1.0), (1.0, 1.0, 1.5)
TOL = 1e-6


def ring(n, radius):
    """``n`` hips evenly spaced on a circle of ``radius`` [m], the first on the +x axis."""
    a = 2.0 * math.pi * np.arange(n) / n
    return np.column_stack((radius * np.cos(a), radius * np.sin(a)))


GEOMETRIES = {
    2: SteerableGeometry(np.array([[0.3, 0.0], [-0.3, 0.0]]), R_W, D),  # front and back, centre line
    3: SteerableGeometry(ring(3, 0.3), R_W, D),  # 120° apart
    6: SteerableGeometry(ring(6, 0.35), R_W, D),  # 60° apart
}


def make(n):
    params = SwmrParams(
        steer_rate_limit=RATE_MAX,
        steer_accel_limit=ACC_MAX,
        drive_rate_limit=DRIVE_MAX,
        drive_accel_limit=20.0,
        base_velocity_limit=VELOCITY,
        base_accel_limit=ACCEL,
        dt=DT,
    )
    return SwmrController(GEOMETRIES[n], params)


def fitted(geometry, o):
    """The twist the commanded wheel states realise (least squares over rolling and no side slip)."""
    return geometry.twist_from_wheels(o.beta_ref, o.beta_dot_ref, o.phi_dot_ref)


def check_limits(geometry, outs, beta0, rate0):
    """Every cycle: |β̇| ≤ β̇_max, |β̈| ≤ β̈_max, β̇ = Δβ/dt, |φ̇| ≤ φ̇_max, |ξ̇| ≤ V, finite,
    and the drive rates are the rolling model of the feasible twist, φ̇ = (f(β)·ξ̇ + d β̇)/r_w."""
    prev_beta, prev_rate = np.asarray(beta0, dtype=float), np.asarray(rate0, dtype=float)
    for k, o in enumerate(outs):
        for name in ('beta_ref', 'beta_dot_ref', 'phi_dot_ref', 'twist_feasible', 'twist_executed'):
            assert np.all(np.isfinite(getattr(o, name))), (k, name)
        assert o.beta_ref.shape == o.beta_dot_ref.shape == o.phi_dot_ref.shape == (geometry.n_wheels,)
        assert np.max(np.abs(o.beta_dot_ref)) <= RATE_MAX + TOL, (k, o.beta_dot_ref)
        assert np.max(np.abs(o.beta_dot_ref - prev_rate)) / DT <= ACC_MAX + TOL, (k, o.beta_dot_ref, prev_rate)
        np.testing.assert_allclose((o.beta_ref - prev_beta) / DT, o.beta_dot_ref, atol=1e-9)
        assert np.max(np.abs(o.phi_dot_ref)) <= DRIVE_MAX + TOL, (k, o.phi_dot_ref)
        assert np.all(np.abs(o.twist_feasible) <= np.array(VELOCITY) + TOL), (k, o.twist_feasible)
        rolling = geometry.wheel_rates(o.beta_ref, o.beta_dot_ref, o.twist_feasible)
        np.testing.assert_allclose(o.phi_dot_ref, rolling, rtol=0, atol=1e-9)
        assert all(0 <= i < geometry.n_wheels for i in o.active_constraints)
        prev_beta, prev_rate = o.beta_ref, o.beta_dot_ref


SPEEDS = st.one_of(
    st.sampled_from([0.0, 0.0, 1e-4, -1e-4, 0.5, -0.5, 2.0, -2.0]),
    st.floats(-1.5, 1.5, allow_nan=False, allow_infinity=False),
)
SEGMENTS = st.lists(st.tuples(SPEEDS, SPEEDS, SPEEDS, st.integers(1, 25)), min_size=1, max_size=4)
ANGLES = st.floats(-math.pi, math.pi)
RATES = st.floats(-RATE_MAX, RATE_MAX)


@pytest.mark.parametrize('n', sorted(GEOMETRIES))
@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(data=st.data(), segments=SEGMENTS)
def test_limits_hold_from_any_state(n, data, segments):
    """From arbitrary steer angles and rates (wheels that need not agree on an ICR)."""
    beta0 = np.array(data.draw(st.lists(ANGLES, min_size=n, max_size=n)))
    rate0 = np.array(data.draw(st.lists(RATES, min_size=n, max_size=n)))
    ctrl = make(n)
    ctrl.reset(beta0, beta_dot=rate0)
    outs = [ctrl.step(seg[:3]) for seg in segments for _ in range(seg[3])]
    check_limits(ctrl.geometry, outs, beta0, rate0)
    assert all(o.status in ('ok', 'stopped') for o in outs)


@pytest.mark.parametrize('n', sorted(GEOMETRIES))
@settings(max_examples=150, deadline=None, derandomize=True, suppress_health_check=[HealthCheck.too_slow])
@given(icr0=st.tuples(st.floats(-3.0, 3.0), st.floats(-3.0, 3.0)), segments=SEGMENTS)
def test_commanded_wheels_realise_the_feasible_twist(n, icr0, segments):
    """From wheels that agree on an ICR: in every cycle the geometry's fit of the commanded
    wheel states is the feasible twist (to the QP's accuracy, as for robot A), and the limits hold."""
    ctrl = make(n)
    geometry = ctrl.geometry
    beta0 = geometry.steer_angles_for_icr(Icr.from_point(*icr0))
    ctrl.reset(beta0)
    outs = [ctrl.step(seg[:3]) for seg in segments for _ in range(seg[3])]
    check_limits(geometry, outs, beta0, np.zeros(n))
    for k, o in enumerate(outs):
        np.testing.assert_allclose(
            geometry.fit_twist(o.beta_ref, o.beta_dot_ref, o.phi_dot_ref),
            o.twist_feasible,
            rtol=0,
            atol=2e-3,
            err_msg=str(k),
        )


SETTLE_S = 6.0
"""From rest with the wheels straight, a constant reachable reference is tracked within 1 % by then."""


@pytest.mark.parametrize('n', sorted(GEOMETRIES))
@pytest.mark.parametrize(
    'ref',
    [
        (0.5, 0.0, 0.0),  # x
        (0.0, 0.5, 0.0),  # y: every wheel steers a quarter turn
        (-0.3, 0.4, 0.0),
        (0.0, 0.0, 0.5),  # spin on the spot
        (0.4, 0.0, 0.2),  # arc left
        (0.3, -0.2, -0.3),  # arc right, sideways
    ],
    ids=['x', 'y', 'diagonal', 'spin', 'arc-left', 'arc-right'],
)
def test_a_constant_reference_is_reached_within_the_settling_time(n, ref):
    ctrl = make(n)
    geometry = ctrl.geometry
    cycles = int(round(SETTLE_S / DT))
    outs = [ctrl.step(ref) for _ in range(cycles + 40)]
    check_limits(geometry, outs, np.zeros(n), np.zeros(n))
    ref = np.asarray(ref)
    for o in outs[cycles:]:
        twist = fitted(geometry, o)
        assert np.linalg.norm(twist - ref) <= 0.01 * np.linalg.norm(ref), (twist, ref)
        np.testing.assert_allclose(twist, o.twist_feasible, atol=1e-9)  # wheels agree: no slip
        assert o.status == 'ok'


def test_a_ctrl_c_that_osqp_keeps_during_a_solve_goes_back_to_the_process():
    """OSQP listens for SIGINT while it solves and ends the solve with status ``sigint``, the
    signal kept: the node's own handler never heard it, and a controller stopped with Ctrl-C in
    the middle of a solve ran on until ``ros2 launch`` killed it. The solver hands it back."""
    import signal
    from types import SimpleNamespace

    from osqp import SolverStatus

    from wmm_control.base import OsqpIcrSolver

    class Interrupted:
        def update(self, **_):
            """The next solve's data: nothing to keep, the solve is interrupted whatever they are."""

        def solve(self, raise_error=False):
            info = SimpleNamespace(iter=3, status_val=SolverStatus.OSQP_SIGINT.value)
            return SimpleNamespace(x=np.full(2, np.nan), info=info)

    heard = []
    previous = signal.signal(signal.SIGINT, lambda *_: heard.append(True))
    try:
        _, status = OsqpIcrSolver(6)._run(Interrupted(), np.zeros(2), np.zeros((6, 2)), np.zeros(6), np.ones(6))
    finally:
        signal.signal(signal.SIGINT, previous)
    assert status is SolverStatus.OSQP_SIGINT
    assert heard == [True]
