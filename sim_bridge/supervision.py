"""What the simulator node judges between steps, ROS-free: the command watchdog, lockstep's
wait for the controllers, the robot's contact with obstacles, and the statuses it reports.

The node (:mod:`sim_bridge.node`) owns the subscriptions, timers and messages; these classes
hold the state those callbacks share, so that each rule can be tested without a ROS graph.
Times are seconds of whichever clock the caller judges by (the node's clock for commands,
the steady wall clock for lockstep's waits).
"""

import math
from collections.abc import Iterable, Mapping
from typing import Any, NamedTuple

from sim_bridge.slip import OdometryCovariance
from sim_bridge.world import SimWorld
from wmm_control.checks import Freshness

__all__ = [
    'wait_groups',
    'poll_period',
    'CommandWatchdog',
    'LockstepWait',
    'ObstacleContact',
    'step_world',
    'Status',
    'statuses',
]


def wait_groups(text: str, groups: Iterable[str]) -> tuple[frozenset[str], str]:
    """The command groups of ``lockstep_groups`` text, and '' or the reason it is invalid.

    ``'all'`` is every group of ``groups``; otherwise a comma-separated list of them.
    """
    groups = set(groups)
    if text.strip() == 'all':
        return frozenset(groups), ''
    chosen = frozenset(g.strip() for g in text.split(',') if g.strip())
    unknown = sorted(chosen - groups)
    if unknown or not chosen:
        return chosen, f'lockstep_groups: unknown groups {unknown}; this robot has {sorted(groups)}'
    return chosen, ''


def poll_period(lockstep_timeout: float) -> float:
    """Wall-clock poll period [s] of lockstep (start-up, and stepping after ``lockstep_timeout``):
    a quarter of the timeout, so that a late step is at most a quarter late, and at most 0.01 s."""
    return min(0.01, lockstep_timeout / 4)


class CommandWatchdog:
    """Per command group: the age of its last accepted command, and whether it was zeroed.

    A group starts timed out (nothing commanded yet: zero velocity). A command accepted at
    ``now`` makes it fresh; :meth:`expire` finds the groups whose command grew older than
    ``timeout`` [s] since, once each until the next command.
    """

    def __init__(self, groups: Iterable[str], timeout: float):
        self._fresh = {g: Freshness(timeout) for g in groups}
        self._timed_out = {g: True for g in self._fresh}

    def set_timeout(self, timeout: float) -> None:
        """Judge every group by a new ``timeout`` [s] from now on."""
        for fresh in self._fresh.values():
            fresh.timeout = timeout

    def accepted(self, group: str, now: float) -> None:
        """A command of ``group`` was applied at ``now`` [s]."""
        self._fresh[group].mark(now)
        self._timed_out[group] = False

    def expire(self, now: float) -> list[tuple[str, float, float]]:
        """The groups that have just timed out at ``now`` [s], as ``(group, age [s], timeout [s])``;
        each is marked timed out (the caller zeroes its velocity)."""
        out = []
        for group, fresh in self._fresh.items():
            if not fresh.fresh(now) and not self._timed_out[group]:
                self._timed_out[group] = True
                out.append((group, fresh.age(now), fresh.timeout))
        return out

    def timed_out(self, group: str) -> bool:
        """True while ``group`` runs on zero velocity (no command yet, or its last one expired)."""
        return self._timed_out[group]

    def age(self, group: str, now: float) -> float:
        """Seconds since ``group``'s last accepted command; infinity before the first."""
        return self._fresh[group].age(now)


class LockstepWait:
    """Lockstep's wait, after publishing a state, for a command from each awaited group.

    ``groups`` are the awaited groups; ``started`` turns true once the first state is out
    (every awaited controller connected, or the start-up wait ran out).
    """

    def __init__(self, groups: frozenset[str]):
        self.groups = groups
        self.started = False
        self._since: float | None = None
        self._arrived: set[str] = set()

    def begin(self, now: float) -> None:
        """A state went out at wall time ``now`` [s]: wait for its answers."""
        self._since = now
        self._arrived.clear()

    def end(self) -> None:
        """Stop waiting (the world steps now)."""
        self._since = None
        self._arrived.clear()

    def arrived(self, group: str) -> bool:
        """Note a command of ``group``; True when it completes the awaited set (time to step).
        A command while nothing is awaited (before the start, or between steps) counts for nothing."""
        if self._since is None:
            return False
        self._arrived.add(group)
        return self.groups <= self._arrived

    def overdue(self, now: float, timeout: float) -> bool:
        """True when a wait began more than ``timeout`` [s] before ``now`` [s] (step anyway)."""
        return self._since is not None and now - self._since > timeout

    def missing(self) -> list[str]:
        """The awaited groups that have not answered yet, sorted."""
        return sorted(self.groups - self._arrived)


class ObstacleContact:
    """The robot's true clearance from the obstacles after each step, and its contacts.

    :attr:`values` are what ``/diagnostics`` reports: ``clearance_m`` (negative: penetration),
    ``closest_link``, ``closest_obstacle``, ``contact_periods`` (steps that ended in contact)
    and ``deepest_contact_m`` (the deepest penetration so far, >= 0).
    """

    def __init__(self) -> None:
        self.values: dict[str, Any] = {
            'clearance_m': math.inf,
            'closest_link': '',
            'closest_obstacle': '',
            'contact_periods': 0,
            'deepest_contact_m': 0.0,
        }

    def update(self, distance: float, link: str, obstacle: str) -> str:
        """Record one step's signed ``distance`` [m] between ``link`` and ``obstacle``.

        Returns:
            '' when clear, else the line that says how deep the contact is.
        """
        self.values.update(clearance_m=distance, closest_link=link, closest_obstacle=obstacle)
        if distance >= 0.0:
            return ''
        self.values['contact_periods'] += 1
        self.values['deepest_contact_m'] = max(self.values['deepest_contact_m'], -distance)
        return f'{link} is {-distance * 1e3:.1f} mm into obstacle {obstacle!r}'

    @property
    def touching(self) -> bool:
        """True when the last step ended in contact."""
        return self.values['clearance_m'] < 0.0


def step_world(
    world: SimWorld, watchdog: CommandWatchdog, contact: ObstacleContact, covariance: OdometryCovariance, now: float
) -> tuple[list[str], str]:
    """One period of ``world``: zero the commands that expired at ``now`` [s], step, check the
    contact with the obstacles (when there are any) and advance the odometry covariance by the
    slip model's twist error over the period.

    Returns:
        (one line per group whose command just timed out, '' or the line of a contact).
    """
    timeouts = []
    for group, age, timeout in watchdog.expire(now):
        world.zero_command(group)
        timeouts.append(f'{group} command timed out (age {age:.3f} s > {timeout} s): zero velocity')
    theta = world.odom_pose()[2]
    world.step()
    touching = contact.update(*world.obstacle_clearance()) if world.obstacles else ''
    twist = world.odom_twist()
    error_mean, error_variance = world.slip.twist_error(twist, world.rim_speed)
    covariance.update(theta, twist, error_mean, error_variance, world.dt)
    return timeouts, touching


class Status(NamedTuple):
    """One ``/diagnostics`` status of the simulator: its part name, level ('ok', 'warn' or
    'error'), message and key values."""

    part: str
    level: str
    message: str
    values: dict


def statuses(
    counters: Mapping[str, Mapping[str, int]],
    watchdog: CommandWatchdog,
    now: float,
    mode: str,
    pace: tuple[float, int, float],
    contact: ObstacleContact,
    n_obstacles: int,
) -> list[Status]:
    """The simulator's statuses: one per command group, the simulation's, and (with obstacles)
    the obstacles'.

    Args:
        counters: per group, the world's command counters (``clamped``, ``rejected``, ...).
        watchdog: the command ages and timeouts, judged at ``now`` [s] (the node's clock).
        mode: the simulation status's message (timing and base mode).
        pace: (simulated time [s], steps [-], wall time since the start [s]); their ratio is
            the real-time factor (0 before any wall time passed).
        contact: the obstacle contact, reported when the world holds ``n_obstacles`` > 0.
    """
    out = []
    for group, counts in counters.items():
        stale = watchdog.timed_out(group)
        level = 'warn' if stale or counts['clamped'] or counts['rejected'] else 'ok'
        message = 'no fresh command (zero velocity)' if stale else 'commanded'
        out.append(Status(f'{group} commands', level, message, {**counts, 'command_age_s': watchdog.age(group, now)}))
    sim_time, steps, wall = pace
    rtf = sim_time / wall if wall > 0 else 0.0
    out.append(Status('simulation', 'ok', mode, {'sim_time_s': sim_time, 'steps': steps, 'real_time_factor': rtf}))
    if n_obstacles:
        values = contact.values
        message = (
            f'{values["closest_link"]} in contact with {values["closest_obstacle"]}'
            if contact.touching
            else f'clear ({n_obstacles} obstacles)'
        )
        out.append(Status('obstacles', 'error' if contact.touching else 'ok', message, values))
    return out
