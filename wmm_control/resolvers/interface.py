"""The seam every redundancy resolver shares: ``step(state, target) -> command``.

A resolver turns the robot's state and an end-effector target into one period's command:
arm joint velocities and a base twist reference. Methods whose arm compensates the base's
predicted velocity error (Sorour eq 14) finish the arm part in a second call,
:meth:`Resolver.compensate`, once the base controller has answered this period's base
reference with the twist it can execute.

Frames: the world frame is fixed, z up; the base frame is ``base_link`` (x forward).
"""

import math
from abc import ABC, abstractmethod
from collections.abc import Iterable
from dataclasses import dataclass, field, replace
from typing import TYPE_CHECKING, Any, Self

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import as_finite_vector
from wmm_control.errors import ShapeError
from wmm_control.geometry import matrix_from_rpy, twist_to_base, wrap_angle

if TYPE_CHECKING:
    from wmm_control.kinematics import KinematicModel
    from wmm_control.kinematics.obstacles import Obstacle
    from wmm_control.resolvers.safety import SafetyStage
    from wmm_control.robot_config import BaseSection

__all__ = [
    'RobotState',
    'BaseReference',
    'SteeringParams',
    'PoseTarget',
    'ResolverDiagnostics',
    'ResolverCommand',
    'Resolver',
    'base_twist_of',
]


def base_twist_of(values: ArrayLike, axes: Iterable[int]) -> np.ndarray:
    """The base twist (vx, vy, ω) whose entries ``axes`` are ``values`` and the rest zero.

    A differential base follows (vx, ω) only (axes (0, 2)): its vy is zero by construction.
    Shape (3,).
    """
    twist = np.zeros(3)
    twist[list(axes)] = values
    return twist


@dataclass(frozen=True)
class SteeringParams:
    """How a method follows a plan's base (:class:`BaseReference`); every method's parameters
    class derives from this one.

    Attributes:
        steering_damping: ζ of the steering of a base without a sideways axis back onto the
            plan's line (:meth:`steering_gain`): the damping ratio of its sideways offset along a
            straight plan at the base's top speed (1: critically damped there, overdamped
            slower; larger: a gentler, slower steering) [-].
    """

    steering_damping: float = 1.0

    def steering_gain(self, base: 'BaseSection', heading_gain: float) -> float:
        """``k_y`` of the tracking law of a base that turns but cannot move sideways (a
        differential base; Kanayama et al. 1990): its turn ``ω`` gets ``k_y v_r e_y``
        (:meth:`BaseReference.pull`), ``v_r`` the plan's forward speed, ``e_y`` the planned
        pose's sideways offset in the base's frame. With the heading held by
        ``ω = ω_r + k_θ e_θ`` (``k_θ`` = ``heading_gain``), along a straight line at ``v_r`` the
        offset obeys ``ë_y + k_θ ė_y + k_y v_r² e_y = 0``, and ``k_y = k_θ² / (4 ζ² v_max²)``
        (ζ = ``steering_damping``, ``v_max`` the base's forward speed limit) makes its damping
        ratio ζ at the top speed, more below it. Without it a pull that holds the heading to the
        plan's leaves a sideways offset as it is.

        Zero for a base that follows a sideways twist itself (steerable, Mecanum: the pull's
        sideways part moves it there) or cannot drive and turn.

        Args:
            base: the robot's base (:attr:`~wmm_control.robot_config.RobotConfig.base`): the axes
                it follows and their speed limits.
            heading_gain: ``k_θ``, the gain of the pull's heading feedback [1/s].

        Returns:
            ``k_y`` [1/m²].
        """
        axes, speed = base.axes, float(base.velocity[0])
        if base.sideways or 0 not in axes or 2 not in axes or speed <= 0.0:
            return 0.0
        return (heading_gain / (2.0 * self.steering_damping * speed)) ** 2


def _rotation(value, name):
    rot = np.asarray(value, dtype=float)
    if rot.shape != (3, 3):
        raise ShapeError(f'{name}: expected a (3, 3) rotation matrix, got shape {rot.shape}')
    as_finite_vector(rot.ravel(), 9, name)
    return rot


@dataclass(frozen=True)
class RobotState:
    """What the robot reports in one period.

    Attributes:
        base_pose: (x, y, θ) of ``base_link`` in the world [m, m, rad]. Shape (3,).
        base_twist: measured base twist (vx, vy, ω) in the base frame [m/s, m/s, rad/s].
            Shape (3,).
        q_arm: arm joint positions [rad or m]. Shape (n,).
        dq_arm: arm joint rates [rad/s or m/s]. Shape (n,).
        ee_position: measured end-effector position in the world [m], or None to use forward
            kinematics from the base pose and the arm joints. Shape (3,).
        ee_rotation: measured end-effector orientation in the world, with ``ee_position``.
            Shape (3, 3).

    Raises:
        ShapeError, NonFiniteError: a wrong size or a NaN/inf entry.
    """

    base_pose: np.ndarray
    base_twist: np.ndarray
    q_arm: np.ndarray
    dq_arm: np.ndarray
    ee_position: np.ndarray | None = None
    ee_rotation: np.ndarray | None = None

    def __post_init__(self):
        object.__setattr__(self, 'base_pose', as_finite_vector(self.base_pose, 3, 'base_pose'))
        object.__setattr__(self, 'base_twist', as_finite_vector(self.base_twist, 3, 'base_twist'))
        q_arm = as_finite_vector(self.q_arm, None, 'q_arm')
        object.__setattr__(self, 'q_arm', q_arm)
        object.__setattr__(self, 'dq_arm', as_finite_vector(self.dq_arm, q_arm.size, 'dq_arm'))
        if (self.ee_position is None) != (self.ee_rotation is None):
            raise ShapeError('give both ee_position and ee_rotation, or neither')
        if self.ee_position is not None:
            object.__setattr__(self, 'ee_position', as_finite_vector(self.ee_position, 3, 'ee_position'))
            object.__setattr__(self, 'ee_rotation', _rotation(self.ee_rotation, 'ee_rotation'))

    def ee_placement(self, model: 'KinematicModel', *, update: bool = False) -> tuple[np.ndarray, np.ndarray]:
        """The end effector's position (3,) [m] and rotation (3, 3) in the world: the measured
        pose when the state carries one, else forward kinematics of ``model``.

        Args:
            model: the robot's kinematic model, already updated at this state's base pose and
                arm joints unless ``update``.
            update: run the model's forward kinematics at this state first when there is no
                measured pose (the model is left alone when there is one).
        """
        if self.ee_position is not None and self.ee_rotation is not None:  # both or neither
            return self.ee_position, self.ee_rotation
        if update:
            model.update(self.base_pose, self.q_arm)
        return model.ee_placement_world()


@dataclass(frozen=True)
class BaseReference:
    """Where a followed plan has the base at a point of its end-effector trajectory: a
    secondary target, below the end effector's (not in the papers; the methods' use of it is
    in ``docs/methods.md``, the planner's section).

    Attributes:
        pose: the planned base pose (x, y, θ) in the world [m, m, rad]. Shape (3,).
        rates: its planned world rates (ẋ, ẏ, θ̇) [m/s, m/s, rad/s]. Shape (3,).
        acceleration: its planned world accelerations (ẍ, ÿ, θ̈) [m/s², m/s², rad/s²]. Shape (3,).
        arm: the arm's posture the plan assumed with it [rad or m]: on the way its travel
            posture, at the stance the posture its inverse kinematics reached the goal with (the
            branch the stance was chosen for); None: the method's own. Shape (n,).
        stance: True for the base's place in the final approach, given with a goal (the plan's
            last pose, at rest, from which the goal is reachable): a method's own posture task
            yields to it there; False for a point of the way there.

    Raises:
        ShapeError, NonFiniteError: a wrong size or a NaN/inf entry.
    """

    pose: np.ndarray
    rates: np.ndarray = field(default_factory=lambda: np.zeros(3))
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(3))
    arm: np.ndarray | None = None
    stance: bool = False

    def __post_init__(self):
        if self.arm is not None:
            object.__setattr__(self, 'arm', as_finite_vector(self.arm, None, 'base reference arm posture'))
        object.__setattr__(self, 'pose', as_finite_vector(self.pose, 3, 'base reference pose'))
        object.__setattr__(self, 'rates', as_finite_vector(self.rates, 3, 'base reference rates'))
        object.__setattr__(self, 'acceleration', as_finite_vector(self.acceleration, 3, 'base reference acceleration'))

    def error(self, base_pose: ArrayLike) -> np.ndarray:
        """The planned pose less ``base_pose`` (x, y, θ), the heading's difference wrapped to
        (−π, π] [m, m, rad]. Shape (3,)."""
        base = np.asarray(base_pose, dtype=float)
        out = self.pose - base
        out[2] = wrap_angle(float(out[2]))
        return out

    def braking_room(
        self, base_pose: ArrayLike, acceleration: ArrayLike, world: bool = False
    ) -> tuple[np.ndarray, np.ndarray]:
        """How far a base at ``base_pose`` may still go on each axis (vx, vy, ω in its own frame,
        or with ``world`` the world's (x, y, θ); down, up) [m, m, rad] and not pass where the
        planned pose would come to rest, were it to brake now from its planned rates at
        ``acceleration`` (on those axes): along the planned motion on an axis, the planned pose's offset from the base plus
        its stopping distance ``v² / (2 a)``; against it, and on an axis it does not move on,
        no end (inf). Braking within it (:meth:`~wmm_control.resolvers.limits.CommandLimits.box`
        with ``room``), the base keeps behind the plan's own braking however its end effector's
        task would draw it on: robot B's base (0.025 m/s²) caught up a lag at the speed the end
        effector asked for and ran 0.2–0.45 m past the stance it could no longer stop at.

        Returns:
            ``(down, up)``, each of shape (3,), non-negative or inf.
        """
        theta = float(np.asarray(base_pose, dtype=float)[2])
        offset, rates = self.error(base_pose), self.rates
        if not world:
            offset, rates = twist_to_base(theta, offset), twist_to_base(theta, rates)
        a = np.asarray(acceleration, dtype=float)
        with np.errstate(divide='ignore', invalid='ignore'):
            stop = np.where(a > 0.0, rates * rates / (2.0 * a), np.inf)
        up = np.where(rates > 0.0, np.maximum(offset + stop, 0.0), np.inf)
        down = np.where(rates < 0.0, np.maximum(stop - offset, 0.0), np.inf)
        return down, up

    def pull(self, base_pose: ArrayLike, gain: ArrayLike, acceleration: ArrayLike, steering: float = 0.0) -> np.ndarray:
        """The rates that bring a base at ``base_pose`` onto the planned pose, in the base's own
        frame (vx, vy, ω): the planned rates as feedforward plus, on each axis, the feedback
        ``gain · e`` (``e`` :meth:`error` in the base's frame) no faster than ``√(2 a |e|)``, the
        speed from which the axis's acceleration limit ``a`` brakes it to rest over its error. A
        base that brakes over metres (robot B, 0.025 m/s²) is not asked for speeds it cannot
        stop from, and comes onto the pose instead of running past it; an axis the base cannot
        move (``a = 0``) gets no feedback. A base without a sideways axis is also steered back
        onto the plan's line as it drives: ``ω += k_y v_r e_y`` (``steering`` = ``k_y``,
        :meth:`SteeringParams.steering_gain`; ``v_r`` the plan's forward speed, its rates in the
        planned pose's frame: negative backing up, zero turning in place or at rest; ``e_y`` the
        sideways entry of ``e``).

        Args:
            base_pose: the base's pose (x, y, θ) in the world [m, m, rad]. Shape (3,).
            gain: the feedback gain of each axis [1/s]. Scalar or shape (3,).
            acceleration: the acceleration limit of each of the base's axes (vx, vy, ω) [m/s²,
                m/s², rad/s²]. Shape (3,).
            steering: ``k_y`` [1/m²]; 0 (a base that moves sideways itself): no steering.

        Returns:
            (vx, vy, ω) [m/s, m/s, rad/s]. Shape (3,).
        """
        theta = float(np.asarray(base_pose, dtype=float)[2])
        error = twist_to_base(theta, self.error(base_pose))
        size = np.abs(error)
        braking = np.sqrt(2.0 * np.asarray(acceleration, dtype=float) * size)
        out = twist_to_base(theta, self.rates) + np.copysign(np.minimum(np.asarray(gain) * size, braking), error)
        if steering > 0.0:
            forward = float(twist_to_base(float(self.pose[2]), self.rates)[0])
            out[2] += steering * forward * float(error[1])
        return out


@dataclass(frozen=True)
class PoseTarget:
    """An end-effector target in the world frame: a set-point, or a point of a trajectory.

    Attributes:
        position: desired position [m]. Shape (3,).
        rotation: desired orientation. Shape (3, 3).
        velocity: desired twist (linear, angular) [m/s, rad/s], world axes; zero for a
            set-point. The velocity-level methods use it as feedforward. Shape (6,).
        acceleration: desired (linear, angular) acceleration [m/s², rad/s²]. Shape (6,).
        base: where a followed plan has the base (:class:`BaseReference`), or None (a goal or
            a trajectory point alone: the methods exactly as the papers have them).
    """

    position: np.ndarray
    rotation: np.ndarray
    velocity: np.ndarray = field(default_factory=lambda: np.zeros(6))
    acceleration: np.ndarray = field(default_factory=lambda: np.zeros(6))
    base: BaseReference | None = None

    @classmethod
    def goal(
        cls, position: ArrayLike, rotation: ArrayLike, stance: ArrayLike | None = None, arm: ArrayLike | None = None
    ) -> Self:
        """A goal: the end effector at rest at ``position``, ``rotation``; with ``stance``
        (x, y, θ) [m, m, rad], the base's place for it, at rest (a :class:`BaseReference` marked
        ``stance``), and ``arm`` the arm's posture there [rad or m] (the stance's inverse
        kinematics), or None (the posture is the method's to find). The one place a stance is
        made: a goal given with a planned base, a held plan point, a plan's final approach."""
        base = None
        if stance is not None:
            base = BaseReference(
                np.asarray(stance, dtype=float), arm=None if arm is None else np.asarray(arm, dtype=float), stance=True
            )
        return cls(position, rotation, base=base)  # type: ignore[arg-type]  # validated on construction

    def __post_init__(self):
        object.__setattr__(self, 'position', as_finite_vector(self.position, 3, 'target position'))
        object.__setattr__(self, 'rotation', _rotation(self.rotation, 'target rotation'))
        object.__setattr__(self, 'velocity', as_finite_vector(self.velocity, 6, 'target velocity'))
        object.__setattr__(self, 'acceleration', as_finite_vector(self.acceleration, 6, 'target acceleration'))

    @classmethod
    def from_rpy(cls, pose: ArrayLike) -> Self:
        """A set-point from ``[x, y, z, roll, pitch, yaw]`` [m, rad] (Sorour Table II layout)."""
        pose = as_finite_vector(pose, 6, 'target pose')
        return cls(pose[:3], matrix_from_rpy(pose[3:]))


@dataclass(frozen=True)
class ResolverDiagnostics:
    """What a user wants to see while a resolver runs.

    Attributes:
        method: the resolver's name.
        mode: 'gross_motion' (ψ target 0), 'mobile_manipulation' (0.5),
            'fine_manipulation' (1), or 'whole_body' for methods without task sharing.
        psi: task-sharing factor ψ used this period (1.0 for whole-body methods).
        position_error: ‖p* − p‖ [m].
        orientation_error: rotation angle between the current and the desired orientation [rad].
        limit_scale: factor s_v in [0, 1] applied to the whole command to keep the velocity
            and braking limits, keeping its direction (1 = unscaled).
        accel_scale: fraction s_a in [0, 1] of the way to that command taken this period, to
            keep the acceleration limits (1 = all of it).
        null_scale: factor in [0, 1] left to the null-space motion once the limits took their
            share (it gives way before the task does; 1 for methods without one).
        compensation_scale: share in [0, 1] of the eq (14) arm command that the arm's limits
            let through; 1 when none was needed or there is no compensation.
        limited: indices (0–2 base twist, 3–9 arm joints) whose bound shaped the command.
        sigma_min: smallest singular value of the arm's analytic Jacobian in the base frame.
        compensated: True once the eq (14) term is in the arm command.
        cycle_time_s: wall time of the call [s].
        reference_time_left: time [s] the set-point trajectory a goal became still has to run
            (the acceleration-level methods); 0 otherwise. Until it ends the goal is not yet
            the target, so it cannot stall (:mod:`~wmm_control.resolvers.progress`).
        clearance: distance of the closest pair the safety stage checks (arm against body,
            itself, the floor) [m]; inf when it checks none.
        closest_pair: that pair's links, ``'a/b'``.
        collision_constraints: pairs within the influence distance (damper rows) this period.
        collision_changed: True when the safety stage changed the method's arm command.
    """

    method: str
    mode: str
    psi: float
    position_error: float
    orientation_error: float
    limit_scale: float
    accel_scale: float
    null_scale: float
    compensation_scale: float
    limited: tuple
    sigma_min: float
    compensated: bool
    cycle_time_s: float
    reference_time_left: float = 0.0
    clearance: float = math.inf
    closest_pair: str = ''
    collision_constraints: int = 0
    collision_changed: bool = False


@dataclass(frozen=True)
class ResolverCommand:
    """One period's command.

    Attributes:
        arm_velocity: arm joint velocities [rad/s or m/s]. Shape (n,).
        base_twist: base twist reference (vx, vy, ω) in the base frame [m/s, m/s, rad/s].
            Shape (3,).
        diagnostics: :class:`ResolverDiagnostics`.
    """

    arm_velocity: np.ndarray
    base_twist: np.ndarray
    diagnostics: ResolverDiagnostics

    def with_arm(self, arm_velocity: ArrayLike, **diagnostics: Any) -> Self:
        """A copy with another arm command and some diagnostics fields replaced."""
        return replace(
            self,
            arm_velocity=np.asarray(arm_velocity, dtype=float),
            diagnostics=replace(self.diagnostics, **diagnostics),
        )


class Resolver(ABC):
    """A redundancy resolution method: the sibling methods of this package share this API."""

    #: Name of the method, as the ``method`` parameter of the ``redundancy_resolver`` node.
    name = 'resolver'

    @abstractmethod
    def step(self, state: RobotState, target: PoseTarget) -> ResolverCommand:
        """One control period.

        Args:
            state: :class:`RobotState`.
            target: :class:`PoseTarget`.

        Returns:
            :class:`ResolverCommand`; every entry finite and within the robot's limits.
        """

    #: the robot's :class:`~wmm_control.kinematics.KinematicModel` (shared, not copied)
    model: 'KinematicModel' = None  # type: ignore[assignment]  # every method's __init__ sets it
    #: the method's :class:`~wmm_control.resolvers.safety.SafetyStage`, which every command passes
    safety: 'SafetyStage' = None  # type: ignore[assignment]  # every method's __init__ sets its stage

    def set_obstacles(self, obstacles: Iterable['Obstacle']) -> None:
        """Keep the robot off ``obstacles`` (:class:`~wmm_control.kinematics.obstacles.Obstacle`,
        world frame) from now on, instead of the previous ones."""
        self.safety.set_obstacles(obstacles)

    def set_base_lag(self, lag: float) -> None:
        """Plan the base's braking near obstacles with the lag τ = ``lag`` [s] of the base
        controller that actually runs (:attr:`~wmm_control.base.BaseController.lag`) instead of
        its robot YAML's defaults.

        Raises:
            ConfigError: ``lag`` is not finite and ≥ 0.
        """
        self.safety.set_base_lag(lag)

    def base_room(
        self, base_pose: ArrayLike, reference: BaseReference, world: bool = False
    ) -> tuple[np.ndarray, np.ndarray] | None:
        """A followed plan's :meth:`BaseReference.braking_room` over the command's entries, as
        :class:`~wmm_control.resolvers.limits.CommandLimits` takes it: the base's linear axes
        (its own (vx, vy), or with ``world`` the world's (x, y), each braking at the slower
        linear axis's limit); its turn and the arm's joints have no such end (inf). None for a
        base without a sideways axis (differential): its path is the way its speed and turn go
        together, and braking its speed alone bent the path (``panda_diff`` came to rest 6 cm
        beside its stance's line, which it cannot close, and the final approach from there
        failed); None for a base that lags its reference (τ > 0, the safety stage's
        :attr:`~wmm_control.resolvers.safety.SafetyStage.base_lag`: robot A's steered wheels),
        whose reference runs ahead of the measured pose by design (with the room robot A's AMP
        and traditional planner lost 2 of the first 25 ``doorway`` goals each that they
        reach without it)."""
        base = self.model.config.base
        if not base.sideways or self.safety.base_lag > 0.0:
            return None
        acceleration = np.asarray(base.acceleration, dtype=float)
        if world:
            axes = [0, 1, 2]
            linear = acceleration[[k for k in base.axes if k < 2]]
            acceleration = np.array([linear.min(), linear.min(), acceleration[2]]) if linear.size else acceleration
        else:
            axes = list(base.axes)
        down, up = reference.braking_room(base_pose, acceleration, world)
        down[2] = up[2] = np.inf
        arm = np.full(self.model.n_arm, np.inf)
        return np.concatenate((down[axes], arm)), np.concatenate((up[axes], arm))

    def compensate(self, command: ResolverCommand, feasible_twist: ArrayLike) -> ResolverCommand:
        """Finish ``command`` with the base controller's answer ``feasible_twist``.

        ``feasible_twist`` is q̇_bf of Sorour eq (15): the twist (vx, vy, ω) [m/s, m/s,
        rad/s], base frame, that the base will execute in answer to ``command.base_twist``.
        Methods without compensation return ``command`` unchanged.
        """
        return command

    @property
    def uses_compensation(self) -> bool:
        """True when :meth:`compensate` changes the command (it needs the feasible twist)."""
        return False

    def reset(self) -> None:  # noqa: B027 (a default: a method without state has nothing to forget)
        """Forget the previous command (the next one starts from rest)."""
