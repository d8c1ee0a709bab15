"""A node's process: main() (:func:`run_node`), its executor, signals, and a guard on ``/clock``."""

import atexit
import faulthandler
import os
import signal
import sys
import threading
from collections.abc import Callable

import rclpy
from rclpy.executors import Executor, ExternalShutdownException, SingleThreadedExecutor

# rclpy.init's RCLError (a command line it cannot take) has no public home in rclpy.
from rclpy.impl.implementation_singleton import rclpy_implementation as _rclpy
from rclpy.node import Node
from rclpy.signals import SignalHandlerOptions
from rclpy.time_source import TimeSource
from rosgraph_msgs.msg import Clock as ClockMsg

from wmm_control.cycle import steady_heap
from wmm_control.errors import WmmError

RCLError = _rclpy.RCLError

__all__ = ['run_node', 'default_executor', 'guard_clock', 'FASTDDS_TRANSPORTS']


def default_executor() -> Executor:
    """rclpy's events executor (several times faster per message in Jazzy), else single-threaded."""
    try:
        from rclpy.experimental import EventsExecutor
    except ImportError:
        return SingleThreadedExecutor()
    return EventsExecutor()


def guard_clock(node: Node) -> None:
    """Make ``node`` drop the ``/clock`` messages rclpy's time source cannot take, with a warning.

    With ``use_sim_time``, rclpy's own time source turns each ``/clock`` message into a time
    point, and raises inside its callback for a negative time (``ValueError: Seconds value must
    not be negative``), which would end the node. A ``/clock`` stamp is at most 2³¹ − 1 s, a
    time rclpy takes, so a negative one is the only such message. It is dropped before rclpy
    sees it, logged through ``node``'s logger (throttled): the ROS clock keeps its last time.
    ``use_sim_time`` set at run time makes a new subscription, guarded in turn.
    """

    def guard(callback: Callable[[ClockMsg], object]) -> Callable[[ClockMsg], None]:
        def guarded(msg: ClockMsg) -> None:
            if msg.clock.sec < 0:
                node.get_logger().warn(
                    f'ignored a /clock message at {msg.clock.sec} s {msg.clock.nanosec} ns: a negative time, '
                    f'which rclpy cannot take; the ROS clock keeps its last time '
                    f'({node.count_publishers("/clock")} publisher(s) on /clock)',
                    throttle_duration_sec=1.0,
                )
                return
            callback(msg)

        return guarded

    def guard_all(_params: object = ()) -> None:
        # rclpy offers no hook on its time source's /clock subscription: find it, wrap its callback.
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

#: [s] the teardown after a stop (the executor, the node, the context) may take before the
#: process leaves without the rest (every thread's stack written to stderr first), exit code 0:
#: the node has stopped; a teardown stuck in the middleware must not need ``ros2 launch``'s
#: SIGKILL, 15 s after Ctrl-C, to end it.
TEARDOWN_LIMIT = 3.0
#: [s] after :data:`TEARDOWN_LIMIT`, when the teardown still holds the interpreter lock (a Fast
#: DDS participant whose destruction waits on one of its own threads, seen once in many stops:
#: the limit's timer, a Python thread, never ran), a timer outside Python ends the process with
#: code 1, every thread's stack written to stderr first (:func:`faulthandler.dump_traceback_later`).
TEARDOWN_BACKSTOP = 2.0
#: [s] the interpreter's exit may take (the middleware's destructors) before the process leaves
#: with code 1, every thread's stack written to stderr (:func:`faulthandler.dump_traceback_later`).
EXIT_LIMIT = 8.0


def run_node(
    node_factory: Callable[[], Node],
    args: list[str] | None = None,
    executor_factory: Callable[[], Executor] = default_executor,
) -> int:
    """Standard main(): init, build the node, spin until Ctrl-C, SIGTERM or shutdown, clean up.

    A configuration error at start-up (the command line's included) is logged and gives exit
    code 2. Ctrl-C and SIGTERM end the spin loop between callbacks: rclpy's own handlers shut
    the context down at once, in the middle of a callback, whose next publish then fails
    ("publisher's context is invalid", a traceback on the way out). Further ones during the
    teardown are only noted (``ros2 launch`` sends SIGINT twice); the previous handlers come
    back once the context is shut down, and from the interpreter's exit on both signals are
    ignored (:func:`_ignore_stop_signals_at_exit`). The process uses Fast DDS's UDP transport
    alone (:data:`FASTDDS_TRANSPORTS`) unless ``FASTDDS_BUILTIN_TRANSPORTS`` is set. The teardown
    has :data:`TEARDOWN_LIMIT` seconds (a node's ``teardown_limit`` attribute, if it has one),
    and with ``args`` None (the process's own command line) the interpreter's exit
    :data:`EXIT_LIMIT`. SIGUSR1
    writes every thread's Python stack to stderr (``kill -USR1 <pid>``: where a node hangs).
    """
    os.environ.setdefault('FASTDDS_BUILTIN_TRANSPORTS', FASTDDS_TRANSPORTS)
    if hasattr(faulthandler, 'register'):  # a node that hangs shows where: kill -USR1 <pid>
        faulthandler.register(signal.SIGUSR1, all_threads=True)
    try:
        rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    except RCLError as exc:  # the command line: a --params-file that cannot be read, a bad rule
        rclpy.logging.get_logger('wmm_control').fatal(f'cannot start: {exc}')
        return 2
    stop = []
    previous = {}
    if threading.current_thread() is threading.main_thread():  # where Python delivers signals
        previous = {
            sig: signal.signal(sig, lambda signum, _frame: stop.append(signum))
            for sig in (signal.SIGINT, signal.SIGTERM)
        }
    _ignore_stop_signals_at_exit(exit_deadline=args is None)
    node = executor = None
    try:
        node = node_factory()
        executor = executor_factory()
        executor.add_node(node)
        # spin_once in a loop rather than spin(): it returns to check the stop request.
        with steady_heap():  # what the node built stays out of the garbage collector's full passes
            while rclpy.ok() and not stop:
                executor.spin_once(timeout_sec=0.1)
    except ExternalShutdownException:
        pass  # the context was shut down from outside (rclpy's own signal handling): a normal stop
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
        deadline = _teardown_deadline(getattr(node, 'teardown_limit', TEARDOWN_LIMIT))
        try:
            if executor is not None:
                executor.shutdown()
                del executor
            if node is not None:
                node.destroy_node()
            rclpy.try_shutdown()
        finally:
            deadline.cancel()
            faulthandler.cancel_dump_traceback_later()
            for sig, handler in previous.items():
                signal.signal(sig, handler)
    return 0


def _teardown_deadline(limit: float) -> threading.Timer:
    """A timer that, unless cancelled within ``limit`` [s], writes every thread's stack to
    stderr and ends the process with code 0 (:data:`TEARDOWN_LIMIT`)."""

    def expire() -> None:
        sys.stderr.write(
            f'[wmm_control] the teardown did not finish within {limit:g} s after the stop; leaving without '
            'the rest (every thread\'s stack follows)\n'
        )
        faulthandler.dump_traceback(sys.stderr, all_threads=True)
        sys.stderr.flush()
        os._exit(0)

    timer = threading.Timer(limit, expire)
    timer.daemon = True
    timer.start()
    # The timer above needs the interpreter lock; this one does not (its own thread, in C).
    faulthandler.dump_traceback_later(limit + TEARDOWN_BACKSTOP, exit=True)
    return timer


_EXIT_GUARD: list[bool] = []


def _ignore_stop_signals_at_exit(exit_deadline: bool) -> None:
    """From the interpreter's exit on, ignore SIGINT and SIGTERM (registered once, by :func:`run_node`).

    After ``main()`` returns, the interpreter's finalization (the middleware's destructors) takes
    a few tenths of a second, during which Python resets SIGINT to the system default: a second
    Ctrl-C then killed the process (exit -2) although the node had stopped cleanly. Python keeps
    an ignored signal ignored through its finalization. With ``exit_deadline`` (a node's process,
    its command line from ``sys.argv``; not a node run inside another program, such as a test),
    an exit stuck in the middleware, which ignored signals cannot end, gets :data:`EXIT_LIMIT`.
    """
    if _EXIT_GUARD or threading.current_thread() is not threading.main_thread():
        return
    _EXIT_GUARD.append(True)

    def ignore() -> None:
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
        if exit_deadline:
            faulthandler.dump_traceback_later(EXIT_LIMIT, exit=True)

    atexit.register(ignore)
