"""Steerable wheeled mobile robot (SWMR) base controller (Sorour 2019 §IV, Fig 4).

Each period ``dt`` the controller takes the reference base twist ξ̇* = (vx, vy, ω) [m/s, m/s,
rad/s] (base frame) and returns steer angles/rates β_ref, β̇_ref, drive rates φ̇_ref and the
feasible twist ξ̇_ref that those commands realise. A reference beyond ``base_velocity_limit``
is first scaled into it as a whole (its direction, hence its ICR, kept). :meth:`SwmrController.step`
is Fig 4 in three parts:

**Steering controller** (:meth:`~SwmrController.build_qp`, :meth:`~SwmrController._icr_next`,
:meth:`~SwmrController._steer`)

1. ICR* of ξ̇* and ICR_curr of the steer angles (:class:`~wmm_control.base.icr.Icr`,
   projective, pure translation included); the shorter of the direct and the complementary
   route (through the border = pure translation) is chosen (:func:`~wmm_control.base.icr.route_between`).
2. ICR P-controller ``ICṘ_ref = λ (ICR* − ICR_curr)``, integrated over one period:
   ``ICR_ref`` is ICR_curr moved a fraction ``λ dt`` of the way along the route.
3. QP ``min ‖ICR_next − ICR_ref‖²`` subject to, for each wheel, the wedge of two lines through
   its hip that bounds the steer change in one period by β̇_max and β̈_max
   (:func:`~wmm_control.base.icr.wedge_row`). A wheel's headings modulo π fill a *double*
   wedge (β and its twin β + π); a wheel whose hip lies within the period's ICR step uses the
   half that holds ICR_ref, so an ICR path through a hip flips that wheel to its twin instead
   of sweeping it round (if the wedges then have no common point, the QP is solved again on
   the halves of ICR_curr). While the
   route passes a hip, steps across it cost ``route_weight`` more than along it (the thin
   wedges would otherwise lead ICR_next round the hip). When ICR_ref already lies in every
   wedge it is the optimum and OSQP is not called.
4. β_ref of ICR_next, the twin (β or β + π, drive reversed) nearest the current angle; the
   steer rate is then clipped into the per-period interval (hard limits).

**Drive controller** (:meth:`~SwmrController._drive`)

5. ξ̈ = K_p (ξ̇* − ξ̇) within ``base_accel_limit``, integrated.

**Feasible twist**

6. Projected onto the motion compatible with the new steer configuration (rotation about its
   ICR, or translation at infinity); its size along that direction is the one nearest the
   projection that keeps the base velocity, drive rate and base acceleration limits
   (:meth:`~SwmrController._feasible_speed`) → ξ̇_ref; φ̇_ref from the inverse actuation model
   with wheel offset d (:func:`~wmm_control.base.steerable_kinematics.rolling_row`).

The QP lives in a gnomonic chart of the ICR sphere centred on ICR_curr (coordinates ``x ∈ R²``,
``z = z_curr + E x``). That chart is the paper's Cartesian ICR plane seen from the current ICR:
lines through the hips stay lines, so the wedges stay linear, and pure translation is an
ordinary point. (A fixed Cartesian box ``|X|, |Y| ≤ L`` cannot do this: with parallel wheels at
rest the wedges are β̈_max dt² = 1.25e-3 rad wide and meet only ~0.19/1.25e-3 ≈ 150 m away, so
the box QP has no solution whenever the wheels are parallel at rest.) The bounded box
representation is kept for reporting (:attr:`Icr.point`, border ``L``).

When the wedges have no common point (steer rates that no single ICR motion continues), an
elastic copy of the QP (one common relaxation ``s ≥ 0`` of all wedges, heavily penalised) gives
the ICR that breaks them least; the per-wheel clip of step 4 then keeps every limit. A solver
error or a non-finite answer instead brakes the steering to rest within β̈_max and ramps the
drive to zero within ``drive_accel_limit`` (status ``'solver_failure'``).

Measured steer angles (:meth:`~SwmrController.step` ``beta_meas``) restart each period: at the
headings of their best-fit ICR, plus the part of each wheel's disagreement with it beyond
``measurement_deadband`` (:meth:`~SwmrController._resync`).
"""

import math
import time
from dataclasses import dataclass, field, fields
from typing import NamedTuple

import numpy as np
import osqp
from osqp import SolverStatus
from scipy import sparse

from wmm_control.base.icr import (
    DEFAULT_ICR_BORDER,
    DEFAULT_ICR_SCALE,
    Icr,
    hip_velocity,
    icr_of_headings,
    route_between,
    tangent_pair,
    wedge_row,
    wrap_half_turn,
)
from wmm_control.base.steerable_kinematics import rolling_row
from wmm_control.checks import finite_floats
from wmm_control.errors import ConfigError, ShapeError

__all__ = ['SwmrParams', 'SwmrOutput', 'IcrQp', 'QpResult', 'OsqpIcrSolver', 'SwmrController']

_INF = 1e30            # OSQP's infinity
_ROW_TOL = 1e-6        # a normalised wedge row within this of its bound counts as active
_RATE_TOL = 1e-9       # [rad/s] a steer rate clipped by more than this counts as active
_ANGLE_TOL = 1e-12     # [rad] a steer change below this is round-off
_FEAS_TOL = 1e-9       # a normalised row violated by at most this counts as satisfied
_HIP_TOL = 1e-9        # a hip velocity below this: the ICR sits on the hip
ELASTIC_WEIGHT = 1e4


@dataclass(frozen=True, kw_only=True)
class SwmrParams:
    """Parameters of :class:`SwmrController` (SI units, angles in rad), keyword-only.

    The limits have no default: they are the robot's, from its YAML
    (:meth:`from_robot_config`).

    Attributes:
        dt: control period t_s [s] (Sorour Table I: 0.025).
        kp: K_p of the twist controller ξ̈ = K_p (ξ̇* − ξ̇) [1/s] (Table I: 2).
        icr_gain: λ of the ICR P-controller [1/s]. The paper gives no value. An exponential
            approach at gain λ asks the steer joints for a deceleration λ·β̇; λ = β̈_max/β̇_max = 2
            never overshoots but has a slow tail, λ = 8 overshoots by 0.13 rad (β̇_max = 1,
            β̈_max = 2, switch from x to y translation). 4.0 overshoots < 0.005 rad and settles
            (1e-3 rad) in 2 s.
        steer_rate_limit: β̇_max [rad/s].
        steer_accel_limit: β̈_max [rad/s²].
        drive_rate_limit: |φ̇| max [rad/s].
        drive_accel_limit: |φ̈| used to ramp the drive to zero after a solver failure [rad/s²].
        base_velocity_limit: |vx|, |vy|, |ω| max [m/s, m/s, rad/s]. Shape (3,).
        base_accel_limit: |ξ̈| max of the twist controller [m/s², m/s², rad/s²]. Shape (3,).
        icr_scale: ℓ [m], metric length of the homogeneous ICR (route rule: arcs of radii R₁, R₂
            on opposite sides switch through straight-line motion iff R₁R₂ > ℓ²).
        icr_border: L [m], half side of the bounded ICR square used for reporting; ICRs at or
            beyond it count as at infinity.
        max_icr_step: largest ICR move per period on the ICR sphere [rad] (chart box bound).
            At speed the bound is smaller: turning a twist of size |ξ̇| by an angle θ changes
            it by |ξ̇| sin θ, which ``base_accel_limit`` dt caps (:meth:`SwmrController._icr_step`).
        stop_threshold: ‖ξ̇*‖ below which the base stops and the steer angles are held.
        route_weight: w, extra cost of ICR_next's deviation across the route ICR_curr → ICR*
            (:class:`IcrQp`), applied while that route passes a hip. With the plain distance of
            the paper the nearest point to ICR_ref slides round the thin steer-limit wedges,
            off the route: an ICR route through two hips then sweeps those wheels round (11.0
            rad of steering where 4.45 are needed); with the weight, 5.5 rad.
        route_hip_distance: [rad] a route passes a hip when the hip's homogeneous point is
            within this of the route's great circle, between ICR_curr and ICR*. (Everywhere,
            the weight would make the ICR jitter with references near zero, whose route
            direction is arbitrary.)
        measurement_deadband: [rad] measured steer angles start the period at the headings of
            their best-fit ICR, moved towards the measurement by the part of each wheel's
            disagreement beyond this band: sensor noise (σ of a few mrad) is not mistaken for
            steering that no single ICR explains, a real lag beyond the band still is.
        eps: OSQP absolute and relative tolerance.
        max_iter: OSQP iteration limit.
    """

    dt: float = 0.025
    kp: float = 2.0
    icr_gain: float = 4.0
    steer_rate_limit: float
    steer_accel_limit: float
    drive_rate_limit: float
    drive_accel_limit: float
    base_velocity_limit: tuple
    base_accel_limit: tuple
    icr_scale: float = DEFAULT_ICR_SCALE
    icr_border: float = DEFAULT_ICR_BORDER
    max_icr_step: float = 0.3
    stop_threshold: float = 1e-3
    route_weight: float = 3000.0
    route_hip_distance: float = 0.15
    measurement_deadband: float = 0.01
    eps: float = 1e-6
    max_iter: int = 4000

    def __post_init__(self):
        for f in fields(self):
            if f.name in ('base_velocity_limit', 'base_accel_limit'):
                try:
                    arr = np.asarray(getattr(self, f.name), dtype=float)
                except (TypeError, ValueError) as exc:
                    raise ConfigError(f'SwmrParams.{f.name}: expected 3 numbers') from exc
                if arr.shape != (3,) or not np.all(np.isfinite(arr)) or np.any(arr <= 0):
                    raise ConfigError(f'SwmrParams.{f.name}: expected 3 finite values > 0, got {arr.tolist()}')
                object.__setattr__(self, f.name, tuple(float(v) for v in arr))
                continue
            val = getattr(self, f.name)
            if not isinstance(val, (int, float, np.floating, np.integer)) or isinstance(val, bool):
                raise ConfigError(f'SwmrParams.{f.name}: expected a number, got {val!r}')
            if not (np.isfinite(val) and val > 0):
                raise ConfigError(f'SwmrParams.{f.name} must be finite and > 0, got {val}')
        if self.icr_gain * self.dt > 1.0:
            raise ConfigError(f'SwmrParams: icr_gain*dt = {self.icr_gain * self.dt} must be <= 1')
        if self.kp * self.dt > 1.0:
            raise ConfigError(f'SwmrParams: kp*dt = {self.kp * self.dt} must be <= 1')
        if self.steer_rate_limit * self.dt >= np.pi / 4:
            raise ConfigError(
                f'SwmrParams: steer_rate_limit*dt = {self.steer_rate_limit * self.dt} rad per period '
                'must be < pi/4')
        if self.max_icr_step >= np.pi / 2:
            raise ConfigError(f'SwmrParams.max_icr_step must be < pi/2, got {self.max_icr_step}')

    @classmethod
    def from_robot_config(cls, robot, **overrides):
        """Limits from a :class:`RobotConfig` of a steerable robot; other fields from ``overrides``.

        Raises:
            ConfigError: the robot has no ``steerable`` section.
        """
        s = getattr(robot, 'steerable', None)
        if s is None:
            raise ConfigError(f'robot {getattr(robot, "name", robot)!r} has no steerable section')
        values = dict(
            steer_rate_limit=s.steer_rate_limit,
            steer_accel_limit=s.steer_accel_limit,
            drive_rate_limit=s.drive_rate_limit,
            drive_accel_limit=s.drive_accel_limit,
            base_velocity_limit=tuple(np.asarray(robot.base.velocity, dtype=float)),
            base_accel_limit=tuple(np.asarray(robot.base.acceleration, dtype=float)),
        )
        values.update(overrides)
        return cls(**values)


@dataclass(slots=True)
class IcrQp:
    """One cycle's ICR QP, ``min ½ (x − x_ref)ᵀ P (x − x_ref)  s.t.  l ≤ A x ≤ u``, plus its context.

    ``P = I + w n nᵀ`` (n ⟂ x_ref): the paper's distance to ICR_ref, with steps across the route
    ICR_curr → ICR* costing 1 + w (``route_weight``) times more than along it, so that
    ICR_next follows the route instead of sliding round the wedges' corners.

    ``x`` are gnomonic chart coordinates around ICR_curr: the ICR is ``z_curr + e1 x₁ + e2 x₂``.
    Rows of ``A``: ``2i`` and ``2i + 1`` are the two wedge lines of wheel i (normalised, lower
    bound only), the last two the chart box ``|x_k| ≤ box``.

    Attributes:
        x_ref: chart coordinates of ICR_ref (the unconstrained optimum). Shape (2,).
        wedges: the 2N wedge rows as ``(r0, r1, lb)`` tuples (:func:`wedge_row`).
        box: half side of the chart box.
        chart: the tangent basis (e1, e2) at ICR_curr, two 3-tuples.
        icr_curr: ICR of the current steer angles.
        target_z: ICR* on the chosen route (representative on the current hemisphere), 3-tuple.
        rate_lower, rate_upper: per-wheel steer-rate interval for this period [rad/s].
        sides: per wheel, +1 or −1: which half of its double wedge (heading or twin) is used.
        mirrored: a wheel whose hip lies within the ICR step may use its mirror wedge.
        route_weight: w of the cost (:attr:`P`).
        route: 'direct', 'complementary' or 'hold'.
        stopped: the reference is below the stop threshold.
    """

    x_ref: np.ndarray
    wedges: list
    box: float
    chart: tuple
    icr_curr: Icr
    target_z: tuple
    rate_lower: list
    rate_upper: list
    sides: list
    route: str
    stopped: bool
    mirrored: bool = False
    route_weight: float = 0.0

    def data(self):
        """OSQP's data: ``(A's values column-major, l, u)``, float arrays.

        The rows of :attr:`A` as OSQP stores its dense pattern (first column, then second).
        Shapes (2(2N + 2),), (2N + 2,), (2N + 2,).
        """
        r0, r1, lb = zip(*self.wedges)
        b = self.box
        lower = np.array(lb + (-b, -b))
        if min(lb) < -_INF:             # a degenerate row's −inf, as OSQP's infinity
            np.maximum(lower, -_INF, out=lower)
        return np.array(r0 + (1.0, 0.0) + r1 + (0.0, 1.0)), lower, np.array((_INF,) * len(lb) + (b, b))

    @property
    def A(self):
        """Constraint matrix. Shape (2N + 2, 2)."""
        return self.data()[0].reshape(2, -1).T.copy()

    @property
    def l(self):  # noqa: E743 — OSQP's name for the lower bounds
        """Lower bounds. Shape (2N + 2,)."""
        return self.data()[1]

    @property
    def u(self):
        """Upper bounds (only the box has finite ones). Shape (2N + 2,)."""
        return self.data()[2]

    @property
    def P(self):
        """Cost Hessian ``I + w n nᵀ``, n the unit normal of x_ref: a step across the route costs 1 + w."""
        m = self.metric
        return m @ m

    @property
    def metric(self):
        """Symmetric S with ``S S = P``: in ``y = S x`` the cost is ``½‖y − S x_ref‖²``.

        ``S = I + (√(1 + w) − 1) n nᵀ``. Shape (2, 2).
        """
        return self._metric(math.sqrt(1.0 + self.route_weight))

    @property
    def metric_inverse(self):
        """S⁻¹ = I + (1/√(1 + w) − 1) n nᵀ. Shape (2, 2)."""
        return self._metric(1.0 / math.sqrt(1.0 + self.route_weight))

    def _metric(self, stretch):
        x0, x1 = self.x_ref.tolist()
        nn = math.hypot(x0, x1)
        if nn == 0.0 or self.route_weight == 0.0:
            return np.eye(2)
        n0, n1 = -x1 / nn, x0 / nn
        k = stretch - 1.0
        return np.array(((1.0 + k * n0 * n0, k * n0 * n1), (k * n0 * n1, 1.0 + k * n1 * n1)))

    @property
    def basis(self):
        """Tangent basis E = [e1 e2] at ICR_curr. Shape (3, 2)."""
        return np.array(self.chart).T

    def x_ref_feasible(self):
        """True when ICR_ref lies in every wedge and in the box: it is then the optimum."""
        x0, x1 = self.x_ref.tolist()
        if abs(x0) > self.box + _FEAS_TOL or abs(x1) > self.box + _FEAS_TOL:
            return False
        return all(r0 * x0 + r1 * x1 - lb >= -_FEAS_TOL for r0, r1, lb in self.wedges)

    def z_at(self, x0, x1):
        """Unit homogeneous ICR at chart coordinates (x0, x1), a 3-tuple."""
        (a0, a1, a2), (b0, b1, b2) = self.chart
        c0, c1, c2 = self.icr_curr.z.tolist()
        z0, z1, z2 = c0 + a0 * x0 + b0 * x1, c1 + a1 * x0 + b1 * x1, c2 + a2 * x0 + b2 * x1
        n = math.sqrt(z0 * z0 + z1 * z1 + z2 * z2)
        return z0 / n, z1 / n, z2 / n

    def icr_of(self, x):
        """The ICR at chart coordinates ``x`` (Shape (2,))."""
        return self.icr_curr._with_z_unchecked(self.z_at(*np.asarray(x, dtype=float).tolist()))

    @property
    def icr_ref(self):
        """ICR_ref, this period's P-controller reference."""
        return self.icr_of(self.x_ref)

    @property
    def icr_target(self):
        """ICR* (the representative on the chosen route)."""
        return self.icr_curr.with_z(self.target_z)


class QpResult(NamedTuple):
    """What a solver returns: ``x`` (Shape (2,)) and a status string.

    The controller uses ``x`` for status ``'solved'``, ``'solved_inaccurate'`` or ``'elastic'``
    (finite ``x`` only); ``'primal_infeasible…'`` and ``'max_iter_reached'`` make it fall back to
    per-wheel clipping towards ICR_ref; anything else, or a non-finite ``x``, is a solver failure
    (safe stop).
    """

    x: np.ndarray
    status: str


_USED = ('solved', 'solved_inaccurate', 'elastic')
_SOLVED = ('solved', 'solved_inaccurate', 'unconstrained', 'not_solved')
_CLIPPED = ('primal_infeasible', 'max_iter_reached')
_OSQP_ACCEPTED = (SolverStatus.OSQP_SOLVED, SolverStatus.OSQP_SOLVED_INACCURATE)
_OSQP_ELASTIC = (SolverStatus.OSQP_PRIMAL_INFEASIBLE, SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE,
                 SolverStatus.OSQP_MAX_ITER_REACHED)


_STATUS = {status.value: status for status in SolverStatus}
_STATUS_NAME = {status: status.name.removeprefix('OSQP_').lower() for status in SolverStatus}
"""'solved', 'primal_infeasible', … for each osqp :class:`osqp.SolverStatus`."""


class OsqpIcrSolver:
    """OSQP set up once for the ICR QP: fixed dense pattern, warm start, polish off.

    Holds a second OSQP instance, also set up once, for the elastic problem (every wedge row
    relaxed by one common ``s ≥ 0``, penalised by ``½ ELASTIC_WEIGHT s²``), solved only when
    the first reports primal infeasibility or stops at its iteration limit; its result is
    returned with status ``'elastic'``. A ``max_iter_reached`` answer is never returned as a
    solution.

    Args:
        n_rows: number of constraint rows (2N + 2).
        eps: absolute and relative tolerance.
        max_iter: iteration limit.
        use_extension: update and solve through osqp's extension object (``OSQP._solver``, not
            public API) instead of ``update()``/``solve()``. It skips ~15 µs of argument
            checking and copying per call, a third of the call on this 2-variable problem
            (``benchmarks/bench_swmr.py`` prints both); a release without that attribute
            takes the public path, with equal results.

    Attributes:
        last_iterations: OSQP iterations of the last solve (the elastic one if it ran).
    """

    def __init__(self, n_rows, eps=1e-6, max_iter=4000, use_extension=True):
        self.n_rows = m = int(n_rows)
        self.last_iterations = 0
        self.use_extension = bool(use_extension)
        settings = dict(verbose=False, polishing=False, warm_starting=True, eps_abs=eps, eps_rel=eps,
                        max_iter=int(max_iter))
        self._osqp = self._setup(np.eye(2), m, settings)
        # The elastic rows are normalised already; OSQP's Ruiz scaling, fighting the heavy weight
        # on s, would multiply its iteration count by ~15 (median ~2000, often max_iter).
        self._elastic = self._setup(np.diag([1.0, 1.0, ELASTIC_WEIGHT]), m + 1, dict(settings, scaling=0))
        self._extensions = {solver: self._extension(solver) for solver in (self._osqp, self._elastic)}

    @staticmethod
    def _setup(p_dense, m, settings):
        # P is constant (set here, never updated). A: dense pattern, every entry stored
        # (placeholder values are non-zero so none is dropped); its values change each cycle.
        n = p_dense.shape[0]
        p = sparse.triu(sparse.csc_matrix(p_dense), format='csc')
        a = sparse.csc_matrix((np.ones(n * m), np.tile(np.arange(m), n), np.arange(0, n * m + 1, m)),
                              shape=(m, n))
        solver = osqp.OSQP()
        solver.setup(p, np.zeros(n), a, -np.full(m, _INF), np.full(m, _INF), **settings)
        return solver

    @staticmethod
    def _extension(solver):
        """osqp's extension object of ``solver`` if it has the calls used here, else None."""
        ext = getattr(solver, '_solver', None)
        if ext is not None and hasattr(ext, 'update_data_vec') and hasattr(ext, 'update_data_mat'):
            return ext
        return None

    def _run(self, solver, q, a_x, lb, ub):
        """Update ``solver``'s q, A (its values column-major), l, u and solve: ``(x, SolverStatus)``."""
        ext = self._extensions[solver] if self.use_extension else None
        if ext is not None:
            ext.update_data_vec(q, lb, ub)
            ext.update_data_mat(None, None, a_x, None)
            ext.solve()
            info, sol = ext.info, ext.solution
        else:
            solver.update(q=q, l=lb, u=ub, Ax=a_x)
            res = solver.solve(raise_error=False)    # the status is handled here
            info, sol = res.info, res
        self.last_iterations = int(info.iter)
        return np.array(sol.x, dtype=float), _STATUS[info.status_val]

    def __call__(self, problem):
        """Solve ``problem`` (an :class:`IcrQp`); returns a :class:`QpResult`.

        OSQP sees the problem in the coordinates ``y = S x`` of :attr:`IcrQp.metric`, where
        its cost is the identity (constant, set up once) and the rows are normalised again: the
        route weight then costs OSQP no conditioning. (With P = I + w n nᵀ itself, condition
        number 1 + w, answers reported 'solved' broke the thin wedges by up to 1e-4.)

        Raises:
            ShapeError: the problem does not have the set-up number of rows.
        """
        a_x, lb, ub = problem.data()
        if lb.shape != (self.n_rows,):
            raise ShapeError(f'ICR QP: A has shape {(lb.shape[0], 2)}, solver set up for ({self.n_rows}, 2)')
        y_ref = np.asarray(problem.x_ref, dtype=float)
        s_inv = None
        if problem.route_weight > 0.0 and y_ref.any():
            s_inv = problem.metric_inverse
            a = a_x.reshape(2, -1).T.copy() @ s_inv
            norms = np.sqrt(np.einsum('ij,ij->i', a, a))
            a /= norms[:, None]
            a_x = a.ravel(order='F')
            lb, ub = np.maximum(lb / norms, -_INF), np.minimum(ub / norms, _INF)
            y_ref = problem.metric @ y_ref
        y, status = self._run(self._osqp, -y_ref, a_x, lb, ub)
        if status in _OSQP_ACCEPTED or status not in _OSQP_ELASTIC:
            return QpResult(y if s_inv is None else s_inv @ y, _STATUS_NAME[status])
        m = lb.shape[0]
        ae = np.zeros((m + 1, 3))
        ae[:m, :2] = a_x.reshape(2, -1).T
        ae[:m - 2, 2] = 1.0          # every wedge row relaxed by s (the box rows are not)
        ae[m, 2] = 1.0               # s ≥ 0
        ye, estatus = self._run(self._elastic, np.concatenate((-y_ref, [0.0])), ae.ravel(order='F'),
                                np.concatenate((lb, [0.0])), np.concatenate((ub, [_INF])))
        if estatus in _OSQP_ACCEPTED:
            return QpResult(ye[:2] if s_inv is None else s_inv @ ye[:2], 'elastic')
        return QpResult(np.asarray(problem.x_ref, dtype=float).copy(), _STATUS_NAME[status])


@dataclass(frozen=True)
class SwmrOutput:
    """One period's commands and diagnostics.

    Attributes:
        beta_ref: steer angles [rad] (unwrapped, continuous). Shape (N,).
        beta_dot_ref: steer rates [rad/s] = (β_ref − β_prev)/dt. Shape (N,).
        phi_dot_ref: drive rates [rad/s]. Shape (N,).
        twist_feasible: ξ̇_ref, the twist-controller output projected onto the motion
            compatible with ICR_next (base frame) [m/s, m/s, rad/s]; the drive rates realise
            it at the end of the period. Shape (3,).
        twist_executed: q̇_bf, the twist the base executes over the coming period: the
            rolling model (least squares over rolling and no-side-slip) at the mid-period
            steer angles β_ref − β̇_ref dt/2 with these drive and steer rates. It differs from
            ``twist_feasible`` only while the wheels steer (by O(|ξ̇| β̇ dt)); it is what the
            arm compensation of Sorour eq (14) needs. Shape (3,).
        icr_next: ICR of the commanded steer angles.
        icr_ref: this period's ICR reference (P-controller output).
        route: 'direct', 'complementary' or 'hold' (stopped or after a failure).
        active_constraints: wheels whose steer rate/acceleration limit binds this period.
        solve_time_s: wall time of the QP solve [s] (0 when no QP was solved).
        status: 'ok', 'stopped' or 'solver_failure'.
        qp_status: 'solved' or 'solved_inaccurate' (OSQP's answer used), 'unconstrained'
            (ICR_ref lies in every wedge: it is the optimum, OSQP not called), 'elastic' (the
            wedges have no common point, or OSQP stopped at its iteration limit: the elastic
            QP's answer used), 'primal_infeasible' or 'max_iter_reached' (no usable answer:
            per-wheel clipping towards ICR_ref), 'not_solved' (steering held at rest), or the
            failure reason.
    """

    beta_ref: np.ndarray
    beta_dot_ref: np.ndarray
    phi_dot_ref: np.ndarray
    twist_feasible: np.ndarray
    twist_executed: np.ndarray
    icr_next: Icr
    icr_ref: Icr
    route: str
    active_constraints: list
    solve_time_s: float
    status: str
    qp_status: str = field(default='not_solved')


class _QpAnswer(NamedTuple):
    """The steering controller's QP answer for one period."""

    x: tuple              # ICR_next in chart coordinates; None when the solver failed
    status: str           # the qp_status of :class:`SwmrOutput`
    solve_time: float     # [s]


class _Steering(NamedTuple):
    """The steering controller's result for one period."""

    beta: list            # β_ref [rad]
    rate: list            # β̇_ref [rad/s]
    icr_next: Icr         # ICR of β_ref
    active: set           # wheels whose rate limit or wedge binds
    qp_status: str
    solve_time: float     # [s]


def _narrow(lo, hi, slope, low, high):
    """``[lo, hi] ∩ {s : low ≤ slope·s ≤ high}`` for ``slope ≠ 0`` (plain floats)."""
    s1, s2 = low / slope, high / slope
    if slope < 0.0:
        s1, s2 = s2, s1
    return (s1 if s1 > lo else lo), (s2 if s2 < hi else hi)


class SwmrController:
    """The §IV steering + drive controller for an N-module steerable base.

    Internal state: the commanded β, β̇ (position-controlled steering: the actuators integrate
    β̇_ref), the last feasible twist (the integrator of the ξ̇ controller) and the drive rates.
    Pass measured angles to :meth:`step` to close the loop on them.

    Args:
        geometry: :class:`SteerableGeometry` (hips, r_w, d).
        params: :class:`SwmrParams`.
        solver: callable ``solver(IcrQp) -> QpResult``; default :class:`OsqpIcrSolver`. It is
            the attribute ``solver`` and may be replaced at run time (tests inject failures).
            It is called only in periods where ICR_ref leaves some wedge.
    """

    def __init__(self, geometry, params, solver=None):
        self.geometry = geometry
        self.params = params
        p = self.params
        n = geometry.n_wheels
        steer_term = geometry.wheel_offset * p.steer_rate_limit / geometry.wheel_radius
        if steer_term >= p.drive_rate_limit:
            raise ConfigError(
                f'd*steer_rate_limit/r_w = {steer_term} rad/s leaves no drive rate below '
                f'drive_rate_limit = {p.drive_rate_limit}')
        self.n_rows = 2 * n + 2
        self.solver = solver if solver is not None else OsqpIcrSolver(self.n_rows, p.eps, p.max_iter)
        self._icr_proto = Icr(np.array([0.0, 0.0, 1.0]), p.icr_scale, p.icr_border)
        # the twist direction ∝ (z₁, −z₀, z₂/ℓ): its angle changes up to max(ℓ, 1/ℓ) × the ICR's
        self._turn_factor = max(p.icr_scale, 1.0 / p.icr_scale) * math.sqrt(2.0)
        self._turn_budget = min(p.base_accel_limit) * p.dt
        ell = p.icr_scale
        # per hip: its unit homogeneous point (route test), and ‖M‖² = 1 + |h|²/ℓ² of the linear
        # map z ↦ v (:func:`hip_velocity`), which bounds how far an ICR step moves its velocity
        self._hip_points, self._hip_gain = [], []
        for hx, hy in geometry.hip_list:
            hn = math.sqrt(hx * hx + hy * hy + ell * ell)
            self._hip_points.append((hx / hn, hy / hn, ell / hn))
            self._hip_gain.append(1.0 + (hx * hx + hy * hy) / (ell * ell))
        self.reset(np.zeros(n))

    # ------------------------------------------------------------------ state
    def reset(self, beta, beta_dot=None, twist=None):
        """Set the commanded state.

        Args:
            beta: steer angles [rad]. Shape (N,).
            beta_dot: steer rates [rad/s], default zero. Shape (N,).
            twist: current base twist (vx, vy, ω) [m/s, m/s, rad/s], default zero; it is the
                ξ̇-controller's integrator state. Shape (3,).
        """
        n = self.geometry.n_wheels
        self._beta = finite_floats(beta, n, 'beta')
        self._beta_dot = [0.0] * n if beta_dot is None else finite_floats(beta_dot, n, 'beta_dot')
        self._twist = [0.0] * 3 if twist is None else finite_floats(twist, 3, 'twist')
        self._phi_dot = self.geometry.wheel_rates(self._beta, self._beta_dot, self._twist).tolist()
        self._icr = self._icr_of(self._beta)

    def restart(self, beta, beta_dot, phi_dot):
        """Go on from the measured state (the last command was not applied as sent): the steer
        angles, the steer rates within the steer rate limit (an encoder glitch beyond it is not
        followed) and the twist that best fits those and the drive rates.

        Args:
            beta, beta_dot, phi_dot: measured steer angles [rad], steer rates and drive rates
                [rad/s]. Shape (N,) each.
        """
        n = self.geometry.n_wheels
        limit = self.params.steer_rate_limit
        beta = finite_floats(beta, n, 'beta')
        beta_dot = [min(limit, max(-limit, r)) for r in finite_floats(beta_dot, n, 'beta_dot')]
        self.reset(beta, beta_dot, self.geometry.fit_twist(beta, beta_dot, finite_floats(phi_dot, n, 'phi_dot')))

    @property
    def beta(self):
        """Commanded steer angles [rad]. Shape (N,)."""
        return np.array(self._beta)

    @property
    def beta_dot(self):
        """Commanded steer rates [rad/s]. Shape (N,)."""
        return np.array(self._beta_dot)

    @property
    def twist(self):
        """Last feasible twist (vx, vy, ω) [m/s, m/s, rad/s]. Shape (3,)."""
        return np.array(self._twist)

    @property
    def phi_dot(self):
        """Last drive rates [rad/s]. Shape (N,)."""
        return np.array(self._phi_dot)

    @property
    def icr(self):
        """ICR of the commanded steer angles."""
        return self._icr

    def _icr_of(self, beta, like=None):
        """ICR of steer angles β (a sequence of floats): :func:`icr_of_headings`, sign of ``like``."""
        z = icr_of_headings([math.cos(b) for b in beta], [math.sin(b) for b in beta],
                            self.geometry.hip_list, self.params.icr_scale, like)
        return self._icr_proto._with_z_unchecked(z)

    def _rate_interval(self):
        """Per-period steer-rate interval [rad/s]: |β̇| ≤ β̇_max and |β̇ − β̇_prev| ≤ β̈_max dt.

        Returns:
            ``(lower, upper)``, lists of floats, one per wheel.
        """
        p = self.params
        dv = p.steer_accel_limit * p.dt
        vmax = p.steer_rate_limit
        lower, upper = [], []
        for rate in self._beta_dot:
            lo, hi = max(-vmax, rate - dv), min(vmax, rate + dv)
            if lo > hi:   # a resynced (measured) rate beyond β̇_max + β̈_max dt: brake as hard as β̈_max allows
                lo = hi = rate - math.copysign(dv, rate)
            lower.append(lo)
            upper.append(hi)
        return lower, upper

    def _resync(self, beta_meas, beta_dot_meas, stopped):
        """Start the period from measured steer angles and rates (either may be None).

        Angles: a wheel set that no single ICR explains exactly has, per wheel, a
        disagreement with the headings of its best-fit ICR (:func:`icr_of_headings`). The
        measurement starts the period with its best-fit ICR and with the commanded set's own
        disagreement, plus only the part of the extra disagreement that lies beyond
        ``measurement_deadband``: sensor noise does not start the QP from wedges without a
        common point, a real lag of a wheel beyond the band is kept. Measured angles equal to
        the commanded ones change nothing. While the steering is held at rest (``stopped`` and no
        steer rate) a wheel keeps its held angle unless the measurement is beyond the band
        from it, and then takes the measurement as it is. Rates beyond
        ±``steer_rate_limit`` (an encoder glitch) are clipped: they are not a state to continue
        from.
        """
        p = self.params
        n = self.geometry.n_wheels
        if beta_dot_meas is not None:
            limit = p.steer_rate_limit
            rates = finite_floats(beta_dot_meas, n, 'beta_dot_meas')
            self._beta_dot = [min(limit, max(-limit, r)) for r in rates]
        if beta_meas is not None:
            meas = finite_floats(beta_meas, n, 'beta_meas')
            if stopped and not any(self._beta_dot):
                # held at rest: within the band of the held angle a measurement is noise, beyond
                # it the wheel was moved and the measurement is taken as it is
                band = p.measurement_deadband
                held = [c if abs(m - c) <= band else m for m, c in zip(meas, self._beta)]
                if held != self._beta:
                    self._beta = held
                    self._icr = self._icr_of(held, like=self._icr.z.tolist())
            elif meas != self._beta:
                z_cmd = self._icr.z.tolist()
                z_meas = icr_of_headings([math.cos(b) for b in meas], [math.sin(b) for b in meas],
                                         self.geometry.hip_list, p.icr_scale, z_cmd)
                band = p.measurement_deadband
                start = []
                for m, c, (hx, hy) in zip(meas, self._beta, self.geometry.hip_list):
                    v_meas = hip_velocity(z_meas, hx, hy, p.icr_scale)
                    v_cmd = hip_velocity(z_cmd, hx, hy, p.icr_scale)
                    if min(math.hypot(*v_meas), math.hypot(*v_cmd)) < _HIP_TOL:   # on the hip: any angle fits
                        start.append(m)
                        continue
                    own = wrap_half_turn(c - math.atan2(v_cmd[1], v_cmd[0]))        # the command's
                    extra = wrap_half_turn(m - math.atan2(v_meas[1], v_meas[0]) - own)
                    start.append(m - extra + math.copysign(max(abs(extra) - band, 0.0), extra))
                self._beta = start
                self._icr = self._icr_of(start, like=z_cmd)

    # ------------------------------------------------------------------ the steering controller
    def build_qp(self, twist_ref):
        """This period's ICR QP for the reference twist, from the controller state.

        Args:
            twist_ref: ξ̇* = (vx, vy, ω) in the base frame [m/s, m/s, rad/s]; beyond
                ``base_velocity_limit`` it is scaled into it. Shape (3,).

        Returns:
            :class:`IcrQp`, its route weight set.
        """
        problem = self._icr_qp(self._bounded_reference(twist_ref))
        self._weigh_route(problem)
        return problem

    def _weigh_route(self, problem):
        """Set the problem's route weight: ``route_weight`` while its route passes a hip, else 0."""
        z = problem.icr_curr.z.tolist()
        passes = self._route_passes_a_hip(z, problem.target_z)
        problem.route_weight = self.params.route_weight if passes else 0.0

    def _icr_qp(self, ref, mirror=True):
        """Steps 1–3 up to the QP: ICR* and its route, ICR_ref, and the wedges (:class:`IcrQp`).

        ``mirror``: a wheel whose hip lies within the ICR step may use its mirror wedge
        (:meth:`_wedge_side`); False keeps every wheel on the wedge of ICR_curr.
        """
        p = self.params
        scale = p.icr_scale
        vx, vy, wz = ref
        zc = self._icr.z.tolist()
        e1, e2 = tangent_pair(*zc)
        stopped = self._stopped(ref)
        step = self._icr_step()
        x0 = x1 = 0.0
        if stopped:
            zt, route = tuple(zc), 'hold'
        else:
            zt, route = route_between(zc, (-vy, vx, scale * wz))
            tn = math.sqrt(zt[0] * zt[0] + zt[1] * zt[1] + zt[2] * zt[2])
            zt = (zt[0] / tn, zt[1] / tn, zt[2] / tn)
            # ICR_ref: a fraction λ dt of the arc ICR_curr → ICR*, along the great circle.
            theta = math.acos(min(1.0, zc[0] * zt[0] + zc[1] * zt[1] + zc[2] * zt[2]))
            d0 = e1[0] * zt[0] + e1[1] * zt[1] + e1[2] * zt[2]
            d1 = e2[0] * zt[0] + e2[1] * zt[1] + e2[2] * zt[2]
            dn = math.sqrt(d0 * d0 + d1 * d1)
            if dn > 1e-12:
                k = math.tan(min(p.icr_gain * p.dt * theta, step)) / dn
                x0, x1 = k * d0, k * d1
        zr = (zc[0] + e1[0] * x0 + e2[0] * x1, zc[1] + e1[1] * x0 + e2[1] * x1,
              zc[2] + e1[2] * x0 + e2[2] * x1)
        rate_lo, rate_hi = self._rate_interval()
        # |v(ICR_ref) − v(ICR_curr)|² ≤ ‖M‖² |x|² (|zr − zc| = |x|: e1, e2 orthonormal), with a
        # margin for round-off; -1 when no mirror wedge may be taken
        reach = (x0 * x0 + x1 * x1) * (1.0 + 1e-6) + 1e-20 if mirror else -1.0
        sides = [self._wedge_side(beta, hx, hy, zc, zr, zt, reach * gain)
                 for beta, (hx, hy), gain in zip(self._beta, self.geometry.hip_list, self._hip_gain)]
        return IcrQp(x_ref=np.array((x0, x1)), wedges=self._wedge_rows(sides, rate_lo, rate_hi, zc, e1, e2),
                     mirrored=mirror, box=math.tan(step), chart=(e1, e2), icr_curr=self._icr, target_z=zt,
                     rate_lower=rate_lo, rate_upper=rate_hi, sides=sides, route=route, stopped=stopped)

    def _wedge_rows(self, sides, rate_lower, rate_upper, zc, e1, e2):
        """The QP's wedges: per wheel, the lines of its extreme headings this period (:func:`wedge_row`).

        Returns:
            2N ``(r0, r1, lb)`` tuples in the chart ``zc + e1 x₁ + e2 x₂``, wheel i's at 2i, 2i + 1.
        """
        dt, scale = self.params.dt, self.params.icr_scale
        wedges = []
        for beta, side, lo, hi, (hx, hy) in zip(self._beta, sides, rate_lower, rate_upper, self.geometry.hip_list):
            a_lo, a_hi = beta + dt * lo, beta + dt * hi
            wedges.append(wedge_row((math.cos(a_lo), math.sin(a_lo)), side, hx, hy, scale, zc, e1, e2))
            wedges.append(wedge_row((math.cos(a_hi), math.sin(a_hi)), -side, hx, hy, scale, zc, e1, e2))
        return wedges

    def _route_passes_a_hip(self, zc, zt):
        """True when the great-circle route ICR_curr → ICR* passes within ``route_hip_distance`` of a hip.

        Only then does the route weight apply: off the route near a hip, a wheel sweeps round.
        """
        p = self.params
        nrm = (zc[1] * zt[2] - zc[2] * zt[1], zc[2] * zt[0] - zc[0] * zt[2], zc[0] * zt[1] - zc[1] * zt[0])
        sin_theta = math.sqrt(nrm[0] * nrm[0] + nrm[1] * nrm[1] + nrm[2] * nrm[2])
        if sin_theta < 1e-12:
            return False
        cos_theta = zc[0] * zt[0] + zc[1] * zt[1] + zc[2] * zt[2]
        for h in self._hip_points:
            off = abs(h[0] * nrm[0] + h[1] * nrm[1] + h[2] * nrm[2]) / sin_theta
            # the hip's foot on the route's great circle is a zc + b zt with a, b ≥ 0
            hc = h[0] * zc[0] + h[1] * zc[1] + h[2] * zc[2]
            ht = h[0] * zt[0] + h[1] * zt[1] + h[2] * zt[2]
            between = hc - ht * cos_theta >= 0.0 and ht - hc * cos_theta >= 0.0
            if off < p.route_hip_distance and between:
                return True
        return False

    def _stopped(self, ref):
        """True when the reference (vx, vy, ω) is below ``stop_threshold``: stop, hold the angles."""
        return math.sqrt(ref[0] * ref[0] + ref[1] * ref[1] + ref[2] * ref[2]) < self.params.stop_threshold

    def _icr_step(self):
        """Largest ICR move of this period on the ICR sphere [rad]: ``max_icr_step``, or less at speed.

        Rotating the twist ξ̇ by θ changes it by |ξ̇| sin θ; with θ at most √2 × the chart box
        (its corner) times the distortion max(ℓ, 1/ℓ) of the map ICR → twist direction, the
        bound ``|ξ̇| sin θ ≤ min(base_accel_limit) dt`` leaves the feasible twist a size within
        the acceleration limit (:meth:`_feasible_speed`).
        """
        v0, v1, v2 = self._twist
        speed = math.sqrt(v0 * v0 + v1 * v1 + v2 * v2)
        if speed <= self._turn_budget:
            return self.params.max_icr_step
        return min(self.params.max_icr_step, math.asin(self._turn_budget / speed) / self._turn_factor)

    def _wedge_side(self, beta, hx, hy, zc, zr, zt, reach):
        """+1 if the wheel heading β points along its hip velocity, −1 if against it (twin).

        The hip velocity is taken at ICR_curr; but when the hip lies within this period's ICR
        step (|v(ICR_curr)| ≤ |v(ICR_ref) − v(ICR_curr)|, v linear in z), at ICR_ref: the ICR
        path passes by the hip, and if it crosses it the half of the wheel's double wedge that
        holds ICR_ref is the mirror one, so the wheel flips to its twin (drive reversed) instead
        of steering half a turn. ICR* decides when both sit on the hip.

        ``reach`` bounds |v(ICR_ref) − v(ICR_curr)|² from above (negative: the wedge of
        ICR_curr is kept); a hip farther than that from the step is not near, without
        evaluating v(ICR_ref).
        """
        scale = self.params.icr_scale
        c, s = math.cos(beta), math.sin(beta)
        vc0, vc1 = hip_velocity(zc, hx, hy, scale)
        along_c = c * vc0 + s * vc1
        vc2 = vc0 * vc0 + vc1 * vc1
        if vc2 <= reach:
            vr0, vr1 = hip_velocity(zr, hx, hy, scale)
            along_r = c * vr0 + s * vr1
            d0, d1 = vr0 - vc0, vr1 - vc1
            if vc2 <= d0 * d0 + d1 * d1 and abs(along_r) > _HIP_TOL:   # near
                return 1.0 if along_r > 0 else -1.0
        if abs(along_c) > _HIP_TOL:
            return 1.0 if along_c > 0 else -1.0
        for z in (zr, zt):                         # ICR_curr on the hip: ICR_ref, then ICR*
            v0, v1 = hip_velocity(z, hx, hy, scale)
            along = c * v0 + s * v1
            if abs(along) > _HIP_TOL:
                return 1.0 if along > 0 else -1.0
        return 1.0

    def _solve(self, problem):
        """Step 3: ICR_next in chart coordinates, as a :class:`_QpAnswer`.

        Its ``x`` is None when the solver failed (``status`` says why); ICR_ref when no usable
        answer exists (per-wheel clipping follows). OSQP is called only when ICR_ref leaves a
        wedge, and ``'not_solved'`` means the steering is held at rest.
        """
        if problem.stopped and not any(self._beta_dot):
            return _QpAnswer((0.0, 0.0), 'not_solved', 0.0)
        if problem.x_ref_feasible():
            return _QpAnswer(tuple(problem.x_ref.tolist()), 'unconstrained', 0.0)
        self._weigh_route(problem)
        t0 = time.perf_counter()
        try:
            res = self.solver(problem)
            x, qp_status = np.asarray(res.x, dtype=float), str(res.status)
        except Exception as exc:  # noqa: BLE001 — any solver exception means a safe stop
            return _QpAnswer(None, f'error: {type(exc).__name__}: {exc}', time.perf_counter() - t0)
        solve_time = time.perf_counter() - t0
        if qp_status.startswith(_CLIPPED):
            return _QpAnswer(tuple(problem.x_ref.tolist()), qp_status, solve_time)
        if qp_status not in _USED:
            return _QpAnswer(None, qp_status, solve_time)
        x = x.tolist() if x.shape == (2,) else ()
        if len(x) != 2 or not all(map(math.isfinite, x)):
            return _QpAnswer(None, f'{qp_status} (non-finite x)', solve_time)
        return _QpAnswer(tuple(x), qp_status, solve_time)

    def _icr_next(self, ref):
        """Steps 1–3: this period's QP and ICR_next in its chart coordinates.

        The wedges are first chosen per wheel (:meth:`_wedge_side`); when some wheel took its
        mirror wedge and the wedges then have no common point, the QP is solved again with every
        wheel on the wedge of ICR_curr.

        Returns:
            ``(problem, answer)``: the :class:`IcrQp` used and its :class:`_QpAnswer` (the
            solve time of both QPs when there were two).
        """
        problem = self._icr_qp(ref)
        answer = self._solve(problem)
        if answer.x is not None and answer.status not in _SOLVED:
            plain = self._icr_qp(ref, mirror=False)
            if plain.sides != problem.sides:
                again = self._solve(plain)
                solve_time = answer.solve_time + again.solve_time
                if again.x is not None and again.status in _SOLVED:
                    return plain, again._replace(solve_time=solve_time)
                answer = answer._replace(solve_time=solve_time)
        return problem, answer

    def _steer(self, problem, answer):
        """Step 4: β_ref of ICR_next (the nearest twin), β̇_ref clipped into the period's limits.

        Returns:
            :class:`_Steering`.
        """
        p = self.params
        x0, x1 = answer.x
        qp_status = answer.status
        hold = qp_status == 'not_solved'
        z_next = problem.z_at(x0, x1)
        dt, scale = p.dt, p.icr_scale
        beta_new, rate, active, clipped = [], [], set(), False
        for i, (beta, lo, hi, (hx, hy)) in enumerate(zip(self._beta, problem.rate_lower, problem.rate_upper,
                                                         self.geometry.hip_list)):
            vx, vy = hip_velocity(z_next, hx, hy, scale)
            wanted = 0.0
            if not hold and math.hypot(vx, vy) >= _HIP_TOL:      # on a hip any angle fits: keep it
                delta = wrap_half_turn(math.atan2(vy, vx) - beta)
                # A change at the round-off of the ICR ↔ β round trip is none: at rest the wheels stay put.
                if abs(delta) > _ANGLE_TOL:
                    wanted = delta / dt
            r = min(max(wanted, lo), hi)
            if r != wanted:
                clipped = True
                if abs(wanted - r) > _RATE_TOL:
                    active.add(i)
            rate.append(r)
            beta_new.append(beta + dt * r)
        if qp_status in _USED:
            for k, (r0, r1, lb) in enumerate(problem.wedges):
                if r0 * x0 + r1 * x1 - lb <= _ROW_TOL:
                    active.add(k // 2)
        if clipped or hold:            # the wheels' own ICR (they may disagree)
            icr_next = self._icr_of(beta_new, like=z_next)
        else:                          # every wheel on its heading for ICR_next
            icr_next = self._icr_proto._with_z_unchecked(z_next)
        return _Steering(beta_new, rate, icr_next, active, qp_status, answer.solve_time)

    # ------------------------------------------------------------------ the drive controller
    def _drive(self, ref, stopped, brake):
        """Step 5: the twist controller's next twist ξ̇_ref(init), acceleration-limited."""
        p = self.params
        amax, dt, twist = p.base_accel_limit, p.dt, self._twist
        if brake:                          # full braking along the twist, scaled to the limits
            acc = [-v for v in twist]
            k = min(1.0 / dt, *(am / max(abs(ac), 1e-300) for ac, am in zip(acc, amax)))
        else:
            goal = (0.0, 0.0, 0.0) if stopped else ref
            acc = [p.kp * (g - v) for g, v in zip(goal, twist)]
            k = min(1.0, *(am / max(abs(ac), 1e-300) for ac, am in zip(acc, amax)))
        if stopped and all(abs(v) <= am * dt for v, am in zip(twist, amax)):
            return [0.0, 0.0, 0.0]         # the last step to rest, within the limits
        return [v + dt * k * ac for v, ac in zip(twist, acc)]

    # ------------------------------------------------------------------ the feasible twist
    def _feasible_twist(self, init, steer):
        """Step 6: ξ̇_ref(init) projected onto the motion of ICR_next, within every limit.

        Returns:
            ``(twist, phi_dot)``, lists of floats.
        """
        p, g = self.params, self.geometry
        z = steer.icr_next.z.tolist()
        c0, c1, c2 = z[1], -z[0], z[2] / p.icr_scale          # twist direction ∝ (Y, −X, 1)
        cn = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        direction = (c0 / cn, c1 / cn, c2 / cn)
        rows = [rolling_row(math.cos(b), math.sin(b), hx, hy, g.wheel_offset)
                for b, (hx, hy) in zip(steer.beta, g.hip_list)]
        proj = sum(c * v for c, v in zip(direction, init))
        speed = self._feasible_speed(direction, proj, rows, steer.rate)
        twist = [speed * c for c in direction]
        d, r_w = g.wheel_offset, g.wheel_radius
        phi_dot = [(f0 * twist[0] + f1 * twist[1] + f2 * twist[2] + d * r) / r_w
                   for (f0, f1, f2), r in zip(rows, steer.rate)]
        return twist, phi_dot

    def _feasible_speed(self, direction, wanted, rows, rate):
        """The size s of the twist ``s · direction`` nearest ``wanted`` within the limits.

        Hard: |s c_k| ≤ base_velocity_limit_k and |φ̇_i(s c)| ≤ drive_rate_limit (an interval
        of s around 0, since |d β̇_i / r_w| < drive_rate_limit). Then, within it, the change
        from the last twist: |s c_k − ξ̇_k| ≤ base_accel_limit_k dt, another interval. When the
        two do not meet (the ICR turned the direction faster than the acceleration limit
        allows at this speed), s is the one of the first interval that exceeds the
        acceleration limit least (minimax of the ratios).
        """
        p = self.params
        d, r_w = self.geometry.wheel_offset, self.geometry.wheel_radius
        # hard: |s c_k| ≤ V_k, then |s a_i + b_i| ≤ L (a_i = f_i·c / r_w, b_i = d β̇_i / r_w)
        lo, hi = -math.inf, math.inf
        for c, vmax in zip(direction, p.base_velocity_limit):
            if c != 0.0:
                bound = vmax / abs(c)
                if bound < hi:
                    lo, hi = -bound, bound
        # φ̇_i is recomputed from s·c afterwards: a bound 1e-12 inside keeps its round-off
        # below the limit (a simulator comparing exactly would clamp a command at the limit).
        drive_limit = p.drive_rate_limit * (1.0 - 1e-12)
        c0, c1, c2 = direction
        for (f0, f1, f2), r in zip(rows, rate):
            a = (f0 * c0 + f1 * c1 + f2 * c2) / r_w
            if a > 1e-300 or a < -1e-300:
                b = d * r / r_w
                lo, hi = _narrow(lo, hi, a, -drive_limit - b, drive_limit - b)
        lo, hi = min(lo, 0.0), max(hi, 0.0)
        # acceleration: |s c_k − v_k| ≤ r_k
        dt = p.dt
        alo, ahi = lo, hi
        for c, v, am in zip(direction, self._twist, p.base_accel_limit):
            r = am * dt
            if c != 0.0:
                alo, ahi = _narrow(alo, ahi, c, v - r, v + r)
            elif abs(v) > r:
                alo, ahi = math.inf, -math.inf
        if alo <= ahi:
            return alo if wanted < alo else (ahi if wanted > ahi else wanted)
        # minimax: the convex max of the lines ±(s c_k − v_k)/r_k is least where a rising and a
        # falling one cross
        lines = []
        for c, v, am in zip(direction, self._twist, p.base_accel_limit):
            r = am * dt
            lines += ((c / r, -v / r), (-c / r, v / r))
        best, best_ratio = 0.0, math.inf
        candidates = [lo, hi] + [(o2 - o1) / (k1 - k2) for k1, o1 in lines for k2, o2 in lines
                                 if k1 > 0.0 > k2]
        for s in candidates:
            s = min(max(s, lo), hi)
            ratio = max(k * s + o for k, o in lines)
            if ratio < best_ratio:
                best, best_ratio = s, ratio
        return best

    # ------------------------------------------------------------------ one period
    def step(self, twist_ref, beta_meas=None, beta_dot_meas=None, brake=False):
        """One control period: steering controller, drive controller, feasible twist (Fig 4).

        Args:
            twist_ref: ξ̇* = (vx, vy, ω) in the base frame [m/s, m/s, rad/s]; beyond
                ``base_velocity_limit`` it is scaled down into the limits, direction kept.
                Shape (3,).
            beta_meas: measured steer angles [rad], optional. Shape (N,). They replace the
                commanded angles as the start of this period (:meth:`_resync`; the commanded
                rate β̇ stays the reference of the acceleration limit). When the steering
                followed the last command exactly they equal the commanded angles and change
                nothing.
            beta_dot_meas: measured steer rates [rad/s] to resync, optional; clipped into
                ±``steer_rate_limit`` (a glitch never yields a command beyond it). Shape (N,).
            brake: stop as fast as the limits allow (a stale reference): the twist decelerates
                uniformly, its binding component at its acceleration limit, instead of
                following the K_p law; the base is at rest within max |v_i|/a_i + one period.

        Returns:
            :class:`SwmrOutput`.

        Raises:
            ShapeError, NonFiniteError: malformed inputs.
        """
        ref = self._bounded_reference(twist_ref)
        self._resync(beta_meas, beta_dot_meas, self._stopped(ref))
        # steering controller: ICR*, route, ICR_ref, QP → ICR_next → β_ref, β̇_ref
        problem, answer = self._icr_next(ref)
        if answer.x is None:
            return self._safe_stop(problem, answer)
        steer = self._steer(problem, answer)
        # drive controller: ξ̇_ref(init), then the feasible twist compatible with ICR_next
        init = self._drive(ref, problem.stopped, brake)
        twist, phi_dot = self._feasible_twist(init, steer)
        return self._commit(problem, steer, twist, phi_dot)

    def _commit(self, problem, steer, twist, phi_dot, status=None):
        """Store the new state and return it as a :class:`SwmrOutput`."""
        self._beta, self._beta_dot, self._twist, self._phi_dot = steer.beta, steer.rate, twist, phi_dot
        self._icr = steer.icr_next
        executed = twist
        if any(steer.rate):     # the rolling model at the mid-period steer angles
            half = 0.5 * self.params.dt
            executed = self.geometry.fit_twist([b - half * r for b, r in zip(steer.beta, steer.rate)],
                                               steer.rate, phi_dot)
        if status is None:
            status = 'stopped' if problem.stopped else 'ok'
        return SwmrOutput(
            beta_ref=np.array(steer.beta), beta_dot_ref=np.array(steer.rate), phi_dot_ref=np.array(phi_dot),
            twist_feasible=np.array(twist), twist_executed=np.array(executed), icr_next=steer.icr_next,
            icr_ref=problem.icr_ref, route=problem.route if status != 'solver_failure' else 'hold',
            active_constraints=sorted(steer.active), solve_time_s=steer.solve_time, status=status,
            qp_status=steer.qp_status)

    def _safe_stop(self, problem, answer):
        """Solver failure: steer rates braked to zero within β̈_max, drive ramped down within φ̈_max."""
        p = self.params
        rate = [min(max(0.0, lo), hi) for lo, hi in zip(problem.rate_lower, problem.rate_upper)]
        beta_new = [b + p.dt * r for b, r in zip(self._beta, rate)]
        peak = max(abs(v) for v in self._phi_dot)
        k = max(0.0, 1.0 - p.drive_accel_limit * p.dt / peak) if peak > 0 else 0.0
        steer = _Steering(beta_new, rate, self._icr_of(beta_new, like=self._icr.z.tolist()), set(), answer.status,
                          answer.solve_time or 0.0)
        return self._commit(problem, steer, [k * v for v in self._twist], [k * v for v in self._phi_dot],
                            status='solver_failure')


    def _bounded_reference(self, twist_ref):
        """ξ̇* checked and scaled down uniformly into ``|ξ̇*_k| ≤ base_velocity_limit_k``.

        A reference beyond the limits is not trusted as given: it is scaled by the largest
        s ∈ (0, 1] that brings every component within its limit, so its direction (its ICR)
        is kept, and no later product can overflow (a finite 1e308 would otherwise give NaN).

        Returns:
            ``(vx, vy, ω)`` as floats [m/s, m/s, rad/s].

        Raises:
            ShapeError, NonFiniteError: not 3 finite numbers.
        """
        ref = finite_floats(twist_ref, 3, 'twist_ref')
        limits = self.params.base_velocity_limit
        s = 1.0
        for v, vmax in zip(ref, limits):
            if abs(v) > vmax:
                s = min(s, vmax / abs(v))
        if s == 1.0:
            return tuple(ref)
        return tuple(min(vmax, max(-vmax, v * s)) for v, vmax in zip(ref, limits))

