"""What the acceleration-level methods share (Xing et al.): the PD tracking law, the joint
acceleration bounds, the manipulability objective, and the integration to velocity commands.

Joint space: the generalized coordinates ``q = (x_b, y_b, θ_b, q_m)`` of Xing eq (2), the
base in world coordinates (robot B's base is holonomic, so J and J_v coincide). A
differential base cannot move sideways: its rates are ``u_b = (v, ω)`` in its own frame,
``(ẋ_b, ẏ_b, θ̇_b) = T(θ) u_b`` with ``T = [[cos θ, 0], [sin θ, 0], [0, 1]]``, so its Jacobian
columns are ``J_b T`` and its drift gains ``J_b Ṫ u_b`` (the nonholonomic model of the base;
every step below is the same over u = (u_b, q̇_m); :func:`~wmm_control.kinematics.tasks.base_rates`). Each period:

1. ``ẍ = ẍ_d + K_d (ẋ_d − J q̇) + K_p e`` (eq 23) on the position rows (r = 3) or the whole
   pose (r = 6, orientation error ``log(R_d Rᵀ)``, world frame); ``J̇q̇`` from pinocchio.
2. Joint acceleration bounds (eqs 6–8) from the position, velocity and acceleration limits of
   all ten coordinates. The bounds are the velocity interval this period may reach
   (:meth:`~wmm_control.resolvers.limits.CommandLimits.box`: velocity limits, braking before a
   position limit, and the acceleration limit around the current rate), divided by the
   period: eq (8)'s upper bound is the *min* of its terms (it prints max), and near a
   position limit it becomes full braking. Our braking term keeps the command that is
   executed (the integrated rate, held for a period) from ever passing the limit.
3. The method's joint accelerations (a subclass), within the bounds.
4. ``q̇ ← q̇ + q̈ T``: the arm gets q̇_m; the base gets (ẋ_b, ẏ_b, θ̇_b) turned into its own
   frame (vx, vy, ω), the reference of its base controller ((v, 0, ω) for a differential base).

A set-point target (zero velocity and acceleration) becomes a smooth trajectory
(:class:`~wmm_control.resolvers.setpoint_trajectory.SetpointTrajectory`); a trajectory point
is tracked as given.

A followed plan's base (:class:`~wmm_control.resolvers.interface.BaseReference` on the target,
not in the papers): eq (23)'s law on the base's planned pose,
``ξ̈* = ξ̈_plan + K_d (ξ̇_plan − ξ̇) + K_p (ξ_plan − ξ)`` (world rates; the position gains on x and
y, the orientation gains on θ), written as a law on the rates,
``ξ̈* = ξ̈_plan + K_d (ξ̇* − ξ̇)`` with ``ξ̇* = ξ̇_plan + (K_p / K_d)(ξ_plan − ξ)``, whose position
feedback is, on each of the base's axes (its own frame), no faster than ``√(2 a e)``: the speed
from which the axis's acceleration limit ``a`` brakes it to rest over its error ``e``
(:meth:`~wmm_control.resolvers.interface.BaseReference.pull`, the velocity-level methods' pull
too). Below that speed it is eq (23)'s law as printed; without the cap robot B's base
(0.025 m/s²) was asked for speeds it cannot brake from (out of AMP's task, 0.20 m past a
planned pose 0.39 m away; ``test_follow_base.py``).
A differential base takes its part along its heading, ``u̇_b* = Tᵀ ξ̈*``, which drops the
sideways part: its turn rate in ``ξ̇*`` also steers it back onto the plan's line,
``+ k_y v_r e_y`` (Kanayama's law, the velocity-level methods' too: one ``pull`` with
:meth:`~wmm_control.resolvers.interface.SteeringParams.steering_gain`, ``k_θ`` the orientation
rows' ``K_p / K_d``); without it a base 0.2 m beside a straight plan stayed 0.2 m beside it
(``test_follow_base.py``). The result
is ``task['base_follow']`` (None without a plan), which each method gives
the base in its own way (:mod:`~wmm_control.resolvers.amp`, :mod:`~wmm_control.resolvers.traditional`).
The same law on the arm's joints towards the plan's arm posture (``BaseReference.arm``: the travel
posture on the way, the stance's posture on the arm's way to it and in the final approach; the
orientation gains), ``q̈_a* = K_p (q_a,plan − q_a) − K_d q̇_a``,
is ``task['arm_follow']`` (None without one), which the traditional planner uses.
"""

import time
from abc import abstractmethod
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np

from wmm_control.errors import ConfigError
from wmm_control.geometry import largest_step, twist_to_world
from wmm_control.kinematics import KinematicModel
from wmm_control.kinematics.tasks import ManipulabilityTask, PoseTask, PostureTask, base_rates
from wmm_control.resolvers.interface import PoseTarget, Resolver, ResolverCommand, ResolverDiagnostics, RobotState
from wmm_control.resolvers.interface import SteeringParams
from wmm_control.resolvers.limits import CommandLimits
from wmm_control.resolvers.pose_servo import _check_fields
from wmm_control.resolvers.safety import SafetyParams, SafetyStage
from wmm_control.resolvers.setpoint_trajectory import SetpointTrajectory
from wmm_control.robot_config import RobotConfig

__all__ = ['AccelerationParams', 'AccelerationResolver', 'TASK_ROWS']

TASK_ROWS = ('position', 'full')


@dataclass(frozen=True)
class AccelerationParams(SafetyParams, SteeringParams):
    """Parameters shared by the acceleration-level methods (Xing §4 defaults), the safety
    stage's (:class:`~wmm_control.resolvers.safety.SafetyParams`) and a followed plan's base's
    (:class:`~wmm_control.resolvers.interface.SteeringParams`).

    Attributes:
        dt: control period T [s].
        rows: ``'full'`` (r = 6, §4.4: a goal is a pose) or ``'position'`` (r = 3, §4.2–4.3).
        kp, kd: PD gains of eq (23) on the position rows [1/s², 1/s].
        kp_rot, kd_rot: the same on the orientation rows (r = 6).
        gamma1, gamma2: gains of the manipulability objective, eqs (12)–(13).
        manipulability: run the tertiary (manipulability) objective, eqs (10)–(13).
        setpoint_speed, setpoint_accel: peak linear speed [m/s] and acceleration [m/s²] of the
            trajectory a set-point becomes.
        setpoint_angular_speed, setpoint_angular_accel: the same for the rotation [rad/s, rad/s²].
        rcond: relative singular-value cut-off of the pseudo-inverses.
    """

    dt: float = 0.025
    rows: str = 'full'
    kp: float = 20.0
    kd: float = 10.0
    kp_rot: float = 5.0
    kd_rot: float = 3.0
    gamma1: float = 5.0
    gamma2: float = 0.5
    manipulability: bool = True
    setpoint_speed: float = 0.1
    setpoint_accel: float = 0.1
    setpoint_angular_speed: float = 0.3
    setpoint_angular_accel: float = 0.3
    rcond: float = 1e-6

    _allow_zero: ClassVar[tuple[str, ...]] = ('gamma1', 'gamma2')

    def __post_init__(self):
        super().__post_init__()
        _check_fields(self, self._allow_zero)
        if self.rows not in TASK_ROWS:
            raise ConfigError(f'rows must be one of {TASK_ROWS}, got {self.rows!r}')


class AccelerationResolver(Resolver):
    """Base of the acceleration-level methods; a subclass gives ``_accelerations``.

    Args:
        robot: robot name, YAML path, RobotConfig or KinematicModel.
        params: an :class:`AccelerationParams` (or subclass).
    """

    name = 'acceleration_level'

    def __init__(self, robot: str | Path | RobotConfig | KinematicModel, params: AccelerationParams) -> None:
        self.model = robot if isinstance(robot, KinematicModel) else KinematicModel(robot)
        self.params = params
        self.limits = CommandLimits.for_robot(self.model.config, params.dt)
        # the stage reads the configuration this method's update computes: one a cycle
        self.safety = SafetyStage.for_robot(self.model.config, params, kinematics=self.model)
        #: the base's entries of the command: world rates, or (v, ω) of a base that does not move sideways
        self.base_rates = base_rates(self.model.config.base.axes)
        self.n_base = self.base_rates.n
        self.n = self.n_base + self.model.n_arm
        #: the end effector's pose task (world rows) and the manipulability objective's
        self.pose_task = PoseTask(self.model)
        self.manipulability_task = ManipulabilityTask(self.model, params.rows)
        #: the followed plan's arm posture (``task['arm_follow']``)
        self.posture_task = PostureTask(self.n_base, self.model.n_arm)
        self._sigma_position = ManipulabilityTask(self.model, 'position')
        self._rows = slice(0, 3) if params.rows == 'position' else slice(0, 6)
        self._position = np.zeros(self.n)
        self._kp = np.array([params.kp] * 3 + [params.kp_rot] * 3)
        self._kd = np.array([params.kd] * 3 + [params.kd_rot] * 3)
        # a followed plan's base (module docstring): K_d on (x, y, θ), and K_p / K_d, the gain of
        # the rates the position feedback asks for
        self._base_kd = self._kd[[0, 1, 5]]
        self._base_gain = self._kp[[0, 1, 5]] / self._base_kd
        self._base_acceleration = np.asarray(self.model.config.base.acceleration, dtype=float)
        # the change a·T and the speed of each of the base's own axes (vx, vy, ω) in a period
        self._base_step = self._base_acceleration * params.dt
        self._base_speed = np.asarray(self.model.config.base.velocity, dtype=float)
        # k_y of a base without a sideways axis (0 for the others), on the heading's gain K_p / K_d
        self._steering = params.steering_gain(self.model.config.base, self._base_gain[2])
        self.reset()

    def reset(self) -> None:
        self._qd: np.ndarray | None = None  # the commanded generalized rates u = (u_b, q̇_m) (the integrator)
        self._last_base = np.zeros(3)  # the last base twist sent (base frame)
        self._setpoint = None  # (goal key, trajectory, time along it)

    # ------------------------------------------------------------------ reference
    def _reference(self, target, pos, rot):
        """The trajectory point to track: ``target`` itself, or its set-point trajectory's."""
        if np.any(target.velocity) or np.any(target.acceleration):
            self._setpoint = None
            return target
        key = (target.position.tobytes(), target.rotation.tobytes())
        if self._setpoint is None or self._setpoint[0] != key:
            p = self.params
            traj = SetpointTrajectory(
                pos, rot, target, p.setpoint_speed, p.setpoint_accel, p.setpoint_angular_speed, p.setpoint_angular_accel
            )
            self._setpoint = [key, traj, 0.0]
        self._setpoint[2] += self.params.dt
        return self._setpoint[1].sample(self._setpoint[2])

    def task_acceleration(self, state: RobotState, target: PoseTarget) -> dict:
        """Eq (23) and what the methods need.

        Returns:
            dict with ``jac`` (r, n_b + n), ``xdd`` (r,), ``drift`` J̇q̇ (r,), ``lower``/``upper``
            joint acceleration bounds (n_b + n,), ``brake_lower``/``brake_upper`` those of the
            braking before a position limit alone, ``qd`` (n_b + n,), ``position_error`` [m],
            ``orientation_error`` [rad], ``sigma`` σ_min of the arm's task rows, ``sigma_position``
            that of its position rows, ``base_follow`` the base's accelerations towards a
            followed plan's pose (n_b,) or None, ``on_the_way`` whether that pose is a point of
            the plan's way (not the stance of its final approach), ``arm_follow`` the arm's towards
            the plan's arm posture (n,) or None (module docstring).
        """
        p = self.params
        theta = state.base_pose[2]
        nb = self.n_base
        rates = self.base_rates
        if self._qd is None:
            self._qd = np.concatenate((rates.of_twist(theta, state.base_twist), state.dq_arm))
            self._last_base = np.asarray(state.base_twist, dtype=float).copy()
        qd = self._qd
        self.model.update(state.base_pose, state.q_arm, rates.to_world(theta, qd[:nb]), qd[nb:])
        pos, rot = state.ee_placement(self.model)
        ref = self._reference(target, pos, rot)
        pose = self.pose_task
        jac = pose.jacobian_world(rates, theta)
        drift = pose.drift(rates, theta, qd[:nb])
        err = np.concatenate(pose.error(pos, rot, ref.position, ref.rotation))
        xd = jac @ qd
        xdd = ref.acceleration + self._kd * (ref.velocity - xd) + self._kp * err
        rows = self._rows
        self._position[nb:] = state.q_arm
        room = None if target.base is None else self.base_room(state.base_pose, target.base, rates.world)
        lo_v, hi_v, _ = self.limits.box(self._position, qd, room)
        down, up = self.limits.braking_rates(self._position, room, qd)
        sigma = self.manipulability_task.sigma_min()
        sigma_position = sigma if rows.stop == 3 else self._sigma_position.sigma_min()
        e_target, e_rot_target = pose.error(pos, rot, target.position, target.rotation)
        base_follow = arm_follow = None
        if target.base is not None:
            planned = target.base
            wanted = twist_to_world(
                theta, planned.pull(state.base_pose, self._base_gain, self._base_acceleration, self._steering)
            )
            world = planned.acceleration + self._base_kd * (wanted - rates.to_world(theta, qd[:nb]))
            base_follow = rates.from_world(theta, world)
            if planned.arm is not None and planned.arm.shape == (self.model.n_arm,):
                posture = self.posture_task.error(state.q_arm, planned.arm)
                arm_follow = self._kp[5] * posture - self._kd[5] * qd[nb:]
        return {
            'jac': jac[rows],
            'xdd': xdd[rows],
            'drift': drift[rows],
            'qd': qd,
            'q_arm': state.q_arm,
            'box_lower': lo_v,
            'box_upper': hi_v,
            'lower': (lo_v - qd) / p.dt,
            'upper': (hi_v - qd) / p.dt,
            'brake_lower': (-down - qd) / p.dt,
            'brake_upper': (up - qd) / p.dt,
            'position_error': float(np.linalg.norm(e_target)),
            'orientation_error': float(np.linalg.norm(e_rot_target)),
            'sigma': sigma,
            'sigma_position': sigma_position,
            'base_follow': base_follow,
            'on_the_way': target.base is not None and not target.base.stance,
            'arm_follow': arm_follow,
        }

    def manipulability_acceleration(self, qd: np.ndarray) -> np.ndarray:
        """Eq (13): ``q̈_A = [0; γ1 ∇²H q̇_m + γ2 (γ1 ∇H − q̇_m)]``, H over the task's rows. Shape (n_b + n,)."""
        p = self.params
        grad, hess = self.manipulability_task.derivatives()
        nb = self.n_base
        out = np.zeros(self.n)
        out[nb:] = p.gamma1 * hess @ qd[nb:] + p.gamma2 * (p.gamma1 * grad - qd[nb:])
        return out

    # ------------------------------------------------------------------ step
    @abstractmethod
    def _accelerations(self, task):
        """The method: ``(q̈ (n_b + n,), diagnostics fields dict)`` within ``task['lower'/'upper']``."""

    def step(self, state: RobotState, target: PoseTarget) -> ResolverCommand:
        t0 = time.perf_counter()
        task = self.task_acceleration(state, target)
        qdd, fields = self._accelerations(task)
        if not np.isfinite(qdd).all():
            qdd = np.nan_to_num(qdd)
        qdd = np.clip(qdd, task['lower'], task['upper'])
        qd = task['qd'] + qdd * self.params.dt
        qd[np.abs(qd) < 1e-12] = 0.0  # a stop is exact: braking by −q̇/T leaves round-off
        nb = self.n_base
        # the safety stage on the rates, within this period's box (q̇_prev ± q̈_max T, ...); the
        # base's are the world frame's (ẋ, ẏ, θ̇), or a differential base's own (v, ω)
        safety = self.safety.filter(
            task['q_arm'],
            qd,
            task['box_lower'],
            task['box_upper'],
            base_pose=state.base_pose,
            base_axes=self.model.config.base.axes,
            base_velocity=state.base_twist,
            world_rates=self.base_rates.world,
            task_jacobian=task['jac'],
        )
        qd = safety.command.copy()
        fields.update(
            clearance=safety.clearance,
            closest_pair=safety.closest_pair,
            collision_constraints=safety.active,
            collision_changed=safety.changed,
        )
        base, qd[:nb] = self.base_rates.twist(
            state.base_pose[2], qd[:nb], self._last_base, self._base_step, self._base_speed
        )
        self._qd, self._last_base = qd, base
        return self._command(qd, base, task, fields, t0)

    def _command(self, qd, base, task, fields, t0):
        time_left = max(self._setpoint[1].duration - self._setpoint[2], 0.0) if self._setpoint else 0.0
        diag = ResolverDiagnostics(
            method=self.name,
            psi=fields.pop('psi', 1.0),
            position_error=task['position_error'],
            orientation_error=task['orientation_error'],
            compensation_scale=1.0,
            sigma_min=task['sigma'],
            compensated=False,
            cycle_time_s=time.perf_counter() - t0,
            reference_time_left=time_left,
            **fields,
        )
        return ResolverCommand(arm_velocity=qd[self.n_base :].copy(), base_twist=base.copy(), diagnostics=diag)

    def _tertiary(self, task, qdd, active, active_pinv, follow=False):
        """Eqs (10)–(11): ``β P_A q̈_A`` with ``P_A = [I − ((I − S) P_N)⁺] P_N``, β keeping the bounds.

        With ``follow``, a followed plan's base accelerations (``task['base_follow']``, less
        the base's share of ``qdd``) join ``q̈_A`` (not in the paper), and with a plan's arm
        posture its arm accelerations (``task['arm_follow']`` within the bounds, less the arm's
        share of ``qdd``) do too; without manipulability (``manipulability`` off) they are all
        of it.

        ``P_A`` is the orthogonal projector onto the motions that leave the task alone
        (``J x = 0``, the null space of ``P_N``) and move no joint outside the active set S
        (``(I − S) x = 0``): over the active columns it is ``I − (J S)⁺ (J S)``, zero elsewhere.
        So it needs only the pseudo-inverse SNS already has, not the printed 10 × 10 ones
        (the same matrix to round-off; a test compares them).

        Args:
            task: :meth:`task_acceleration`'s dict.
            qdd: the primary and secondary accelerations (n_b + n,).
            active: the active set S (bool, (n_b + n,)).
            active_pinv: ``(J S)⁺`` over the active columns, (|S|, r).

        Returns:
            (q̈_t (n_b + n,), β).
        """
        cols = np.flatnonzero(active)
        objective = self.manipulability_acceleration(task['qd']) if self.params.manipulability else np.zeros(self.n)
        nb = self.n_base
        if follow:
            objective[:nb] += task['base_follow'] - qdd[:nb]
        if task['arm_follow'] is not None:
            objective[nb:] += np.clip(task['arm_follow'], task['lower'][nb:], task['upper'][nb:]) - qdd[nb:]
        q_a = objective[cols]
        q_t = np.zeros(self.n)
        q_t[cols] = q_a - active_pinv @ (task['jac'][:, cols] @ q_a)
        beta, _ = largest_step(qdd, q_t, task['lower'], task['upper'])
        return beta * q_t, beta
