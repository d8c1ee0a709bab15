"""How the simulator steps, as the other nodes learn it: the latched ``sim/lockstep_timeout``.

``wmm_sim`` publishes once, transient local (:data:`~wmm_control.nodes.qos.LATCHED_QOS`, so a
node started later still gets it), and again when its ``lockstep_timeout`` changes:
``sim/lockstep_timeout`` (``std_msgs/Float64``, relative: ``/r1/sim/lockstep_timeout`` for a
simulator in ``/r1``): 0 when it steps on its own clock (``timing: realtime``), else its
``lockstep_timeout`` [s], the longest wall time it waits after each state for the commands
that answer it before it steps anyway (``timing: lockstep``).

In lockstep nothing moves while the nodes compute, however long that takes, so a node that
knows it (:class:`SimTiming`):

- ages its inputs by the simulation's time, not the wall clock: the stamp of the last joint
  state it admitted (:meth:`~wmm_control.nodes.inputs.JointStateWatchdog.now`). An input
  that stops while the simulation goes on still goes stale;
- answers every state however long it waited (``max_state_wait`` does not apply: the world
  has not moved on from it);
- waits for the answers of the other nodes (``reference_wait``, ``compensation_timeout``) as
  long as the simulator waits for its own, while they come (:class:`AnswerWait`);
- still stops the robot when the joint states truly stop: the simulator publishes a state at
  least every ``lockstep_timeout`` while it runs, so the watchdog's wall-clock timeout grows by
  that much (:meth:`SimTiming.watchdog_timeout`), no more.

Nodes that never hear from a simulator (a real robot) keep their wall-clock rules.
"""

from __future__ import annotations

import math
from collections.abc import Callable

from rclpy.node import Node
from rclpy.timer import Timer
from std_msgs.msg import Float64

from wmm_control.nodes.qos import LATCHED_QOS

__all__ = ['LOCKSTEP_TOPIC', 'SimTiming', 'AnswerWait']

#: The simulator's latched timing (relative): 0 in realtime, else its ``lockstep_timeout`` [s].
LOCKSTEP_TOPIC = 'sim/lockstep_timeout'


class SimTiming:
    """What ``node`` knows of the simulator's timing, from :data:`LOCKSTEP_TOPIC`.

    Args:
        node: the node that subscribes (and logs the change).
        on_change: called with the new ``lockstep_timeout`` (0: realtime) each time it changes.
    """

    def __init__(self, node: Node, on_change: Callable[[float], object] | None = None) -> None:
        self._node = node
        self._on_change = on_change
        #: the simulator's lockstep_timeout [s]; 0 while it steps in realtime (or is not heard)
        self.lockstep_timeout = 0.0
        self.subscription = node.create_subscription(Float64, LOCKSTEP_TOPIC, self._on_message, LATCHED_QOS)

    @property
    def lockstep(self) -> bool:
        """True while the simulator steps in lockstep with the nodes."""
        return self.lockstep_timeout > 0.0

    def wait_for(self, configured: float) -> float:
        """How long [s] to wait for another node's answer, ``configured`` in realtime: in lockstep
        at least as long as the simulator waits (a wait of 0, no wait, stays 0)."""
        if configured > 0.0 and self.lockstep:
            return max(float(configured), self.lockstep_timeout)
        return float(configured)

    def watchdog_timeout(self, configured: float) -> float:
        """After how long [s] of wall time without joint states they have truly stopped:
        ``configured``, plus in lockstep the simulator's wait for the slowest answer."""
        return float(configured) + self.lockstep_timeout

    def _on_message(self, msg: Float64) -> None:
        value = float(msg.data)
        logger = self._node.get_logger()
        if not (math.isfinite(value) and value >= 0.0):
            logger.warn(f'rejected /{LOCKSTEP_TOPIC} {value}: not a time; keeping {self.lockstep_timeout:g} s')
            return
        if value == self.lockstep_timeout:
            return
        self.lockstep_timeout = value
        if value > 0.0:
            logger.info(
                f'the simulator steps in lockstep (it waits up to {value:g} s for the commands): inputs are aged '
                'by the simulation\'s time, every state is answered however long it waited, and the answers of '
                f'the other nodes are awaited up to {value:g} s'
            )
        else:
            logger.info('the simulator steps in realtime: inputs are aged by this node\'s clock')
        if self._on_change is not None:
            self._on_change(value)


class AnswerWait:
    """How long a node waits for another node's answer to the state of a period (the base
    controller for the reference of its stamp, the resolver for the feasible twist).

    ``configured`` [s] in realtime (0: no wait). In lockstep as long as the simulator waits for
    the commands (:meth:`SimTiming.wait_for`) while the answers come, however late; after one
    that never came, ``configured`` again until the next one comes (late or not): a node that
    answers nothing, or a reference published by hand (unstamped), does not slow the simulation
    to one step per ``lockstep_timeout``.
    """

    def __init__(self, timing: SimTiming, configured: float) -> None:
        self.timing = timing
        self.configured = float(configured)
        #: the last answer awaited came (or nothing was awaited yet)
        self.answering = True

    def seconds(self) -> float:
        """How long [s] to wait for the next answer."""
        return self.timing.wait_for(self.configured) if self.answering else self.configured

    def answered(self) -> None:
        """An answer awaited came, in time or late."""
        self.answering = True

    def missed(self) -> None:
        """An answer awaited did not come within the wait."""
        self.answering = False

    def start(self, timer: Timer) -> None:
        """(Re)start ``timer``, the wait's one-shot timer, to fire :meth:`seconds` from now."""
        period = int(self.seconds() * 1e9)
        if period != timer.timer_period_ns:
            timer.timer_period_ns = period
        timer.reset()
