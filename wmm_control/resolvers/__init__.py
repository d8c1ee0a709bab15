"""Redundancy resolution: one seam, ``step(state, target) -> command``, one module per method.

* :mod:`~wmm_control.resolvers.pinv`: the whole-body damped pseudo-inverse (Sorour eq 8);
* :mod:`~wmm_control.resolvers.task_sharing`: task sharing (Sorour eqs 9–14).
"""

from wmm_control.resolvers.interface import (
    PoseTarget, Resolver, ResolverCommand, ResolverDiagnostics, RobotState)
from wmm_control.resolvers.limits import CommandLimits, LimitResult
from wmm_control.resolvers.pinv import PinvParams, PinvResolver
from wmm_control.resolvers.pose_servo import PoseServoParams, PoseServoResolver
from wmm_control.resolvers.task_sharing import TaskSharingParams, TaskSharingResolver, psi_of_error

__all__ = [
    'CommandLimits', 'LimitResult', 'PinvParams', 'PinvResolver', 'PoseServoParams', 'PoseServoResolver',
    'PoseTarget', 'Resolver', 'ResolverCommand', 'ResolverDiagnostics', 'RobotState', 'TaskSharingParams',
    'TaskSharingResolver', 'psi_of_error', 'METHODS', 'make_resolver',
]

#: Resolver class by ``method`` name.
METHODS = {PinvResolver.name: PinvResolver, TaskSharingResolver.name: TaskSharingResolver}


def make_resolver(method, robot='steerable', **params):
    """Build the resolver named ``method`` with keyword parameters of its params class.

    Raises:
        ConfigError: unknown method or an invalid parameter.
    """
    from wmm_control.errors import ConfigError
    try:
        cls = METHODS[method]
    except KeyError as exc:
        raise ConfigError(f'unknown method {method!r}; one of {sorted(METHODS)}') from exc
    params_cls = TaskSharingParams if cls is TaskSharingResolver else PinvParams
    try:
        return cls(robot, params_cls(**params))
    except TypeError as exc:
        raise ConfigError(f'method {method}: {exc}') from exc
