"""Helpers shared by the nodes: parameters, command messages, freshness, diagnostics, main().

Parameter defaults live in ``config/<node>.yaml`` (``<node_name>: ros__parameters:``); the
code declares each parameter with a description and range and takes its default from
that file, so the YAML is the one place a default is written.
"""

import math
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray

from wmm_control.errors import ConfigError, WmmError
from wmm_control.paths import config_path

__all__ = [
    'Param', 'declare_parameters', 'load_defaults', 'float_array', 'parse_command',
    'Freshness', 'diagnostic_status', 'diagnostic_array', 'seconds', 'run_node',
]


@dataclass(frozen=True)
class Param:
    """One ROS parameter: name, description, optional numeric range or allowed strings.

    ``lo``/``hi`` give a FloatingPointRange (or IntegerRange for int defaults) that rclpy
    enforces on overrides; ``choices`` restricts a string parameter.
    """

    name: str
    description: str
    lo: float = None
    hi: float = None
    choices: tuple = None
    read_only: bool = False


def load_defaults(yaml_name, node_name):
    """``ros__parameters`` of ``node_name`` (or ``/**``) from ``config/<yaml_name>``."""
    path = config_path(yaml_name)
    try:
        doc = yaml.safe_load(path.read_text()) or {}
    except (OSError, yaml.YAMLError) as exc:
        raise ConfigError(f'cannot read parameter defaults {path}: {exc}') from exc
    for key in (node_name, '/' + node_name, '/**'):
        section = doc.get(key)
        if isinstance(section, dict) and isinstance(section.get('ros__parameters'), dict):
            return section['ros__parameters']
    raise ConfigError(f'{path}: no "{node_name}: ros__parameters:" section')


def _descriptor(spec, default):
    desc = ParameterDescriptor(description=spec.description, read_only=spec.read_only)
    if spec.lo is not None or spec.hi is not None:
        if isinstance(default, bool) or not isinstance(default, (int, float)):
            raise ConfigError(f'parameter {spec.name}: a range needs a numeric default, got {default!r}')
        if isinstance(default, int):
            desc.integer_range = [IntegerRange(
                from_value=int(spec.lo if spec.lo is not None else -2**62),
                to_value=int(spec.hi if spec.hi is not None else 2**62), step=0)]
        else:
            desc.floating_point_range = [FloatingPointRange(
                from_value=float(spec.lo if spec.lo is not None else -1e300),
                to_value=float(spec.hi if spec.hi is not None else 1e300), step=0.0)]
    if spec.choices:
        desc.additional_constraints = 'one of: ' + ', '.join(spec.choices)
    return desc


def declare_parameters(node, yaml_name, specs):
    """Declare every parameter of ``specs`` with its defaults from ``config/<yaml_name>``.

    Returns:
        A namespace with one attribute per parameter (its value after overrides).

    Raises:
        ConfigError: a default is missing from the YAML, a value is out of range or not
            an allowed choice (the message names the parameter and the allowed values).
    """
    defaults = load_defaults(yaml_name, node.get_name())
    values = {}
    for spec in specs:
        if spec.name not in defaults:
            raise ConfigError(f'config/{yaml_name}: no default for parameter {spec.name!r}')
        default = defaults[spec.name]
        if isinstance(default, int) and not isinstance(default, bool) and spec.lo is not None \
                and isinstance(spec.lo, float):
            default = float(default)
        try:
            if isinstance(default, list) and not default:
                # rclpy cannot infer a type from []: an empty default is an optional double array.
                value = node.declare_parameter(
                    spec.name, Parameter.Type.DOUBLE_ARRAY, _descriptor(spec, default)).value
                value = [] if value is None else list(value)
            else:
                value = node.declare_parameter(spec.name, default, _descriptor(spec, default)).value
        except (rclpy.exceptions.InvalidParameterValueException,
                rclpy.exceptions.InvalidParameterTypeException) as exc:
            raise ConfigError(f'parameter {spec.name}: {exc}') from exc
        if spec.choices and value not in spec.choices:
            raise ConfigError(f'parameter {spec.name}: {value!r} is not one of {list(spec.choices)}')
        if isinstance(value, float) and not math.isfinite(value):
            raise ConfigError(f'parameter {spec.name}: must be finite, got {value}')
        values[spec.name] = value
    return SimpleNamespace(**values)


def float_array(values):
    """A ``std_msgs/Float64MultiArray`` holding ``values``."""
    msg = Float64MultiArray()
    msg.data = [float(v) for v in values]
    return msg


def parse_command(msg, size):
    """Validate a ``Float64MultiArray`` command.

    Returns:
        ``(array, '')`` when it holds ``size`` finite numbers, else ``(None, reason)``.
    """
    data = np.asarray(msg.data, dtype=float)
    if data.shape != (size,):
        return None, f'expected {size} values, got {data.size}'
    if not np.all(np.isfinite(data)):
        return None, f'non-finite values at indices {np.flatnonzero(~np.isfinite(data)).tolist()}'
    return data, ''


def seconds(clock):
    """The clock's current time in seconds (float)."""
    return clock.now().nanoseconds * 1e-9


class Freshness:
    """Age of the last received message, judged by the receiver's clock at receipt.

    A message's own header stamp is never used: a sender with a skewed or paused clock
    cannot make stale data look fresh.
    """

    def __init__(self, timeout):
        self.timeout = float(timeout)
        self._last = None

    def mark(self, now):
        """Record a receipt at time ``now`` [s]."""
        self._last = now

    def reset(self):
        self._last = None

    def age(self, now):
        """Seconds since the last receipt; infinity before the first one."""
        return math.inf if self._last is None else now - self._last

    def fresh(self, now):
        """True when a message arrived within the timeout (and the clock did not jump back)."""
        age = self.age(now)
        return 0.0 <= age <= self.timeout


def diagnostic_status(name, hardware_id, level, message, values):
    """A ``DiagnosticStatus``; ``level`` is 'ok', 'warn' or 'error'; values become KeyValues."""
    status = DiagnosticStatus()
    status.level = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN,
                    'error': DiagnosticStatus.ERROR}[level]
    status.name = name
    status.hardware_id = hardware_id
    status.message = message
    status.values = [KeyValue(key=str(k), value=_kv(v)) for k, v in values.items()]
    return status


def _kv(value):
    if isinstance(value, float):
        return f'{value:.9g}'
    if isinstance(value, (list, tuple, np.ndarray)):
        return '[' + ', '.join(_kv(float(v)) if isinstance(v, (float, np.floating)) else str(v)
                               for v in value) + ']'
    return str(value)


def diagnostic_array(stamp, statuses):
    """A ``DiagnosticArray`` with header stamp ``stamp``."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = list(statuses)
    return msg


def default_executor():
    """rclpy's events executor (several times faster per message in Jazzy), else single-threaded."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return SingleThreadedExecutor()
    return EventsExecutor()


def run_node(node_factory, args=None, executor_factory=default_executor):
    """Standard main(): init, build the node, spin until Ctrl-C or shutdown, clean up.

    A configuration error at start-up is logged and gives exit code 2.
    """
    rclpy.init(args=args)
    node = None
    try:
        node = node_factory()
        executor = executor_factory()
        executor.add_node(node)
        # spin_once in a loop rather than spin(): the events executor's spin() does not
        # return on SIGINT, while this loop sees the shutdown that rclpy's handler triggers.
        while rclpy.ok():
            executor.spin_once(timeout_sec=0.1)
    except (KeyboardInterrupt, ExternalShutdownException):
        pass
    except WmmError as exc:
        logger = node.get_logger() if node is not None else rclpy.logging.get_logger('wmm_control')
        logger.fatal(f'{type(exc).__name__}: {exc}')
        return 2
    finally:
        if node is not None:
            node.destroy_node()
        rclpy.try_shutdown()
    return 0
