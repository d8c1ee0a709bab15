"""Redundancy resolution: one seam, ``step(state, target) -> command``, one module per method.

* :mod:`~wmm_control.resolvers.pinv`: the whole-body damped pseudo-inverse (Sorour eq 8);
* :mod:`~wmm_control.resolvers.task_sharing`: task sharing (Sorour eqs 9–14);
* :mod:`~wmm_control.resolvers.amp`: adaptive motion planning at acceleration level (Xing eqs 6–15, 23);
* :mod:`~wmm_control.resolvers.traditional`: J⁺ with manipulability in the null space (Xing §4.3).
"""

from dataclasses import fields
from pathlib import Path
from typing import Any

from wmm_control.errors import ConfigError
from wmm_control.kinematics import KinematicModel
from wmm_control.resolvers.interface import PoseTarget, Resolver, ResolverCommand, ResolverDiagnostics, RobotState
from wmm_control.resolvers.limits import CommandLimits, LimitResult
from wmm_control.resolvers.pinv import PinvParams, PinvResolver
from wmm_control.resolvers.pose_servo import PoseServoParams, PoseServoResolver
from wmm_control.resolvers.task_sharing import TaskSharingParams, TaskSharingResolver, psi_of_error
from wmm_control.resolvers.acceleration_level import AccelerationResolver
from wmm_control.resolvers.amp import AmpParams, AmpResolver
from wmm_control.resolvers.traditional import TraditionalParams, TraditionalResolver
from wmm_control.robot_config import RobotConfig

__all__ = [
    'CommandLimits',
    'LimitResult',
    'PinvParams',
    'PinvResolver',
    'PoseServoParams',
    'PoseServoResolver',
    'PoseTarget',
    'Resolver',
    'ResolverCommand',
    'ResolverDiagnostics',
    'RobotState',
    'TaskSharingParams',
    'TaskSharingResolver',
    'psi_of_error',
    'METHODS',
    'make_resolver',
    'method_parameters',
    'AmpParams',
    'AmpResolver',
    'TraditionalParams',
    'TraditionalResolver',
]

#: (resolver class, parameters class) by ``method`` name.
METHODS = {
    cls.name: (cls, params)
    for cls, params in (
        (PinvResolver, PinvParams),
        (TaskSharingResolver, TaskSharingParams),
        (AmpResolver, AmpParams),
        (TraditionalResolver, TraditionalParams),
    )
}


def method_parameters(method: str) -> tuple[str, ...]:
    """Names of the parameters of ``method`` (its parameters class's fields, ``dt`` included)."""
    return tuple(f.name for f in fields(METHODS[method][1]))


def make_resolver(
    method: str, robot: str | Path | RobotConfig | KinematicModel, **params: Any
) -> PoseServoResolver | AccelerationResolver:
    """Build the resolver named ``method`` with keyword parameters of its params class.

    Raises:
        ConfigError: unknown method or an invalid parameter.
    """
    try:
        cls, params_cls = METHODS[method]
    except KeyError as exc:
        raise ConfigError(f'unknown method {method!r}; one of {sorted(METHODS)}') from exc
    try:
        # METHODS pairs each resolver class with its own parameters class
        return cls(robot, params_cls(**params))  # type: ignore[arg-type]
    except TypeError as exc:
        raise ConfigError(f'method {method}: {exc}') from exc
