"""Steerable wheeled mobile robot (SWMR) base controller (Sorour 2019 §IV).

Each period ``dt`` the controller takes the reference base twist ξ̇* = (vx, vy, ω) [m/s, m/s,
rad/s] (base frame) and returns steer angles/rates β_ref, β̇_ref, drive rates φ̇_ref and the
feasible twist q̇_bf that those commands realise:

1. ICR* of ξ̇* and ICR_curr of the commanded steer angles (:class:`~wmm_control.base.icr.Icr`,
   projective, pure translation included); the shorter of the direct and the complementary
   route (through the border = pure translation) is chosen (:func:`choose_route`).
2. ICR P-controller ``ICṘ_ref = λ (ICR* − ICR_curr)``, integrated over one period:
   ``ICR_ref`` is ICR_curr moved a fraction ``λ dt`` of the way along the route.
3. QP (OSQP, 2 variables, fixed dense pattern, warm-started, values updated each cycle):
   ``min ‖ICR_next − ICR_ref‖²`` subject to, for each wheel, the wedge of two lines through its
   hip that bounds the steer change in one period by β̇_max and β̈_max.
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
    choose_route,
    hip_velocity_matrices,
    tangent_basis,
    wrap_half_turn,
)
from wmm_control.checks import as_finite_vector
from wmm_control.errors import ConfigError, ShapeError

__all__ = ['SwmrParams', 'SwmrOutput', 'IcrQp', 'QpResult', 'OsqpIcrSolver', 'SwmrController']

_INF = 1e30            # OSQP's infinity
_ROW_TOL = 1e-6        # a normalised wedge row within this of its bound counts as active
_RATE_TOL = 1e-9       # [rad/s] a steer rate clipped by more than this counts as active
ELASTIC_WEIGHT = 1e4   # penalty on the common wedge relaxation s of the elastic QP


@dataclass(frozen=True)
class SwmrParams:
    """Parameters of :class:`SwmrController` (SI units, angles in rad).

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
    steer_rate_limit: float = 1.0
    steer_accel_limit: float = 2.0
    drive_rate_limit: float = 12.0
    drive_accel_limit: float = 20.0
    base_velocity_limit: tuple = (1.0, 1.0, 1.0)
    base_accel_limit: tuple = (1.0, 1.0, 1.5)
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
        m = self.A.shape[0]
        p = np.diag([1.0, 1.0, ELASTIC_WEIGHT])
        q = np.concatenate((self.q, [0.0]))
        a = np.zeros((m + 1, 3))
        a[:m, :2] = self.A
        a[:m - 2, 2] = 1.0
        a[m, 2] = 1.0
        lb = np.concatenate((self.l, [0.0]))
        ub = np.concatenate((self.u, [_INF]))
        return p, q, a, lb, ub

    def icr_of(self, x):
        """The ICR at chart coordinates ``x`` (Shape (2,))."""
        return self.icr_curr.with_z(self.icr_curr.z + self.basis @ np.asarray(x, dtype=float))


@dataclass(frozen=True)
class QpResult:
    """What a solver returns: ``x`` (Shape (2,)), a status string and the duals (or None).

    Status ``'solved'``, ``'solved_inaccurate'`` or ``'max_iter_reached'`` with a finite ``x`` is
    used; ``'primal_infeasible'`` makes the controller fall back to per-wheel clipping; anything
    else, or a non-finite ``x``, is a solver failure (safe stop).
    """

    x: np.ndarray
    status: str
    y: np.ndarray = None


_USABLE = ('solved', 'solved_inaccurate', 'max_iter_reached')
_USED = _USABLE + ('elastic',)
_OSQP_STATUS = {1: 'solved', 2: 'solved_inaccurate', 3: 'primal_infeasible',
                4: 'primal_infeasible_inaccurate', 5: 'dual_infeasible', 6: 'dual_infeasible_inaccurate',
                7: 'max_iter_reached', 8: 'time_limit_reached', 9: 'non_convex', 10: 'interrupted',
                11: 'unsolved'}
_INFEASIBLE = ('primal_infeasible', 'primal_infeasible_inaccurate')


class OsqpIcrSolver:
    """OSQP set up once for the ICR QP: fixed dense pattern, warm start, polish off.

    Holds a second OSQP instance, also set up once, for the elastic problem
    (:meth:`IcrQp.elastic`), solved only when the first reports primal infeasibility; its
    result is returned with status ``'elastic'``.

    Args:
        n_rows: number of constraint rows (2N + 2).
        eps: absolute and relative tolerance.
        max_iter: iteration limit.
    """

    def __init__(self, n_rows, eps=1e-6, max_iter=4000):
        self.n_rows = int(n_rows)
        settings = dict(verbose=False, polishing=False, warm_starting=True, eps_abs=eps, eps_rel=eps,
                        max_iter=int(max_iter))
        self._osqp = self._setup(np.eye(2), self.n_rows, settings)
        self._elastic = self._setup(np.diag([1.0, 1.0, ELASTIC_WEIGHT]), self.n_rows + 1, settings)

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
    def _run(solver, q, a, lb, ub):
        solver.update(q=q, l=lb, u=ub, Ax=a.ravel(order='F'))
        res = solver.solve(raise_error=False)
        status = _OSQP_STATUS.get(int(res.info.status_val), str(res.info.status))
        return np.array(res.x, dtype=float), status, np.array(res.y, dtype=float)

    def __call__(self, problem):
        """Solve ``problem`` (an :class:`IcrQp`) with updated values; returns a :class:`QpResult`.

        Raises:
            ShapeError: the problem's A does not have the set-up shape.
        """
        if problem.A.shape != (self.n_rows, 2):
            raise ShapeError(f'ICR QP: A has shape {problem.A.shape}, solver set up for ({self.n_rows}, 2)')
        x, status, y = self._run(self._osqp, problem.q, problem.A, problem.l, problem.u)
        if status in _INFEASIBLE:
            _, qe, ae, le, ue = problem.elastic()
            xe, estatus, ye = self._run(self._elastic, qe, ae, le, ue)
            if estatus in _USABLE:
                return QpResult(xe[:2], 'elastic', ye)
            return QpResult(x, f'{status} (elastic: {estatus})', y)
        return QpResult(x, status, y)


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

    def __init__(self, geometry, params=None, solver=None):
        self.geometry = geometry
        self.params = params if params is not None else SwmrParams()
        p = self.params
        n = geometry.n_wheels
        steer_term = geometry.wheel_offset * p.steer_rate_limit / geometry.wheel_radius
        if steer_term >= p.drive_rate_limit:
            raise ConfigError(
                f'd*steer_rate_limit/r_w = {steer_term} rad/s leaves no drive rate below '
                f'drive_rate_limit = {p.drive_rate_limit}')
        self.n_rows = 2 * n + 2
        self.solver = solver if solver is not None else OsqpIcrSolver(self.n_rows, p.eps, p.max_iter)
        self._m = hip_velocity_matrices(geometry.hips, p.icr_scale)
        self._icr_proto = Icr(np.array([0.0, 0.0, 1.0]), p.icr_scale, p.icr_border)
        self._m2 = np.repeat(self._m, 2, axis=0)          # one matrix per wedge row
        self._m_norm = np.maximum(1.0, np.linalg.norm(self._m, axis=(1, 2)))
        self._vmax = np.asarray(p.base_velocity_limit)
        self._amax = np.asarray(p.base_accel_limit)
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
        p = self.params
        c, s = np.cos(beta), np.sin(beta)
        hips = self.geometry.hips
        g = np.column_stack((-s, c, (hips[:, 0] * c + hips[:, 1] * s) / p.icr_scale))
        t = np.linalg.svd(g)[2][-1]
        z = np.array([-t[1], t[0], t[2]])
        if like is not None and float(z @ like) < 0:
            z = -z
        return self._icr_proto._with_z_unchecked(z)

    def _rate_interval(self):
        """Per-period steer-rate interval [rad/s]: |β̇| ≤ β̇_max and |β̇ − β̇_prev| ≤ β̈_max dt."""
        p = self.params
        dv = p.steer_accel_limit * p.dt
        lo = np.maximum(-p.steer_rate_limit, self._beta_dot - dv)
        hi = np.minimum(p.steer_rate_limit, self._beta_dot + dv)
        # A resynced (measured) rate beyond β̇_max + β̈_max dt: brake as hard as β̈_max allows.
        bad = lo > hi
        if np.any(bad):
            brake = self._beta_dot[bad] - np.sign(self._beta_dot[bad]) * dv
            lo[bad] = brake
            hi[bad] = brake
        return lo, hi

    # ------------------------------------------------------------------ QP
    def build_qp(self, twist_ref):
        """Build this period's ICR QP for the reference twist, from the controller state.

        Args:
            twist_ref: ξ̇* = (vx, vy, ω) in the base frame [m/s, m/s, rad/s]. Shape (3,).

        Returns:
            :class:`IcrQp`.
        """
        p = self.params
        twist_ref = as_finite_vector(twist_ref, 3, 'twist_ref')
        curr = self._icr
        zc = curr.z
        basis = tangent_basis(zc)
        stopped = bool(math.sqrt(float(twist_ref @ twist_ref)) < p.stop_threshold)
        if stopped:
            target_z, route = zc, 'hold'
            x_ref = np.zeros(2)
        else:
            target = curr._with_z_unchecked(
                np.array([-twist_ref[1], twist_ref[0], p.icr_scale * twist_ref[2]]))
            target_z, route = choose_route(curr, target)
            theta = math.acos(min(1.0, max(-1.0, float(zc @ target_z))))
            d = basis.T @ target_z
            dn = math.sqrt(float(d @ d))
            step = min(p.icr_gain * p.dt * theta, p.max_icr_step)
            x_ref = math.tan(step) * d / dn if dn > 1e-12 else np.zeros(2)
        rate_lo, rate_hi = self._rate_interval()

        beta = self._beta
        cb, sb = np.cos(beta), np.sin(beta)
        v_curr = self._m @ zc                      # (N, 2) hip velocity directions now
        side = cb * v_curr[:, 0] + sb * v_curr[:, 1]
        on_hip = np.abs(side) < 1e-9 * self._m_norm
        if np.any(on_hip):                         # ICR on a hip: open the wedge towards the goal
            v_goal = self._m[on_hip] @ target_z
            side[on_hip] = cb[on_hip] * v_goal[:, 0] + sb[on_hip] * v_goal[:, 1]
        sigma = np.where(side < 0, -1.0, 1.0)
        a_lo = beta + p.dt * rate_lo
        a_hi = beta + p.dt * rate_hi
        # cross(e_lo, v) >= 0 and cross(v, e_hi) >= 0 with e = σ (cos, sin), v = M_i (z_c + E x):
        # rows r_lo = σ (−sin a_lo, cos a_lo) M_i, r_hi = σ (sin a_hi, −cos a_hi) M_i.  Shape (2N, 3).
        c = np.empty((2 * beta.size, 2))
        c[0::2, 0], c[0::2, 1] = -np.sin(a_lo), np.cos(a_lo)
        c[1::2, 0], c[1::2, 1] = np.sin(a_hi), -np.cos(a_hi)
        c *= np.repeat(sigma, 2)[:, None]
        r = np.einsum('kj,kjl->kl', c, self._m2)
        rows = r @ basis
        nr = np.sqrt(np.einsum('kj,kj->k', rows, rows))
        ok = nr > 1e-12
        a = np.zeros((self.n_rows, 2))
        lb = np.full(self.n_rows, -_INF)
        ub = np.full(self.n_rows, _INF)
        a[:-2][ok] = rows[ok] / nr[ok, None]
        lb[:-2][ok] = -(r[ok] @ zc) / nr[ok]
        box = np.tan(p.max_icr_step)
        a[-2, 0] = 1.0
        a[-1, 1] = 1.0
        lb[-2:] = -box
        ub[-2:] = box
        return IcrQp(
            P=np.eye(2), q=-x_ref, A=a, l=lb, u=ub, basis=basis, x_ref=x_ref,
            icr_curr=curr, icr_target=curr._with_z_unchecked(target_z),
            icr_ref=curr._with_z_unchecked(zc + basis @ x_ref),
            rate_lower=rate_lo, rate_upper=rate_hi, route=route, stopped=stopped)

    def solve_qp(self, problem):
        """Solve ``problem`` with :attr:`solver`.

        Returns:
            ``(x, qp_status, solve_time_s)``; ``x`` is None on failure (``qp_status`` says why).
            On primal infeasibility ``x`` is the unconstrained optimum ``x_ref`` (the steer
            rates are clipped per wheel afterwards).
        """
        t0 = time.perf_counter()
        try:
            res = self.solver(problem)
        except Exception as exc:  # noqa: BLE001 — any solver exception means a safe stop
            return None, f'error: {type(exc).__name__}: {exc}', time.perf_counter() - t0
        elapsed = time.perf_counter() - t0
        status = str(getattr(res, 'status', 'unknown'))
        x = np.asarray(getattr(res, 'x', None), dtype=float) if getattr(res, 'x', None) is not None else None
        if status.startswith(_INFEASIBLE):
            return problem.x_ref.copy(), status, elapsed
        if status not in _USED or x is None or x.shape != (2,) or not np.all(np.isfinite(x)):
            return None, status if status not in _USED else f'{status} (non-finite x)', elapsed
        return x, status, elapsed

    # ------------------------------------------------------------------ step
    def step(self, twist_ref, beta_meas=None, beta_dot_meas=None):
        """One control period.

        Args:
            twist_ref: ξ̇* = (vx, vy, ω) in the base frame [m/s, m/s, rad/s]. Shape (3,).
            beta_meas: measured steer angles [rad] to resync the state, optional. Shape (N,).
            beta_dot_meas: measured steer rates [rad/s] to resync, optional. Shape (N,).

        Returns:
            :class:`SwmrOutput`.

        Raises:
            ShapeError, NonFiniteError: malformed inputs.
        """
        p = self.params
        n = self.geometry.n_wheels
        twist_ref = as_finite_vector(twist_ref, 3, 'twist_ref')
        if beta_meas is not None:
            self._beta = as_finite_vector(beta_meas, n, 'beta_meas').copy()
            self._icr = self._icr_of_beta(self._beta, like=self._icr.z)
        if beta_dot_meas is not None:
            self._beta_dot = as_finite_vector(beta_dot_meas, n, 'beta_dot_meas').copy()

        problem = self.build_qp(twist_ref)
        hold = problem.stopped and not np.any(self._beta_dot)
        if hold:
            x, qp_status, solve_time = np.zeros(2), 'not_solved', 0.0
        else:
            x, qp_status, solve_time = self.solve_qp(problem)
            if x is None:
                return self._safe_stop(problem, qp_status, solve_time)

        # Steer: ICR_next -> nearest twin -> hard clip into the period's rate interval.
        z_next = self._icr.z + problem.basis @ x
        z_next /= math.sqrt(float(z_next @ z_next))
        v = self._m @ z_next
        vn = np.linalg.norm(v, axis=1)
        delta = wrap_half_turn(np.arctan2(v[:, 1], v[:, 0]) - self._beta)
        delta[vn < 1e-9] = 0.0                      # ICR on a hip: any angle fits, keep it
        if hold:
            delta[:] = 0.0
        wanted = delta / p.dt
        rate = np.clip(wanted, problem.rate_lower, problem.rate_upper)
        beta_new = self._beta + p.dt * rate
        active = set(np.flatnonzero(np.abs(wanted - rate) > _RATE_TOL).tolist())
        if qp_status in _USED:
            slack = problem.A[:-2] @ x - problem.l[:-2]
            active.update((np.flatnonzero(slack <= _ROW_TOL) // 2).tolist())
        icr_next = self._icr_of_beta(beta_new, like=z_next)

        # Drive: K_p twist controller, projection on the motion compatible with icr_next, limits.
        goal = np.zeros(3) if problem.stopped else twist_ref
        acc = p.kp * (goal - self._twist)
        acc *= min(1.0, float(np.min(self._amax / np.maximum(np.abs(acc), 1e-300))))
        if problem.stopped and np.all(np.abs(self._twist) <= self._amax * p.dt):
            acc = -self._twist / p.dt        # the last step to rest, within the limits
        init = self._twist + p.dt * acc
        c = icr_next.twist_direction
        feasible = (c @ init) * c
        feasible *= self._velocity_scale(feasible, beta_new, rate)
        phi_dot = (self.geometry.rolling_rows(beta_new) @ feasible
                   + self.geometry.wheel_offset * rate) / self.geometry.wheel_radius

        executed = self._executed_twist(beta_new, rate, phi_dot, feasible)
        self._beta, self._beta_dot, self._twist, self._phi_dot = beta_new, rate, feasible, phi_dot
        self._icr = icr_next
        return SwmrOutput(
            beta_ref=beta_new.copy(), beta_dot_ref=rate.copy(), phi_dot_ref=phi_dot.copy(),
            twist_feasible=feasible.copy(), twist_executed=executed, icr_next=icr_next, icr_ref=problem.icr_ref,
            route=problem.route, active_constraints=sorted(int(i) for i in active),
            solve_time_s=solve_time, status='stopped' if problem.stopped else 'ok',
            qp_status=qp_status)

    def _executed_twist(self, beta_new, rate, phi_dot, feasible):
        """Twist over the coming period: the rolling model at the mid-period steer angles."""
        if not np.any(rate):
            return feasible.copy()
        return self.geometry.twist_from_wheels(beta_new - 0.5 * self.params.dt * rate, rate, phi_dot)

    def _velocity_scale(self, twist, beta, rate):
        """Largest s ∈ [0, 1] with |s ξ̇| within the base limits and |φ̇(s ξ̇)| ≤ drive_rate_limit."""
        p = self.params
        s = 1.0
        big = np.abs(twist) > 0
        if np.any(big):
            s = min(s, float(np.min(self._vmax[big] / np.abs(twist[big]))))
        a = self.geometry.rolling_rows(beta) @ twist / self.geometry.wheel_radius
        b = self.geometry.wheel_offset * rate / self.geometry.wheel_radius
        nz = np.abs(a) > 1e-300
        if np.any(nz):
            s = min(s, float(np.min((p.drive_rate_limit - np.sign(a[nz]) * b[nz]) / np.abs(a[nz]))))
        return max(0.0, s)

    def _safe_stop(self, problem, qp_status, solve_time):
        """Solver failure: steer rates braked to zero within β̈_max, drive ramped down within φ̈_max."""
        p = self.params
        rate = np.clip(0.0, problem.rate_lower, problem.rate_upper)
        beta_new = self._beta + p.dt * rate
        peak = float(np.max(np.abs(self._phi_dot)))
        k = max(0.0, 1.0 - p.drive_accel_limit * p.dt / peak) if peak > 0 else 0.0
        phi_dot = self._phi_dot * k
        twist = self._twist * k
        self._beta, self._beta_dot, self._twist, self._phi_dot = beta_new, rate, twist, phi_dot
        self._icr = self._icr_of_beta(beta_new, like=self._icr.z)
        return SwmrOutput(
            beta_ref=beta_new.copy(), beta_dot_ref=rate.copy(), phi_dot_ref=phi_dot.copy(),
            twist_feasible=twist.copy(), twist_executed=self._executed_twist(beta_new, rate, phi_dot, twist),
            icr_next=self._icr, icr_ref=problem.icr_ref, route='hold',
            active_constraints=[], solve_time_s=solve_time, status='solver_failure',
            qp_status=qp_status)

