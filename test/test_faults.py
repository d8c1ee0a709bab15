"""Faults of whole processes: the simulator, the base controller and the resolver, each its own
process (the installed console scripts, started as ``ros2 run`` starts them) on a private
domain, robot A in real time with its default parameters.

One run, the faults in turn while the robot drives to a far goal:

1. the base controller is killed (SIGKILL) and later started again;
2. the base controller stalls (SIGSTOP) longer than the simulator's command timeout but
   shorter than its own joint-state timeout, then continues (SIGCONT);
3. the simulator stops (SIGSTOP) and, a second later, continues (SIGCONT);
4. the resolver is killed.

Then robot B (Mecanum base, AMP) in a second run: its base controller killed and started
again, then stalled as robot A's.

The run records, by this process's clock at receipt, every command, the ground-truth twist
and the nodes' ``/rosout``; the tests below check each fault against it.
"""

import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
import rclpy
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped, TwistStamped
from nav_msgs.msg import Odometry
from rcl_interfaces.msg import Log
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.parameter_client import AsyncParameterClient
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from wmm_control.experiments.ros_run import private_domain_id
from wmm_control.nodes.parameters import load_defaults
from wmm_control.robot_config import load_robot

BIN = Path(sys.executable).parent
COMMAND_TIMEOUT = load_defaults('wmm_sim.yaml', 'wmm_sim')['command_timeout']
STATE_TIMEOUT = load_defaults('redundancy_resolver.yaml', 'redundancy_resolver')['state_timeout']
SWMR = load_defaults('swmr_controller.yaml', 'swmr_controller')
BASE_ACCEL_LIMIT = np.asarray(load_robot('steerable').base.acceleration)  # the robot YAML's
ROBOT = load_robot('steerable')
PERIOD = ROBOT.period  # every node's default
#: A node's own scheduling on a loaded 2-core machine, on top of the figures the design gives
#: (a timeout plus the periods in which it is noticed and acted upon), when judged by the
#: stamps the nodes give their messages; and with the delivery to this process, when judged
#: by arrival (unstamped commands).
SCHEDULING = 0.05
DELIVERY = 0.25
GOAL = (12.0, 3.0, 1.0)


def _seconds(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


class Record(Node):
    """Everything the faults are judged by, stamped with this process's monotonic clock."""

    def __init__(self, context):
        super().__init__('fault_recorder', context=context)
        self.topics = {}
        self.stamps = {}
        for topic in (
            'arm_controller/commands',
            'steer_controller/commands',
            'drive_controller/commands',
            'wheel_controller/commands',
        ):
            self._record(Float64MultiArray, topic, lambda m: np.array(m.data))
        for topic in ('base/reference', 'base/feasible_twist'):
            self._record(
                TwistStamped, topic, lambda m: np.array([m.twist.linear.x, m.twist.linear.y, m.twist.angular.z])
            )
        self._record(
            Odometry,
            'ground_truth/odom',
            lambda m: np.array([m.twist.twist.linear.x, m.twist.twist.linear.y, m.twist.twist.angular.z]),
        )
        arm = list(ROBOT.arm.joints)
        self._record(JointState, 'joint_states', lambda m: np.array([dict(zip(m.name, m.velocity))[j] for j in arm]))
        # Per joint-state stamp: whether its base joints report rest (the rates applied over its period).
        self.base_at_rest = {}
        self.create_subscription(
            JointState,
            'joint_states',
            lambda m: self.base_at_rest.__setitem__(
                _seconds(m.header.stamp), not any(v for n, v in zip(m.name, m.velocity) if n not in arm)
            ),
            50,
        )
        self.logs = []
        self.create_subscription(
            Log,
            '/rosout',
            lambda m: self.logs.append((time.monotonic(), m.name, m.msg)),
            QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE),
        )
        self.goal = self.create_publisher(PoseStamped, 'goal_pose', 10)
        self.diagnostics = []
        self.create_subscription(
            DiagnosticArray,
            '/diagnostics',
            lambda m: self.diagnostics.extend(
                (time.monotonic(), {kv.key: kv.value for kv in s.values})
                for s in m.status
                if s.name == '/redundancy_resolver'
            ),
            50,
        )

    def _record(self, msg_type, topic, values):
        series = self.topics.setdefault(topic, [])
        self.stamps[topic] = stamps = []

        def callback(msg):
            series.append((time.monotonic(), values(msg)))
            if hasattr(msg, 'header'):
                stamps.append(_seconds(msg.header.stamp))

        self.create_subscription(msg_type, topic, callback, 50)

    def series(self, topic, start=-np.inf, end=np.inf):
        """``(times, values)`` received in [start, end); of a stamped topic, only the messages
        stamped after every one received before ``start`` (a process that was stopped may
        deliver messages it had sent before, late)."""
        rows = self.topics[topic]
        stamps = self.stamps[topic]
        newest = max((s for (t, _), s in zip(rows, stamps) if t < start), default=-np.inf)
        keep = [i for i, (t, _) in enumerate(rows) if start <= t < end and (not stamps or stamps[i] > newest)]
        return np.array([rows[i][0] for i in keep]), np.array([rows[i][1] for i in keep])

    def publish_goal(self, goal=GOAL, quaternion=(0.5**0.5, 0.0, 0.0, 0.5**0.5)):
        """The goal: position ``goal``, orientation ``quaternion`` (x, y, z, w); by default robot A's
        far goal, RPY (π/2, 0, 0) as at the start."""
        msg = PoseStamped()
        msg.header.frame_id = 'world'
        msg.pose.position.x, msg.pose.position.y, msg.pose.position.z = goal
        q = msg.pose.orientation
        q.x, q.y, q.z, q.w = quaternion
        self.goal.publish(msg)


class System:
    """The three processes and the recorder, on a domain of this test alone."""

    def __init__(self):
        self.domain = private_domain_id(37)
        self.env = dict(os.environ, ROS_DOMAIN_ID=str(self.domain))
        self.procs = {}
        self.context = rclpy.Context()
        rclpy.init(context=self.context, domain_id=self.domain)
        self.rec = Record(self.context)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.executor.add_node(self.rec)
        self.events = {}
        self.wall = {}  # the system clock at each event: the nodes' stamps in real time

    def start(self, name, *params):
        """Start the executable ``name`` with ``params`` (``'robot:=mecanum'``, ...)."""
        args = ['--ros-args', *(a for p in params for a in ('-p', p))] if params else []
        self.procs[name] = subprocess.Popen(
            [str(BIN / name), *args], env=self.env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True
        )

    def signal(self, name, sig):
        self.events[(name, sig)] = time.monotonic()
        self.wall[(name, sig)] = time.time()
        self.procs[name].send_signal(sig)
        if sig == signal.SIGKILL:
            self.procs[name].wait(timeout=10)

    def spin(self, seconds, until=None):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.01)
            if until is not None and until():
                return True
        return until is None

    def set_parameter(self, node, name, value):
        """Set a live parameter of ``node`` through its parameter service, as ``ros2 param set`` does."""
        client = AsyncParameterClient(self.rec, node)
        assert self.spin(30.0, client.services_are_ready), f'no parameter service of {node}'
        future = client.set_parameters([Parameter(name, value=value)])
        assert self.spin(30.0, future.done), f'{node} did not answer'
        assert all(r.successful for r in future.result().results), future.result()

    def drive_to_goal(self, speed, command_topic, *goal):
        """Send the goal (``goal``: :meth:`Record.publish_goal`'s arguments) until the base is under
        way faster than ``speed`` and this recorder hears every process (discovery may take a while)."""

        def moving():
            if self.rec.count_subscribers('goal_pose'):
                self.rec.publish_goal(*goal)
            heard = all(
                len(self.rec.topics[t]) > 20
                for t in (command_topic, 'arm_controller/commands', 'base/feasible_twist', 'base/reference')
            )
            return self.base_speed() > speed and heard

        assert self.spin(120.0, moving), 'the robot never started for the goal'

    def kill_restart_and_stall(self, controller, speed, command_topic):
        """The base controller killed, started again, then stalled; events 'base restarted' and
        'stall over' mark the ends of the windows the tests judge.

        The stall: the simulator zeroes the base after its command timeout, and the controller,
        whose joint-state timeout has not passed (made long here, so that a loaded machine cannot
        stretch the stall past it), answers the newest joint state (its subscription keeps only
        that one), not those queued meanwhile."""
        self.spin(1.0)
        self.signal(controller, signal.SIGKILL)
        assert self.spin(5.0, lambda: self.base_speed() == 0.0), 'the base did not stop'
        self.spin(1.0)
        self.events['base restarted'] = restarted = time.monotonic()
        self.start(controller)
        assert self.spin(
            60.0, lambda: self.base_speed() > speed and len(self.rec.series(command_topic, restarted)[0]) > 10
        ), 'the base did not resume'
        self.spin(1.0)
        self.set_parameter(controller, 'joint_state_timeout', 10.0)
        # Stopped just after an answer, between cycles: a stop that lands between the controller's
        # last check of a cycle and its publish sends that answer a second later, when it goes on,
        # and the simulator applies it for a period (a late command, another fault than this one).
        answers = len(self.rec.topics['base/feasible_twist'])
        assert self.spin(5.0, lambda: len(self.rec.topics['base/feasible_twist']) > answers)
        self.signal(controller, signal.SIGSTOP)
        self.spin(1.0)
        self.signal(controller, signal.SIGCONT)
        assert self.spin(30.0, lambda: self.base_speed() > speed), 'the base did not resume after the stall'
        self.spin(1.0)
        self.events['stall over'] = time.monotonic()

    def base_speed(self):
        _, twist = self.rec.series('ground_truth/odom', time.monotonic() - 0.2)
        return float(np.max(np.linalg.norm(twist[:, :2], axis=1))) if len(twist) else 0.0

    def close(self):
        self.executor.remove_node(self.rec)
        self.rec.destroy_node()
        rclpy.try_shutdown(context=self.context)
        outputs = {}
        for name, proc in self.procs.items():
            if proc.poll() is None:
                proc.send_signal(signal.SIGCONT)
                proc.send_signal(signal.SIGINT)
            try:
                outputs[name] = proc.communicate(timeout=30)[0]
            except subprocess.TimeoutExpired:
                proc.kill()
                outputs[name] = proc.communicate()[0]
        return outputs


def _run(scenario):
    """A new system through ``scenario(system)``; the system (records, event times and the
    processes' output) after it ends. The output is printed when the scenario fails."""
    system = System()
    try:
        scenario(system)
    except BaseException:
        outputs = system.close()
        print('\n'.join(f'--- {name}\n{out}' for name, out in outputs.items()))
        raise
    system.outputs = system.close()
    return system


@pytest.fixture(scope='module')
def run():
    """The faults of robot A in turn."""

    def scenario(system):
        for name in ('wmm_sim', 'swmr_controller', 'redundancy_resolver'):
            system.start(name)
        system.drive_to_goal(0.2, 'steer_controller/commands')
        system.kill_restart_and_stall('swmr_controller', 0.2, 'steer_controller/commands')
        system.set_parameter('swmr_controller', 'joint_state_timeout', SWMR['joint_state_timeout'])
        system.spin(1.0)
        system.signal('wmm_sim', signal.SIGSTOP)
        system.spin(1.0)
        system.signal('wmm_sim', signal.SIGCONT)
        assert system.spin(10.0, lambda: system.base_speed() > 0.2), 'the base did not resume after the simulator'
        system.spin(1.0)
        system.signal('redundancy_resolver', signal.SIGKILL)
        system.spin(2.0)

    return _run(scenario)


def _first(times, values, predicate, after):
    """Time of the first value after ``after`` that satisfies ``predicate``, or inf."""
    for t, v in zip(times, values):
        if t >= after and predicate(v):
            return t
    return np.inf


def _moving_periods(rec, topic, after):
    """Simulation periods after ``after`` in which ``topic`` (a state of the simulator) still moves."""
    times, values = rec.series(topic, after)
    stop = next((i for i, v in enumerate(values) if not np.any(np.abs(v) > 1e-9)), len(values))
    return stop, times[stop] if stop < len(times) else np.inf


def _is_zero(v):
    return not np.any(v)


def _jumps_per_period(stamps, twist):
    """The change of ``twist`` between consecutive messages, per period of their ``stamps`` [s]: a
    loaded machine's recorder may miss messages (or a controller skip a state), and the limits
    bound the change per period of the sender's time."""
    periods = np.maximum(np.round(np.diff(np.asarray(stamps, dtype=float)) / PERIOD), 1.0)
    return np.abs(np.diff(np.asarray(twist, dtype=float), axis=0)) / periods[:, None]


def _starts_from_rest(run, after, end, topics, sent_after=-np.inf, factor=2.0, limit=BASE_ACCEL_LIMIT):
    """The base, after ``after``, resumes from rest without a jump: on each of ``topics``, the
    first twist off rest and every change per period after it are within ``factor`` times the
    per-period acceleration limit (``limit``, the robot's; on robot A the projection onto the
    next ICR may pass it). Only messages stamped (system clock) after ``sent_after`` count: a
    stopped simulator delivers what it sent before, late."""
    step = np.asarray(limit) * PERIOD
    for topic in topics:
        kept = [
            (s, v)
            for (t, v), s in zip(run.rec.topics[topic], run.rec.stamps[topic])
            if after <= t < end and s > sent_after
        ]
        stamps, twist = np.array([s for s, _ in kept]), np.array([v for _, v in kept])
        moving = np.flatnonzero(np.any(np.abs(twist) > 1e-9, axis=1))
        assert len(moving) > 10, f'{topic}: the base moves again'
        assert np.all(np.abs(twist[moving[0]]) <= factor * step + 1e-12), (topic, np.abs(twist[moving[0]]) / step)
        jumps = _jumps_per_period(stamps[moving[0] :], twist[moving[0] :])
        assert np.all(jumps <= factor * step + 1e-12), (topic, jumps.max(axis=0) / step)


# In simulation periods: the robot does not move while the simulator does not step, so the stop
# is judged by the periods the simulator runs, not by wall time (a loaded machine, or Fast DDS's
# shared-memory transport after a peer is killed, which the executables do not use, can hold it).
COMMAND_PERIODS = int(np.ceil(COMMAND_TIMEOUT / PERIOD)) + 2
#: A base controller that starts again, or goes on after a stall, changes the twist by at most one
#: period of acceleration (measured, on robot A: 1.0), up to a quarter more where the feasible twist
#: is projected onto the next ICR.
RESUME_FACTOR = 1.25


def test_a_killed_base_controller_stops_the_base_within_the_command_timeout(run):
    rec, killed = run.rec, run.events[('swmr_controller', signal.SIGKILL)]
    t_last, _ = rec.series('drive_controller/commands', end=killed)
    periods, _ = _moving_periods(rec, 'ground_truth/odom', t_last[-1])
    assert periods <= COMMAND_PERIODS, periods
    # Meanwhile the resolver goes on without its feasible twist, and says so (throttled, once a second)
    # and counts it on /diagnostics.
    dropped = [
        m for t, name, m in rec.logs if name == 'redundancy_resolver' and t > killed and 'without compensation' in m
    ]
    assert dropped
    counts = [(t, int(v['compensation_dropped'])) for t, v in rec.diagnostics if 'compensation_dropped' in v]
    before = max(n for t, n in counts if t < killed)
    assert max(n for t, n in counts if t < run.events['base restarted']) > before


def test_a_restarted_base_controller_drives_the_base_again(run):
    restarted, end = run.events['base restarted'], run.events[('wmm_sim', signal.SIGSTOP)]
    _, twist = run.rec.series('ground_truth/odom', restarted, end)
    assert not np.any(twist[0]) and np.max(np.linalg.norm(twist[:, :2], axis=1)) > 0.2


def test_a_restarted_base_controller_resumes_within_the_acceleration_limits(run):
    """Judged on the true twist: this recorder may discover the new process's publishers only
    after its first commands."""
    _starts_from_rest(
        run,
        run.events['base restarted'],
        run.events[('swmr_controller', signal.SIGSTOP)],
        ['ground_truth/odom'],
        factor=RESUME_FACTOR,
    )


def _answers_from_rest_after_the_stall(run, controller, limit):
    """The simulator zeroed the base during the stall: the controller's answer to the first joint
    state that reports the base at rest (its rates are zero) starts from rest, and its answers
    after it change by at most ``RESUME_FACTOR`` periods of acceleration each: the controller
    finds that its last command was not applied, or that the stall held up a cycle (whose answer
    it drops), and restarts from the measured state (logged).

    Judged on the answers by the stamps of the joint states they answer, and on the true twist:
    the base starts again from rest, without a lurch back to its speed before the stall."""
    stalled, resumed = run.events[(controller, signal.SIGSTOP)], run.events[(controller, signal.SIGCONT)]
    periods, _ = _moving_periods(run.rec, 'ground_truth/odom', stalled + 0.05)
    assert periods <= COMMAND_PERIODS + 2, 'the simulator stopped the base during the stall'
    answers = sorted(
        (s, tuple(v))
        for (t, v), s in zip(run.rec.topics['base/feasible_twist'], run.rec.stamps['base/feasible_twist'])
        if resumed <= t < run.events['stall over'] and s > run.wall[(controller, signal.SIGSTOP)]
    )
    first = next((i for i, (s, _) in enumerate(answers) if run.rec.base_at_rest.get(s)), None)
    assert first is not None, [
        (s - run.wall[(controller, signal.SIGSTOP)], run.rec.base_at_rest.get(s), v) for s, v in answers[:15]
    ]
    twist = np.array([v for _, v in answers[first:]])
    step = np.asarray(limit) * PERIOD
    assert len(twist) > 10
    assert np.all(np.abs(twist[0]) <= RESUME_FACTOR * step + 1e-12), np.abs(twist[0]) / step
    jumps = _jumps_per_period([s for s, _ in answers[first:]], twist)
    worst = int(np.argmax(jumps.max(axis=1) / step.max()))
    context = [
        (answers[first + k][0], twist[k].round(5).tolist(), run.rec.base_at_rest.get(answers[first + k][0]))
        for k in range(max(worst - 2, 0), min(worst + 3, len(twist)))
    ]
    assert np.all(jumps <= RESUME_FACTOR * step + 1e-12), (jumps.max(axis=0) / step, context)
    # Logged: the last command not applied, or the answer of a cycle held up by the stall dropped.
    assert [
        m
        for t, name, m in run.rec.logs
        if name == controller and t > resumed and ('not applied' in m or 'answer dropped' in m)
    ]
    _starts_from_rest(run, resumed, run.events['stall over'], ['ground_truth/odom'], factor=RESUME_FACTOR, limit=limit)


def test_a_stalled_base_controller_answers_from_rest_within_the_acceleration_limits(run):
    _answers_from_rest_after_the_stall(run, 'swmr_controller', BASE_ACCEL_LIMIT)


def test_a_stopped_simulator_gives_a_zero_base_reference_within_two_periods_of_the_state_timeout(run):
    """Judged by the stamps: the resolver's zero reference is stamped by its clock when it
    decides, the joint states by the simulator's (both the system clock, in real time)."""
    rec, stopped, resumed = run.rec, run.events[('wmm_sim', signal.SIGSTOP)], run.events[('wmm_sim', signal.SIGCONT)]
    last_state = max(s for (t, _), s in zip(rec.topics['joint_states'], rec.stamps['joint_states']) if t < resumed)
    zeros = [
        s
        for (t, v), s in zip(rec.topics['base/reference'], rec.stamps['base/reference'])
        if stopped <= t < resumed and not np.any(v)
    ]
    assert zeros, 'no zero reference while the simulator was stopped'
    assert min(zeros) - last_state <= STATE_TIMEOUT + 2 * PERIOD + SCHEDULING, min(zeros) - last_state


@pytest.mark.parametrize(
    'topic', ['base/reference', 'arm_controller/commands', 'steer_controller/commands', 'drive_controller/commands']
)
def test_a_stopped_simulator_gives_zero_commands_until_it_returns(run, topic):
    rec, stopped = run.rec, run.events[('wmm_sim', signal.SIGSTOP)]
    _, values = rec.series(topic, stopped - 0.5, stopped)
    assert np.any(values), 'the robot was moving'
    t_zero = _first(*rec.series(topic), _is_zero, stopped)
    timeout = STATE_TIMEOUT if topic.startswith(('base/', 'arm')) else SWMR['joint_state_timeout']
    assert t_zero - stopped <= timeout + 2 * PERIOD + DELIVERY, t_zero - stopped
    # Zero until the simulator comes back.
    _, held = rec.series(topic, t_zero, run.events[('wmm_sim', signal.SIGCONT)])
    assert not np.any(held)


def test_after_the_simulator_returns_the_controllers_resync_without_a_jump(run):
    rec, resumed = run.rec, run.events[('wmm_sim', signal.SIGCONT)]
    end = run.events[('redundancy_resolver', signal.SIGKILL)]
    _starts_from_rest(
        run,
        resumed,
        end,
        ['base/feasible_twist', 'ground_truth/odom'],
        sent_after=run.wall[('wmm_sim', signal.SIGCONT)],
    )
    # The arm restarts from rest within its acceleration limits.
    _, arm = rec.series('arm_controller/commands', resumed, end)
    assert np.any(arm)
    arm_step = ROBOT.arm.acceleration * PERIOD
    assert np.all(np.abs(np.diff(arm, axis=0)) <= arm_step * (1 + 1e-6) + 1e-9)


def test_a_killed_resolver_stops_arm_and_base_by_their_timeouts(run):
    rec, killed = run.rec, run.events[('redundancy_resolver', signal.SIGKILL)]
    t_last, _ = rec.series('arm_controller/commands', end=killed)
    # The arm: the simulator's command timeout.
    periods, _ = _moving_periods(rec, 'joint_states', t_last[-1])
    assert periods <= COMMAND_PERIODS, periods
    # The base: the base controller's reference timeout, then braking at its acceleration limits,
    # counted in the controller's answers (one per joint state; on a busy machine an answer may
    # come a period late, and the simulator holds the last command meanwhile). The reference and
    # the answers carry the stamps of the joint states they answer.
    last_reference = max(
        s for (t, _), s in zip(rec.topics['base/reference'], rec.stamps['base/reference']) if t < killed
    )
    answers = sorted(
        (s, t, v)
        for (t, v), s in zip(rec.topics['base/feasible_twist'], rec.stamps['base/feasible_twist'])
        if s > last_reference
    )
    stop = next(i for i, (_, _, v) in enumerate(answers) if not np.any(v))
    braking = float(np.max(np.max(np.abs([v for _, _, v in answers[:stop]]), axis=0) / BASE_ACCEL_LIMIT))
    # (+2: the reference's delivery and the period in which its age is noticed; +1: the zero answer)
    bound = np.ceil(SWMR['reference_timeout'] / PERIOD) + 2 + np.ceil(braking / PERIOD - 1e-9) + 1
    assert stop <= bound, (
        stop,
        bound,
        killed,
        [(round(s, 3), round(t, 3), np.round(v, 3).tolist()) for s, t, v in answers[: stop + 1]],
    )
    # The simulator applies the zero answer: at rest within a period or two of receiving it.
    periods, _ = _moving_periods(rec, 'ground_truth/odom', answers[stop][1])
    assert periods <= 3, periods


def test_no_process_failed(run):
    for name, out in run.outputs.items():
        assert 'Traceback' not in out, f'{name}:\n{out}'


# ---------------------------------------------------------------- robot B

ROBOT_B = load_robot('mecanum')
GOAL_B = (6.0, 1.0, 0.49)  # far ahead, at the start's height
QUAT_B = (0.0, 0.5**0.5, 0.0, 0.5**0.5)  # Ry(π/2), as at the start
SPEED_B = 0.05  # [m/s] under way (the base accelerates at 0.025 m/s²)


@pytest.fixture(scope='module')
def run_b():
    """Robot B (Mecanum base, AMP): its base controller killed and started again, then stalled
    (SIGSTOP) longer than the simulator's command timeout, as robot A's above."""

    def scenario(system):
        system.start('wmm_sim', 'robot:=mecanum')
        system.start('mecanum_controller')
        system.start('redundancy_resolver', 'robot:=mecanum', 'method:=amp')
        system.drive_to_goal(SPEED_B, 'wheel_controller/commands', GOAL_B, QUAT_B)
        system.kill_restart_and_stall('mecanum_controller', SPEED_B, 'wheel_controller/commands')

    return _run(scenario)


def test_robot_b_restarted_base_controller_resumes_within_the_acceleration_limits(run_b):
    _starts_from_rest(
        run_b,
        run_b.events['base restarted'],
        run_b.events[('mecanum_controller', signal.SIGSTOP)],
        ['ground_truth/odom'],
        factor=RESUME_FACTOR,
        limit=ROBOT_B.base.acceleration,
    )


def test_robot_b_stalled_base_controller_answers_from_rest_within_the_acceleration_limits(run_b):
    _answers_from_rest_after_the_stall(run_b, 'mecanum_controller', ROBOT_B.base.acceleration)


def test_robot_b_no_process_failed(run_b):
    for name, out in run_b.outputs.items():
        assert 'Traceback' not in out, f'{name}:\n{out}'
