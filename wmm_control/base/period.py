"""One period of a base controller closed on a measured joint state, ROS-free: where it starts
from, and what of its answer may go out.

A base controller normally goes on from its own last command. It restarts from the measured
state instead after a gap in the measurements (``resync``: a timeout, start-up, or commands
nobody received yet), after a period whose answer was dropped (it came too late to publish),
and when the rates a joint state reports are not those of the last command
(:func:`~wmm_control.base.applied.unapplied_command`). A command that is not finite (which the
controllers never give) goes out as zero rates, the controller reset. The base controller
nodes (:mod:`wmm_control.nodes.base_controller`) run one :class:`BasePeriod` per joint state.
"""

from dataclasses import dataclass

import numpy as np

from wmm_control.base.applied import unapplied_command
from wmm_control.checks import JointCheck
from wmm_control.base.contract import BaseCommand, BaseController
from wmm_control.paths import load_defaults

__all__ = ['BasePeriod', 'PeriodAnswer', 'NODE_NAMES', 'node_default']

#: The base controller node (and executable) of each base family; its parameter file
#: (``config/<node>.yaml``) holds the tuning the direct engine takes too.
NODE_NAMES = {
    'steerable': 'swmr_controller',
    'mecanum': 'mecanum_controller',
    'differential': 'differential_controller',
}


def node_default(family: str, parameter: str) -> float:
    """The default of the base controller node of ``family`` for ``parameter``
    (``applied_rate_tolerance`` [rad/s], ``reference_timeout`` [s], …)."""
    name = NODE_NAMES[family]
    return float(load_defaults(f'{name}.yaml', name)[parameter])


@dataclass(frozen=True)
class PeriodAnswer:
    """What one period answers.

    Attributes:
        command: the controller's answer as it gave it (status, family details).
        rates: the rates to publish per command group, in the controller's group order [rad/s];
            finite (zero when the command was not).
        twist: the feasible twist to publish (vx, vy, ω) [m/s, m/s, rad/s]; finite.
        non_finite: '' or the line saying the command was not finite (then zeroed).
    """

    command: BaseCommand
    rates: dict
    twist: np.ndarray
    non_finite: str


class BasePeriod:
    """The periods of ``base``, each closed on a measured joint state.

    Args:
        base: the robot's base controller (:func:`~wmm_control.base.make_base_controller`).
        applied_rate_tolerance: largest difference [rad/s] between a joint state's rates and the
            last command under which that command counts as applied; 0 never checks.
    """

    def __init__(self, base: BaseController, applied_rate_tolerance: float) -> None:
        self.base = base
        self.groups = tuple(base.command_groups)
        self.tolerance = float(applied_rate_tolerance)
        #: the checks of each command group's measured joints (a glitch's rates)
        self.checks = {g: JointCheck(joints, base.rate_limits[g]) for g, joints in base.command_groups.items()}
        self._last: np.ndarray | None = None  # the last published rates, all groups in a row
        self._dropped = False  # the last period's answer was not published

    def measured(self, reads: dict, with_rates: bool) -> tuple[dict, dict | None, str]:
        """The measured state a period closes on, from each command group's read
        ``(positions, rates, reason)`` (positions None when the group could not be read, and
        ``reason`` says why; :meth:`check` or the node's joint selectors).

        Returns:
            (positions, rates, '') per group, ``rates`` None without ``with_rates`` or when a
            group is left out; or ({}, None, reason) when a required group could not be read:
            the state runs no cycle. A group that is not required is left out.
        """
        positions: dict = {}
        rates: dict | None = {} if with_rates else None
        for group, (q, dq, reason) in reads.items():
            if q is None:
                if group in self.base.required_groups:
                    return {}, None, reason
                rates = None
                continue
            positions[group] = q
            if rates is not None:
                rates[group] = dq
        return positions, rates, ''

    def check(self, positions: dict, rates: dict | None) -> tuple[dict, dict | None, str]:
        """:meth:`measured` of the groups' measured ``positions`` and ``rates`` (None: the state
        has none), each checked (:attr:`checks`)."""
        reads = {
            g: check.read(positions[g], None if rates is None else rates.get(g))
            if g in positions
            else (None, None, f'without the {g} joints')
            for g, check in self.checks.items()
        }
        return self.measured(reads, rates is not None)

    def start(self, positions: dict, rates: dict | None, resync: bool) -> str:
        """Where the period of a joint state starts from: the measured ``positions`` and ``rates``
        per group (``rates`` None when the state has none) after a gap (``resync``), a dropped
        answer or a command not applied; else the controller's own state.

        Returns:
            '' or why the last command was not applied (the period restarts from the measured state).
        """
        why = ''
        if resync:
            self.base.reset(positions, rates if self.base.resync_from_rates else None)
        elif self._dropped:
            self.base.reset(positions, rates)  # from rest when the state has no rates
        elif rates is not None and self._last is not None:
            measured = np.concatenate([rates[g] for g in self.groups])
            why = unapplied_command(measured, self._last, self.tolerance)
            if why:
                self.base.reset(positions, rates)
        self._dropped = False
        return why

    def step(self, reference, positions: dict | None) -> PeriodAnswer:
        """The controller's answer to ``reference`` (None: brake) closed on ``positions`` (None:
        from its own state)."""
        command = self.base.step(reference, positions)
        rates = {g: command.rates[g] for g in self.groups}
        twist = command.feasible_twist
        if all(np.all(np.isfinite(v)) for v in (twist, *rates.values())):
            return PeriodAnswer(command, rates, twist, '')
        why = f'non-finite command {[v.tolist() for v in rates.values()]}: zero rates'
        self.base.reset(positions)
        return PeriodAnswer(command, {g: np.zeros(len(v)) for g, v in rates.items()}, np.zeros(3), why)

    def published(self, answer: PeriodAnswer) -> None:
        """``answer`` went out: the next period checks that its rates were applied."""
        self._last = np.concatenate(list(answer.rates.values()))

    def dropped(self) -> None:
        """The answer came too late to publish: the next period restarts from the measured state."""
        self._dropped = True
