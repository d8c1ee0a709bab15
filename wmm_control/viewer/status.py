"""What the viewer's status panel says: the latest ``/diagnostics`` of each node, as Markdown (ROS-free).

Each node's status (one ``DiagnosticStatus`` per node; the simulator has one per command
group and one for the simulation) is kept by name, newest first replaced. The panel shows,
per status, its level and message and the keys a user watches (:data:`KEYS`): the resolver's
method, mode, ψ, task scale (α of AMP), σ_min, errors, goal reached or stalled, the safety
stage's clearance, closest pair, whether it changed the command and the limits that shaped it
(with the cycles each did, of the ``binding_<limit>`` counts), and cycle time;
the base controllers' status, solve time and rejected or stale inputs; the simulator's command
watchdogs (a group whose commands timed out is held at zero velocity) and real-time factor.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

__all__ = ['NodeStatus', 'StatusBoard', 'KEYS', 'LEVELS']

#: ``DiagnosticStatus.level`` → word.
LEVELS = {0: 'OK', 1: 'WARN', 2: 'ERROR', 3: 'STALE'}

#: Keys shown, with their labels, in this order (keys a status lacks are left out); ``binding_``
#: stands for the ``binding_<limit>`` counts, one row of those above zero (:func:`_binding`).
KEYS = (
    ('method', 'method'),
    ('mode', 'mode'),
    ('psi', 'ψ (task sharing)'),
    ('limit_scale', 'task scale α / s_v'),
    ('sigma_min', 'σ_min'),
    ('position_error_m', 'position error [m]'),
    ('orientation_error_rad', 'orientation error [rad]'),
    ('goal_reached', 'goal reached'),
    ('goal_stalled', 'goal stalled'),
    ('clearance_m', 'clearance [m]'),
    ('closest_pair', 'closest pair'),
    ('collision_changed', 'avoiding contact'),
    ('binding_', 'limits that shaped it [cycles]'),
    ('relaxed_cycles', 'limits relaxed [cycles]'),
    ('cycle_time_us', 'cycle time [µs]'),
    ('status', 'status'),
    ('route', 'route'),
    ('solve_time_us', 'solve time [µs]'),
    ('velocity_scale', 'velocity scale'),
    ('wheel_rate_ratio', 'wheel rate / limit'),
    ('reference_age_s', 'reference age [s]'),
    ('command_age_s', 'command age [s]'),
    ('stale_cycles', 'stale cycles (watchdog)'),
    ('joint_states_skipped', 'joint states skipped'),
    ('references_rejected', 'references rejected'),
    ('commands_not_applied', 'commands not applied'),
    ('goals_rejected', 'goals rejected'),
    ('compensation_dropped', 'compensation dropped'),
    ('clamped', 'clamped'),
    ('rejected', 'rejected'),
    ('sim_time_s', 'sim time [s]'),
    ('real_time_factor', 'real-time factor'),
)


def _binding(values: dict[str, str]) -> str | None:
    """The ``binding_<limit>`` counts above zero as ``limit cycles, ...``, most first ('none'
    when no limit bound; None when the status has no such counts)."""
    counts = [
        (key[len('binding_') :].replace('_', ' '), value) for key, value in values.items() if key.startswith('binding_')
    ]
    if not counts:
        return None
    bound = sorted(((int(v), name) for name, v in counts if v.isdigit() and int(v) > 0), reverse=True)
    return ', '.join(f'{name} {cycles}' for cycles, name in bound) or 'none'


def _cell(value: str) -> str:
    """A value as the panel shows it: numbers to 4 significant digits, Markdown-safe."""
    try:
        number = float(value)
    except ValueError:
        return value.replace('|', '\\|')
    if value.strip().lower() in ('true', 'false') or not math.isfinite(number):
        return value
    return f'{number:.4g}'


@dataclass(frozen=True)
class NodeStatus:
    """One ``DiagnosticStatus``: name, level (0 OK, 1 WARN, 2 ERROR, 3 STALE), message, key → value."""

    name: str
    level: int
    message: str
    values: dict[str, str]
    received: float  # [s] receiver's clock at receipt

    @classmethod
    def of(cls, status, received: float) -> NodeStatus:
        """The :class:`NodeStatus` of a ``diagnostic_msgs/DiagnosticStatus`` received at
        ``received`` [s] (its level a byte, as rclpy gives it, or an int)."""
        level = status.level
        return cls(
            status.name,
            int.from_bytes(level, 'little') if isinstance(level, bytes) else int(level),
            status.message,
            {kv.key: kv.value for kv in status.values},
            received,
        )


class StatusBoard:
    """The newest status of each name, and the panel's Markdown of them."""

    def __init__(self) -> None:
        self._latest: dict[str, NodeStatus] = {}

    def update(self, status: NodeStatus) -> None:
        self._latest[status.name] = status

    def __len__(self) -> int:
        return len(self._latest)

    def get(self, name: str) -> NodeStatus | None:
        return self._latest.get(name)

    def markdown(self, now: float, stale_after: float = 5.0) -> str:
        """The panel: one section per status (the resolver's, the controllers', then the others by
        name); one received more than ``stale_after`` seconds before ``now`` is marked stale."""
        if not self._latest:
            return '*No /diagnostics yet.*'
        sections = []
        # The resolver first, then the base controllers, then the simulator's statuses.
        order = sorted(self._latest, key=lambda n: (not n.startswith('redundancy_resolver'), 'controller' not in n, n))
        for name in order:
            status = self._latest[name]
            level = LEVELS.get(status.level, str(status.level))
            age = now - status.received
            if age > stale_after:
                level = f'{level}, {age:.0f} s old'
            rows = []
            for key, label in KEYS:
                value = _binding(status.values) if key == 'binding_' else status.values.get(key)
                if value is not None:
                    rows.append(f'| {label} | {_cell(value)} |')
            table = '\n'.join(['| | |', '|---|---|', *rows]) if rows else ''
            message = status.message.replace('|', '\\|') or '—'
            sections.append(f'**{name}** — {level}: {message}\n\n{table}'.rstrip())
        return '\n\n'.join(sections)
