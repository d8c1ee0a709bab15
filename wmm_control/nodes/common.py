"""Helpers shared by the nodes: parameters, command messages, freshness, diagnostics, main().

Every default is written once. A node's own tuning lives in ``config/<node>.yaml``
(``<node_name>: ros__parameters:``); a robot's geometry, limits and start state live in its
robot YAML (``config/robots/<robot>.yaml``). The code declares each parameter with a
description, a range (numeric ones) and whether it may change at run time, and takes its
default from that file; a parameter that follows the robot (``Param.default_from``) must not
appear in the node YAML.
"""

import array
import atexit
import math
import os
import signal
import statistics
import time
import threading
from collections import deque
from pathlib import Path
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import rclpy
import yaml
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor, SetParametersResult
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.parameter import Parameter as RosParameter
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.signals import SignalHandlerOptions
from rclpy.time_source import TimeSource

from wmm_control.checks import Freshness
from wmm_control.errors import ConfigError, WmmError
from wmm_control.nodes.conversions import float_array, twist_stamped
from wmm_control.paths import config_path
from wmm_control.robot_config import load_robot, robot_names

RCLError = _rclpy.RCLError

__all__ = [
    'Param', 'declare_parameters', 'load_defaults', 'robot_method', 'robot_param', 'robot_period', 'require_base', 'parameter_error', 'float_array', 'parse_command',
    'Freshness', 'diagnostic_status', 'node_status', 'diagnostic_array', 'seconds', 'run_node', 'guard_clock',
    'stamp_key', 'parse_base_reference', 'twist_stamped', 'JointSelector', 'StampedExchange',
    'BaseReference', 'JointStateWatchdog', 'max_state_wait_param', 'StampGate', 'STATE_PUB_QOS', 'STATE_SUB_QOS',
    'COMMAND_QOS', 'CLOCK_QOS', 'DIAGNOSTICS_QOS',
]


# ---------------------------------------------------------------- QoS (docs/nodes.md's table)

#: State streams a node *publishes* (``joint_states``, ``odom``, ``ee_pose``): reliable, keep
#: last 10, volatile (the system default), so that reliable and best-effort subscribers both
#: match (REP 2003: a sensor source publishes reliable, its consumers choose).
STATE_PUB_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                           durability=DurabilityPolicy.VOLATILE)
#: State streams a node *consumes*: best effort, keep last 1, volatile. A late sample is worth
#: less than the next one, and never stalls the sender; only the newest is kept, so a node that
#: was held up (a stall, a busy machine) answers the state of now, not a backlog of states the
#: simulator has already stepped past (their answers would be applied late, one by one).
STATE_SUB_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.BEST_EFFORT,
                           durability=DurabilityPolicy.VOLATILE)
#: Commands and set-points (``*/commands``, ``base/reference``, ``base/feasible_twist``,
#: ``goal_pose``, ``ee_reference``): reliable, keep last 10, volatile: none is lost (the base
#: exchange matches each reference to its joint state by stamp, so two queued references must
#: both arrive), and none is replayed to a late joiner.
COMMAND_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=10, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.VOLATILE)
#: ``/clock``: reliable, keep last 1 (only the newest time matters; rclpy's time source
#: subscribes best effort, which matches).
CLOCK_QOS = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1, reliability=ReliabilityPolicy.RELIABLE,
                       durability=DurabilityPolicy.VOLATILE)
#: ``/diagnostics``: reliable, keep last 10, volatile (what diagnostic_aggregator expects).
DIAGNOSTICS_QOS = STATE_PUB_QOS


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
    default_from: object = None


def robot_param(description=''):
    """The ``robot`` parameter every node has: a shipped robot's name, an alias A/B, or a path to
    a robot YAML file (validated when the node loads it: an unknown name or a bad file stops the
    start-up with a message naming the file and the item)."""
    return Param('robot', (description + ' ' if description else '') +
                 f'A robot name ({", ".join(robot_names())}; aliases A, B) or a path to a robot YAML file.',
                 read_only=True)


def max_state_wait_param():
    """The ``max_state_wait`` parameter of every node that answers ``/joint_states``."""
    return Param('max_state_wait', 'Longest time [s] a joint state may wait in this node (from its receipt to its '
                 'cycle, steady clock) and still run a cycle: one that waited longer (the node was held up, and a '
                 'real-time simulator has stepped past it) runs none; nor does one that reached this node that much '
                 'later than joint states usually do (it was queued in the transport while the node was held up). '
                 '0: no limit (lockstep).', lo=0.0, hi=60.0)


def require_base(robot, families, node_name):
    """Raise a ConfigError unless ``robot``'s base is one of ``families`` (this node drives those)."""
    if robot.base_type not in families:
        raise ConfigError(f'robot {robot.name!r} has a {robot.base_type} base; {node_name} drives '
                          f'{" and ".join(families)} bases')


def robot_period(values):
    """The default of a node's ``period``: the control period of its ``robot`` (the robot YAML's
    ``period``), so that the simulator and every controller agree unless one is told otherwise."""
    return load_robot(values.robot).period


def robot_method(values):
    """The default of ``redundancy_resolver``'s ``method``: its ``robot``'s (the robot YAML's
    ``method``)."""
    return load_robot(values.robot).method


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
            desc.floating_point_range = [FloatingPointRange(from_value=float(spec.lo), to_value=float(spec.hi),
                                                            step=0.0)]
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


def parameter_error(spec, value):
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


def declare_parameters(node, yaml_name, specs, on_change=None, check=None):
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
    values = {}
    for spec in specs:
        if spec.default_from is not None:
            if spec.name in defaults:
                raise ConfigError(f'config/{yaml_name}: {spec.name!r} has its default elsewhere (one home '
                                  'for every default): remove it from this file')
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
        except (rclpy.exceptions.InvalidParameterValueException,
                rclpy.exceptions.InvalidParameterTypeException) as exc:
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
    overrides = node._parameter_overrides      # rclpy's start-up values (command line, params files)
    if name in overrides and _is_double(default):
        overrides[name] = _as_double(overrides[name])


def _watch(node, namespace, specs, on_change, check):
    """Validate run-time sets of the parameters of ``specs``, then apply them to ``namespace``."""

    def validate(params):
        changes = {}
        for prm in params:
            spec = specs.get(prm.name)
            if spec is None:
                continue            # use_sim_time and the like: rclpy's
            reason = parameter_error(spec, prm.value)
            if reason:
                return SetParametersResult(successful=False, reason=f'{prm.name}: {reason}')
            changes[prm.name] = _plain(prm.value)
        if changes and check is not None:
            reason = check(SimpleNamespace(**{**vars(namespace), **changes}))
            if reason:
                return SetParametersResult(successful=False, reason=reason)
        return SetParametersResult(successful=True)

    def apply(params):
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


def node_status(node: 'rclpy.node.Node', part: str, robot_name: str, level: str, message: str,
                values: dict) -> DiagnosticStatus:
    """A ``DiagnosticStatus`` of ``node`` that says which node sent it.

    Its name is the node's fully qualified name, followed by ``: <part>`` when ``part`` is
    given (``/r1/wmm_sim: simulation``); its hardware id is ``<robot_name> <fully qualified
    name>``. Two robots in two namespaces, or a renamed node, are told apart on the shared
    ``/diagnostics``.
    """
    fqn = node.get_fully_qualified_name()
    return diagnostic_status(f'{fqn}: {part}' if part else fqn, f'{robot_name} {fqn}', level, message, values)


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


def guard_clock(node):
    """Make ``node`` drop the ``/clock`` messages rclpy's time source cannot take, with a warning.

    With ``use_sim_time``, rclpy's own time source turns each ``/clock`` message into a time
    point, and raises inside its callback for a negative time (``ValueError: Seconds value must
    not be negative``), which would end the node. A ``/clock`` stamp is at most 2³¹ − 1 s, a
    time rclpy takes, so a negative one is the only such message. It is dropped before rclpy
    sees it, logged through ``node``'s logger (throttled): the ROS clock keeps its last time.
    ``use_sim_time`` set at run time makes a new subscription, guarded in turn.
    """
    def guard(callback):
        def guarded(msg):
            if msg.clock.sec < 0:
                node.get_logger().warn(
                    f'ignored a /clock message at {msg.clock.sec} s {msg.clock.nanosec} ns: a negative time, '
                    f'which rclpy cannot take; the ROS clock keeps its last time '
                    f'({node.count_publishers("/clock")} publisher(s) on /clock)', throttle_duration_sec=1.0)
                return
            callback(msg)
        return guarded

    def guard_all(_params=()):
        for sub in node.subscriptions:
            if isinstance(getattr(sub.callback, '__self__', None), TimeSource):
                sub.callback = guard(sub.callback)

    guard_all()
    node.add_post_set_parameters_callback(guard_all)


#: Fast DDS transports of the executables, unless the environment names others: UDP alone.
#: With its shared-memory transport too (Fast DDS's default), a peer killed (SIGKILL) or
#: stopped (SIGSTOP) at the wrong moment stalled the surviving processes' traffic for 0.2 to 2 s
#: (measured, see docs/robustness.md), which fired their watchdogs; over UDP it never did.
FASTDDS_TRANSPORTS = 'UDPv4'


def run_node(node_factory, args=None, executor_factory=default_executor):
    """Standard main(): init, build the node, spin until Ctrl-C, SIGTERM or shutdown, clean up.

    A configuration error at start-up (the command line's included) is logged and gives exit
    code 2. Ctrl-C and SIGTERM end the spin loop between callbacks: rclpy's own handlers shut
    the context down at once, in the middle of a callback, whose next publish then fails
    ("publisher's context is invalid", a traceback on the way out). Further ones during the
    teardown are only noted (``ros2 launch`` sends SIGINT twice); the previous handlers come
    back once the context is shut down, and from the interpreter's exit on both signals are
    ignored (:func:`_ignore_stop_signals_at_exit`). The process uses Fast DDS's UDP transport
    alone (:data:`FASTDDS_TRANSPORTS`) unless ``FASTDDS_BUILTIN_TRANSPORTS`` is set.
    """
    os.environ.setdefault('FASTDDS_BUILTIN_TRANSPORTS', FASTDDS_TRANSPORTS)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:        # the command line: a --params-file that cannot be read, a bad rule
        rclpy.logging.get_logger('wmm_control').fatal(f'cannot start: {exc}')
        return 2
    stop = []
    previous = {}
    if threading.current_thread() is threading.main_thread():     # where Python delivers signals
        previous = {sig: signal.signal(sig, lambda signum, _frame: stop.append(signum))
                    for sig in (signal.SIGINT, signal.SIGTERM)}
    _ignore_stop_signals_at_exit()
    node = executor = None
    try:
        node = node_factory()
        executor = executor_factory()
        executor.add_node(node)
        # spin_once in a loop rather than spin(): it returns to check the stop request.
        while rclpy.ok() and not stop:
            executor.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:
        pass
    except WmmError as exc:
        logger = node.get_logger() if node is not None else rclpy.logging.get_logger('wmm_control')
        logger.fatal(f'{type(exc).__name__}: {exc}')
        return 2
    finally:
        # The stop handler stays in place until the node and the context are gone: a second
        # Ctrl-C or SIGTERM during the teardown (``ros2 launch`` sends SIGINT twice) is only
        # noted, instead of raising KeyboardInterrupt inside rclpy (an abort).
        # The executor goes first, here: left to the garbage collector after the handlers are back,
        # the events executor ran pending callbacks from its destructor, where a signal then raised
        # KeyboardInterrupt inside rclpy (an abort under ``ros2 launch``).
        try:
            if executor is not None:
                executor.shutdown()
                del executor
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        finally:
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    return 0


_EXIT_GUARD: list[bool] = []


def _ignore_stop_signals_at_exit():
    """From the interpreter's exit on, ignore SIGINT and SIGTERM (registered once, by :func:`run_node`).

    After ``main()`` returns, the interpreter's finalization (the middleware's destructors) takes
    a few tenths of a second, during which Python resets SIGINT to the system default: a second
    Ctrl-C then killed the process (exit -2) although the node had stopped cleanly. Python keeps
    an ignored signal ignored through its finalization.
    """
    if _EXIT_GUARD or threading.current_thread() is not threading.main_thread():
        return
    _EXIT_GUARD.append(True)

    def ignore():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)

    atexit.register(ignore)


# ---------------------------------------------------------------- base controllers' exchange

def stamp_key(stamp):
    """A header stamp as a hashable, comparable ``(sec, nanosec)``."""
    return (stamp.sec, stamp.nanosec)


def parse_base_reference(msg, base_frame):
    """Validate a ``/base/reference`` ``TwistStamped`` of a planar base.

    Returns:
        ``(array (vx, vy, ω), warning)`` when it is finite and in ``base_frame`` (or has an
        empty frame, taken as ``base_frame``); ``warning`` is '' unless the frame is empty or
        it moves out of the plane (ignored). Else ``(None, reason)``.
    """
    ref = np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z])
    if not np.all(np.isfinite(ref)):
        return None, f'non-finite values {ref.tolist()}'
    if msg.header.frame_id not in ('', base_frame):
        return None, f'frame {msg.header.frame_id!r}: expected {base_frame!r}'
    warnings = []
    if not msg.header.frame_id:
        warnings.append(f'empty frame_id, taken as {base_frame!r}')
    other = (msg.twist.linear.z, msg.twist.angular.x, msg.twist.angular.y)
    if any(abs(v) > 1e-9 for v in other):
        warnings.append('linear.z, angular.x, angular.y are ignored (planar base)')
    return ref, '; '.join(warnings)


class JointSelector:
    """Reads named joints from ``sensor_msgs/JointState`` messages, whatever their order.

    The index of each name layout is cached (senders use one or two layouts).

    Args:
        joints: the joint names to read, in the order they are returned.
        velocity_limits: optional |q̇| limit per joint [rad/s]; a measured rate beyond
            ``PLAUSIBLE_FACTOR`` times it is taken for a glitch and the message is rejected.
        position_limits: optional ``(lower, upper)`` per joint [rad]; a position beyond them by
            more than ``POSITION_MARGIN`` is rejected.
    """

    PLAUSIBLE_FACTOR = 10.0
    POSITION_MARGIN = 0.5       # [rad]
    MAX_POSITION = 1e9          # [rad] no joint angle is larger (a wheel at 12 rad/s needs 2.6 years)

    def __init__(self, joints, cache_size=16, velocity_limits=None, position_limits=None):
        self.joints = tuple(joints)
        self._cache = {}
        self._cache_size = cache_size
        self._max_rate = None if velocity_limits is None else \
            self.PLAUSIBLE_FACTOR * np.broadcast_to(np.asarray(velocity_limits, dtype=float), len(self.joints))
        self._bounds = None if position_limits is None else (
            np.asarray(position_limits[0], dtype=float) - self.POSITION_MARGIN,
            np.asarray(position_limits[1], dtype=float) + self.POSITION_MARGIN)

    def _layout(self, names):
        where = {}
        for i, name in enumerate(names):
            where.setdefault(name, []).append(i)
        missing = [j for j in self.joints if j not in where]
        if missing:
            return f'without joints {missing}'
        twice = [j for j in self.joints if len(where[j]) > 1]
        if twice:
            return f'listing joints {twice} more than once (ambiguous)'
        return np.array([where[j][0] for j in self.joints])

    def indices(self, msg):
        """Indices of the joints in ``msg`` and '' or ``(None, reason)``.

        A message lacking a joint, naming one of them twice, or whose positions (or
        non-empty velocities) differ in length from its names, gives None.
        """
        names = tuple(msg.name)
        if names not in self._cache:
            if len(self._cache) >= self._cache_size:
                self._cache.clear()
            self._cache[names] = self._layout(names)
        idx = self._cache[names]
        if isinstance(idx, str):
            return None, idx
        if len(msg.position) != len(names):
            return None, f'with {len(msg.position)} positions for {len(names)} names'
        if len(msg.velocity) not in (0, len(names)):
            return None, f'with {len(msg.velocity)} velocities for {len(names)} names'
        return idx, ''

    def read(self, msg):
        """``(positions, velocities, '')`` of the joints, or ``(None, None, reason)``.

        Velocities are zero when the message has none. Non-finite values, and values beyond
        the plausibility bounds given at construction, give a reason.
        """
        idx, reason = self.indices(msg)
        if idx is None:
            return None, None, reason
        q = np.asarray(msg.position, dtype=float)[idx]
        dq = np.asarray(msg.velocity, dtype=float)[idx] if len(msg.velocity) else np.zeros(len(idx))
        if not (np.all(np.isfinite(q)) and np.all(np.isfinite(dq))):
            return None, None, f'with non-finite values: positions {q.tolist()}, velocities {dq.tolist()}'
        if self._max_rate is not None and np.any(np.abs(dq) > self._max_rate):
            bad = [self.joints[i] for i in np.flatnonzero(np.abs(dq) > self._max_rate)]
            return None, None, (f'with rates of {bad} beyond {self.PLAUSIBLE_FACTOR:g} times their limits '
                                f'(a measurement glitch?)')
        if np.any(np.abs(q) > self.MAX_POSITION):
            return None, None, f'with positions beyond {self.MAX_POSITION:g} rad: not joint angles'
        if self._bounds is not None and (np.any(q < self._bounds[0]) or np.any(q > self._bounds[1])):
            bad = [self.joints[i] for i in np.flatnonzero((q < self._bounds[0]) | (q > self._bounds[1]))]
            return None, None, (f'with positions of {bad} more than {self.POSITION_MARGIN} rad beyond '
                                'their limits')
        return q, dq, ''


class StampGate:
    """Which joint states run a control cycle, judged by their header stamps.

    The controllers integrate one ``period`` per cycle, so a cycle must answer a new instant
    of the sender's time: a message stamped at or before the last cycle's (a second
    publisher, a replayed or re-ordered message, a zero stamp amid stamped ones) runs no
    cycle, nor does one stamped more than ``max_jump`` after it (a far-future stamp: a
    sender that really paused that long trips the joint-state timeout first, which calls
    :meth:`restart`). Messages that reach the node one after another run one cycle each, one
    period each, as their stamps say (the subscription keeps only the newest, so a backlog
    does not reach it). Messages that all carry a zero stamp (published by hand) each run one.

    The median of the last ``window`` stamp steps is the sender's period;
    :meth:`period_mismatch` reports it when it differs from ``period`` by more than 10 %.
    """

    def __init__(self, period, max_jump, window=40):
        self.period = float(period)
        self.max_jump = float(max_jump)
        self._steps = deque(maxlen=window)
        self._last = None

    def restart(self):
        """Any next stamp starts a new time base (the sender restarted, or was silent)."""
        self._last = None

    def admit(self, stamp):
        """'' when the message stamped ``stamp`` runs a cycle, else why not."""
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        last = self._last
        if last is None or (ns == 0 and last == 0):
            self._last = ns
            return ''
        step = (ns - last) * 1e-9
        if step <= 0.0:
            return (f'stamped {ns * 1e-9:.9g} s, not after the last cycle\'s {last * 1e-9:.9g} s (a second '
                    'publisher, or an old or re-ordered message)')
        if step > self.max_jump:
            return f'stamped {step:.6g} s after the last cycle\'s, beyond {self.max_jump:g} s (a far-future stamp)'
        self._last = ns
        self._steps.append(step)
        return ''

    @property
    def measured_period(self):
        """Median stamp step of the last cycles [s]; 0 before half a window."""
        if len(self._steps) < self._steps.maxlen // 2:
            return 0.0
        return statistics.median(self._steps)     # as np.median, 15 times faster on a deque

    def period_mismatch(self):
        """'' or a sentence saying that the sender's period differs from ``period``."""
        measured = self.measured_period
        if measured == 0.0 or abs(measured - self.period) <= 0.1 * self.period:
            return ''
        return (f'joint states come every {measured:.6g} s by their stamps, but this node\'s period is '
                f'{self.period:g} s: its rate and acceleration limits act per {self.period:g} s')


class StampedExchange:
    """One cycle per state message, run with the reference of the same stamp.

    A state stamped S runs the cycle that answers the reference stamped S: at once if the
    latest reference already carries S, else when it comes, or after ``wait`` seconds of
    ``clock`` (steady, so a paused sim clock cannot stall it) with whatever reference is
    latest. A state arriving while another waits runs the waiting one first.

    Args:
        node: the node owning the wait timer.
        wait: longest wait for the reference [s]; 0 runs every cycle at once.
        run_cycle: ``run_cycle(stamp, payload)``, the cycle of one state; ``stamp`` is the
            state's ``(sec, nanosec)``.
        clock: the clock of the wait timer.
    """

    def __init__(self, node, wait, run_cycle, clock):
        self._run_cycle = run_cycle
        self._pending = None            # (stamp, payload) of the state waiting for its reference
        self._ref_stamp = None
        self._timer = node.create_timer(wait, self.run_pending, clock=clock, autostart=False) if wait > 0 else None

    def reference_received(self, stamp):
        """Note a reference (already stored by the caller) stamped ``stamp``."""
        self._ref_stamp = stamp_key(stamp)
        if self._pending is not None and self._pending[0] == self._ref_stamp:
            self.run_pending()

    def state_received(self, stamp, payload):
        """A state stamped ``stamp``: its cycle runs now or once its reference comes."""
        if self._pending is not None:         # the previous state's reference never came
            self.run_pending()
        key = stamp_key(stamp)
        self._pending = (key, payload)
        if self._ref_stamp == key or self._timer is None:
            self.run_pending()
        else:
            self._timer.reset()

    def run_pending(self):
        """Run the waiting state's cycle now (nothing if none waits)."""
        if self._timer is not None:
            self._timer.cancel()
        if self._pending is None:
            return
        stamp, payload = self._pending
        self._pending = None
        self._run_cycle(stamp, payload)


class BaseReference:
    """The latest ``/base/reference`` of a planar base, validated, with its age.

    Its age is judged by the node's clock at receipt (:class:`Freshness`), never by its stamp.

    Args:
        node: the node whose clock and logger are used.
        base_frame: the one frame accepted besides an empty one.
        timeout: age [s] beyond which :meth:`current` gives None.
        velocity_limit: |vx|, |vy|, |ω| limits; a reference beyond them is kept (the
            controller scales it into them) with a logged warning.
    """

    def __init__(self, node, base_frame, timeout, velocity_limit=None):
        self._node = node
        self.base_frame = base_frame
        self.value = np.zeros(3)
        self.freshness = Freshness(timeout)
        self.rejected = 0
        self._limit = None if velocity_limit is None else np.asarray(velocity_limit, dtype=float)
        self._stale_logged = False

    def accept(self, msg):
        """Store ``msg`` if valid (True); else count and log the rejection (False)."""
        ref, reason = parse_base_reference(msg, self.base_frame)
        logger = self._node.get_logger()
        if ref is None:
            self.rejected += 1
            logger.warn(f'rejected /base/reference: {reason}', throttle_duration_sec=1.0)
            return False
        if reason:
            logger.warn(f'/base/reference: {reason}', throttle_duration_sec=10.0)
        if self._limit is not None and np.any(np.abs(ref) > self._limit):
            logger.warn(f'/base/reference {ref.tolist()} is beyond the velocity limits {self._limit.tolist()}: '
                        'scaled into them', throttle_duration_sec=1.0)
        self.value = ref
        self.freshness.mark(seconds(self._node.get_clock()))
        self._stale_logged = False
        return True

    def current(self, now):
        """The reference at node time ``now`` [s], or None when it is stale (logged once)."""
        if self.freshness.fresh(now):
            return self.value
        if not self._stale_logged and np.any(self.value):
            self._node.get_logger().warn(f'/base/reference older than {self.freshness.timeout} s: braking to rest')
            self._stale_logged = True
        return None


#: Joint states over which :class:`JointStateWatchdog` finds the usual delivery (about 1 s at 40 Hz).
DELIVERY_WINDOW = 40


class JointStateWatchdog:
    """The timing of a controller's ``/joint_states`` input: stamps, age and period.

    :meth:`admit` decides, by the stamps (:class:`StampGate`), whether a message runs a cycle,
    and logs why not (throttled). While admitted joint states are older than ``timeout``,
    ``on_timeout()`` is called every ``period``; the timer runs on ``clock`` (give it the
    steady clock: a paused sim clock must not hide a stop). A timeout sets
    :attr:`need_resync`, which the node clears once it has resynchronised, and lets the next
    stamp start a new time base.

    :meth:`waited_too_long` tells, when the cycle is about to run, whether the state waited in
    this node longer than ``max_wait`` since its receipt (the node's steady clock: no clock of
    the sender's is involved). A node that was held up (stopped, or starved on a busy machine)
    may run a state that waited for its reference meanwhile; a real-time simulator has stepped
    past it, and an answer to it would be applied now, as if it were current.

    With ``max_wait`` set, :meth:`admit` also skips a state that reached this node more than
    ``max_wait`` later than the joint states usually do: its receipt on the node's clock minus its
    stamp, against the smallest such offset of the last :data:`DELIVERY_WINDOW` states (a constant
    offset between the sender's clock and this node's cancels). A node held up (stopped, or
    starved) finds the states sent meanwhile queued in its transport: they reach its callback one
    by one after it goes on, the oldest first, each looking new to it, and each reports rates the
    simulator has since changed.
    """

    def __init__(self, node, timeout, period, clock, on_timeout, action, topic='joint_states', max_wait=0.0):
        self._node = node
        self.max_wait = float(max_wait)
        self._clock = clock
        self._on_timeout = on_timeout
        self._action = action
        self._topic = topic
        self.freshness = Freshness(timeout)
        self._period = float(period)
        self.stamps = StampGate(period, max_jump=self._max_jump(timeout))
        self.skipped = 0
        self.need_resync = True
        self._offsets = deque(maxlen=DELIVERY_WINDOW)   # receipt − stamp [ns] of the last joint states
        self.timer = node.create_timer(period, self._check, clock=clock)

    def _max_jump(self, timeout):
        return max(float(timeout), 4.0 * self._period)

    def set_timeout(self, timeout):
        """A new timeout [s] (a parameter set at run time): for the age and for the stamp jump."""
        self.freshness.timeout = float(timeout)
        self.stamps.max_jump = self._max_jump(timeout)

    def waited_too_long(self, received_ns):
        """True (logged, throttled, and counted as skipped) when a joint state received at
        ``received_ns`` (``time.monotonic_ns()`` in its callback) waited longer than ``max_wait``."""
        if self.max_wait <= 0.0:
            return False
        wait = (time.monotonic_ns() - received_ns) * 1e-9
        if wait <= self.max_wait:
            return False
        self.skipped += 1
        self._node.get_logger().warn(
            f'/{self._topic} waited {wait:.3g} s in this node, beyond max_state_wait {self.max_wait:g} s (the node '
            'was held up): cycle skipped', throttle_duration_sec=1.0)
        return True

    def mark(self):
        """A joint state arrived now."""
        self.freshness.mark(seconds(self._clock))

    def late(self, stamp):
        """How much later [s] than the usual delivery the joint state stamped ``stamp`` reached this
        node now (0 when it is the earliest of the window, or unstamped: a zero stamp tells no time)."""
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        if ns == 0:
            return 0.0
        offset = self._node.get_clock().now().nanoseconds - ns
        self._offsets.append(offset)
        return (offset - min(self._offsets)) * 1e-9

    def admit(self, stamp):
        """True when the joint state stamped ``stamp`` runs a cycle (it is then marked fresh)."""
        logger = self._node.get_logger()
        late = self.late(stamp) if self.max_wait > 0.0 else 0.0
        if late > self.max_wait:
            self.skipped += 1
            logger.warn(f'/{self._topic} arrived {late:.3g} s later than the usual delivery, beyond max_state_wait '
                        f'{self.max_wait:g} s (it was queued while this node was held up): cycle skipped',
                        throttle_duration_sec=1.0)
            return False
        reason = self.stamps.admit(stamp)
        if reason:
            self.skipped += 1
            publishers = self._node.count_publishers(self._topic)
            logger.warn(f'/{self._topic} {reason}; {publishers} publisher(s) on it: cycle skipped',
                        throttle_duration_sec=1.0)
            return False
        self.mark()
        mismatch = self.stamps.period_mismatch()
        if mismatch:
            logger.warn(mismatch, throttle_duration_sec=10.0)
        return True

    def resync(self, *outputs):
        """True when the node restarts from the measured state this cycle.

        That is after a timeout (and at start-up), and also while any of ``outputs`` (the
        command publishers) has no matched subscription yet: commands that nobody receives
        must not advance the controller's state, or the first one that arrives would jump.
        """
        if not all(pub.get_subscription_count() > 0 for pub in outputs):
            return True
        due = self.need_resync
        self.need_resync = False
        return due

    def _check(self):
        age = self.freshness.age(seconds(self._clock))
        if not self.freshness.timeout < age < math.inf:
            return
        if not self.need_resync:
            self._node.get_logger().warn(f'no /{self._topic} for {self.freshness.timeout} s: {self._action}')
            self.need_resync = True
        self.stamps.restart()
        self._offsets.clear()
        self._on_timeout()
