"""One contract for every base controller, whatever its wheels (ROS-free).

A base controller answers, once per period, the resolver's base twist reference ξ̇* with
joint rate commands for the base's command groups and the feasible twist q̇_bf those commands
realise (Sorour et al. 2019 Fig 4: the middle block between the resolver and the arm
compensation of eq 14). Every family implements :class:`BaseController`:

- :class:`SteerableBaseController`: the steerable base of Sorour §IV (:class:`SwmrController`), groups
  ``steer`` and ``drive``, closed on the measured steer angles;
- :class:`WheelBaseController`: a Mecanum (Xing eq 16) or differential base
  (:class:`WheelController`), one group ``wheel``.

The group names are those of the simulator's ``world.command_groups`` and of the
``/<group>_controller/commands`` topics. Joint values go in and out per group: a mapping
group → array in the order of ``command_groups[group]``.

The adapters only translate: the numbers are those of the wrapped controller, which stays
available as ``controller``. :func:`make_base_controller` builds the one of a robot.
"""

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any, Protocol, Self, runtime_checkable

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.base.steerable_kinematics import SteerableGeometry
from wmm_control.base.swmr_controller import SwmrController, SwmrParams
from wmm_control.base.wheel_controller import WheelController
from wmm_control.errors import ConfigError
from wmm_control.robot_config import DifferentialBase, MecanumBase, RobotConfig, SteerableBase

__all__ = [
    'BaseCommand',
    'BaseController',
    'SteerableBaseController',
    'WheelBaseController',
    'base_controller_class',
    'make_base_controller',
]

#: Joint values per command group: group name → array in the group's joint order.
Groups = Mapping[str, np.ndarray]


@dataclass(frozen=True)
class BaseCommand:
    """One period's answer of a base controller.

    Attributes:
        rates: joint rate commands [rad/s] per command group, each in the order of
            ``command_groups[group]``; every group of the controller is present.
        feasible_twist: q̇_bf, the twist (vx, vy, ω) [m/s, m/s, rad/s] (base frame) the base
            executes over the coming period with these rates: what the arm compensation of
            Sorour eq (14) needs. Shape (3,).
        status: the family's status word (``'ok'``, ``'stopped'``, ``'solver_failure'``;
            ``'tracking'``, ``'limited'``, ``'braking'``).
        detail: the wrapped controller's own output (:class:`SwmrOutput` or :class:`WheelOutput`).
    """

    rates: dict
    feasible_twist: np.ndarray
    status: str
    detail: Any


@runtime_checkable
class BaseController(Protocol):
    """What every base controller offers.

    Attributes:
        family: the base family (``'steerable'``, ``'mecanum'``, ``'differential'``).
        command_groups: ordered mapping group name → tuple of joint names (command order).
        required_groups: the groups whose joints a joint state must carry to run a cycle
            (those whose positions the controller closes on, or whose rates it reads).
        rate_limits: |q̇| bound per group [rad/s] (a number or one per joint).
        velocity_limit: |vx|, |vy|, |ω| bounds of the base [m/s, m/s, rad/s]. Shape (3,).
        lag: τ [s], the time constant with which the base's twist follows its reference (0
            for a base that tracks it within its acceleration limits); the safety stage plans
            a lagging base's braking with it.
        resync_from_rates: whether a start after a gap in the measurements (``reset`` when they
            come back) goes on from the measured rates (a wheeled base) or starts at rest from
            the measured positions (a steerable base: it re-reads its steer angles).
        controller: the wrapped family controller.
    """

    family: str
    command_groups: Mapping[str, tuple]
    required_groups: tuple
    rate_limits: Mapping[str, Any]
    velocity_limit: np.ndarray
    lag: float
    resync_from_rates: bool
    controller: Any

    def reset(self, positions: Groups | None = None, rates: Groups | None = None) -> None:
        """Start again from the measured joints: at rest when ``rates`` is None, else going on
        from the measured rates (the last command was not applied as sent)."""

    def step(self, reference, positions: Groups | None = None) -> BaseCommand:
        """One period towards ``reference`` ξ̇* (base frame, Shape (3,); beyond the limits it is
        scaled into them), closed on the measured ``positions`` when given. ``reference``
        None (stale or missing) brakes the base to rest at its acceleration limits."""

    def diagnostic_values(self, command: BaseCommand) -> dict:
        """The family's values of ``command`` for ``/diagnostics``."""

    def describe(self) -> str:
        """One line on the controller and its limits (for the start-up log)."""

    @classmethod
    def default_lag(cls, robot: RobotConfig) -> float:
        """τ [s] of this controller on ``robot`` at the robot YAML's defaults: the ``lag`` an
        instance made without overrides has."""


class SteerableBaseController:
    """:class:`BaseController` of a steerable base: :class:`SwmrController` (Sorour §IV).

    Groups ``steer`` (β̇_ref) and ``drive`` (φ̇_ref); the feasible twist is ``twist_executed``.
    The measured steer angles close the loop (``beta_meas``); a ``None`` reference brakes.
    """

    family = SteerableBase.family
    required_groups = ('steer',)
    resync_from_rates = False

    def __init__(self, controller: SwmrController, base: SteerableBase) -> None:
        self.controller = controller
        self.command_groups: Mapping[str, tuple] = base.command_groups
        p = controller.params
        self.rate_limits: Mapping[str, Any] = {'steer': p.steer_rate_limit, 'drive': p.drive_rate_limit}
        self.velocity_limit = np.array(p.base_velocity_limit, dtype=float)
        self.lag = p.lag

    @classmethod
    def default_lag(cls, robot: RobotConfig) -> float:
        """:attr:`SwmrParams.lag` (1/K_p + 1/λ) at the parameters' defaults."""
        return SwmrParams.from_robot_config(robot).lag

    @classmethod
    def from_robot_config(cls, robot: RobotConfig, dt: float, **overrides: Any) -> Self:
        """Geometry, joints and limits from a steerable robot; ``overrides``: :class:`SwmrParams`
        fields (``kp``, ``icr_gain``, ...)."""
        params = SwmrParams.from_robot_config(robot, dt=dt, **overrides)
        # a steerable base: SwmrParams.from_robot_config has raised for any other
        base: SteerableBase = robot.base  # type: ignore[assignment]
        return cls(SwmrController(SteerableGeometry.from_config(base), params), base)

    def reset(self, positions: Groups | None = None, rates: Groups | None = None) -> None:
        c = self.controller
        beta = c.beta if positions is None else positions['steer']
        if rates is None:
            c.reset(beta)
        else:
            c.restart(beta, rates['steer'], rates['drive'])

    def step(self, reference: ArrayLike | None, positions: Groups | None = None) -> BaseCommand:
        beta = None if positions is None else positions['steer']
        if reference is None:
            out = self.controller.step(np.zeros(3), beta_meas=beta, brake=True)
        else:
            out = self.controller.step(reference, beta_meas=beta)
        return BaseCommand({'steer': out.beta_dot_ref, 'drive': out.phi_dot_ref}, out.twist_executed, out.status, out)

    def diagnostic_values(self, command: BaseCommand) -> dict:
        out = command.detail
        return {
            'route': out.route,
            'qp_status': out.qp_status,
            'icr_next_xy': out.icr_next.point,
            'icr_at_infinity': out.icr_next.at_infinity,
            'active_constraints': list(out.active_constraints),
            'solve_time_us': out.solve_time_s * 1e6,
            'beta_ref': out.beta_ref,
        }

    def describe(self) -> str:
        p = self.controller.params
        return (
            f'{self.controller.geometry.n_wheels} modules, t_s {p.dt} s, β̇ ≤ {p.steer_rate_limit} rad/s, '
            f'β̈ ≤ {p.steer_accel_limit} rad/s²'
        )


class WheelBaseController:
    """:class:`BaseController` of a Mecanum or differential base: :class:`WheelController`.

    One group ``wheel`` (the robot's wheel order); the feasible twist is the wheel map of the
    rates. The wheel positions are not needed; ``reset`` with rates goes on from the twist
    the measured wheel rates make.
    """

    required_groups = ('wheel',)
    resync_from_rates = True
    lag = 0.0  # the wheel controller tracks its reference within its acceleration limits

    def __init__(self, controller: WheelController, base: MecanumBase | DifferentialBase) -> None:
        self.controller = controller
        self.family = base.family
        self.command_groups: Mapping[str, tuple] = base.command_groups
        self.rate_limits: Mapping[str, Any] = {'wheel': controller.params.wheel_rate_limit}
        self.velocity_limit = np.array(controller.params.velocity_limit, dtype=float)

    @classmethod
    def default_lag(cls, robot: RobotConfig) -> float:
        """0: the wheel controller tracks its reference within its acceleration limits."""
        return cls.lag

    @classmethod
    def from_robot_config(cls, robot: RobotConfig, dt: float, **overrides: Any) -> Self:
        """Wheel map, joints and limits from a Mecanum or differential robot.

        Raises:
            ConfigError: any ``overrides`` (the wheel controller has no parameters to change).
        """
        if overrides:
            raise ConfigError(f'robot {robot.name!r} has a {robot.base.family} base: no parameters {sorted(overrides)}')
        controller = WheelController.from_robot_config(robot, dt)
        # a Mecanum or differential base: WheelController.from_robot_config has raised for any other
        return cls(controller, robot.base)  # type: ignore[arg-type]

    def reset(self, positions: Groups | None = None, rates: Groups | None = None) -> None:
        if rates is None:
            self.controller.reset()
        else:
            self.controller.restart(rates['wheel'])

    def step(self, reference: ArrayLike | None, positions: Groups | None = None) -> BaseCommand:
        out = self.controller.stop() if reference is None else self.controller.step(reference)
        return BaseCommand({'wheel': out.wheel_rates}, out.twist, out.status, out)

    def diagnostic_values(self, command: BaseCommand) -> dict:
        out = command.detail
        return {
            'velocity_scale': out.velocity_scale,
            'accel_scale': out.accel_scale,
            'reference_dropped': out.dropped,
            'reference_limited': out.reference,
            'wheel_rates': out.wheel_rates,
            'wheel_rate_ratio': float(np.max(np.abs(out.wheel_rates))) / self.controller.params.wheel_rate_limit,
        }

    def describe(self) -> str:
        p = self.controller.params
        return (
            f't_s {p.dt} s, |v| ≤ {list(p.velocity_limit)}, |a| ≤ {list(p.accel_limit)}, '
            f'wheels ≤ {p.wheel_rate_limit} rad/s'
        )


def make_base_controller(
    robot: RobotConfig, dt: float, **overrides: Any
) -> SteerableBaseController | WheelBaseController:
    """The base controller of ``robot`` (a :class:`~wmm_control.robot_config.RobotConfig`) with
    period ``dt`` [s]: :class:`SteerableBaseController` or :class:`WheelBaseController`.

    Args:
        overrides: :class:`SwmrParams` fields of a steerable base (``kp``, ``icr_gain``); a
            wheeled base has none.

    Raises:
        ConfigError: overrides for a wheeled base, or a base of no known family.
    """
    return base_controller_class(robot).from_robot_config(robot, dt, **overrides)


def base_controller_class(robot: RobotConfig) -> type[SteerableBaseController] | type[WheelBaseController]:
    """The :class:`BaseController` class that drives ``robot``'s base: the one place that maps a
    base family to its controller.

    Raises:
        ConfigError: a base of no known family.
    """
    match robot.base:
        case SteerableBase():
            return SteerableBaseController
        case MecanumBase() | DifferentialBase():
            return WheelBaseController
    raise ConfigError(f'robot {robot.name!r} has a base of no known family: {type(robot.base).__name__}')
