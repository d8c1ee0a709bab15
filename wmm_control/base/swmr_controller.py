"""Steerable wheeled mobile robot (SWMR) base controller (Sorour 2019 §IV, Fig 4).

For any steerable base of N ≥ 2 steer + drive modules (:class:`SteerableGeometry`). Each
period ``dt`` the controller takes the reference base twist ξ̇* = (vx, vy, ω) [m/s, m/s,
rad/s] (base frame) and returns steer angles/rates β_ref, β̇_ref, drive rates φ̇_ref and the
feasible twist ξ̇_ref that those commands realise. A reference beyond ``base_velocity_limit``
is first scaled into it as a whole (its direction, hence its ICR, kept). :meth:`SwmrController.step`
is Fig 4 in three parts:

**Steering controller** (:meth:`~SwmrController.build_qp`, :meth:`~SwmrController._icr_next`,
:meth:`~SwmrController._steer`)

1. ICR* of ξ̇* and ICR_curr of the steer angles (:class:`~wmm_control.base.icr.Icr`,
   projective, pure translation included; :func:`~wmm_control.base.icr.icr_of_headings`);
   the shorter of the direct and the complementary route (through the border = pure
   translation) is chosen (:func:`~wmm_control.base.icr.choose_route`).
2. ICR P-controller ``ICṘ_ref = λ (ICR* − ICR_curr)``, integrated over one period:
   ``ICR_ref`` is ICR_curr moved a fraction ``λ dt`` of the way along the route.
3. QP ``min ‖ICR_next − ICR_ref‖²`` subject to, for each wheel, the wedge of two lines through
   its hip that bounds the steer change in one period by β̇_max and β̈_max
   (:func:`~wmm_control.base.icr.wedge_rows`, all wheels at once). A wheel's headings modulo π
   fill a *double* wedge (β and its twin β + π); a wheel whose hip lies within the period's
   ICR step uses the half that holds ICR_ref, so an ICR path through a hip flips that wheel
   to its twin instead of sweeping it round (if the wedges then have no common point, the QP
   is solved again on the halves of ICR_curr). While the
   route passes a hip, steps across it cost ``route_weight`` more than along it (the thin
   wedges would otherwise lead ICR_next round the hip). When ICR_ref already lies in every
   wedge it is the optimum and OSQP is not called.
4. β_ref of ICR_next, the twin (β or β + π, drive reversed) nearest the current angle
   (:meth:`~wmm_control.base.steerable_kinematics.SteerableGeometry.steer_angles_for_icr`);
   the steer rate is then clipped into the per-period interval (hard limits).

**Drive controller** (:meth:`~SwmrController._drive`)

5. ξ̈ = K_p (ξ̇* − ξ̇) within ``base_accel_limit``, integrated.

**Feasible twist**

6. Projected onto the motion compatible with the new steer configuration (rotation about its
   ICR, or translation at infinity); its size along that direction is the one nearest the
   projection that keeps the base velocity, drive rate and base acceleration limits
   (:meth:`~SwmrController._feasible_speed`) → ξ̇_ref; φ̇_ref from the inverse actuation model
   with wheel offset d
   (:meth:`~wmm_control.base.steerable_kinematics.SteerableGeometry.drive_rates`).

The QP lives in a gnomonic chart of the ICR sphere centred on ICR_curr (coordinates ``x ∈ R²``,
``z = z_curr + E x``, :func:`~wmm_control.base.icr.tangent_basis`). That chart is the paper's
Cartesian ICR plane seen from the current ICR: lines through the hips stay lines, so the
wedges stay linear, and pure translation is an ordinary point. (A fixed Cartesian box
``|X|, |Y| ≤ L`` cannot do this: with parallel wheels at rest the wedges are β̈_max dt² =
1.25e-3 rad wide and meet only ~0.19/1.25e-3 ≈ 150 m away, so the box QP has no solution
whenever the wheels are parallel at rest.) The bounded box representation is kept for
reporting (:attr:`Icr.point`, border ``L``).

When the wedges have no common point (steer rates that no single ICR motion continues), an
elastic copy of the QP (one common relaxation ``s ≥ 0`` of all wedges, heavily penalised) gives
the ICR that breaks them least; the per-wheel clip of step 4 then keeps every limit. A solver
error or a non-finite answer instead brakes the steering to rest within β̈_max and ramps the
drive to zero within ``drive_accel_limit`` (status ``'solver_failure'``).

Measured steer angles (:meth:`~SwmrController.step` ``beta_meas``) restart each period: at the
headings of their best-fit ICR, plus the part of each wheel's disagreement with it beyond
``measurement_deadband`` (:meth:`~SwmrController._resync`).

Every per-wheel quantity is a numpy array over the N modules; the state (β, β̇, ξ̇, φ̇) too.
"""

import math
import signal
import time
from dataclasses import dataclass, field, fields
from typing import Any, NamedTuple, Self

import numpy as np
import osqp
from osqp import SolverStatus
from scipy import sparse

from wmm_control.base.icr import (
    DEFAULT_ICR_BORDER,
    DEFAULT_ICR_SCALE,
    Icr,
    choose_route,
    icr_of_headings,
    tangent_basis,
    wedge_rows,
)
from wmm_control.base.steerable_kinematics import SteerableGeometry
from wmm_control.checks import as_finite_vector
from wmm_control.geometry import scale_into_limits, wrap_angle
from wmm_control.errors import ConfigError, ShapeError
from wmm_control.robot_config import RobotConfig, SteerableBase

__all__ = ['SwmrParams', 'SwmrOutput', 'IcrQp', 'QpResult', 'OsqpIcrSolver', 'SwmrController']

_INF = 1e30  # OSQP's infinity
_ROW_TOL = 1e-6  # a normalised wedge row within this of its bound counts as active
_RATE_TOL = 1e-9  # [rad/s] a steer rate clipped by more than this counts as active
_ANGLE_TOL = 1e-12  # [rad] a steer change below this is round-off
_FEAS_TOL = 1e-9  # a normalised row violated by at most this counts as satisfied
_HIP_TOL = 1e-9  # a hip velocity below this: the ICR sits on the hip
ELASTIC_WEIGHT = 1e4
_BOX_ROWS = np.eye(2)
_EYE2 = np.eye(2)
_EYE2.flags.writeable = False
_ZERO2 = np.zeros(2)
_ZERO2.flags.writeable = False
_ZERO3 = np.zeros(3)
_ZERO3.flags.writeable = False


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
                f'SwmrParams: steer_rate_limit*dt = {self.steer_rate_limit * self.dt} rad per period must be < pi/4'
            )
        if self.max_icr_step >= np.pi / 2:
            raise ConfigError(f'SwmrParams.max_icr_step must be < pi/2, got {self.max_icr_step}')

    @property
    def lag(self) -> float:
        """τ [s], the lag with which the base's twist follows its reference: the ICR P-controller
        (gain λ) moves the ICR towards the reference's, and the twist controller (gain K_p) follows
        along the direction the wheels allow: two first-order lags in series, which delay a step
        by the sum of their time constants, τ = 1/K_p + 1/λ (0.75 s with Table I's K_p = 2 and
        λ = 4)."""
        return 1.0 / self.kp + 1.0 / self.icr_gain

    @classmethod
    def from_robot_config(cls, robot: RobotConfig, **overrides: Any) -> Self:
        """Limits from a :class:`RobotConfig` of a steerable robot; other fields from ``overrides``.

        Raises:
            ConfigError: the robot's base is not a steerable one.
        """
        s = robot.base
        if not isinstance(s, SteerableBase):
            raise ConfigError(f'robot {robot.name!r} has a {s.family} base, not a steerable one')
        values: dict[str, Any] = dict(
            steer_rate_limit=s.steer_rate_limit,
            steer_accel_limit=s.steer_accel_limit,
            drive_rate_limit=s.drive_rate_limit,
            drive_accel_limit=s.drive_accel_limit,
            base_velocity_limit=tuple(np.asarray(s.velocity, dtype=float)),
            base_accel_limit=tuple(np.asarray(s.acceleration, dtype=float)),
        )
        values.update(overrides)
        return cls(**values)


@dataclass(slots=True)
class IcrQp:
    """One cycle's ICR QP, ``min ½ (x − x_ref)ᵀ P (x − x_ref)  s.t.  l ≤ A x ≤ u``, plus its context.

    ``P = I + w n nᵀ`` (n ⟂ x_ref): the paper's distance to ICR_ref, with steps across the route
    ICR_curr → ICR* costing 1 + w (``route_weight``) times more than along it, so that
    ICR_next follows the route instead of sliding round the wedges' corners.

    ``x`` are gnomonic chart coordinates around ICR_curr: the ICR is ``z_curr + E x``.
    Rows of ``A``: ``i`` and ``N + i`` are the two wedge lines of wheel i, for its lowest and
    its highest heading of the period (:attr:`rows`, normalised, lower bound only), the last
    two the chart box ``|x_k| ≤ box``.

    Attributes:
        x_ref: chart coordinates of ICR_ref (the unconstrained optimum). Shape (2,).
        rows: the 2N wedge rows (:func:`~wmm_control.base.icr.wedge_rows`). Shape (2N, 2).
        lower: their lower bounds (−inf for a degenerate row). Shape (2N,).
        box: half side of the chart box.
        basis: the tangent basis E = [e1 e2] at ICR_curr. Shape (3, 2).
        icr_curr: ICR of the current steer angles.
        target_z: ICR* on the chosen route (unit representative on the current hemisphere).
            Shape (3,).
        rate_lower, rate_upper: per-wheel steer-rate interval for this period [rad/s]. Shape (N,).
        sides: per wheel, +1 or −1: which half of its double wedge (heading or twin) is used.
            Shape (N,).
        mirrored: a wheel whose hip lies within the ICR step may use its mirror wedge.
        route_weight: w of the cost (:attr:`P`).
        route: 'direct', 'complementary' or 'hold'.
        stopped: the reference is below the stop threshold.
    """

    x_ref: np.ndarray
    rows: np.ndarray
    lower: np.ndarray
    box: float
    basis: np.ndarray
    icr_curr: Icr
    target_z: np.ndarray
    rate_lower: np.ndarray
    rate_upper: np.ndarray
    sides: np.ndarray
    route: str
    stopped: bool
    mirrored: bool = False
    route_weight: float = 0.0

    @property
    def A(self) -> np.ndarray:
        """Constraint matrix: the wedge rows, then the box rows. Shape (2N + 2, 2)."""
        return np.concatenate((self.rows, _BOX_ROWS))

    @property
    def l(self) -> np.ndarray:  # noqa: E743 — OSQP's name for the lower bounds
        """Lower bounds (a degenerate row's −inf as OSQP's infinity). Shape (2N + 2,)."""
        lower = np.concatenate((self.lower, (-self.box, -self.box)))
        return np.maximum(lower, -_INF, out=lower)

    @property
    def u(self) -> np.ndarray:
        """Upper bounds (only the box has finite ones). Shape (2N + 2,)."""
        upper = np.full(self.lower.shape[0] + 2, _INF)
        upper[-2:] = self.box
        return upper

    @property
    def P(self) -> np.ndarray:
        """Cost Hessian ``I + w n nᵀ``, n the unit normal of x_ref: a step across the route costs 1 + w."""
        m = self.metric
        return m @ m

    @property
    def metric(self) -> np.ndarray:
        """Symmetric S with ``S S = P``: in ``y = S x`` the cost is ``½‖y − S x_ref‖²``.

        ``S = I + (√(1 + w) − 1) n nᵀ``. Shape (2, 2).
        """
        return self._metric(math.sqrt(1.0 + self.route_weight))

    @property
    def metric_inverse(self) -> np.ndarray:
        """S⁻¹ = I + (1/√(1 + w) − 1) n nᵀ. Shape (2, 2)."""
        return self._metric(1.0 / math.sqrt(1.0 + self.route_weight))

    def _metric(self, stretch: float) -> np.ndarray:
        return self._metrics(stretch)[0]

    def _metrics(self, stretch: float) -> tuple[np.ndarray, np.ndarray]:
        """``I + (k − 1) n nᵀ`` for k = ``stretch`` and for k = 1/``stretch`` (n ⟂ x_ref)."""
        x0, x1 = self.x_ref.tolist()
        nn = math.hypot(x0, x1)
        if nn == 0.0 or self.route_weight == 0.0:
            return np.eye(2), np.eye(2)
        n0, n1 = -x1 / nn, x0 / nn
        outer = np.array(((n0 * n0, n0 * n1), (n1 * n0, n1 * n1)))
        return _EYE2 + (stretch - 1.0) * outer, _EYE2 + (1.0 / stretch - 1.0) * outer

    def x_ref_feasible(self) -> bool:
        """True when ICR_ref lies in every wedge and in the box: it is then the optimum."""
        x = self.x_ref
        if abs(x[0]) > self.box + _FEAS_TOL or abs(x[1]) > self.box + _FEAS_TOL:
            return False
        return bool((self.rows @ x - self.lower).min() >= -_FEAS_TOL)

    def z_at(self, x) -> np.ndarray:
        """Unit homogeneous ICR at chart coordinates ``x`` (Shape (2,)). Shape (3,)."""
        z = self.icr_curr.z + self.basis @ x
        return z / math.sqrt(z @ z)

    def icr_of(self, x) -> Icr:
        """The ICR at chart coordinates ``x`` (Shape (2,))."""
        return self.icr_curr._with_z_unchecked(self.icr_curr.z + self.basis @ np.asarray(x, dtype=float))

    @property
    def icr_ref(self) -> Icr:
        """ICR_ref, this period's P-controller reference."""
        return self.icr_of(self.x_ref)

    @property
    def icr_target(self) -> Icr:
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
_OSQP_ELASTIC = (
    SolverStatus.OSQP_PRIMAL_INFEASIBLE,
    SolverStatus.OSQP_PRIMAL_INFEASIBLE_INACCURATE,
    SolverStatus.OSQP_MAX_ITER_REACHED,
)


_STATUS = {status.value: status for status in SolverStatus}
_STATUS_NAME = {status: status.name.removeprefix('OSQP_').lower() for status in SolverStatus}
"""'solved', 'primal_infeasible', … for each osqp :class:`osqp.SolverStatus`."""


class OsqpIcrSolver:
    """OSQP (its public ``setup``/``update``/``solve``) set up once for the ICR QP: fixed dense
    pattern, values updated each call, warm start, polish off.

    Holds a second OSQP instance, also set up once, for the elastic problem (every wedge row
    relaxed by one common ``s ≥ 0``, penalised by ``½ ELASTIC_WEIGHT s²``), solved only when
    the first reports primal infeasibility or stops at its iteration limit; its result is
    returned with status ``'elastic'``. A ``max_iter_reached`` answer is never returned as a
    solution.

    Args:
        n_rows: number of constraint rows (2N + 2).
        eps: absolute and relative tolerance.
        max_iter: iteration limit.

    Attributes:
        last_iterations: OSQP iterations of the last solve (the elastic one if it ran).
    """

    def __init__(self, n_rows: int, eps: float = 1e-6, max_iter: int = 4000):
        self.n_rows = m = int(n_rows)
        self.last_iterations = 0
        settings = dict(
            verbose=False, polishing=False, warm_starting=True, eps_abs=eps, eps_rel=eps, max_iter=int(max_iter)
        )
        self._osqp = self._setup(np.eye(2), m, settings)
        #: each instance's upper bounds as last sent (:meth:`_run` sends them only when they change)
        self._upper: dict[osqp.OSQP, bytes] = {}
        # The elastic rows are normalised already; OSQP's Ruiz scaling, fighting the heavy weight
        # on s, would multiply its iteration count by ~15 (median ~2000, often max_iter).
        self._elastic = self._setup(np.diag([1.0, 1.0, ELASTIC_WEIGHT]), m + 1, dict(settings, scaling=0))
        self._elastic_a = np.zeros((m + 1, 3))
        self._elastic_a[: m - 2, 2] = 1.0  # every wedge row relaxed by s (the box rows are not)
        self._elastic_a[m, 2] = 1.0  # s ≥ 0

    @staticmethod
    def _setup(p_dense: np.ndarray, m: int, settings: dict) -> osqp.OSQP:
        # P is constant (set here, never updated). A: dense pattern, every entry stored
        # (placeholder values are non-zero so none is dropped); its values change each cycle.
        n = p_dense.shape[0]
        p = sparse.triu(sparse.csc_matrix(p_dense), format='csc')
        a = sparse.csc_matrix((np.ones(n * m), np.tile(np.arange(m), n), np.arange(0, n * m + 1, m)), shape=(m, n))
        solver = osqp.OSQP()
        solver.setup(p, np.zeros(n), a, -np.full(m, _INF), np.full(m, _INF), **settings)
        return solver

    def _run(
        self, solver: osqp.OSQP, q: np.ndarray, a: np.ndarray, lb: np.ndarray, ub: np.ndarray
    ) -> tuple[np.ndarray, SolverStatus]:
        """Update ``solver``'s q, A's values (``a`` dense, stored column-major), l, u and solve.

        u (the box's bounds, the others OSQP's infinity) changes only with the box: it is sent
        only when it differs from what this instance holds."""
        upper = ub.tobytes()
        if self._upper.get(solver) == upper:
            solver.update(q=q, l=lb, Ax=a.ravel(order='F'))
        else:
            solver.update(q=q, l=lb, u=ub, Ax=a.ravel(order='F'))
            self._upper[solver] = upper
        res = solver.solve(raise_error=False)  # the status is handled here
        self.last_iterations = int(res.info.iter)
        status = _STATUS[res.info.status_val]
        if status is SolverStatus.OSQP_SIGINT:
            # OSQP listens for Ctrl-C while it solves and keeps it: the process's own handler
            # (a node's shutdown) never heard it, and a node stopped with SIGINT ran on until it
            # was killed. The period's answer is the failed solve's (a safe stop); the signal
            # goes back to the process.
            signal.raise_signal(signal.SIGINT)
        return np.array(res.x, dtype=float), status

    def __call__(self, problem: IcrQp) -> QpResult:
        """Solve ``problem`` (its :attr:`~IcrQp.A`, :attr:`~IcrQp.l`, :attr:`~IcrQp.u` and
        :attr:`~IcrQp.metric`); returns a :class:`QpResult`.

        OSQP sees the problem in the coordinates ``y = S x`` of :attr:`IcrQp.metric`, where
        its cost is the identity (constant, set up once) and the rows are normalised again: the
        route weight then costs OSQP no conditioning. (With P = I + w n nᵀ itself, condition
        number 1 + w, answers reported 'solved' broke the thin wedges by up to 1e-4.)

        Raises:
            ShapeError: the problem does not have the set-up number of rows.
        """
        a, lb, ub = problem.A, problem.l, problem.u
        if lb.shape != (self.n_rows,):
            raise ShapeError(f'ICR QP: A has shape {a.shape}, solver set up for ({self.n_rows}, 2)')
        y_ref = problem.x_ref
        s_inv = None
        if problem.route_weight > 0.0 and y_ref.any():
            metric, s_inv = problem._metrics(math.sqrt(1.0 + problem.route_weight))
            a = a @ s_inv
            norms = np.sqrt((a * a).sum(axis=1))
            a /= norms[:, None]
            lb, ub = np.maximum(lb / norms, -_INF), np.minimum(ub / norms, _INF)
            y_ref = metric @ y_ref
        y, status = self._run(self._osqp, -y_ref, a, lb, ub)
        if status in _OSQP_ACCEPTED or status not in _OSQP_ELASTIC:
            return QpResult(y if s_inv is None else s_inv @ y, _STATUS_NAME[status])
        ae = self._elastic_a.copy()
        ae[:-1, :2] = a
        ye, estatus = self._run(self._elastic, np.append(-y_ref, 0.0), ae, np.append(lb, 0.0), np.append(ub, _INF))
        if estatus in _OSQP_ACCEPTED:
            return QpResult(ye[:2] if s_inv is None else s_inv @ ye[:2], 'elastic')
        return QpResult(problem.x_ref.copy(), _STATUS_NAME[status])


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

    x: np.ndarray | None  # ICR_next in chart coordinates, Shape (2,); None when the solver failed
    status: str  # the qp_status of :class:`SwmrOutput`
    solve_time: float  # [s]


class _Steering(NamedTuple):
    """The steering controller's result for one period."""

    beta: np.ndarray  # β_ref [rad], Shape (N,)
    rate: np.ndarray  # β̇_ref [rad/s], Shape (N,)
    icr_next: Icr  # ICR of β_ref
    active: set  # wheels whose rate limit or wedge binds
    qp_status: str
    solve_time: float  # [s]


class SwmrController:
    """The §IV steering + drive controller for an N-module steerable base (N ≥ 2).

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

    def __init__(self, geometry: SteerableGeometry, params: 'SwmrParams', solver=None):
        self.geometry = geometry
        self.params = p = params
        n = geometry.n_wheels
        steer_term = geometry.wheel_offset * p.steer_rate_limit / geometry.wheel_radius
        if steer_term >= p.drive_rate_limit:
            raise ConfigError(
                f'd*steer_rate_limit/r_w = {steer_term} rad/s leaves no drive rate below '
                f'drive_rate_limit = {p.drive_rate_limit}'
            )
        self.n_rows = 2 * n + 2
        self.solver = solver if solver is not None else OsqpIcrSolver(self.n_rows, p.eps, p.max_iter)
        self._icr_proto = Icr(np.array([0.0, 0.0, 1.0]), p.icr_scale, p.icr_border)
        # the twist direction ∝ (z₁, −z₀, z₂/ℓ): its angle changes up to max(ℓ, 1/ℓ) × the ICR's
        self._turn_factor = max(p.icr_scale, 1.0 / p.icr_scale) * math.sqrt(2.0)
        self._turn_budget = min(p.base_accel_limit) * p.dt
        self._velocity_limit = np.array(p.base_velocity_limit)
        self._accel_limit = np.array(p.base_accel_limit)
        self._accel_step = self._accel_limit * p.dt  # |Δξ̇| per period
        # per hip: its velocity map z ↦ v (also per wedge row: wheel i's at rows i, N + i) and
        # its unit homogeneous point (the route test)
        self._hip_map = geometry.hip_velocity_map(p.icr_scale)
        self._row_maps = np.concatenate((self._hip_map, self._hip_map))
        self._hip_rows = np.concatenate((self._hip_map[:, 0], self._hip_map[:, 1]))  # (2N, 3): vx rows, vy rows
        points = np.column_stack((geometry.hips, np.full(n, p.icr_scale)))
        points /= np.linalg.norm(points, axis=1)[:, None]
        self._hip_points = np.column_stack((points, np.ones(n)))  # (N, 4): the unit point, then 1
        self._last_icr: tuple[bytes, np.ndarray] = (b'', _ZERO3)  # steer angles and their ICR
        self.reset(np.zeros(n))

    # ------------------------------------------------------------------ state
    def reset(self, beta, beta_dot=None, twist=None) -> None:
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
        self._icr = self._icr_of(self._beta)

    def restart(self, beta, beta_dot, phi_dot) -> None:
        """Go on from the measured state (the last command was not applied as sent): the steer
        angles, the steer rates within the steer rate limit (an encoder glitch beyond it is not
        followed) and the twist that best fits those and the drive rates.

        Args:
            beta, beta_dot, phi_dot: measured steer angles [rad], steer rates and drive rates
                [rad/s]. Shape (N,) each.
        """
        n = self.geometry.n_wheels
        limit = self.params.steer_rate_limit
        beta = as_finite_vector(beta, n, 'beta')
        beta_dot = np.clip(as_finite_vector(beta_dot, n, 'beta_dot'), -limit, limit)
        self.reset(beta, beta_dot, self.geometry.twist_from_wheels(beta, beta_dot, phi_dot))

    @property
    def beta(self) -> np.ndarray:
        """Commanded steer angles [rad]. Shape (N,)."""
        return self._beta.copy()

    @property
    def beta_dot(self) -> np.ndarray:
        """Commanded steer rates [rad/s]. Shape (N,)."""
        return self._beta_dot.copy()

    @property
    def twist(self) -> np.ndarray:
        """Last feasible twist (vx, vy, ω) [m/s, m/s, rad/s]. Shape (3,)."""
        return self._twist.copy()

    @property
    def phi_dot(self) -> np.ndarray:
        """Last drive rates [rad/s]. Shape (N,)."""
        return self._phi_dot.copy()

    @property
    def icr(self) -> Icr:
        """ICR of the commanded steer angles."""
        return self._icr

    def _icr_of(self, beta: np.ndarray, like=None) -> Icr:
        """ICR of steer angles β (Shape (N,)): :func:`icr_of_headings`, on the hemisphere of ``like``.

        The last angles' ICR is kept: steering held at rest asks again for the same angles."""
        key = beta.tobytes()
        if key != self._last_icr[0]:
            self._last_icr = (key, icr_of_headings(self.geometry.slip_rows(beta), self.params.icr_scale))
        z = self._last_icr[1]
        if like is not None and z @ like < 0.0:
            z = -z
        return self._icr_proto._with_z_unchecked(z)

    def _rate_interval(self) -> tuple[np.ndarray, np.ndarray]:
        """Per-period steer-rate interval [rad/s]: |β̇| ≤ β̇_max and |β̇ − β̇_prev| ≤ β̈_max dt.

        Returns:
            ``(lower, upper)``. Shape (N,) each.
        """
        p = self.params
        dv = p.steer_accel_limit * p.dt
        vmax = p.steer_rate_limit
        rate = self._beta_dot
        lower, upper = np.maximum(rate - dv, -vmax), np.minimum(rate + dv, vmax)
        beyond = lower > upper
        if beyond.any():  # a resynced (measured) rate beyond β̇_max + β̈_max dt: brake as hard as β̈_max allows
            brake = rate - np.copysign(dv, rate)
            lower, upper = np.where(beyond, brake, lower), np.where(beyond, brake, upper)
        return lower, upper

    def _resync(self, beta_meas, beta_dot_meas, stopped: bool) -> None:
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
            self._beta_dot = np.clip(as_finite_vector(beta_dot_meas, n, 'beta_dot_meas'), -limit, limit)
        if beta_meas is None:
            return
        meas = as_finite_vector(beta_meas, n, 'beta_meas')
        band = p.measurement_deadband
        if stopped and not self._beta_dot.any():
            # held at rest: within the band of the held angle a measurement is noise, beyond
            # it the wheel was moved and the measurement is taken as it is
            held = np.where(np.abs(meas - self._beta) <= band, self._beta, meas)
            if not np.array_equal(held, self._beta):
                self._beta = held
                self._icr = self._icr_of(held, like=self._icr.z)
        elif not np.array_equal(meas, self._beta):
            z_cmd = self._icr.z
            z_meas = icr_of_headings(self.geometry.slip_rows(meas), p.icr_scale, z_cmd)
            v = self._hip_rows @ np.array((z_meas, z_cmd)).T  # (2N, 2): hip velocities, vx then vy
            heading = np.arctan2(v[n:], v[:n])
            on_hip = np.hypot(v[n:], v[:n]).min(axis=1) < _HIP_TOL  # any angle fits
            own = wrap_angle(self._beta - heading[:, 1], math.pi)  # the command's disagreement
            extra = wrap_angle(meas - heading[:, 0] - own, math.pi)
            start = meas - extra + np.copysign(np.maximum(np.abs(extra) - band, 0.0), extra)
            self._beta = np.where(on_hip, meas, start)
            self._icr = self._icr_of(self._beta, like=z_cmd)

    # ------------------------------------------------------------------ the steering controller
    def build_qp(self, twist_ref) -> IcrQp:
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

    def _weigh_route(self, problem: IcrQp) -> None:
        """Set the problem's route weight: ``route_weight`` while its route passes a hip, else 0."""
        passes = self._route_passes_a_hip(problem.icr_curr.z, problem.target_z)
        problem.route_weight = self.params.route_weight if passes else 0.0

    def _icr_qp(self, ref: np.ndarray, mirror: bool = True) -> IcrQp:
        """Steps 1–3 up to the QP: ICR* and its route, ICR_ref, and the wedges (:class:`IcrQp`).

        ``mirror``: a wheel whose hip lies within the ICR step may use its mirror wedge
        (:meth:`_wedge_sides`); False keeps every wheel on the wedge of ICR_curr.
        """
        p = self.params
        zc = self._icr.z
        basis = tangent_basis(zc)
        stopped = self._stopped(ref)
        step = self._icr_step()
        x_ref = _ZERO2
        if stopped:
            zt, route = zc, 'hold'
        else:
            vx, vy, wz = ref.tolist()
            zt, route = choose_route(zc, (-vy, vx, p.icr_scale * wz))
            # ICR_ref: a fraction λ dt of the arc ICR_curr → ICR*, along the great circle.
            d0, d1 = (zt @ basis).tolist()  # the arc's direction in the chart
            dn = math.hypot(d0, d1)
            if dn > 1e-12:
                theta = math.atan2(dn, float(zc @ zt))
                k = math.tan(min(p.icr_gain * p.dt * theta, step)) / dn
                x_ref = np.array((k * d0, k * d1))
        lower, upper = self._rate_interval()
        sides = self._wedge_sides(zc, zc + basis @ x_ref, zt, mirror)
        dt = p.dt
        # wheel i's rows i, N + i: its extreme headings this period, on the sides +σ_i and −σ_i
        headings = np.concatenate((self._beta + dt * lower, self._beta + dt * upper))
        rows, bounds = wedge_rows(headings, np.concatenate((sides, -sides)), self._row_maps, zc, basis)
        return IcrQp(
            x_ref=x_ref,
            rows=rows,
            lower=bounds,
            mirrored=mirror,
            box=math.tan(step),
            basis=basis,
            icr_curr=self._icr,
            target_z=zt,
            rate_lower=lower,
            rate_upper=upper,
            sides=sides,
            route=route,
            stopped=stopped,
        )

    def _route_passes_a_hip(self, zc: np.ndarray, zt: np.ndarray) -> bool:
        """True when the great-circle route ICR_curr → ICR* passes within ``route_hip_distance`` of a hip.

        Only then does the route weight apply: off the route near a hip, a wheel sweeps round.
        """
        c0, c1, c2 = zc.tolist()
        t0, t1, t2 = zt.tolist()
        normal = (c1 * t2 - c2 * t1, c2 * t0 - c0 * t2, c0 * t1 - c1 * t0)  # zc × zt
        sin_theta = math.hypot(*normal)
        if sin_theta < 1e-12:
            return False
        cos_theta = c0 * t0 + c1 * t1 + c2 * t2
        # per hip h (unit, homogeneous), all ≥ 0: its distance from the route's great circle
        # within the band on either side, h·(zc − zt cos θ) and h·(zt − zc cos θ) (its foot on
        # the circle is a zc + b zt with a, b ≥ 0)
        band = self.params.route_hip_distance * sin_theta
        tests = np.array(
            (
                (-normal[0], -normal[1], -normal[2], band),
                (normal[0], normal[1], normal[2], band),
                (c0 - t0 * cos_theta, c1 - t1 * cos_theta, c2 - t2 * cos_theta, 0.0),
                (t0 - c0 * cos_theta, t1 - c1 * cos_theta, t2 - c2 * cos_theta, 0.0),
            )
        )
        return bool((self._hip_points @ tests.T >= 0.0).all(axis=1).any())

    def _stopped(self, ref: np.ndarray) -> bool:
        """True when the reference (vx, vy, ω) is below ``stop_threshold``: stop, hold the angles."""
        return math.sqrt(ref @ ref) < self.params.stop_threshold

    def _icr_step(self) -> float:
        """Largest ICR move of this period on the ICR sphere [rad]: ``max_icr_step``, or less at speed.

        Rotating the twist ξ̇ by θ changes it by |ξ̇| sin θ; with θ at most √2 × the chart box
        (its corner) times the distortion max(ℓ, 1/ℓ) of the map ICR → twist direction, the
        bound ``|ξ̇| sin θ ≤ min(base_accel_limit) dt`` leaves the feasible twist a size within
        the acceleration limit (:meth:`_feasible_speed`).
        """
        speed = math.sqrt(self._twist @ self._twist)
        if speed <= self._turn_budget:
            return self.params.max_icr_step
        return min(self.params.max_icr_step, math.asin(self._turn_budget / speed) / self._turn_factor)

    def _wedge_sides(self, zc: np.ndarray, zr: np.ndarray, zt: np.ndarray, mirror: bool) -> np.ndarray:
        """Per wheel +1 if its heading β points along its hip velocity, −1 if against it (twin).

        The hip velocity is taken at ICR_curr; but when the hip lies within this period's ICR
        step (|v(ICR_curr)| ≤ |v(ICR_ref) − v(ICR_curr)|, v linear in z) and ``mirror``, at
        ICR_ref: the ICR path passes by the hip, and if it crosses it the half of the wheel's
        double wedge that holds ICR_ref is the mirror one, so the wheel flips to its twin
        (drive reversed) instead of steering half a turn. With ICR_curr on the hip, ICR_ref
        decides, then ICR*.

        Returns:
            Shape (N,).
        """
        n = self.geometry.n_wheels
        # hip velocities (vx rows, then vy rows) at ICR_curr, ICR_ref, ICR* and 2 ICR_curr − ICR_ref
        v = self._hip_rows @ np.array((zc, zr, zt, zc + zc - zr)).T  # (2N, 4)
        along = np.cos(self._beta)[:, None] * v[:n] + np.sin(self._beta)[:, None] * v[n:]  # (N, 4)
        decided = np.abs(along) > _HIP_TOL
        sides = np.where(along[:, 0] > 0.0, 1.0, -1.0)
        if not decided[:, 0].all():  # ICR_curr on a hip: ICR_ref decides, then ICR*, else +1
            sign = np.where(along > 0.0, 1.0, -1.0)
            sides = np.where(
                decided[:, 0], sides, np.where(decided[:, 1], sign[:, 1], np.where(decided[:, 2], sign[:, 2], 1.0))
            )
        if mirror:
            # per hip |v_c|² − |v_r − v_c|² = (2 v_c − v_r) · v_r
            closer = (v[:, 3] * v[:, 1]).reshape(2, n).sum(axis=0)
            near = (closer <= 0.0) & decided[:, 1]
            if near.any():
                sides = np.where(near, np.where(along[:, 1] > 0.0, 1.0, -1.0), sides)
        return sides

    def _solve(self, problem: IcrQp) -> _QpAnswer:
        """Step 3: ICR_next in chart coordinates, as a :class:`_QpAnswer`.

        Its ``x`` is None when the solver failed (``status`` says why); ICR_ref when no usable
        answer exists (per-wheel clipping follows). OSQP is called only when ICR_ref leaves a
        wedge, and ``'not_solved'`` means the steering is held at rest.
        """
        if problem.stopped and not self._beta_dot.any():
            return _QpAnswer(np.zeros(2), 'not_solved', 0.0)
        if problem.x_ref_feasible():
            return _QpAnswer(problem.x_ref, 'unconstrained', 0.0)
        self._weigh_route(problem)
        t0 = time.perf_counter()
        try:
            res = self.solver(problem)
            x, qp_status = np.asarray(res.x, dtype=float), str(res.status)
        except Exception as exc:  # noqa: BLE001 — any solver exception means a safe stop
            return _QpAnswer(None, f'error: {type(exc).__name__}: {exc}', time.perf_counter() - t0)
        solve_time = time.perf_counter() - t0
        if qp_status.startswith(_CLIPPED):
            return _QpAnswer(problem.x_ref, qp_status, solve_time)
        if qp_status not in _USED:
            return _QpAnswer(None, qp_status, solve_time)
        if x.shape != (2,) or not np.isfinite(x).all():
            return _QpAnswer(None, f'{qp_status} (non-finite x)', solve_time)
        return _QpAnswer(x, qp_status, solve_time)

    def _icr_next(self, ref: np.ndarray) -> tuple[IcrQp, _QpAnswer]:
        """Steps 1–3: this period's QP and ICR_next in its chart coordinates.

        The wedges are first chosen per wheel (:meth:`_wedge_sides`); when some wheel took its
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
            if not np.array_equal(plain.sides, problem.sides):
                again = self._solve(plain)
                solve_time = answer.solve_time + again.solve_time
                if again.x is not None and again.status in _SOLVED:
                    return plain, again._replace(solve_time=solve_time)
                answer = answer._replace(solve_time=solve_time)
        return problem, answer

    def _steer(self, problem: IcrQp, answer: _QpAnswer) -> _Steering:
        """Step 4: β_ref of ICR_next (the nearest twin), β̇_ref clipped into the period's limits.

        Returns:
            :class:`_Steering`.
        """
        dt = self.params.dt
        qp_status = answer.status
        hold = qp_status == 'not_solved'
        icr = problem.icr_of(answer.x)
        beta = self._beta
        if hold:
            wanted = np.zeros_like(beta)
        else:
            # on a hip any angle fits: the wheel keeps it
            delta = self.geometry.steer_angles_for_icr(icr, near=beta) - beta
            # A change at the round-off of the ICR ↔ β round trip is none: at rest the wheels stay put.
            wanted = np.where(np.abs(delta) > _ANGLE_TOL, delta, 0.0) / dt
        rate = np.minimum(np.maximum(wanted, problem.rate_lower), problem.rate_upper)
        cut = np.abs(wanted - rate)
        clipped = bool(cut.any())
        active = set(np.flatnonzero(cut > _RATE_TOL).tolist()) if clipped else set()
        if qp_status in _USED:
            binding = problem.rows @ answer.x - problem.lower <= _ROW_TOL
            active.update((np.flatnonzero(binding) % self.geometry.n_wheels).tolist())
        beta_new = beta + dt * rate
        if clipped or hold:  # the wheels' own ICR (they may disagree)
            icr = self._icr_of(beta_new, like=icr.z)
        return _Steering(beta_new, rate, icr, active, qp_status, answer.solve_time)

    # ------------------------------------------------------------------ the drive controller
    def _drive(self, ref: np.ndarray, stopped: bool, brake: bool) -> np.ndarray:
        """Step 5: the twist controller's next twist ξ̇_ref(init), acceleration-limited. Shape (3,)."""
        p = self.params
        dt, twist = p.dt, self._twist
        if stopped and (np.abs(twist) <= self._accel_step).all():
            return np.zeros(3)  # the last step to rest, within the limits
        if brake:  # full braking along the twist, scaled to the limits
            acc = -twist
            k_max = 1.0 / dt
        else:
            acc = p.kp * ((0.0 if stopped else ref) - twist)
            k_max = 1.0
        k = min(k_max, float((self._accel_limit / np.maximum(np.abs(acc), 1e-300)).min()))
        return twist + (dt * k) * acc

    # ------------------------------------------------------------------ the feasible twist
    def _feasible_twist(self, init: np.ndarray, steer: _Steering) -> tuple[np.ndarray, np.ndarray]:
        """Step 6: ξ̇_ref(init) projected onto the motion of ICR_next, within every limit.

        Returns:
            ``(twist, phi_dot)``, Shapes (3,), (N,).
        """
        g = self.geometry
        direction = steer.icr_next.twist_direction  # ∝ (Y, −X, 1)
        rows = g.rolling_rows(steer.beta)
        # the drive rates are affine in the size s of the twist s · direction: φ̇ = s a + b
        steering = g.drive_rates(rows, steer.rate, _ZERO3)
        per_speed = g.drive_rates(rows, steer.rate, direction) - steering
        speed = self._feasible_speed(direction.tolist(), float(direction @ init), per_speed, steering)
        return speed * direction, speed * per_speed + steering

    def _feasible_speed(self, direction: list, wanted: float, per_speed: np.ndarray, steering: np.ndarray) -> float:
        """The size s of the twist ``s · direction`` nearest ``wanted`` within the limits.

        Hard: |s c_k| ≤ base_velocity_limit_k and |s a_i + b_i| ≤ drive_rate_limit, the drive
        rates φ̇_i = s a_i + b_i (``per_speed`` a, ``steering`` b = d β̇_i / r_w): an interval of
        s around 0, since |b_i| < drive_rate_limit. Then, within it, the change from the last
        twist: |s c_k − ξ̇_k| ≤ base_accel_limit_k dt, another interval. When the two do not
        meet (the ICR turned the direction faster than the acceleration limit allows at this
        speed), s is the one of the first interval that exceeds the acceleration limit least
        (minimax of the ratios).

        Args:
            direction: the unit twist direction c, 3 floats.
            wanted: the size of the projection.
            per_speed, steering: a and b. Shape (N,) each.
        """
        p = self.params
        # φ̇_i is computed as s a_i + b_i afterwards: a bound 1e-12 inside keeps its round-off
        # below the limit (a simulator comparing exactly would clamp a command at the limit).
        drive_limit = p.drive_rate_limit * (1.0 - 1e-12)
        # |s a_i + b_i| ≤ L ⟺ −(L + b_i sgn a_i) ≤ s |a_i| ≤ L − b_i sgn a_i, both bounds > 0:
        # s ≤ 1/up and s ≥ −1/down, with up, down the largest |a_i| / bound
        size, toward = np.abs(per_speed), steering * np.sign(per_speed)
        up = float((size / (drive_limit - toward)).max())
        down = float((size / (drive_limit + toward)).max())
        for c, vmax in zip(direction, p.base_velocity_limit):  # and |s c_k| ≤ V_k
            up, down = max(up, abs(c) / vmax), max(down, abs(c) / vmax)
        lo, hi = -1.0 / down, 1.0 / up  # c is a unit vector: up, down > 0
        # acceleration: |s c_k − v_k| ≤ r_k
        twist, accel = self._twist.tolist(), self._accel_step.tolist()
        alo, ahi = lo, hi
        for c, v, r in zip(direction, twist, accel):
            if c != 0.0:
                s1, s2 = (v - r) / c, (v + r) / c
                if c < 0.0:
                    s1, s2 = s2, s1
                alo, ahi = max(alo, s1), min(ahi, s2)
            elif abs(v) > r:
                alo, ahi = math.inf, -math.inf
        if alo <= ahi:
            return min(max(wanted, alo), ahi)
        # minimax: the convex max of the lines ±(s c_k − v_k)/r_k is least where a rising and a
        # falling one cross
        lines: list[tuple[float, float]] = []
        for c, v, r in zip(direction, twist, accel):
            lines += ((c / r, -v / r), (-c / r, v / r))
        best, best_ratio = 0.0, math.inf
        candidates = [lo, hi] + [(o2 - o1) / (k1 - k2) for k1, o1 in lines for k2, o2 in lines if k1 > 0.0 > k2]
        for s in candidates:
            s = min(max(s, lo), hi)
            ratio = max(k * s + o for k, o in lines)
            if ratio < best_ratio:
                best, best_ratio = s, ratio
        return best

    # ------------------------------------------------------------------ one period
    def step(self, twist_ref, beta_meas=None, beta_dot_meas=None, brake: bool = False) -> SwmrOutput:
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

    def _commit(
        self, problem: IcrQp, steer: _Steering, twist: np.ndarray, phi_dot: np.ndarray, status: str | None = None
    ) -> SwmrOutput:
        """Store the new state and return it as a :class:`SwmrOutput`."""
        self._beta, self._beta_dot, self._twist, self._phi_dot = steer.beta, steer.rate, twist, phi_dot
        self._icr = steer.icr_next
        executed = twist
        if steer.rate.any():  # the rolling model at the mid-period steer angles
            executed = self.geometry.fit_twist(steer.beta - (0.5 * self.params.dt) * steer.rate, steer.rate, phi_dot)
        if status is None:
            status = 'stopped' if problem.stopped else 'ok'
        return SwmrOutput(
            beta_ref=steer.beta.copy(),
            beta_dot_ref=steer.rate.copy(),
            phi_dot_ref=phi_dot.copy(),
            twist_feasible=twist.copy(),
            twist_executed=executed.copy(),
            icr_next=steer.icr_next,
            icr_ref=problem.icr_ref,
            route=problem.route if status != 'solver_failure' else 'hold',
            active_constraints=sorted(steer.active),
            solve_time_s=steer.solve_time,
            status=status,
            qp_status=steer.qp_status,
        )

    def _safe_stop(self, problem: IcrQp, answer: _QpAnswer) -> SwmrOutput:
        """Solver failure: steer rates braked to zero within β̈_max, drive ramped down within φ̈_max."""
        p = self.params
        rate = np.minimum(np.maximum(0.0, problem.rate_lower), problem.rate_upper)
        beta_new = self._beta + p.dt * rate
        peak = float(np.abs(self._phi_dot).max())
        k = max(0.0, 1.0 - p.drive_accel_limit * p.dt / peak) if peak > 0 else 0.0
        steer = _Steering(
            beta_new, rate, self._icr_of(beta_new, like=self._icr.z), set(), answer.status, answer.solve_time or 0.0
        )
        return self._commit(problem, steer, k * self._twist, k * self._phi_dot, status='solver_failure')

    def _bounded_reference(self, twist_ref) -> np.ndarray:
        """ξ̇* checked and scaled down uniformly into ``|ξ̇*_k| ≤ base_velocity_limit_k``.

        A reference beyond the limits is not trusted as given: it is scaled by the largest
        s ∈ (0, 1] that brings every component within its limit, so its direction (its ICR)
        is kept, and no later product can overflow (a finite 1e308 would otherwise give NaN).

        Returns:
            ``(vx, vy, ω)`` [m/s, m/s, rad/s]. Shape (3,).

        Raises:
            ShapeError, NonFiniteError: not 3 finite numbers.
        """
        return scale_into_limits(as_finite_vector(twist_ref, 3, 'twist_ref'), self._velocity_limit)[0]
