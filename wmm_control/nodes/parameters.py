"""The nodes' ROS parameters: declaration, defaults, validation and run-time changes.

Every default is written once. A node's own tuning lives in ``config/<node>.yaml``
(``<node_name>: ros__parameters:``); a robot's geometry, limits and start state live in its
robot YAML (``config/robots/<robot>.yaml``). The code declares each parameter with a
description, a range (numeric ones) and whether it may change at run time, and takes its
default from that file; a parameter that follows the robot (``Param.default_from``) must not
appear in the node YAML.
"""

import array
import dataclasses
import math
from collections.abc import Callable, Mapping, Sequence
from pathlib import Path
from dataclasses import dataclass
from types import SimpleNamespace
from typing import Any

import rclpy
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.parameter import Parameter as RosParameter

from wmm_control.errors import ConfigError
from wmm_control.paths import load_defaults
from wmm_control.robot_config import RobotConfig, load_robot, robot_names

__all__ = [
    'Param',
    'declare_parameters',
    'load_defaults',
    'robot_method',
    'robot_param',
    'robot_period',
    'require_base',
    'parameter_error',
    'max_state_wait_param',
    'defaults_elsewhere',
]


@dataclass(frozen=True)
class Param:
    """One ROS parameter: name, description, numeric range or allowed strings, mutability.

    Every numeric parameter (scalar or array) needs ``lo`` and ``hi``: a FloatingPointRange
    (IntegerRange for int defaults) that rclpy enforces on scalars and this module on every
    element of an array. ``choices`` restricts a string parameter, ``size`` the allowed lengths
    of an array. A parameter that is not ``read_only`` takes effect when set at run time (the
    node's ``on_change`` hook, or its value read where it is used).

    ``default_from(values)`` gives the default of a parameter whose home is not the node YAML
    (e.g. the robot YAML's start state), from the values declared before it.
    """

    name: str
    description: str
    lo: float | None = None
    hi: float | None = None
    choices: tuple | None = None
    read_only: bool = False
    size: tuple | None = None
    default_from: Callable[..., Any] | None = None
    #: where ``default_from`` takes the default from, as the parameter tables name it ('' : the
    #: robot YAML)
    default_home: str = ''


def robot_param(description: str = '') -> Param:
    """The ``robot`` parameter every node has: a shipped robot's name, an alias A/B, or a path to
    a robot YAML file (validated when the node loads it: an unknown name or a bad file stops the
    start-up with a message naming the file and the item)."""
    return Param(
        'robot',
        (description + ' ' if description else '')
        + f'A robot name ({", ".join(robot_names())}; aliases A, B) or a path to a robot YAML file.',
        read_only=True,
    )


def max_state_wait_param() -> Param:
    """The ``max_state_wait`` parameter of every node that answers ``/joint_states``."""
    return Param(
        'max_state_wait',
        'Longest time [s] a joint state may wait in this node (from its receipt to its '
        'cycle, steady clock) and still run a cycle: one that waited longer (the node was held up, and a '
        'real-time simulator has stepped past it) runs none; nor does one that reached this node that much '
        'later than joint states usually do (it was queued in the transport while the node was held up). '
        '0: no limit. Not applied while the simulator steps in lockstep (it says so on sim/lockstep_timeout).',
        lo=0.0,
        hi=60.0,
    )


def defaults_elsewhere(specs: Sequence[Param], defaults: Mapping[str, Any], home: str) -> tuple[Param, ...]:
    """``specs``, each one named in ``defaults`` taking its default from there (its one home: a
    parameter class's field, a constructor's signature), named ``home`` in the parameter tables,
    instead of the node YAML."""
    return tuple(
        dataclasses.replace(spec, default_from=lambda _values, d=defaults[spec.name]: d, default_home=home)
        if spec.name in defaults
        else spec
        for spec in specs
    )


def require_base(robot: RobotConfig, families: Sequence[str], node_name: str) -> None:
    """Raise a ConfigError unless ``robot``'s base is one of ``families`` (this node drives those)."""
    if robot.base.family not in families:
        raise ConfigError(
            f'robot {robot.name!r} has a {robot.base.family} base; {node_name} drives {" and ".join(families)} bases'
        )


def robot_period(values: SimpleNamespace) -> float:
    """The default of a node's ``period``: the control period of its ``robot`` (the robot YAML's
    ``period``), so that the simulator and every controller agree unless one is told otherwise."""
    return load_robot(values.robot).period


def robot_method(values: SimpleNamespace) -> str:
    """The default of ``redundancy_resolver``'s ``method``: its ``robot``'s (the robot YAML's
    ``method``)."""
    return load_robot(values.robot).method


def _is_number(value):
    return isinstance(value, (int, float)) and not isinstance(value, bool)


def _numeric(value):
    """True for a number or a non-empty list of numbers."""
    if isinstance(value, (list, tuple)):
        return bool(value) and all(_is_number(v) for v in value)
    return _is_number(value)


def _descriptor(spec, default):
    desc = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if _numeric(default):
        if spec.lo is None or spec.hi is None:
            raise ConfigError(f'parameter {spec.name}: a numeric parameter needs a range (lo and hi)')
        first = default[0] if isinstance(default, (list, tuple)) else default
        if isinstance(first, int):
            desc.integer_range = [IntegerRange(from_value=int(spec.lo), to_value=int(spec.hi), step=0)]
        else:
            desc.floating_point_range = [
                FloatingPointRange(from_value=float(spec.lo), to_value=float(spec.hi), step=0.0)
            ]
    elif spec.lo is not None or spec.hi is not None:
        raise ConfigError(f'parameter {spec.name}: a range needs a numeric default, got {default!r}')
    constraints = []
    if spec.choices:
        constraints.append('one of: ' + ', '.join(spec.choices))
    if spec.size:
        constraints.append('length ' + ' or '.join(str(n) for n in spec.size))
    if isinstance(default, (list, tuple)) and _numeric(default):
        constraints.append(f'every element in [{spec.lo}, {spec.hi}]')
    desc.additional_constraints = '; '.join(constraints)
    return desc


def parameter_error(spec: Param, value: Any) -> str:
    """Why ``value`` is not valid for ``spec`` ('' when it is).

    Checks what rclpy's descriptor does not: allowed strings, finiteness, and the length and
    element range of an array.
    """
    if spec.choices and value not in spec.choices:
        return f'{value!r} is not one of {list(spec.choices)}'
    if isinstance(value, float) and not math.isfinite(value):
        return f'must be finite, got {value}'
    if isinstance(value, (list, tuple, array.array)):
        values = list(value)
        if spec.size and len(values) not in spec.size:
            return f'expected {" or ".join(str(n) for n in spec.size)} values, got {len(values)}'
        if spec.lo is not None and values and all(_is_number(v) for v in values):
            bad = [v for v in values if not (math.isfinite(v) and spec.lo <= v <= spec.hi)]
            if bad:
                return f'values {bad} are outside [{spec.lo}, {spec.hi}]'
    return ''


def _plain(value):
    return list(value) if isinstance(value, (list, tuple, array.array)) else value


def declare_parameters(
    node: 'rclpy.node.Node',
    yaml_name: str,
    specs: Sequence[Param],
    on_change: Mapping[str, Callable[[Any], object]] | None = None,
    check: Callable[[SimpleNamespace], str] | None = None,
) -> SimpleNamespace:
    """Declare every parameter of ``specs``, defaults from ``config/<yaml_name>``, and keep them live.

    An integer for a double parameter (``-p stall_time:=5``, ``ros2 param set NODE stall_time 5``)
    is taken as that double, at start-up and at run time.

    A set at run time (``ros2 param set``, the SetParameters service) is validated by rclpy
    (type, read-only, scalar range) and by :func:`parameter_error` and ``check``; a refused one
    keeps the old value and answers with the reason. An accepted one updates the returned
    namespace and calls ``on_change[name](value)``.

    Args:
        node: the node.
        yaml_name: its parameter file, ``config/<yaml_name>``; its stem names the section.
        specs: the :class:`Param` of every parameter.
        on_change: ``{name: callable(value)}``, run after a run-time change of ``name``.
        check: ``check(values) -> reason``: cross-parameter constraints on the namespace the
            values would have after a change ('' accepts).

    Returns:
        A namespace with one attribute per parameter (its current value).

    Raises:
        ConfigError: a default is missing from the YAML or written both there and elsewhere
            (``default_from``), a value is out of range or invalid (the message names the
            parameter and the allowed values).
    """
    # The section is the node's default name, the file's stem: a node renamed at start-up
    # (``-r __node:=left_base``) keeps its defaults; ``--params-file`` overrides go by name.
    defaults = load_defaults(yaml_name, Path(yaml_name).stem)
    values: dict[str, Any] = {}
    for spec in specs:
        if spec.default_from is not None:
            if spec.name in defaults:
                raise ConfigError(
                    f'config/{yaml_name}: {spec.name!r} has its default elsewhere (one home '
                    'for every default): remove it from this file'
                )
            default = spec.default_from(SimpleNamespace(**values))
        elif spec.name not in defaults:
            raise ConfigError(f'config/{yaml_name}: no default for parameter {spec.name!r}')
        else:
            default = defaults[spec.name]
        if isinstance(default, int) and not isinstance(default, bool) and isinstance(spec.lo, float):
            default = float(default)
        if isinstance(default, (list, tuple)) and not default:
            raise ConfigError(f'parameter {spec.name}: an empty list has no type; give a value')
        _integer_override_as_double(node, spec.name, default)
        try:
            value = _plain(node.declare_parameter(spec.name, default, _descriptor(spec, default)).value)
        except (rclpy.exceptions.InvalidParameterValueException, rclpy.exceptions.InvalidParameterTypeException) as exc:
            raise ConfigError(f'parameter {spec.name}: {exc}') from exc
        reason = parameter_error(spec, value)
        if reason:
            raise ConfigError(f'parameter {spec.name}: {reason}')
        values[spec.name] = value
    namespace = SimpleNamespace(**values)
    if check is not None:
        reason = check(namespace)
        if reason:
            raise ConfigError(reason)
    _watch(node, namespace, {s.name: s for s in specs}, on_change or {}, check)
    return namespace


def _is_double(value) -> bool:
    """True for a float, or a non-empty list of floats: a parameter of type DOUBLE or DOUBLE_ARRAY."""
    if isinstance(value, (list, tuple, array.array)):
        return bool(value) and all(isinstance(v, float) for v in value)
    return isinstance(value, float)


def _as_double(prm: RosParameter) -> RosParameter:
    """``prm`` with its value as a double (array) when it is an integer (array), else ``prm``."""
    if prm.type_ == RosParameter.Type.INTEGER:
        return RosParameter(prm.name, RosParameter.Type.DOUBLE, float(prm.value))
    if prm.type_ == RosParameter.Type.INTEGER_ARRAY:
        return RosParameter(prm.name, RosParameter.Type.DOUBLE_ARRAY, [float(v) for v in prm.value])
    return prm


def _integer_override_as_double(node: 'rclpy.node.Node', name: str, default) -> None:
    """An integer given at start-up (``-p stall_time:=5``, a params file's ``5``) for a double
    parameter is taken as that double (rclpy refuses it: a type mismatch)."""
    # rclpy's start-up values (command line, params files): no public API reads or converts them.
    overrides = node._parameter_overrides
    if name in overrides and _is_double(default):
        overrides[name] = _as_double(overrides[name])


def _watch(node, namespace, specs, on_change, check):
    """Validate run-time sets of the parameters of ``specs``, then apply them to ``namespace``."""

    def validate(params: list[RosParameter]) -> SetParametersResult:
        changes = {}
        for prm in params:
            spec = specs.get(prm.name)
            if spec is None:
                continue  # use_sim_time and the like: rclpy's
            reason = parameter_error(spec, prm.value)
            if reason:
                return SetParametersResult(successful=False, reason=f'{prm.name}: {reason}')
            changes[prm.name] = _plain(prm.value)
        if changes and check is not None:
            reason = check(SimpleNamespace(**{**vars(namespace), **changes}))
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def apply(params: list[RosParameter]) -> None:
        for prm in params:
            if prm.name in specs:
                value = _plain(prm.value)
                setattr(namespace, prm.name, value)
                if prm.name in on_change:
                    on_change[prm.name](value)
                node.get_logger().info(f'parameter {prm.name} set to {value}')

    doubles = {name for name, spec in specs.items() if _is_double(getattr(namespace, name))}

    def integers_as_doubles(params: list[RosParameter]) -> list[RosParameter]:
        # ``ros2 param set NODE stall_time 5`` sends an integer: taken as 5.0 for a double parameter.
        return [_as_double(prm) if prm.name in doubles else prm for prm in params]

    node.add_pre_set_parameters_callback(integers_as_doubles)
    node.add_on_set_parameters_callback(validate)
    node.add_post_set_parameters_callback(apply)
