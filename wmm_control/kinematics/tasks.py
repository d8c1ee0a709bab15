"""Tasks: what a method asks of the robot, each as its error and its Jacobian on one configuration.

A task reads the configuration the cycle computed once: the robot's
:class:`~wmm_control.kinematics.KinematicModel` after its
:meth:`~wmm_control.kinematics.KinematicModel.update` (placements and joint Jacobians, which the
safety stage's collision model reads too). It gives

* its **error**: how far the robot is from what the task asks, and
* its **Jacobian**: how the method's command ``u = (u_b, q̇_a)`` moves that error's coordinates.

The methods keep their laws as the papers write them and turn a task's error and Jacobian into a
command: Sorour eq (12)'s ``λ_p e + ṗ*`` and its damped pseudo-inverses, Xing eq (23)'s
``ẍ* + K_d (ẋ* − J q̇) + K_p e`` and SNS (:mod:`wmm_control.resolvers`).

The tasks:

* :class:`PoseTask`: the end effector's pose. The position error ``p* − p`` and the orientation
  error ``log(R* Rᵀ)`` (world frame); in the RPY variant (Sorour's) the orientation's coordinates
  are its wrapped RPY angles, with ``M_RPY`` in the Jacobian (eq 7). Its Jacobian over the base's
  own twist (the velocity methods, Sorour eq 7, base-frame rows) or over the base's
  :class:`BaseRates` (the acceleration methods, Xing eq 2, world rows) with ``J̇ q̇`` (eq 4).
* :class:`PostureTask`: an arm posture (eq 13's ``q_a,dex``, a followed plan's arm posture):
  error ``q_ref − q_a``, Jacobian the arm's selection.
* :class:`ManipulabilityTask`: Yoshikawa's measure squared ``H = det(J_m J_mᵀ)`` (Xing eq 10),
  its gradient (appendix A) and Hessian (appendix B) over the arm's joints, Xing's tertiary
  objective.

The base's part of a command:

* the velocity methods: the base's twist in its own frame on the axes it follows, a subset of
  (vx, vy, ω) (:attr:`~wmm_control.robot_config.BaseSpec.axes`), the columns of ``H J_b``;
* the acceleration methods (:func:`base_rates`): the world rates ``(ẋ, ẏ, θ̇)`` of a base that
  moves sideways, ``(v, ω)`` in its own frame of one that does not, ``q̇_b = T(θ) u_b`` with
  ``T = [[cos θ, 0], [sin θ, 0], [0, 1]]``: its Jacobian columns are ``J_b T`` and its drift gains
  ``J_b Ṫ u_b`` (the nonholonomic model of the base).
"""

from abc import ABC, abstractmethod

import numpy as np

from wmm_control.geometry import rotation_2d, rotation_error, rpy_from_matrix, rpy_rate_map, twist_to_base
from wmm_control.geometry import twist_to_world, wrap_angle
from wmm_control.kinematics.model import N_BASE, KinematicModel, arm_rows
from wmm_control.errors import WmmError

__all__ = [
    'BaseRates',
    'ManipulabilityTask',
    'PoseTask',
    'PostureTask',
    'base_rates',
    'twist_columns',
]

#: the columns of ``H J_b`` (Sorour eq 4, J_b = I₆) that the base's twist entries (vx, vy, ω) move
_H_COLS = (0, 1, 5)
_EYE = {3: np.eye(3), 6: np.eye(6)}
# (w @ _SKEW).reshape(3, 3) is the cross-product matrix [w]×, row by row: (−ε_abc w_c)_ab.
_SKEW = np.array(
    [[0, 0, 0, 0, 0, -1, 0, 1, 0], [0, 0, 1, 0, 0, 0, -1, 0, 0], [0, -1, 0, 1, 0, 0, 0, 0, 0]], dtype=float
)


def twist_columns(base_axes: tuple[int, ...]) -> list[int]:
    """The columns of Sorour's ``H J_b`` (6 wide, J_b = I₆) that a base following ``base_axes``
    of its twist (vx, vy, ω) = (0, 1, 2) moves."""
    return [_H_COLS[a] for a in base_axes]


# ---------------------------------------------------------------------- the base's rates
class BaseRates(ABC):
    """The base's entries ``u_b`` of an acceleration-level command and its world rates
    ``q̇_b = T(θ) u_b`` (module docstring). :func:`base_rates` gives the robot's."""

    #: how many entries u_b has
    n: int
    #: whether u_b are the world's rates (ẋ, ẏ, θ̇) (else the base's own (v, ω)), as the safety
    #: stage takes them (:meth:`~wmm_control.resolvers.safety.SafetyStage.filter`'s ``world_rates``)
    world: bool

    @abstractmethod
    def to_world(self, theta: float, u_b: np.ndarray) -> np.ndarray:
        """``T(θ) u_b``: the world rates (ẋ, ẏ, θ̇). Shape (3,)."""

    @abstractmethod
    def from_world(self, theta: float, world: np.ndarray) -> np.ndarray:
        """``Tᵀ(θ) w`` of a world vector over (x, y, θ): a base without a sideways axis drops the
        sideways part. Shape (n,)."""

    @abstractmethod
    def of_twist(self, theta: float, twist: np.ndarray) -> np.ndarray:
        """u_b of a base moving at ``twist`` (vx, vy, ω) in its own frame. Shape (n,)."""

    @abstractmethod
    def columns(self, theta: float, jac_base: np.ndarray) -> np.ndarray:
        """``J_b T``: the columns over u_b of a Jacobian's world-rate columns ``J_b`` (m, 3). Shape (m, n)."""

    @abstractmethod
    def drift(self, theta: float, u_b: np.ndarray, jac_base: np.ndarray) -> np.ndarray | None:
        """``J_b Ṫ u_b``: what the base's turning adds to ``J̇ q̇`` (m,), None when nothing."""

    @abstractmethod
    def twist(
        self, theta: float, u_b: np.ndarray, last: np.ndarray, step: np.ndarray, speed: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """The twist (vx, vy, ω) sent to the base controller for ``u_b``, and the u_b it stands for.

        ``last`` is the twist sent last period, ``step`` the change a·T each of the base's own
        axes may make in a period and ``speed`` their velocity limits (shapes (3,)).
        """


class _WorldRates(BaseRates):
    """A base that moves sideways: ``u_b = (ẋ, ẏ, θ̇)``, ``T = I``."""

    n = 3
    world = True

    def to_world(self, theta, u_b):
        return u_b

    def from_world(self, theta, world):
        return world

    def of_twist(self, theta, twist):
        return twist_to_world(theta, twist)

    def columns(self, theta, jac_base):
        return jac_base

    def drift(self, theta, u_b, jac_base):
        return None

    def twist(self, theta, u_b, last, step, speed):
        base = twist_to_base(theta, u_b)
        # The bounds hold the world-frame rates; the base controller limits its own frame, which
        # turns with the base. Keep the base-frame change within a·T too (a few 1e-5 m/s at most)
        # and the integrator consistent with what is sent.
        base = last + np.clip(base - last, -step, step)
        # The same for the velocity limits: two world-frame rates at their bound make up to √2
        # times the limit on one base axis. Clipping each axis towards the box keeps the change
        # within a·T (the last twist is inside the box).
        np.clip(base, -speed, speed, out=base)
        base[np.abs(base) < 1e-12] = 0.0
        return base, twist_to_world(theta, base)


class _UnicycleRates(BaseRates):
    """A base without a sideways axis: ``u_b = (v, ω)`` in its own frame."""

    n = 2
    world = False

    @staticmethod
    def _t(theta):
        axes = rotation_2d(theta)  # the base's x and y axes in the world (columns)
        return np.array([[axes[0, 0], 0.0], [axes[1, 0], 0.0], [0.0, 1.0]]), axes

    def to_world(self, theta, u_b):
        return self._t(theta)[0] @ u_b

    def from_world(self, theta, world):
        return self._t(theta)[0].T @ world

    def of_twist(self, theta, twist):
        return np.array([twist[0], twist[2]], dtype=float)

    def columns(self, theta, jac_base):
        return jac_base @ self._t(theta)[0]

    def drift(self, theta, u_b, jac_base):
        # Ṫ u_b = ω v (−sin θ, cos θ, 0): the heading's turn rotates the forward speed
        return jac_base[:, :2] @ (u_b[1] * u_b[0] * self._t(theta)[1][:, 1])

    def twist(self, theta, u_b, last, step, speed):
        # (v, ω) is already the base frame's, within its bounds
        base = np.array([u_b[0], 0.0, u_b[1]])
        base[np.abs(base) < 1e-12] = 0.0
        return base, base[[0, 2]]


def base_rates(base_axes: tuple[int, ...]) -> BaseRates:
    """The acceleration methods' base entries for a base following ``base_axes`` of its twist
    (vx, vy, ω) = (0, 1, 2): the world's rates for a base that follows all three, (v, ω) for one
    that follows (vx, ω).

    Raises:
        WmmError: a base that follows other axes.
    """
    axes = tuple(base_axes)
    if axes == (0, 1, 2):
        return _WorldRates()
    if axes == (0, 2):
        return _UnicycleRates()
    raise WmmError(f'an acceleration-level method needs a base that follows (vx, vy, ω) or (vx, ω), got axes {axes}')


# ---------------------------------------------------------------------- the end effector's pose
class PoseTask:
    """The end effector's pose (module docstring).

    Args:
        model: the configuration (updated by the cycle before the task is asked).
        orientation: ``'log'`` (the SO(3) log error and the geometric Jacobian) or ``'rpy'``
            (Sorour: RPY angles, ``J_mm = M_RPY [H J_b, J_a]``).
        rpy_damping: the damping of Ω⁻¹ in ``M_RPY`` near pitch ±π/2
            (:func:`~wmm_control.geometry.rpy_rate_map`).
    """

    def __init__(self, model: KinematicModel, orientation: str = 'log', rpy_damping: float = 1e-3) -> None:
        if orientation not in ('rpy', 'log'):
            raise WmmError(f"orientation must be 'rpy' or 'log', got {orientation!r}")
        self.model = model
        self.orientation = orientation
        self.rpy_damping = rpy_damping

    @staticmethod
    def error(
        position: np.ndarray, rotation: np.ndarray, target_position: np.ndarray, target_rotation: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray]:
        """``(p* − p, log(R* Rᵀ))`` of the end effector at (``position``, ``rotation``) from a
        target: world frame [m], [rad]. Shapes (3,), (3,)."""
        return target_position - position, rotation_error(target_rotation, rotation)

    @staticmethod
    def rpy_error(rotation: np.ndarray, target_rotation: np.ndarray) -> np.ndarray:
        """The wrapped difference of the target's RPY angles and the end effector's (Sorour eq 12's
        angular error; for ZYX angles the base yaw only shifts the yaw, so the base frame's
        equals the world's). Shape (3,)."""
        return wrap_angle(rpy_from_matrix(target_rotation) - rpy_from_matrix(rotation))

    def rpy_rates(self, omega: np.ndarray) -> np.ndarray:
        """Ω⁻¹ ω: the base-frame RPY rates of the end effector turning at ``omega`` (base
        frame), Ω⁻¹ damped by ``rpy_damping``. Shape (3,)."""
        return rpy_rate_map(self.model.ee_pose_base()[3:], self.rpy_damping)[3:, 3:] @ omega

    def jacobian_base(self, columns: list[int] | np.ndarray) -> np.ndarray:
        """The task's Jacobian over u = (the base's twist entries, q̇_a), base-frame rows: Sorour
        eq (7)'s ``J_mm`` (RPY) or ``[H J_b, J_a]`` (log), the base's columns of ``H J_b`` given
        by ``columns`` (:func:`twist_columns`). Shape (6, len(columns) + n)."""
        model = self.model
        nb = len(columns)
        if self.orientation == 'rpy':
            cols = np.concatenate((np.asarray(columns, dtype=int), np.arange(6, 6 + model.n_arm)))
            return model.jmm(self.rpy_damping)[:, cols]
        jac = np.empty((6, nb + model.n_arm))
        jac[:, :nb] = model.h_matrix()[:, columns]
        jac[:, nb:] = model.arm_jacobian_base()
        return jac

    def jacobian_world(self, rates: BaseRates, theta: float) -> np.ndarray:
        """The task's Jacobian over u = (u_b, q̇_a), world rows (Xing eq 2, the base's columns
        ``J_b T``). Shape (6, rates.n + n)."""
        jac = self.model.jacobian_world()
        if rates.world:
            return jac
        return np.hstack((rates.columns(theta, jac[:, :N_BASE]), jac[:, N_BASE:]))

    def drift(self, rates: BaseRates, theta: float, u_b: np.ndarray) -> np.ndarray:
        """``J̇ q̇`` of the configuration's rates (Xing eq 4) with the base's ``J_b Ṫ u_b``:
        the end effector's acceleration at ``u̇ = 0``, world axes. Shape (6,)."""
        drift = self.model.jdot_qdot()
        extra = rates.drift(theta, u_b, self.model.jacobian_world()[:, :N_BASE])
        return drift if extra is None else drift + extra


# ---------------------------------------------------------------------- an arm posture
class PostureTask:
    """An arm posture: error ``q_ref − q_a``, Jacobian ``[0 I]`` over u = (u_b, q̇_a).

    Args:
        n_base: the command's base entries.
        n_arm: its arm joints.
    """

    def __init__(self, n_base: int, n_arm: int) -> None:
        self.n_base = n_base
        self.n_arm = n_arm

    @staticmethod
    def error(q_arm: np.ndarray, posture: np.ndarray) -> np.ndarray:
        """``q_ref − q_a`` [rad or m]. Shape (n,)."""
        return posture - q_arm

    def jacobian(self) -> np.ndarray:
        """``[0 I]``: the arm's selection out of u. Shape (n, n_b + n)."""
        return np.eye(self.n_arm, self.n_base + self.n_arm, self.n_base)

    def pull(self, q_arm: np.ndarray, posture: np.ndarray, gain: float) -> np.ndarray:
        """``Jᵀ gain e``: the task's proportional pull over u (zero on the base's entries), the
        secondary task ``z`` of Sorour eq (13). Shape (n_b + n,)."""
        z = np.zeros(self.n_base + self.n_arm)
        z[self.n_base :] = gain * self.error(q_arm, posture)
        return z


# ---------------------------------------------------------------------- manipulability
class ManipulabilityTask:
    """Yoshikawa's manipulability squared, ``H = det(J_m J_mᵀ)`` (Xing eq 10), of the arm's
    Jacobian ``J_m`` (world axes; its position rows, or all six), with its gradient and Hessian
    over the arm's joints: a task whose error the method raises (Xing's tertiary objective, eqs
    10–13).

    Args:
        model: the configuration.
        rows: ``'position'`` or ``'full'``.
    """

    def __init__(self, model: KinematicModel, rows: str = 'position') -> None:
        self.rows = arm_rows(rows)
        self.model = model
        n = model.n_arm
        self._upper = np.triu(np.ones((n, n)))  # [k ≤ i]
        self._strict_upper = np.triu(np.ones((n, n)), 1)
        self._sym_weight = 2.0 * self._strict_upper + np.eye(n)
        self._cached: tuple[int, tuple[np.ndarray, np.ndarray]] | None = None

    def jacobian(self) -> np.ndarray:
        """J_m: the arm's columns of the world Jacobian, the task's rows. Shape (3 or 6, n)."""
        return self.model.jacobian_world()[self.rows, N_BASE:]  # a copy

    def value(self) -> float:
        """``H = det(J_m J_mᵀ)``."""
        jm = self.jacobian()
        return float(np.linalg.det(jm @ jm.T))

    def sigma_min(self) -> float:
        """The smallest singular value of J_m (a distance-to-singularity measure)."""
        return float(np.linalg.svd(self.jacobian(), compute_uv=False)[-1])

    def gradient(self) -> np.ndarray:
        """∂H/∂q_m (Xing appendix A), exact, in closed form (:meth:`derivatives`). Shape (n,).

        Raises:
            numpy.linalg.LinAlgError: ``J_m J_mᵀ`` is singular.
        """
        return self.derivatives()[0].copy()

    def hessian(self) -> np.ndarray:
        """∂²H/∂q_m² (Xing appendix B), exact, in closed form, symmetric (:meth:`derivatives`). Shape (n, n)."""
        return self.derivatives()[1].copy()

    def derivatives(self) -> tuple[np.ndarray, np.ndarray]:
        """(∇H (n,), ∇²H (n, n)) over q_m, from J_m alone; computed once per configuration (kept
        until the model's next update: asking for both costs one evaluation). Read-only arrays.

        Serial chain, world axes: column i of J_m is ``J_i = (v_i, w_i)``, with ``w_i`` the
        joint axis and ``v_i = w_i × (p_e − p_i)`` for a revolute joint, ``(u_i, 0)`` for a
        prismatic one along u_i. Moving a revolute joint k rotates the chain beyond it about
        its axis (a prismatic one translates it, which w_k = 0 expresses in every term), so

        * ``∂J_i/∂q_k = (w_k × v_i, w_k × w_i)`` for k ≤ i, ``(w_i × v_k, 0)`` for k > i;
        * for l ≤ k: ``∂²J_i/∂q_l∂q_k = w_l × (w_k × J_i)`` (both halves) for k ≤ i,
          ``(w_l × (w_i × v_k), 0)`` for l ≤ i < k, ``(w_i × (w_l × v_k), 0)`` for i < l.

        With ``M = J_m J_mᵀ``, ``P = M⁻¹ J_m`` (columns ``(a_i, b_i)``, position rows then
        angular ones) and ``⟨X, Y⟩ = tr(Xᵀ Y)``:

        * ``g_k = tr(M⁻¹ ∂_k M) = 2⟨P, ∂_k J_m⟩`` and ``∇H = H g`` (appendix A);
        * ``∇²H = H (g gᵀ + A + B − C)`` (appendix B), where
          ``B_lk = 2⟨M⁻¹ ∂_l J_m, ∂_k J_m⟩``, ``C_lk = tr(M⁻¹ ∂_l M M⁻¹ ∂_k M)`` and
          ``A_lk = 2⟨P, ∂²_lk J_m⟩``.

        ``A`` never needs the (7, 7, 6, 7) second derivatives: expanding the triple
        products, for l ≤ k,
        ``A_lk / 2 = w_kᵀ S_k w_l − tr(S_k) w_l·w_k + (w_l·v_k)(c_k − c_l) + w_lᵀ R_l v_k
        − Σ_{i<k} (w_l·w_i)(a_i·v_k)``, with ``S_k = Σ_{i≥k} (a_i v_iᵀ + b_i w_iᵀ)``,
        ``R_l = Σ_{i<l} a_i w_iᵀ`` and ``c_l = tr R_l``: running sums of 3×3 matrices.

        At an exact singularity of ``M`` the derivatives are those of det(M + εI), ε = 1e-12 tr M.
        """
        revision = self.model.revision
        if self._cached is not None and self._cached[0] == revision:
            return self._cached[1]
        nr = self.rows.stop
        n = self.model.n_arm
        jac = self.model.jacobian_world()[:, N_BASE:]  # (6, n): v rows, then w rows
        jm = jac[:nr]
        v, w = jac[:3], jac[3:]
        wt = w.T
        m = jm @ jm.T
        h = np.linalg.det(m)
        if h == 0.0:
            # Exactly singular (a square arm Jacobian, e.g. six joints and six rows, at a
            # singularity): the derivatives of det(M + εI), ε = 1e-12 tr M, the limit of which
            # they approach; they point the way out of the singularity.
            m = m + (1e-12 * max(np.trace(m), 1e-300)) * _EYE[nr]
            h = np.linalg.det(m)
        minv = np.linalg.inv(m)
        p = minv @ jm
        # ∂J_m/∂q_k as dj[k] (nr, n); z[k, :, i] = w_k × v_i (and × w_i for all six rows).
        skew = (wt @ _SKEW).reshape(n, 3, 3)  # [w_k]×
        upper = self._upper[:, None, :]  # [k ≤ i]
        if nr == 3:
            z = skew @ v
            dj = np.where(upper > 0, z, z.transpose(2, 1, 0))
            outer = p.T[:, :, None] * v.T[:, None, :]  # a_i v_iᵀ
        else:
            z = skew[:, None] @ jac.reshape(2, 3, n)
            dj = np.empty((n, 2, 3, n))
            np.copyto(dj[:, 0], np.where(upper > 0, z[:, 0], z[:, 0].transpose(2, 1, 0)))
            np.multiply(z[:, 1], upper, out=dj[:, 1])
            dj = dj.reshape(n, 6, n)
            outer = p.reshape(2, 3, n).transpose(2, 1, 0) @ jac.reshape(2, 3, n).transpose(2, 0, 1)
        djf = dj.reshape(n, -1)
        g = 2.0 * (djf @ p.ravel())
        y = minv @ dj  # M⁻¹ ∂J_k
        half_b = y.reshape(n, -1) @ djf.T  # B / 2
        mdm = y @ jm.T + p @ dj.transpose(0, 2, 1)  # M⁻¹ ∂M_k
        c = mdm.reshape(n, -1) @ mdm.transpose(0, 2, 1).reshape(n, -1).T
        # A, upper triangle (l ≤ k) of A / 2, terms in the order of the docstring.
        s_k = outer[::-1].cumsum(0)[::-1]
        a_v = p[:3]
        aw = a_v.T[:, :, None] * wt[:, None, :]  # a_i w_iᵀ
        r_l = aw.cumsum(0) - aw
        c_l = r_l.trace(axis1=1, axis2=2)
        ww = wt @ w
        half = ((wt[:, None, :] @ s_k)[:, 0, :] @ w).T - ww * s_k.trace(axis1=1, axis2=2)
        half += (wt @ v) * (c_l - c_l[:, None])
        half += (wt[:, None, :] @ r_l)[:, 0, :] @ v
        half -= ww @ ((a_v.T @ v) * self._strict_upper)
        half *= self._sym_weight  # 2 above the diagonal, 1 on it
        # T = that weighted triangle + (B − C) / 2: ∇²H = H (g gᵀ + T + Tᵀ), exactly symmetric.
        half += half_b
        c *= 0.5
        half -= c
        hess = half + half.T
        hess += np.outer(g, g)
        hess *= h
        out = (h * g, hess)
        for arr in out:
            arr.flags.writeable = False
        self._cached = (revision, out)
        return out
