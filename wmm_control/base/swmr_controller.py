"""Steerable wheeled mobile robot (SWMR) base controller (Sorour 2019 §IV).

Each period ``dt`` the controller takes the reference base twist ξ̇* = (vx, vy, ω) [m/s, m/s,
rad/s] (base frame) and returns steer angles/rates β_ref, β̇_ref, drive rates φ̇_ref and the
feasible twist q̇_bf that those commands realise. A reference beyond ``base_velocity_limit``
is first scaled into it as a whole (its direction, hence its ICR, kept):

1. ICR* of ξ̇* and ICR_curr of the commanded steer angles (:class:`~wmm_control.base.icr.Icr`,
   projective, pure translation included); the shorter of the direct and the complementary
   route (through the border = pure translation) is chosen (:func:`choose_route`).
2. ICR P-controller ``ICṘ_ref = λ (ICR* − ICR_curr)``, integrated over one period:
   ``ICR_ref`` is ICR_curr moved a fraction ``λ dt`` of the way along the route.
3. QP (OSQP, 2 variables, fixed dense pattern, warm-started, values updated each cycle):
   ``min ‖ICR_next − ICR_ref‖²`` subject to, for each wheel, the wedge of two lines through its
   hip that bounds the steer change in one period by β̇_max and β̈_max. When ICR_ref already
   lies in every wedge it is the optimum and OSQP is not called.
4. β_ref of ICR_next, the twin (β or β + π, drive reversed) nearest the current angle; the
   steer rate is then clipped into the per-period interval (hard limits), β̇_ref by differencing.
5. ξ̈ = K_p (ξ̇* − ξ̇), integrated, projected onto the motion compatible with the new steer
   configuration (rotation about its ICR, or translation at infinity), scaled into the base and
   drive rate limits → q̇_bf; φ̇_ref from the inverse actuation model with wheel offset d.

The QP lives in a gnomonic chart of the ICR sphere centred on ICR_curr (coordinates ``x ∈ R²``,
``z = z_curr + E x``). That chart is the paper's Cartesian ICR plane seen from the current ICR:
lines through the hips stay lines, so the wedges stay linear, and pure translation is an
ordinary point. (A fixed Cartesian box ``|X|, |Y| ≤ L`` cannot do this: with parallel wheels at
rest the wedges are β̈_max dt² = 1.25e-3 rad wide and meet only ~0.19/1.25e-3 ≈ 150 m away, so
the box QP has no solution whenever the wheels are parallel at rest.) The bounded box
representation is kept for reporting (:attr:`Icr.point`, border ``L``).

When the wedges have no common point (steer rates that no single ICR motion continues, e.g.
near a hip where β varies fast), an elastic copy of the QP (one common relaxation ``s ≥ 0`` of
all wedges, heavily penalised) gives the ICR that breaks them least; the per-wheel clip of
step 4 then keeps every limit. A solver error or a non-finite answer instead brakes the steering
to rest within β̈_max and ramps the drive to zero within ``drive_accel_limit``
(status ``'solver_failure'``).
"""

import math
import time
from dataclasses import dataclass, field, fields

import numpy as np
import osqp
import scipy.sparse as sp

from wmm_control.base.icr import (
    DEFAULT_ICR_BORDER,
    DEFAULT_ICR_SCALE,
    Icr,
    hip_velocity_matrices,
    tangent_pair,
)
from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError, ShapeError

__all__ = ['SwmrParams', 'SwmrOutput', 'IcrQp', 'QpResult', 'OsqpIcrSolver', 'SwmrController']

_INF = 1e30            # OSQP's infinity
_ROW_TOL = 1e-6        # a normalised wedge row within this of its bound counts as active
_RATE_TOL = 1e-9       # [rad/s] a steer rate clipped by more than this counts as active
_ANGLE_TOL = 1e-12     # [rad] a steer change below this is round-off
_FEAS_TOL = 1e-9       # a normalised row violated by at most this counts as satisfied
ELASTIC_WEIGHT = 1e4   # penalty on the common wedge relaxation s of the elastic QP


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
        stop_threshold: ‖ξ̇*‖ below which the base stops and the steer angles are held.
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


@dataclass(frozen=True)
class IcrQp:
    """One cycle's ICR QP, ``min ½ xᵀPx + qᵀx  s.t.  l ≤ A x ≤ u``, plus its context.

    ``x`` are gnomonic chart coordinates around ICR_curr: the ICR is ``z_curr + basis @ x``.
    Rows of ``A``: ``2i`` and ``2i + 1`` are the two wedge lines of wheel i (normalised, lower
    bound only), the last two the chart box ``|x_k| ≤ tan(max_icr_step)``.

    Attributes:
        P: Shape (2, 2).  q: Shape (2,).  A: Shape (2N + 2, 2).  l, u: Shape (2N + 2,).
        basis: tangent basis E at ICR_curr. Shape (3, 2).
        x_ref: chart coordinates of ICR_ref. Shape (2,).
        icr_curr: ICR of the current steer angles.
        icr_target: ICR* (the representative on the chosen route).
        icr_ref: ICR_ref, this period's P-controller reference.
        rate_lower, rate_upper: per-wheel steer-rate interval for this period [rad/s]. Shape (N,).
        route: 'direct', 'complementary' or 'hold'.
        stopped: the reference is below the stop threshold.
    """

    P: np.ndarray
    q: np.ndarray
    A: np.ndarray
    l: np.ndarray
    u: np.ndarray
    basis: np.ndarray
    x_ref: np.ndarray
    icr_curr: Icr
    icr_target: Icr
    icr_ref: Icr
    rate_lower: np.ndarray
    rate_upper: np.ndarray
    route: str
    stopped: bool

    def elastic(self):
        """The elastic problem used when this one is infeasible, as ``(P, q, A, l, u)``.

        Variables ``(x₁, x₂, s)``: every wedge row is relaxed by the same ``s ≥ 0`` (a
        distance in chart units, rows being normalised) and ``s`` is penalised by
        ``½ ELASTIC_WEIGHT s²``, so the solution violates the steer-limit wedges as little as possible
        (the steer rates are then clipped into their limits per wheel). Shapes (3, 3), (3,),
        (2N + 3, 3), (2N + 3,), (2N + 3,).
        """
        p = np.diag([1.0, 1.0, ELASTIC_WEIGHT])
        q = np.concatenate((self.q, [0.0]))
        return (p, q) + _elastic_rows(self.A, self.l, self.u)

    def icr_of(self, x):
        """The ICR at chart coordinates ``x`` (Shape (2,))."""
        return self.icr_curr.with_z(self.icr_curr.z + self.basis @ np.asarray(x, dtype=float))


def _elastic_rows(a, lb, ub):
    """Rows ``(A, l, u)`` of the elastic problem (:meth:`IcrQp.elastic`) from the QP's ``a, lb, ub``."""
    m = a.shape[0]
    ae = np.zeros((m + 1, 3))
    ae[:m, :2] = a
    ae[:m - 2, 2] = 1.0
    ae[m, 2] = 1.0
    return ae, np.concatenate((lb, [0.0])), np.concatenate((ub, [_INF]))


@dataclass(frozen=True)
class QpResult:
    """What a solver returns: ``x`` (Shape (2,)), a status string and the duals (or None).

    Status ``'solved'``, ``'solved_inaccurate'``, ``'max_iter_reached'``, ``'elastic'`` or
    ``'unconstrained'`` (``x_ref`` satisfies every row) with a finite ``x`` is used; ``'primal_infeasible'`` makes the controller fall back to per-wheel clipping; anything
    else, or a non-finite ``x``, is a solver failure (safe stop).
    """

    x: np.ndarray
    status: str
    y: np.ndarray = None


_USABLE = ('solved', 'solved_inaccurate', 'max_iter_reached')
_USED = _USABLE + ('elastic', 'unconstrained')
_OSQP_STATUS = {1: 'solved', 2: 'solved_inaccurate', 3: 'primal_infeasible',
                4: 'primal_infeasible_inaccurate', 5: 'dual_infeasible', 6: 'dual_infeasible_inaccurate',
                7: 'max_iter_reached', 8: 'time_limit_reached', 9: 'non_convex', 10: 'interrupted',
                11: 'unsolved'}
_INFEASIBLE = ('primal_infeasible', 'primal_infeasible_inaccurate')


class OsqpIcrSolver:
    """OSQP set up once for the ICR QP: fixed dense pattern, warm start, polish off.

    Holds a second OSQP instance, also set up once, for the elastic problem
    (:meth:`IcrQp.elastic`), solved only when the first reports primal infeasibility; its
    result is returned with status ``'elastic'``. An ``x_ref`` (the unconstrained optimum,
    ``q = −x_ref``) that satisfies every row is the optimum itself: it is returned with status
    ``'unconstrained'`` and OSQP is not called.

    Args:
        n_rows: number of constraint rows (2N + 2).
        eps: absolute and relative tolerance.
        max_iter: iteration limit.
    """

    def __init__(self, n_rows, eps=1e-6, max_iter=4000):
        self.n_rows = m = int(n_rows)
        settings = dict(verbose=False, polishing=False, warm_starting=True, eps_abs=eps, eps_rel=eps,
                        max_iter=int(max_iter))
        self._osqp = self._setup(np.eye(2), m, settings)
        # The elastic rows are normalised already; OSQP's Ruiz scaling, fighting the heavy weight
        # on s, would multiply its iteration count by ~15 (median ~2000, often max_iter).
        self._elastic = self._setup(np.diag([1.0, 1.0, ELASTIC_WEIGHT]), m + 1, dict(settings, scaling=0))

    @staticmethod
    def _setup(p_dense, m, settings):
        # P is constant (set here, never updated). A: dense pattern, every entry stored
        # (placeholder values are non-zero so none is dropped); its values change each cycle.
        n = p_dense.shape[0]
        p = sp.triu(sp.csc_matrix(p_dense), format='csc')
        a = sp.csc_matrix((np.ones(n * m), np.tile(np.arange(m), n), np.arange(0, n * m + 1, m)), shape=(m, n))
        solver = osqp.OSQP()
        solver.setup(p, np.zeros(n), a, -np.full(m, _INF), np.full(m, _INF), **settings)
        return solver

    @staticmethod
    def _run(solver, q, a_x, lb, ub):
        # osqp 1.x keeps its C-extension solver as ``_solver``; updating and solving through
        # it skips ~30 µs of wrapper overhead per call. That attribute is not public API, so
        # any other osqp release takes the public update()/solve() path, with equal results.
        ext = getattr(solver, '_solver', None)
        if ext is not None and hasattr(ext, 'update_data_vec') and hasattr(ext, 'update_data_mat'):
            ext.update_data_vec(q, lb, ub)
            ext.update_data_mat(None, None, a_x, None)
            ext.solve()
            info, sol = ext.info, ext.solution
        else:
            solver.update(q=q, l=lb, u=ub, Ax=a_x)
            try:
                res = solver.solve(raise_error=False)    # the status is handled here
            except TypeError:                            # a release without that keyword
                res = solver.solve()
            info, sol = res.info, res
        status = _OSQP_STATUS.get(int(info.status_val), str(info.status))
        return np.array(sol.x, dtype=float), status, np.array(sol.y, dtype=float)

    def solve(self, x_ref, a, lb, ub):
        """Solve ``min ‖x − x_ref‖²  s.t.  lb ≤ a x ≤ ub`` (rows laid out as :class:`IcrQp`).

        Args:
            x_ref: the unconstrained optimum. Shape (2,).
            a: Shape (n_rows, 2).  lb, ub: Shape (n_rows,).

        Returns:
            ``(x, status, y)``; ``y`` (the duals) is None when OSQP was not called.
        """
        ax = a @ x_ref
        if (lb - ax <= _FEAS_TOL).all() and (ax - ub <= _FEAS_TOL).all():
            return x_ref.copy(), 'unconstrained', None
        a_x = a.ravel(order='F')
        x, status, y = self._run(self._osqp, -x_ref, a_x, lb, ub)
        if status not in _INFEASIBLE:
            return x, status, y
        ae, le, ue = _elastic_rows(a, lb, ub)
        xe, estatus, ye = self._run(self._elastic, np.concatenate((-x_ref, [0.0])), ae.ravel(order='F'), le, ue)
        if estatus in _USABLE:
            return xe[:2], 'elastic', ye
        return x, f'{status} (elastic: {estatus})', y

    def __call__(self, problem):
        """Solve ``problem`` (an :class:`IcrQp`) with updated values; returns a :class:`QpResult`.

        Raises:
            ShapeError: the problem's A does not have the set-up shape.
        """
        if problem.A.shape != (self.n_rows, 2):
            raise ShapeError(f'ICR QP: A has shape {problem.A.shape}, solver set up for ({self.n_rows}, 2)')
        return QpResult(*self.solve(-np.asarray(problem.q, dtype=float), problem.A, problem.l, problem.u))


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
        qp_status: the solver's status: 'solved', 'solved_inaccurate', 'max_iter_reached',
            'unconstrained' (ICR_ref satisfies every wedge, it is the optimum; OSQP not called),
            'elastic' (wedges infeasible, elastic QP used), 'primal_infeasible' (fallback:
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


class SwmrController:
    """The §IV steering + drive controller for an N-module steerable base.

    Internal state: the commanded β, β̇ (position-controlled steering: the actuators integrate
    β̇_ref), the last feasible twist (the integrator of the ξ̇ controller) and the drive rates.
    Pass measured angles to :meth:`step` to resync.

    Args:
        geometry: :class:`SteerableGeometry` (hips, r_w, d).
        params: :class:`SwmrParams`.
        solver: callable ``solver(IcrQp) -> QpResult``; default :class:`OsqpIcrSolver`. It is
            the attribute ``solver`` and may be replaced at run time (tests inject failures).
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
        m = hip_velocity_matrices(geometry.hips, p.icr_scale)
        # Hip i: M_i z = (z1 + my_i z2, −z0 + mx_i z2); tol_i flags an ICR on the hip.
        self._wheels = [(float(hx), float(hy), float(mi[0, 2]), float(mi[1, 2]),
                         1e-9 * max(1.0, float(np.linalg.norm(mi)))) for (hx, hy), mi in zip(geometry.hips, m)]
        self._icr_proto = Icr(np.array([0.0, 0.0, 1.0]), p.icr_scale, p.icr_border)
        self._box = math.tan(p.max_icr_step)
        self._ub = np.concatenate((np.full(2 * n, _INF), [self._box, self._box]))
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
        self._beta = as_finite_vector(beta, n, 'beta').copy()
        self._beta_dot = np.zeros(n) if beta_dot is None else as_finite_vector(beta_dot, n, 'beta_dot').copy()
        self._twist = np.zeros(3) if twist is None else as_finite_vector(twist, 3, 'twist').copy()
        self._phi_dot = self.geometry.wheel_rates(self._beta, self._beta_dot, self._twist)
        self._icr = self._icr_of_beta(self._beta)

    @property
    def beta(self):
        """Commanded steer angles [rad]. Shape (N,)."""
        return self._beta.copy()

    @property
    def beta_dot(self):
        """Commanded steer rates [rad/s]. Shape (N,)."""
        return self._beta_dot.copy()

    @property
    def twist(self):
        """Last feasible twist (vx, vy, ω) [m/s, m/s, rad/s]. Shape (3,)."""
        return self._twist.copy()

    @property
    def phi_dot(self):
        """Last drive rates [rad/s]. Shape (N,)."""
        return self._phi_dot.copy()

    @property
    def icr(self):
        """ICR of the commanded steer angles."""
        return self._icr

    def _icr_of_beta(self, beta, like=None):
        """ICR of steer angles β (least squares, as :meth:`Icr.from_steer_angles`), sign of ``like``."""
        beta = np.asarray(beta, dtype=float)
        return self._icr_of_cs(np.cos(beta).tolist(), np.sin(beta).tolist(), like)

    def _icr_of_cs(self, cos_beta, sin_beta, like):
        """:meth:`_icr_of_beta` from the cosines and sines of β (sequences of floats).

        The least-squares twist direction t (rows g_i = (−sin, cos, (hx cos + hy sin)/ℓ)) is the
        eigenvector of the smallest eigenvalue λ of S = GᵀG: closed-form λ (trigonometric
        method), t the largest cross product of two rows of S − λI. An ill-conditioned case
        (repeated eigenvalues) falls back to the SVD of G.
        """
        ell = self.params.icr_scale
        g = [(-s, c, (hx * c + hy * s) / ell) for c, s, (hx, hy, _, _, _) in zip(cos_beta, sin_beta, self._wheels)]
        s00 = s01 = s02 = s11 = s12 = s22 = 0.0
        for g0, g1, g2 in g:
            s00 += g0 * g0
            s01 += g0 * g1
            s02 += g0 * g2
            s11 += g1 * g1
            s12 += g1 * g2
            s22 += g2 * g2
        q = (s00 + s11 + s22) / 3.0
        off = s01 * s01 + s02 * s02 + s12 * s12
        pp = math.sqrt(((s00 - q) ** 2 + (s11 - q) ** 2 + (s22 - q) ** 2 + 2.0 * off) / 6.0)
        t = None
        if pp > 1e-9 * q:
            b00, b11, b22 = (s00 - q) / pp, (s11 - q) / pp, (s22 - q) / pp
            b01, b02, b12 = s01 / pp, s02 / pp, s12 / pp
            det = b00 * (b11 * b22 - b12 * b12) - b01 * (b01 * b22 - b12 * b02) + b02 * (b01 * b12 - b11 * b02)
            phi = math.acos(min(1.0, max(-1.0, 0.5 * det))) / 3.0
            lam = q + 2.0 * pp * math.cos(phi + 2.0 * math.pi / 3.0)
            r0 = (s00 - lam, s01, s02)
            r1 = (s01, s11 - lam, s12)
            r2 = (s02, s12, s22 - lam)
            best, bn = None, 0.0
            for u, v in ((r0, r1), (r0, r2), (r1, r2)):
                c = (u[1] * v[2] - u[2] * v[1], u[2] * v[0] - u[0] * v[2], u[0] * v[1] - u[1] * v[0])
                cn = c[0] * c[0] + c[1] * c[1] + c[2] * c[2]
                if cn > bn:
                    best, bn = c, cn
            # The cross product scales with the two other eigenvalue gaps; too small: degenerate.
            if bn > 1e-12 * (pp * pp) ** 2:
                t = best
        if t is None:
            t = np.linalg.svd(np.array(g))[2][-1].tolist()
        z = (-t[1], t[0], t[2])
        if like is not None and z[0] * like[0] + z[1] * like[1] + z[2] * like[2] < 0:
            z = (-z[0], -z[1], -z[2])
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
        for rate in self._beta_dot.tolist():
            lo, hi = max(-vmax, rate - dv), min(vmax, rate + dv)
            if lo > hi:   # a resynced (measured) rate beyond β̇_max + β̈_max dt: brake as hard as β̈_max allows
                lo = hi = rate - math.copysign(dv, rate)
            lower.append(lo)
            upper.append(hi)
        return lower, upper

    # ------------------------------------------------------------------ QP
    def _problem(self, vx, vy, wz):
        """This period's QP data for the reference twist (vx, vy, ω), from the controller state.

        Returns:
            ``(x_ref, (e1, e2), a, lb, rate_lower, rate_upper, target_z, route, stopped)``:
            x_ref (Shape (2,)), the tangent basis as two 3-tuples, the rows ``a`` (Shape (2N + 2, 2))
            and lower bounds ``lb`` (Shape (2N + 2,)) laid out as in :class:`IcrQp` (upper bounds
            are the constant ``self._ub``), the rate interval as lists, ICR* as a 3-tuple (the
            representative on the chosen route), the route and the stop flag.
        """
        p = self.params
        z0, z1, z2 = self._icr.z.tolist()
        e1, e2 = tangent_pair(z0, z1, z2)
        stopped = math.sqrt(vx * vx + vy * vy + wz * wz) < p.stop_threshold
        x0 = x1 = 0.0
        if stopped:
            t0, t1, t2, route = z0, z1, z2, 'hold'
        else:
            t0, t1, t2 = -vy, vx, p.icr_scale * wz
            tn = math.sqrt(t0 * t0 + t1 * t1 + t2 * t2)
            t0, t1, t2 = t0 / tn, t1 / tn, t2 / tn
            cos = z0 * t0 + z1 * t1 + z2 * t2
            if cos < 0.0:            # choose_route: the representative on the current hemisphere
                t0, t1, t2, cos = -t0, -t1, -t2, -cos
            route = 'complementary' if z2 * t2 < 0.0 else 'direct'
            theta = math.acos(min(1.0, cos))
            d0 = e1[0] * t0 + e1[1] * t1 + e1[2] * t2
            d1 = e2[0] * t0 + e2[1] * t1 + e2[2] * t2
            dn = math.sqrt(d0 * d0 + d1 * d1)
            if dn > 1e-12:
                k = math.tan(min(p.icr_gain * p.dt * theta, p.max_icr_step)) / dn
                x0, x1 = k * d0, k * d1
        rate_lo, rate_hi = self._rate_interval()

        # cross(e_lo, v) >= 0 and cross(v, e_hi) >= 0 with e = σ (cos, sin), v = M_i (z_c + E x):
        # rows r = c M_i with c_lo = σ (−sin a_lo, cos a_lo), c_hi = σ (sin a_hi, −cos a_hi),
        # i.e. r = (−c1, c0, my c0 + mx c1); σ orients the wheel along the hip velocity.
        dt = p.dt
        rows, lb = [], []
        for beta, lo, hi, (_, _, my, mx, tol) in zip(self._beta.tolist(), rate_lo, rate_hi, self._wheels):
            cb, sb = math.cos(beta), math.sin(beta)
            side = cb * (z1 + my * z2) + sb * (mx * z2 - z0)
            if abs(side) < tol:      # ICR on the hip: open the wedge towards the goal
                side = cb * (t1 + my * t2) + sb * (mx * t2 - t0)
            sig = -1.0 if side < 0 else 1.0
            a_lo, a_hi = beta + dt * lo, beta + dt * hi
            for c0, c1 in ((-sig * math.sin(a_lo), sig * math.cos(a_lo)),
                           (sig * math.sin(a_hi), -sig * math.cos(a_hi))):
                r2 = my * c0 + mx * c1
                w0 = -c1 * e1[0] + c0 * e1[1] + r2 * e1[2]
                w1 = -c1 * e2[0] + c0 * e2[1] + r2 * e2[2]
                nr = math.sqrt(w0 * w0 + w1 * w1)
                if nr > 1e-12:
                    rows += (w0 / nr, w1 / nr)
                    lb.append((c1 * z0 - c0 * z1 - r2 * z2) / nr)
                else:
                    rows += (0.0, 0.0)
                    lb.append(-_INF)
        rows += (1.0, 0.0, 0.0, 1.0)
        lb += (-self._box, -self._box)
        a = np.array(rows).reshape(-1, 2)
        return (np.array((x0, x1)), (e1, e2), a, np.array(lb), rate_lo, rate_hi, (t0, t1, t2), route,
                stopped)

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
        ref = as_finite_vector(twist_ref, 3, 'twist_ref').tolist()
        limits = self.params.base_velocity_limit
        s = 1.0
        for v, vmax in zip(ref, limits):
            if abs(v) > vmax:
                s = min(s, vmax / abs(v))
        if s == 1.0:
            return tuple(ref)
        return tuple(min(vmax, max(-vmax, v * s)) for v, vmax in zip(ref, limits))

    def build_qp(self, twist_ref):
        """Build this period's ICR QP for the reference twist, from the controller state.

        Args:
            twist_ref: ξ̇* = (vx, vy, ω) in the base frame [m/s, m/s, rad/s]. Shape (3,).

        Returns:
            :class:`IcrQp`.
        """
        return self._as_icr_qp(self._problem(*self._bounded_reference(twist_ref)))

    def _as_icr_qp(self, data):
        """The :class:`IcrQp` of :meth:`_problem`'s ``data``."""
        x_ref, (e1, e2), a, lb, rate_lo, rate_hi, target_z, route, stopped = data
        curr = self._icr
        basis = np.array((e1, e2)).T
        return IcrQp(
            P=np.eye(2), q=-x_ref, A=a, l=lb, u=self._ub.copy(), basis=basis, x_ref=x_ref,
            icr_curr=curr, icr_target=curr._with_z_unchecked(target_z),
            icr_ref=self._icr_at(e1, e2, *x_ref.tolist()),
            rate_lower=np.array(rate_lo), rate_upper=np.array(rate_hi), route=route, stopped=stopped)

    def _icr_at(self, e1, e2, x0, x1):
        """The ICR at chart coordinates (x0, x1) around the current ICR (tangent basis e1, e2)."""
        z0, z1, z2 = self._icr.z.tolist()
        return self._icr_proto._with_z_unchecked(
            (z0 + e1[0] * x0 + e2[0] * x1, z1 + e1[1] * x0 + e2[1] * x1, z2 + e1[2] * x0 + e2[2] * x1))

    def solve_qp(self, problem):
        """Solve ``problem`` with :attr:`solver`.

        Returns:
            ``(x, qp_status, solve_time_s)``; ``x`` is None on failure (``qp_status`` says why).
            On primal infeasibility ``x`` is the unconstrained optimum ``x_ref`` (the steer
            rates are clipped per wheel afterwards).
        """
        return self._timed_solve(self.solver, (problem,), problem.x_ref)

    @staticmethod
    def _timed_solve(call, args, x_ref):
        """``call(*args)`` (a :class:`QpResult` or an ``(x, status, y)`` tuple), timed and checked."""
        t0 = time.perf_counter()
        try:
            res = call(*args)
        except Exception as exc:  # noqa: BLE001 — any solver exception means a safe stop
            return None, f'error: {type(exc).__name__}: {exc}', time.perf_counter() - t0
        elapsed = time.perf_counter() - t0
        if isinstance(res, tuple):
            x, status = res[0], res[1]
        else:
            x, status = getattr(res, 'x', None), str(getattr(res, 'status', 'unknown'))
        x = np.asarray(x, dtype=float) if x is not None else None
        if status.startswith(_INFEASIBLE):
            return x_ref.copy(), status, elapsed
        if status not in _USED or x is None or x.shape != (2,) or not np.isfinite(x).all():
            return None, status if status not in _USED else f'{status} (non-finite x)', elapsed
        return x, status, elapsed

    # ------------------------------------------------------------------ step
    def step(self, twist_ref, beta_meas=None, beta_dot_meas=None, brake=False):
        """One control period.

        Args:
            twist_ref: ξ̇* = (vx, vy, ω) in the base frame [m/s, m/s, rad/s]; beyond
                ``base_velocity_limit`` it is scaled down into the limits, direction kept.
                Shape (3,).
            beta_meas: measured steer angles [rad], optional. Shape (N,). They replace the
                commanded angles as the start of this period (the loop closes on them; the
                commanded rate β̇ stays the reference of the acceleration limit). When the
                steering followed the last command exactly they equal the commanded angles
                and change nothing.
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
        p = self.params
        n = self.geometry.n_wheels
        vx, vy, wz = self._bounded_reference(twist_ref)
        if beta_meas is not None:
            self._beta = as_finite_vector(beta_meas, n, 'beta_meas').copy()
            self._icr = self._icr_of_beta(self._beta, like=self._icr.z)
        if beta_dot_meas is not None:
            # a measured rate beyond the limit (an encoder glitch) is not a state to continue from
            limit = p.steer_rate_limit
            self._beta_dot = np.clip(as_finite_vector(beta_dot_meas, n, 'beta_dot_meas'), -limit, limit)

        data = self._problem(vx, vy, wz)
        x_ref, (e1, e2), a, lb, rate_lo, rate_hi, _, route, stopped = data
        z0, z1, z2 = self._icr.z.tolist()
        icr_ref = self._icr_at(e1, e2, *x_ref.tolist())
        beta_dot = self._beta_dot.tolist()
        hold = stopped and not any(beta_dot)
        if hold:
            x0 = x1 = 0.0
            qp_status, solve_time = 'not_solved', 0.0
        else:
            if isinstance(self.solver, OsqpIcrSolver):
                x, qp_status, solve_time = self._timed_solve(self.solver.solve, (x_ref, a, lb, self._ub), x_ref)
            else:
                x, qp_status, solve_time = self.solve_qp(self._as_icr_qp(data))
            if x is None:
                return self._safe_stop(rate_lo, rate_hi, icr_ref, qp_status, solve_time)
            x0, x1 = x.tolist()

        # Steer: ICR_next -> nearest twin -> hard clip into the period's rate interval.
        n0, n1, n2 = z0 + e1[0] * x0 + e2[0] * x1, z1 + e1[1] * x0 + e2[1] * x1, z2 + e1[2] * x0 + e2[2] * x1
        nn = math.sqrt(n0 * n0 + n1 * n1 + n2 * n2)
        n0, n1, n2 = n0 / nn, n1 / nn, n2 / nn
        dt = p.dt
        half_pi = 0.5 * math.pi
        beta_new, rate, active = [], [], set()
        for i, (beta, lo, hi, (_, _, my, mx, _)) in enumerate(zip(self._beta.tolist(), rate_lo, rate_hi,
                                                                   self._wheels)):
            v0, v1 = n1 + my * n2, mx * n2 - n0
            if hold or math.sqrt(v0 * v0 + v1 * v1) < 1e-9:   # ICR on a hip: any angle fits, keep it
                wanted = 0.0
            else:
                delta = (math.atan2(v1, v0) - beta + half_pi) % math.pi - half_pi
                # A change at the round-off of the ICR ↔ β round trip is none: at rest the wheels stay put.
                wanted = delta / dt if abs(delta) > _ANGLE_TOL else 0.0
            r = min(max(wanted, lo), hi)
            if abs(wanted - r) > _RATE_TOL:
                active.add(i)
            rate.append(r)
            beta_new.append(beta + dt * r)
        if qp_status in _USED:
            for k, ((a0, a1), low) in enumerate(zip(a[:-2].tolist(), lb[:-2].tolist())):
                if a0 * x0 + a1 * x1 - low <= _ROW_TOL:
                    active.add(k // 2)
        cos_new = [math.cos(b) for b in beta_new]
        sin_new = [math.sin(b) for b in beta_new]
        icr_next = self._icr_of_cs(cos_new, sin_new, (n0, n1, n2))

        # Drive: K_p twist controller, projection on the motion compatible with icr_next, limits.
        amax = p.base_accel_limit
        twist = self._twist.tolist()
        goal = (0.0, 0.0, 0.0) if stopped else (vx, vy, wz)
        if brake:
            acc = [-v for v in twist]          # full braking along the twist, scaled to the limits below
            k = min(1.0 / dt, *(am / max(abs(ac), 1e-300) for ac, am in zip(acc, amax)))
        else:
            acc = [p.kp * (g - v) for g, v in zip(goal, twist)]
            k = min(1.0, amax[0] / max(abs(acc[0]), 1e-300), amax[1] / max(abs(acc[1]), 1e-300),
                    amax[2] / max(abs(acc[2]), 1e-300))
        acc = [ac * k for ac in acc]
        if stopped and all(abs(v) <= am * dt for v, am in zip(twist, amax)):
            acc = [-v / dt for v in twist]   # the last step to rest, within the limits
        init = [v + dt * ac for v, ac in zip(twist, acc)]
        c0, c1, c2 = icr_next.z.tolist()                 # twist direction ∝ (Y, −X, 1) = (z1, −z0, z2/ℓ)
        c0, c1, c2 = c1, -c0, c2 / p.icr_scale
        cn = math.sqrt(c0 * c0 + c1 * c1 + c2 * c2)
        c0, c1, c2 = c0 / cn, c1 / cn, c2 / cn
        proj = c0 * init[0] + c1 * init[1] + c2 * init[2]
        feasible = [proj * c0, proj * c1, proj * c2]
        f_rows = self._rolling_rows(cos_new, sin_new)
        s = self._velocity_scale(feasible, f_rows, rate)
        feasible = [s * f for f in feasible]
        d, r_w = self.geometry.wheel_offset, self.geometry.wheel_radius
        phi_dot = [(f0 * feasible[0] + f1 * feasible[1] + f2 * feasible[2] + d * r) / r_w
                   for (f0, f1, f2), r in zip(f_rows, rate)]

        executed = self._executed_twist(beta_new, rate, phi_dot, feasible)
        self._beta, self._beta_dot = np.array(beta_new), np.array(rate)
        self._twist, self._phi_dot = np.array(feasible), np.array(phi_dot)
        self._icr = icr_next
        return SwmrOutput(
            beta_ref=np.array(beta_new), beta_dot_ref=np.array(rate), phi_dot_ref=np.array(phi_dot),
            twist_feasible=np.array(feasible), twist_executed=executed, icr_next=icr_next, icr_ref=icr_ref,
            route=route, active_constraints=sorted(active),
            solve_time_s=solve_time, status='stopped' if stopped else 'ok',
            qp_status=qp_status)

    def _rolling_rows(self, cos_beta, sin_beta):
        """Rows ``f(β_i) = (cos β, sin β, d − hy cos β + hx sin β)`` of the rolling constraint, as tuples."""
        d = self.geometry.wheel_offset
        return [(c, s, d - hy * c + hx * s) for c, s, (hx, hy, _, _, _) in zip(cos_beta, sin_beta, self._wheels)]

    def _executed_twist(self, beta_new, rate, phi_dot, feasible):
        """Twist over the coming period: the rolling model at the mid-period steer angles.

        Least squares over the N rolling and N no-side-slip rows (as
        :meth:`SteerableGeometry.twist_from_wheels`), solved by its 3×3 normal equations.
        Arguments are sequences of floats; returns Shape (3,).
        """
        if not any(rate):
            return np.array(feasible, dtype=float)
        d, r_w = self.geometry.wheel_offset, self.geometry.wheel_radius
        half = 0.5 * self.params.dt
        n00 = n01 = n02 = n11 = n12 = n22 = b0 = b1 = b2 = 0.0
        for beta, r, phi, (hx, hy, _, _, _) in zip(beta_new, rate, phi_dot, self._wheels):
            mid = beta - half * r
            c, s = math.cos(mid), math.sin(mid)
            f2, g2 = d - hy * c + hx * s, hx * c + hy * s
            rhs = r_w * phi - d * r
            n00 += c * c + s * s
            n01 += c * s - s * c
            n02 += c * f2 - s * g2
            n11 += s * s + c * c
            n12 += s * f2 + c * g2
            n22 += f2 * f2 + g2 * g2
            b0 += c * rhs
            b1 += s * rhs
            b2 += f2 * rhs
        # Cramer on the symmetric 3×3 system.
        m00, m01, m02 = n11 * n22 - n12 * n12, n02 * n12 - n01 * n22, n01 * n12 - n02 * n11
        det = n00 * m00 + n01 * m01 + n02 * m02
        m11, m12, m22 = n00 * n22 - n02 * n02, n01 * n02 - n00 * n12, n00 * n11 - n01 * n01
        return np.array(((m00 * b0 + m01 * b1 + m02 * b2) / det,
                         (m01 * b0 + m11 * b1 + m12 * b2) / det,
                         (m02 * b0 + m12 * b1 + m22 * b2) / det))

    def _velocity_scale(self, twist, f_rows, rate):
        """Largest s ∈ [0, 1] with |s ξ̇| within the base limits and |φ̇(s ξ̇)| ≤ drive_rate_limit."""
        p = self.params
        d, r_w = self.geometry.wheel_offset, self.geometry.wheel_radius
        s = 1.0
        for v, vmax in zip(twist, p.base_velocity_limit):
            if v != 0.0:
                s = min(s, vmax / abs(v))
        for (f0, f1, f2), r in zip(f_rows, rate):
            a = (f0 * twist[0] + f1 * twist[1] + f2 * twist[2]) / r_w
            if abs(a) > 1e-300:
                b = d * r / r_w
                s = min(s, (p.drive_rate_limit - (b if a > 0 else -b)) / abs(a))
        return max(0.0, s)

    def _safe_stop(self, rate_lo, rate_hi, icr_ref, qp_status, solve_time):
        """Solver failure: steer rates braked to zero within β̈_max, drive ramped down within φ̈_max."""
        p = self.params
        rate = np.clip(0.0, rate_lo, rate_hi)
        beta_new = self._beta + p.dt * rate
        peak = float(np.max(np.abs(self._phi_dot)))
        k = max(0.0, 1.0 - p.drive_accel_limit * p.dt / peak) if peak > 0 else 0.0
        phi_dot = self._phi_dot * k
        twist = self._twist * k
        self._beta, self._beta_dot, self._twist, self._phi_dot = beta_new, rate, twist, phi_dot
        self._icr = self._icr_of_beta(beta_new, like=self._icr.z)
        return SwmrOutput(
            beta_ref=beta_new.copy(), beta_dot_ref=rate.copy(), phi_dot_ref=phi_dot.copy(),
            twist_feasible=twist.copy(),
            twist_executed=self._executed_twist(beta_new.tolist(), rate.tolist(), phi_dot.tolist(), twist.tolist()),
            icr_next=self._icr, icr_ref=icr_ref, route='hold',
            active_constraints=[], solve_time_s=solve_time, status='solver_failure',
            qp_status=qp_status)
