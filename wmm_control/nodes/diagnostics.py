"""``/diagnostics`` messages of the nodes, and their log lines of goal events."""

from collections.abc import Iterable, Mapping
from typing import Any

import numpy as np
import rclpy
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray, DiagnosticStatus, KeyValue

__all__ = ['diagnostic_status', 'node_status', 'diagnostic_array', 'DiagnosticsGate', 'log_lines']


def log_lines(node: 'rclpy.node.Node', lines: Iterable[tuple[str, str]]) -> None:
    """Log ``(level, message)`` pairs (a :class:`~wmm_control.resolvers.targets.LogThrottle`'s
    lines): 'info' as information, any other level as a warning, through ``node``'s logger."""
    logger = node.get_logger()
    for level, message in lines:
        if level == 'info':  # one call site per severity: rclpy refuses a change at one
            logger.info(message)
        else:
            logger.warn(message)


def diagnostic_status(
    name: str, hardware_id: str, level: str, message: str, values: Mapping[str, Any]
) -> DiagnosticStatus:
    """A ``DiagnosticStatus``; ``level`` is 'ok', 'warn' or 'error'; values become KeyValues."""
    status = DiagnosticStatus()
    status.level = {'ok': DiagnosticStatus.OK, 'warn': DiagnosticStatus.WARN, 'error': DiagnosticStatus.ERROR}[level]
    status.name = name
    status.hardware_id = hardware_id
    status.message = message
    status.values = [KeyValue(key=str(k), value=_kv(v)) for k, v in values.items()]
    return status


def node_status(
    node: 'rclpy.node.Node', part: str, robot_name: str, level: str, message: str, values: dict
) -> DiagnosticStatus:
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
        return '[' + ', '.join(_kv(float(v)) if isinstance(v, (float, np.floating)) else str(v) for v in value) + ']'
    return str(value)


def diagnostic_array(stamp: Time, statuses: Iterable[DiagnosticStatus]) -> DiagnosticArray:
    """A ``DiagnosticArray`` with header stamp ``stamp``."""
    msg = DiagnosticArray()
    msg.header.stamp = stamp
    msg.status = list(statuses)
    return msg


class DiagnosticsGate:
    """When a node's next ``/diagnostics`` message is due: the first call, then once every
    ``period`` [s] of the node's own clock (read at each call, so a changed ``diagnostics_period``
    parameter applies from the next message); never with a period of 0."""

    def __init__(self) -> None:
        self._next = 0.0

    def due(self, now: float, period: float) -> bool:
        """True when a message is due at ``now`` [s]; it then counts as sent."""
        if period <= 0.0 or now + 1e-9 < self._next:
            return False
        self._next = now + period
        return True
