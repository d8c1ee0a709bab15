"""Helpers shared by the nodes: parameters, command messages, freshness, diagnostics, main().

Parameter defaults live in ``config/<node>.yaml`` (``<node_name>: ros__parameters:``); the
code declares each parameter with a description and range and takes its default from
that file, so the YAML is the one place a default is written.
"""

import math
from pathlib import Path
from dataclasses import dataclass
from types import SimpleNamespace

import numpy as np
import rclpy
import yaml
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue
from geometry_msgs.msg import TwistStamped
from rcl_interfaces.msg import FloatingPointRange, IntegerRange, ParameterDescriptor
from rclpy.executors import ExternalShutdownException, SingleThreadedExecutor
from rclpy.parameter import Parameter
from std_msgs.msg import Float64MultiArray

from wmm_control.errors import ConfigError, WmmError
from wmm_control.paths import config_path

__all__ = [
    'Param', 'declare_parameters', 'load_defaults', 'float_array', 'parse_command',
    'Freshness', 'diagnostic_status', 'diagnostic_array', 'seconds', 'run_node',
    'stamp_key', 'parse_base_reference', 'twist_stamped', 'JointSelector', 'StampedExchange',
    'BaseReference', 'JointStateWatchdog',
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
    # The section is the node's default name, the file's stem: a node renamed at start-up
    # (``-r __node:=left_base``) keeps its defaults; ``--params-file`` overrides go by name.
    defaults = load_defaults(yaml_name, Path(yaml_name).stem)
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


# ---------------------------------------------------------------- base controllers' exchange

def stamp_key(stamp):
    """A header stamp as a hashable, comparable ``(sec, nanosec)``."""
    return (stamp.sec, stamp.nanosec)


def parse_base_reference(msg, base_frame):
    """Validate a ``/base/reference`` ``TwistStamped`` of a planar base.

    Returns:
        ``(array (vx, vy, ω), warning)`` when it is finite and in ``base_frame`` (or has an
        empty frame); ``warning`` is '' unless it moves out of the plane (ignored). Else
        ``(None, reason)``.
    """
    ref = np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z])
    if not np.all(np.isfinite(ref)):
        return None, f'non-finite values {ref.tolist()}'
    if msg.header.frame_id not in ('', base_frame):
        return None, f'frame {msg.header.frame_id!r}: expected {base_frame!r}'
    other = (msg.twist.linear.z, msg.twist.angular.x, msg.twist.angular.y)
    if any(abs(v) > 1e-9 for v in other):
        return ref, 'linear.z, angular.x, angular.y are ignored (planar base)'
    return ref, ''


def twist_stamped(stamp, frame, twist):
    """A ``TwistStamped`` of the planar twist (vx, vy, ω); ``stamp`` a Time or ``(sec, nanosec)``."""
    msg = TwistStamped()
    msg.header.stamp = stamp if isinstance(stamp, Time) else Time(sec=stamp[0], nanosec=stamp[1])
    msg.header.frame_id = frame
    msg.twist.linear.x, msg.twist.linear.y = float(twist[0]), float(twist[1])
    msg.twist.angular.z = float(twist[2])
    return msg


class JointSelector:
    """Finds named joints in ``sensor_msgs/JointState`` messages, whatever their order.

    The index of each name layout is cached (senders use one or two layouts).
    """

    def __init__(self, joints, cache_size=16):
        self.joints = tuple(joints)
        self._cache = {}
        self._cache_size = cache_size

    def indices(self, msg):
        """Indices of the joints in ``msg`` and '' or ``(None, reason)``.

        A message lacking a joint, or whose positions (or non-empty velocities) differ in
        length from its names, gives None.
        """
        names = tuple(msg.name)
        if names not in self._cache:
            if len(self._cache) >= self._cache_size:
                self._cache.clear()
            where = {name: i for i, name in enumerate(names)}
            missing = [j for j in self.joints if j not in where]
            self._cache[names] = missing if missing else np.array([where[j] for j in self.joints])
        idx = self._cache[names]
        if isinstance(idx, list):
            return None, f'without joints {idx}'
        if len(msg.position) != len(names):
            return None, f'with {len(msg.position)} positions for {len(names)} names'
        if len(msg.velocity) not in (0, len(names)):
            return None, f'with {len(msg.velocity)} velocities for {len(names)} names'
        return idx, ''


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
    """

    def __init__(self, node, base_frame, timeout):
        self._node = node
        self.base_frame = base_frame
        self.value = np.zeros(3)
        self.freshness = Freshness(timeout)
        self.rejected = 0
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
        self.value = ref
        self.freshness.mark(seconds(self._node.get_clock()))
        self._stale_logged = False
        return True

    def current(self, now):
        """The reference at node time ``now`` [s], or None when it is stale (logged once)."""
        if self.freshness.fresh(now):
            return self.value
        if not self._stale_logged and np.any(self.value):
            self._node.get_logger().warn(f'/base/reference older than {self.freshness.timeout} s: stopping')
            self._stale_logged = True
        return None


class JointStateWatchdog:
    """Calls ``on_timeout()`` every ``period`` while joint states are older than ``timeout``.

    It runs on ``clock`` (give it the steady clock: a paused sim clock must not hide a stop)
    and sets :attr:`need_resync`, which the node clears once it has resynchronised.
    """

    def __init__(self, node, timeout, period, clock, on_timeout, action):
        self._node = node
        self._clock = clock
        self._on_timeout = on_timeout
        self._action = action
        self.freshness = Freshness(timeout)
        self.need_resync = True
        self.timer = node.create_timer(period, self._check, clock=clock)

    def mark(self):
        """A joint state arrived now."""
        self.freshness.mark(seconds(self._clock))

    def _check(self):
        age = self.freshness.age(seconds(self._clock))
        if not self.freshness.timeout < age < math.inf:
            return
        if not self.need_resync:
            self._node.get_logger().warn(f'no /joint_states for {self.freshness.timeout} s: {self._action}')
            self.need_resync = True
        self._on_timeout()
