"""A controller's inputs: joint states read by name and watched for their timing, the base reference."""

from __future__ import annotations

import math
import time
from collections import deque
from collections.abc import Callable, Iterable
from typing import TYPE_CHECKING

import numpy as np
from numpy.typing import ArrayLike

from wmm_control.checks import Freshness, JointCheck
from wmm_control.nodes.conversions import parse_base_reference
from wmm_control.nodes.sim_timing import SimTiming
from wmm_control.nodes.stamps import StampGate, seconds

if TYPE_CHECKING:
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import TwistStamped
    from rclpy.clock import Clock
    from rclpy.node import Node
    from rclpy.publisher import Publisher
    from sensor_msgs.msg import JointState

__all__ = ['JointSelector', 'BaseReference', 'JointStateWatchdog', 'DELIVERY_WINDOW']


class JointSelector:
    """Reads named joints from ``sensor_msgs/JointState`` messages, whatever their order, and
    checks their values (:class:`~wmm_control.checks.JointCheck`, as the direct engine does).

    The index of each name layout is cached (senders use one or two layouts).

    Args:
        joints: the joint names to read, in the order they are returned.
        velocity_limits: optional |q̇| limit per joint [rad/s]; a measured rate beyond
            ``PLAUSIBLE_FACTOR`` times it is taken for a glitch and the message is rejected.
        position_limits: optional ``(lower, upper)`` per joint [rad]; a position beyond them by
            more than ``JointCheck.POSITION_MARGIN`` is rejected.
    """

    def __init__(
        self,
        joints: Iterable[str],
        cache_size: int = 16,
        velocity_limits: ArrayLike | None = None,
        position_limits: tuple[ArrayLike, ArrayLike] | None = None,
    ) -> None:
        self.joints = tuple(joints)
        self._cache: dict[tuple[str, ...], np.ndarray | str] = {}
        self._cache_size = cache_size
        #: the checks of the values read
        self.check = JointCheck(self.joints, velocity_limits, position_limits)

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

    def indices(self, msg: JointState) -> tuple[np.ndarray, str] | tuple[None, str]:
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

    def read(self, msg: JointState) -> tuple[np.ndarray, np.ndarray, str] | tuple[None, None, str]:
        """``(positions, velocities, '')`` of the joints, or ``(None, None, reason)``.

        Velocities are zero when the message has none. Values that fail :attr:`check` give a
        reason.
        """
        idx, reason = self.indices(msg)
        if idx is None:
            return None, None, reason
        q = np.asarray(msg.position, dtype=float)[idx]
        return self.check.read(q, np.asarray(msg.velocity, dtype=float)[idx] if len(msg.velocity) else None)


class BaseReference:
    """The latest ``/base/reference`` of a planar base, validated, with its age.

    Its age is judged by the node's clock at receipt (:class:`Freshness`), never by its stamp.

    Args:
        node: the node whose logger is used.
        base_frame: the one frame accepted besides an empty one.
        timeout: age [s] beyond which :meth:`current` gives None.
        velocity_limit: |vx|, |vy|, |ω| limits; a reference beyond them is kept (the
            controller scales it into them) with a logged warning.
        now: the node's clock [s] (its receipt time); default: the node's ROS clock.
    """

    def __init__(
        self,
        node: Node,
        base_frame: str,
        timeout: float,
        velocity_limit: ArrayLike | None = None,
        now: Callable[[], float] | None = None,
    ) -> None:
        self._node = node
        self._now = now if now is not None else (lambda: seconds(node.get_clock()))
        self.base_frame = base_frame
        self.value = np.zeros(3)
        self.freshness = Freshness(timeout)
        self.rejected = 0
        self._limit = None if velocity_limit is None else np.asarray(velocity_limit, dtype=float)
        self._stale_logged = False

    def accept(self, msg: TwistStamped) -> bool:
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
            logger.warn(
                f'/base/reference {ref.tolist()} is beyond the velocity limits {self._limit.tolist()}: '
                'scaled into them',
                throttle_duration_sec=1.0,
            )
        self.value = ref
        self.freshness.mark(self._now())
        self._stale_logged = False
        return True

    def current(self, now: float) -> np.ndarray | None:
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

    :meth:`waited_too_long` tells, when the cycle is about to run and again before it publishes,
    whether the state waited in this node longer than ``max_wait`` since its receipt (the node's
    steady clock: no clock of the sender's is involved). A node that was held up (stopped, or
    starved on a busy machine) may run a state that waited for its reference meanwhile, or be
    held in the middle of a cycle; a real-time simulator has stepped past that state, and an
    answer to it would be applied now, as if it were current.

    With ``max_wait`` set, :meth:`admit` also skips a state that reached this node more than
    ``max_wait`` later than the joint states usually do: its receipt on the node's clock minus its
    stamp, against the smallest such offset of the last :data:`DELIVERY_WINDOW` states (a constant
    offset between the sender's clock and this node's cancels). A node held up (stopped, or
    starved) finds the states sent meanwhile queued in its transport: they reach its callback one
    by one after it goes on, the oldest first, each looking new to it, and each reports rates the
    simulator has since changed.

    It also learns how the simulator steps (:attr:`timing`,
    :class:`~wmm_control.nodes.sim_timing.SimTiming`): in lockstep nothing moves while a node computes,
    so no state is skipped for its wait (``max_wait`` does not apply), the node's inputs are aged
    by the simulation's time (:meth:`now`), and the joint states count as stopped only after
    ``timeout`` plus the simulator's ``lockstep_timeout`` of wall time (it steps at least that
    often while it runs).
    """

    def __init__(
        self,
        node: Node,
        timeout: float,
        period: float,
        clock: Clock,
        on_timeout: Callable[[], object],
        action: str,
        topic: str = 'joint_states',
        max_wait: float = 0.0,
    ) -> None:
        self._node = node
        self.max_wait = float(max_wait)
        #: the simulator's timing, learned from its latched topic
        self.timing = SimTiming(node)
        #: the simulation's time [s]: the stamp of the last joint state admitted (0 before the first)
        self.sim_time = 0.0
        self._clock = clock
        self._on_timeout = on_timeout
        self._action = action
        self._topic = topic
        self.freshness = Freshness(timeout)
        self._period = float(period)
        self.stamps = StampGate(period, max_jump=self._max_jump(timeout))
        self.skipped = 0
        self.need_resync = True
        self._offsets: deque[int] = deque(maxlen=DELIVERY_WINDOW)  # receipt − stamp [ns] of the last joint states
        self.timer = node.create_timer(period, self._check, clock=clock)

    def _max_jump(self, timeout):
        return max(float(timeout), 4.0 * self._period)

    def set_timeout(self, timeout: float) -> None:
        """A new timeout [s] (a parameter set at run time): for the age and for the stamp jump."""
        self.freshness.timeout = float(timeout)
        self.stamps.max_jump = self._max_jump(timeout)

    def now(self, clock: Clock) -> float:
        """The time [s] by which the node ages its inputs: in lockstep the simulation's
        (:attr:`sim_time`), else ``clock``'s."""
        return self.sim_time if self.timing.lockstep else seconds(clock)

    @property
    def limits_wait(self) -> bool:
        """True when ``max_wait`` applies: set, and the simulator does not step in lockstep."""
        return self.max_wait > 0.0 and not self.timing.lockstep

    def waited_too_long(self, received_ns: int, outcome: str = 'cycle skipped') -> bool:
        """True (logged with ``outcome``, throttled, and counted as skipped) when a joint state
        received at ``received_ns`` (``time.monotonic_ns()`` in its callback) waited longer than
        ``max_wait`` (never in lockstep)."""
        if not self.limits_wait:
            return False
        wait = (time.monotonic_ns() - received_ns) * 1e-9
        if wait <= self.max_wait:
            return False
        self.skipped += 1
        self._node.get_logger().warn(
            f'/{self._topic} waited {wait:.3g} s in this node, beyond max_state_wait {self.max_wait:g} s (the node '
            f'was held up): {outcome}',
            throttle_duration_sec=1.0,
        )
        return True

    def mark(self) -> None:
        """A joint state arrived now."""
        self.freshness.mark(seconds(self._clock))

    def late(self, stamp: Time) -> float:
        """How much later [s] than the usual delivery the joint state stamped ``stamp`` reached this
        node now (0 when it is the earliest of the window, or unstamped: a zero stamp tells no time)."""
        ns = stamp.sec * 1_000_000_000 + stamp.nanosec
        if ns == 0:
            return 0.0
        offset = self._node.get_clock().now().nanoseconds - ns
        self._offsets.append(offset)
        return (offset - min(self._offsets)) * 1e-9

    def admit(self, stamp: Time) -> bool:
        """True when the joint state stamped ``stamp`` runs a cycle (it is then marked fresh)."""
        logger = self._node.get_logger()
        late = self.late(stamp) if self.limits_wait else 0.0
        if late > self.max_wait:
            self.skipped += 1
            logger.warn(
                f'/{self._topic} arrived {late:.3g} s later than the usual delivery, beyond max_state_wait '
                f'{self.max_wait:g} s (it was queued while this node was held up): cycle skipped',
                throttle_duration_sec=1.0,
            )
            return False
        reason = self.stamps.admit(stamp)
        if reason:
            self.skipped += 1
            publishers = self._node.count_publishers(self._topic)
            logger.warn(
                f'/{self._topic} {reason}; {publishers} publisher(s) on it: cycle skipped', throttle_duration_sec=1.0
            )
            return False
        self.mark()
        self.sim_time = (stamp.sec * 1_000_000_000 + stamp.nanosec) * 1e-9
        mismatch = self.stamps.period_mismatch()
        if mismatch:
            logger.warn(mismatch, throttle_duration_sec=10.0)
        return True

    def resync(self, *outputs: Publisher) -> bool:
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
        timeout = self.timing.watchdog_timeout(self.freshness.timeout)
        if not timeout < age < math.inf:
            return
        if not self.need_resync:
            lockstep = (
                f' (the simulator, in lockstep, steps at least every {self.timing.lockstep_timeout:g} s)'
                if self.timing.lockstep
                else ''
            )
            self._node.get_logger().warn(f'no /{self._topic} for {timeout:g} s{lockstep}: {self._action}')
            self.need_resync = True
        self.stamps.restart()
        self._offsets.clear()
        self._on_timeout()
