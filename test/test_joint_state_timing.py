"""Joint-state timing: one cycle per instant of the sender's time, whatever the delivery.

Two publishers on ``/joint_states``, a replayed message, a burst of queued messages, a gap:
no controller runs two cycles for one stamp nor integrates several periods in one cycle,
each cycle's period is the one its stamps say, and a sender whose period disagrees with the
node's is reported (log and ``/diagnostics``).
"""

import math

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import TwistStamped
from rcl_interfaces.msg import Log
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ros_helpers import held_up, overrides, stamp_s
from sim_bridge.node import SimNode
from wmm_control.base.mecanum import MecanumKinematics
from wmm_control.experiments.ros_run import LOCKSTEP_TIMEOUT
from wmm_control.nodes.conversions import twist_stamped
from wmm_control.nodes.stamps import StampGate
from wmm_control.nodes.mecanum_controller import MecanumControllerNode
from wmm_control.robot_config import load_robot

DT = 0.025
ROBOT = load_robot('mecanum')
WHEELS = ROBOT.base.wheel_joints


def _time(t):
    ns = round(t * 1e9)
    return Time(sec=ns // 1_000_000_000, nanosec=ns % 1_000_000_000)


# ---------------------------------------------------------------- the gate alone


def test_the_gate_admits_each_new_instant_once():
    gate = StampGate(DT, max_jump=0.2)
    assert gate.admit(_time(10.0)) == ''
    assert 'not after' in gate.admit(_time(10.0))  # the same instant again
    assert 'not after' in gate.admit(_time(9.0))  # backwards
    assert 'not after' in gate.admit(_time(0.0))  # a zero stamp amid stamped ones
    assert 'far-future' in gate.admit(_time(1e6))
    assert gate.admit(_time(10.025)) == ''  # the stream goes on from the last cycle
    assert gate.admit(_time(10.1)) == ''  # a gap of three periods: one cycle
    gate.restart()  # the sender was silent: a new time base
    assert gate.admit(_time(0.5)) == ''


def test_messages_that_all_carry_a_zero_stamp_each_run_a_cycle():
    gate = StampGate(DT, max_jump=0.2)
    assert [gate.admit(_time(0.0)) for _ in range(3)] == ['', '', '']


def test_the_gate_measures_the_senders_period_and_reports_a_mismatch():
    gate = StampGate(DT, max_jump=0.2)
    for k in range(30):
        gate.admit(_time(1.0 + 0.05 * k))
    assert gate.measured_period == pytest.approx(0.05)
    assert 'every 0.05 s' in gate.period_mismatch() and 'period is 0.025 s' in gate.period_mismatch()
    same = StampGate(DT, max_jump=0.2)
    for k in range(30):
        same.admit(_time(1.0 + DT * k + (0.001 if k % 2 else 0.0)))  # jitter of 1 ms
    assert same.period_mismatch() == ''


# ---------------------------------------------------------------- in a system


class Probe(Node):
    """Records the controller's feasible twists, diagnostics and warnings; publishes joint states."""

    def __init__(self, context):
        super().__init__('timing_probe', context=context)
        self.feasible, self.diag, self.warnings = [], [], []
        self.create_subscription(TwistStamped, '/base/feasible_twist', self.feasible.append, 50)
        self.wheels = []  # listened to, as the simulator does: a controller unheard stays at rest
        self.create_subscription(Float64MultiArray, '/wheel_controller/commands', self.wheels.append, 50)
        self.create_subscription(DiagnosticArray, '/diagnostics', self._on_diag, 50)
        self.create_subscription(
            Log,
            '/rosout',
            self._on_log,
            QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE),
        )
        self.pub_js = self.create_publisher(JointState, '/joint_states', 50)
        self.pub_ref = self.create_publisher(TwistStamped, '/base/reference', 50)

    def _on_diag(self, msg):
        for s in msg.status:
            if s.name == '/mecanum_controller':
                self.diag.append({kv.key: kv.value for kv in s.values})

    def _on_log(self, msg):
        if msg.name == 'mecanum_controller' and msg.level >= Log.WARN:
            self.warnings.append(msg.msg)

    def state(self, t, velocity=()):
        """A joint state stamped ``t``; without ``velocity`` the stamps alone decide (the node
        cannot check that its last command was applied)."""
        js = JointState()
        js.header.stamp = _time(t)
        js.name = list(WHEELS)
        js.position = [0.0] * 4
        js.velocity = [float(v) for v in velocity]
        self.pub_js.publish(js)

    def per_stamp(self):
        counts = {}
        for m in self.feasible:
            counts[stamp_s(m)] = counts.get(stamp_s(m), 0) + 1
        return counts


def twist_of(msg):
    return np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z])


def test_a_second_publisher_replaying_the_simulators_states_runs_no_second_cycle(ros):
    """A real-time simulator and the Mecanum controller; a second publisher echoes every joint
    state the simulator sends (same stamp), once the controller has answered it: one feasible
    twist per stamp, and the duplicates are logged with the number of publishers. (Echoed at
    once, or to a lockstep simulator that steps on the answer, the copy would meet the next
    state in the controller's queue, which keeps only the newest.)"""
    probe = ros.add(Probe(ros.context))
    echo = ros.add(Node('echo', context=ros.context))
    pub = echo.create_publisher(JointState, '/joint_states', 10)
    states, echoed = {}, set()

    def keep(msg):  # its own copies come back to it: each stamp is echoed once
        states.setdefault(stamp_s(msg), msg)

    def echo_answered(twist):  # the controller keeps only the newest state: a copy sent at
        msg = states.pop(stamp_s(twist), None)  # once would replace the original, unseen
        if msg is not None and stamp_s(twist) not in echoed:
            echoed.add(stamp_s(twist))
            pub.publish(msg)

    echo.create_subscription(JointState, '/joint_states', keep, 10)
    echo.create_subscription(TwistStamped, '/base/feasible_twist', echo_answered, 10)
    node = ros.add(MecanumControllerNode(context=ros.context, parameter_overrides=overrides(diagnostics_period=1e-9)))
    ros.add(SimNode(context=ros.context, parameter_overrides=overrides(robot='mecanum', timing='realtime')))
    reference = echo.create_publisher(TwistStamped, '/base/reference', 10)
    echo.create_subscription(
        JointState,
        '/joint_states',
        lambda m: reference.publish(twist_stamped(m.header.stamp, 'base_link', (0.2, 0.1, 0.5))),
        10,
    )
    # Until 70 copies were seen (the echo's discovery may take a moment on a loaded machine).
    assert ros.spin_until(lambda: len(probe.feasible) >= 80 and node.watchdog.skipped >= 70, timeout=60.0)
    assert node.watchdog.skipped <= len(probe.feasible) + 1  # one copy per stamp, no storm
    # Every stamp runs exactly one cycle.
    counts = probe.per_stamp()
    assert set(counts.values()) == {1}, {t: n for t, n in counts.items() if n != 1}
    # Logged with the number of publishers (the simulator, the echo and this probe's).
    assert any('not after the last cycle' in w and '3 publisher(s)' in w for w in probe.warnings), probe.warnings
    # Its limits act per simulated period: the twist never changes faster than the limit, but
    # where the controller restarted from the measured state (a late command zeroed by the
    # simulator's command timeout on a loaded machine: the wheels did stop)
    twists = np.array([twist_of(m) for m in sorted(probe.feasible, key=stamp_s)])
    step = np.asarray(ROBOT.base.acceleration) * DT
    jumps = np.any(np.abs(np.diff(twists, axis=0)) > step * (1 + 1e-9) + 1e-12, axis=1)
    restarts = node.counters['commands_not_applied']  # the restarts (their warning is throttled)
    assert jumps.sum() <= restarts, (int(jumps.sum()), restarts)
    assert np.any(twists)


def test_a_backlog_is_skipped_to_the_newest_state_and_a_gap_runs_only_one_period(ros):
    """A controller held up while the simulator went on (here: states published while nothing
    spins) answers the newest state, one period from its last answer, and none of the states
    queued before it; a gap of five periods after it still moves the twist by one period."""
    probe = ros.add(Probe(ros.context))
    ros.add(
        MecanumControllerNode(
            context=ros.context,
            parameter_overrides=overrides(reference_wait=0.0, reference_timeout=10.0, joint_state_timeout=10.0),
        )
    )
    ros.spin_for(0.2)
    probe.pub_ref.publish(twist_stamped(_time(0.0), 'base_link', (0.2, 0.0, 0.0)))
    ros.spin_for(0.05)
    probe.state(4.975)  # one state answered: the controller is under way
    assert ros.spin_until(lambda: len(probe.feasible) == 1, timeout=5.0)
    backlog = 8
    for k in range(backlog):  # published while the controller does not spin
        probe.state(5.0 + k * DT)
    newest = 5.0 + (backlog - 1) * DT
    assert ros.spin_until(lambda: any(stamp_s(m) == pytest.approx(newest) for m in probe.feasible), timeout=5.0)
    ros.spin_for(0.1)
    answered = len(probe.feasible) - 1
    # The subscription keeps only the newest state: at most one older one can have slipped in
    # (taken while the backlog was still being delivered).
    assert answered <= 2, [stamp_s(m) for m in probe.feasible]
    probe.state(newest + 6 * DT)  # five periods missing
    assert ros.spin_until(lambda: len(probe.feasible) == answered + 2, timeout=5.0)
    ros.spin_for(0.1)
    vx = [twist_of(m)[0] for m in probe.feasible]
    step = ROBOT.base.acceleration[0] * DT
    # Every cycle, the newest state's and the gap's included, moves the twist by one period.
    np.testing.assert_allclose(np.diff([0.0] + vx), step, rtol=1e-9)
    assert len(vx) == answered + 2


@pytest.mark.parametrize('max_wait', [0.1, 0.0], ids=['limited', 'unlimited'])
def test_a_state_that_waited_longer_than_max_state_wait_runs_no_cycle(ros, max_wait):
    """A state whose reference does not come waits ``reference_wait`` (0.3 s here) in the
    controller, as it would while the node is held up: beyond ``max_state_wait`` its cycle is
    skipped (logged, counted); with no limit it runs with the latest reference."""
    probe = ros.add(Probe(ros.context))
    node = ros.add(
        MecanumControllerNode(
            context=ros.context,
            parameter_overrides=overrides(
                reference_wait=0.3, reference_timeout=10.0, joint_state_timeout=10.0, max_state_wait=max_wait
            ),
        )
    )
    ros.spin_for(0.2)
    probe.pub_ref.publish(twist_stamped(_time(0.0), 'base_link', (0.2, 0.0, 0.0)))
    ros.spin_for(0.05)
    probe.state(5.0)
    ros.spin_for(0.6)
    if max_wait:
        assert not probe.feasible and node.watchdog.skipped == 1
        assert ros.spin_until(lambda: any('beyond max_state_wait 0.1 s' in w for w in probe.warnings), timeout=5.0)
    else:
        assert len(probe.feasible) == 1 and twist_of(probe.feasible[0])[0] > 0.0


@pytest.mark.parametrize('tolerance', [0.002, 0.0], ids=['checked', 'unchecked'])
def test_answers_that_were_not_applied_move_the_base_one_period_from_the_rates_applied(ros, tolerance):
    """As the simulator does, each joint state reports the wheel rates applied over its period.
    When the controller's answers are not applied (lost, late, or zeroed by the simulator's
    command timeout), the states go on reporting the rates applied before. Checked, every answer
    starts from the rates applied, so the last one is one period of acceleration from them;
    unchecked, from the controller's own last command, one period further per answer."""
    probe = ros.add(Probe(ros.context))
    ros.add(
        MecanumControllerNode(
            context=ros.context,
            parameter_overrides=overrides(
                reference_wait=0.0, reference_timeout=10.0, joint_state_timeout=10.0, applied_rate_tolerance=tolerance
            ),
        )
    )
    ros.spin_for(0.2)
    probe.pub_ref.publish(twist_stamped(_time(0.0), 'base_link', (0.2, 0.0, 0.0)))
    ros.spin_for(0.05)
    for k in range(10):  # nominal periods: each state reports the command it followed
        applied = list(probe.wheels[-1].data) if probe.wheels else [0.0] * 4
        probe.state(5.0 + k * DT, applied)
        assert ros.spin_until(lambda k=k: len(probe.feasible) > k, timeout=5.0)
    ros.spin_for(0.1)
    applied = list(probe.wheels[-1].data)
    before = len(probe.feasible)
    unapplied = 5
    for k in range(unapplied):  # each answered before the next, none applied
        probe.state(5.0 + (10 + k) * DT, applied)
        assert ros.spin_until(lambda k=k: len(probe.feasible) > before + k, timeout=5.0)
    vx_applied = MecanumKinematics.from_config(ROBOT.base).twist_from_wheels(np.array(applied))[0]
    step = ROBOT.base.acceleration[0] * DT
    last = twist_of(probe.feasible[-1])[0] - vx_applied
    if tolerance:
        assert last == pytest.approx(step, rel=1e-6)
    else:
        assert last == pytest.approx(unapplied * step, rel=1e-6)


def test_a_cycle_held_up_past_max_state_wait_publishes_nothing_and_the_next_starts_from_the_measured_rates(ros):
    """A controller stopped in the middle of a cycle (SIGSTOP, or starved) finishes it after the
    simulator has moved on: that answer, to a state long gone, is dropped (logged), not applied
    as current; the next state reports the base zeroed by the simulator's command timeout, and
    its answer starts from rest, not from the speed before the stall."""
    probe = ros.add(Probe(ros.context))
    node = ros.add(
        MecanumControllerNode(
            context=ros.context,
            parameter_overrides=overrides(
                reference_wait=0.0, reference_timeout=10.0, joint_state_timeout=10.0, max_state_wait=0.1
            ),
        )
    )
    ros.spin_for(0.2)
    probe.pub_ref.publish(twist_stamped(_time(0.0), 'base_link', (0.2, 0.0, 0.0)))
    ros.spin_for(0.05)
    for k in range(20):  # under way: each state reports the command it followed
        probe.state(5.0 + k * DT, list(probe.wheels[-1].data) if probe.wheels else [0.0] * 4)
        assert ros.spin_until(lambda k=k: len(probe.feasible) > k, timeout=5.0)
    ros.spin_for(0.1)
    before, commands = len(probe.feasible), len(probe.wheels)
    with held_up(node.base, 'step', 0.3):
        probe.state(5.0 + 20 * DT, list(probe.wheels[-1].data))
        assert ros.spin_until(lambda: any('answer dropped' in w for w in probe.warnings), timeout=5.0)
    ros.spin_for(0.1)
    assert len(probe.feasible) == before and len(probe.wheels) == commands  # nothing published
    probe.state(5.0 + 40 * DT, [0.0] * 4)  # the simulator zeroed the base meanwhile
    assert ros.spin_until(lambda: len(probe.feasible) > before, timeout=5.0)
    ros.spin_for(0.1)
    # it was under way: several periods of acceleration (the probe echoes every other command a
    # period late, and the controller restarts from that one, so 20 states make 10 steps)
    assert twist_of(probe.feasible[before - 1])[0] > 5 * ROBOT.base.acceleration[0] * DT
    assert abs(twist_of(probe.feasible[-1])[0]) <= ROBOT.base.acceleration[0] * DT * (1 + 1e-9)


def test_a_simulator_period_that_disagrees_with_the_controllers_is_reported(ros):
    probe = ros.add(Probe(ros.context))
    ros.add(
        MecanumControllerNode(
            context=ros.context,
            parameter_overrides=overrides(diagnostics_period=1e-9),
        )
    )
    ros.add(
        SimNode(
            context=ros.context,
            parameter_overrides=overrides(
                robot='mecanum',
                timing='lockstep',
                lockstep_groups='wheel',
                period=0.05,
                lockstep_timeout=LOCKSTEP_TIMEOUT,
            ),
        )
    )
    assert ros.spin_until(lambda: any('every 0.05 s' in w for w in probe.warnings), timeout=60.0)
    assert any("this node's period is 0.025 s" in w for w in probe.warnings)
    # and its diagnostics say so, once a cycle has measured it (a cycle that restarted the
    # measurement after a stall of the lockstep start-up reports 0)
    assert ros.spin_until(
        lambda: bool(probe.diag) and math.isclose(float(probe.diag[-1]['measured_period_s']), 0.05, rel_tol=1e-6),
        timeout=30.0,
    )
