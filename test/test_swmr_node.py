"""swmr_controller node with the simulator (lockstep, kinematic base, slip off), in process."""

import time

import numpy as np
import pytest
from builtin_interfaces.msg import Time
from geometry_msgs.msg import TwistStamped
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ros_helpers import ScriptedController, overrides, pose2d, stamp_s
from sim_bridge.node import SimNode
from wmm_control.base import SwmrController
from wmm_control.errors import ConfigError
from wmm_control.geometry import se2_twist
from wmm_control.experiments.ros_run import LOCKSTEP_TIMEOUT
from wmm_control.nodes.swmr_controller import SwmrControllerNode

DT = 0.025


class ReferencePublisher(ScriptedController):
    """Answers each joint state with a /base/reference from ``ref(t)`` (None: publish nothing)
    and an arm command of zeros; records the feasible twists."""

    def __init__(self, context, ref):
        super().__init__(context, ('arm',), lambda t, js: {'arm': np.zeros(7)}, name='reference_publisher')
        self.ref = ref
        self.pub_ref = self.create_publisher(TwistStamped, '/base/reference', 10)
        self.feasible, self.sent, self.steer = {}, [], []
        self.create_subscription(TwistStamped, '/base/feasible_twist', self._on_feasible, 10)
        self.create_subscription(
            Float64MultiArray, '/steer_controller/commands', lambda m: self.steer.append(list(m.data)), 10
        )

    def _on_joints(self, msg):
        super()._on_joints(msg)
        value = self.ref(stamp_s(msg))
        if value is None:
            return
        out = TwistStamped()
        out.header.stamp = msg.header.stamp
        out.header.frame_id = 'base_link'
        out.twist.linear.x, out.twist.linear.y, out.twist.angular.z = (float(v) for v in value)
        self.sent.append(tuple(float(v) for v in value))
        self.pub_ref.publish(out)

    def _on_feasible(self, msg):
        self.feasible[round(stamp_s(msg) / DT)] = np.array(
            [msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z]
        )


def run(ros, ref, seconds, controller_params=None, **sim_params):
    ros.add(
        SimNode(
            context=ros.context,
            parameter_overrides=overrides(
                timing='lockstep', lockstep_groups='steer,drive', lockstep_timeout=LOCKSTEP_TIMEOUT, **sim_params
            ),
        )
    )
    ros.add(SwmrControllerNode(context=ros.context, parameter_overrides=overrides(**(controller_params or {}))))
    pub = ros.add(ReferencePublisher(ros.context, ref))
    n = int(round(seconds / DT)) + 1
    assert ros.spin_until(lambda: len(pub.truth) >= n, timeout=60)
    return pub


@pytest.mark.parametrize(
    'ref',
    [
        (0.4, 0.0, 0.0),  # translation along x
        (0.0, 0.3, 0.0),  # along y: every wheel turns by π/2
        (0.3, -0.3, 0.0),  # diagonal
        (0.0, 0.0, 0.5),  # rotation about the base centre
        (0.4, 0.0, 0.3),  # arc turning left
        (-0.2, 0.3, -0.4),  # arc backwards and right
    ],
    ids=['x', 'y', 'diagonal', 'rotation', 'arc-left', 'arc-right-backwards'],
)
def test_reference_twist_is_tracked_within_one_percent(ros, ref):
    # Watchdogs far above a lockstep period, so a loaded machine cannot make the data look stale.
    pub = run(
        ros,
        lambda t: ref,
        8.0,
        controller_params=dict(reference_timeout=2.0, joint_state_timeout=2.0),
    )
    ref = np.array(ref)
    for msg in pub.truth[-40:]:  # the last second
        twist = np.array([msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.angular.z])
        assert np.linalg.norm(twist - ref) <= 0.01 * np.linalg.norm(ref), (twist, ref)


def test_feasible_twist_is_what_the_base_executes_over_the_next_period(ros):
    # A reference that changes direction and curvature, so that the wheels steer throughout.
    def ref(t):
        return (0.4 * np.cos(0.6 * t), 0.3 * np.sin(0.4 * t), 0.4 * np.sin(0.7 * t))

    pub = run(ros, ref, 6.0)
    poses = {round(stamp_s(m) / DT): pose2d(m) for m in pub.truth}
    worst, checked = 0.0, 0
    for k, feasible in pub.feasible.items():
        if k in poses and k + 1 in poses:
            executed = se2_twist(poses[k], poses[k + 1], DT)
            worst = max(worst, float(np.max(np.abs(executed - feasible))))
            checked += 1
    assert checked >= 200
    assert worst <= 1e-3


def test_stale_reference_stops_the_base_and_holds_the_wheel_angles(ros):
    # The reference stops after 3 s; reference_timeout 0.2 s (in lockstep, which the controller
    # learns from the simulator, of simulated time: the next 120 periods brake the base to rest).
    pub = run(ros, lambda t: (0.3, 0.2, 0.1) if t < 3.0 else None, 3.0)
    moving = np.array(pub.velocities()['drive_fl_joint'])
    assert abs(moving) > 0.5
    ros.spin_for(0.5)
    n0 = len(pub.joint_states)
    assert ros.spin_until(lambda: len(pub.joint_states) >= n0 + 120, timeout=60)
    last = pub.velocities()
    assert all(abs(last[f'drive_{m}_joint']) < 1e-9 for m in ('fl', 'fr', 'rl', 'rr'))
    assert all(abs(last[f'steer_{m}_joint']) < 1e-9 for m in ('fl', 'fr', 'rl', 'rr'))
    steer_then = [pub.positions(n0)[f'steer_{m}_joint'] for m in ('fl', 'fr', 'rl', 'rr')]
    steer_now = [pub.positions()[f'steer_{m}_joint'] for m in ('fl', 'fr', 'rl', 'rr')]
    np.testing.assert_allclose(steer_now, steer_then, atol=0.05)  # held, not straightened
    assert np.ptp(steer_now) > 0.05  # still set for the arc


STEER = [f'steer_{m}_joint' for m in ('fl', 'fr', 'rl', 'rr')]


def _time(seconds):
    return Time(sec=int(seconds), nanosec=int(round((seconds - int(seconds)) * 1e9)))


class Recorder(Node):
    """Publishes joint states and references by hand; records the controller's outputs."""

    def __init__(self, context):
        super().__init__('recorder', context=context)
        self.steer, self.drive, self.feasible = [], [], []
        self.create_subscription(
            Float64MultiArray, '/steer_controller/commands', lambda m: self.steer.append(list(m.data)), 10
        )
        self.create_subscription(
            Float64MultiArray, '/drive_controller/commands', lambda m: self.drive.append(list(m.data)), 10
        )
        self.create_subscription(TwistStamped, '/base/feasible_twist', self.feasible.append, 10)
        self.pub_js = self.create_publisher(JointState, '/joint_states', 10)
        self.pub_ref = self.create_publisher(TwistStamped, '/base/reference', 10)

    def joint_state(self, beta, stamp=0.0, names=STEER, positions=None):
        js = JointState()
        js.header.stamp = _time(stamp)
        js.name = list(names)
        js.position = [float(b) for b in (beta if positions is None else positions)]
        js.velocity = [0.0] * len(js.position)
        self.pub_js.publish(js)

    def reference(self, ref, stamp=0.0, frame='base_link'):
        r = TwistStamped()
        r.header.stamp = _time(stamp)
        r.header.frame_id = frame
        r.twist.linear.x, r.twist.linear.y, r.twist.angular.z = (float(v) for v in ref)
        self.pub_ref.publish(r)

    def send(self, beta, ref, frame='base_link'):
        """An unstamped reference, then an unstamped joint state (the stamps match)."""
        self.reference(ref, frame=frame)
        self.joint_state(beta)


def twist_of(msg):
    return np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z])


@pytest.mark.parametrize('use_sim_time', [False, True])
def test_joint_state_timeout_commands_zero_rates(ros, use_sim_time):
    # Under use_sim_time with no /clock at all the ROS clock stands still: the watchdog must
    # still see the joint states stop.
    ros.add(
        SwmrControllerNode(
            context=ros.context, parameter_overrides=overrides(joint_state_timeout=0.1, use_sim_time=use_sim_time)
        )
    )
    rec = ros.add(Recorder(ros.context))
    ros.spin_for(0.3)
    for _ in range(40):
        rec.send(np.zeros(4), (0.5, 0.0, 0.0))
        ros.spin_for(0.01)
    assert ros.spin_until(lambda: len(rec.drive) >= 20)
    assert max(abs(v) for v in rec.drive[-1]) > 0.1
    n = len(rec.drive)
    ros.spin_for(0.5)  # joint states stopped
    assert len(rec.drive) > n
    assert rec.drive[-1] == [0.0] * 4 and rec.steer[-1] == [0.0] * 4


def test_bad_references_are_rejected(ros):
    node = ros.add(SwmrControllerNode(context=ros.context))
    rec = ros.add(Recorder(ros.context))
    ros.spin_for(0.3)
    rec.send(np.zeros(4), (0.2, 0.0, 0.0))
    ros.spin_for(0.1)
    rec.send(np.zeros(4), (np.nan, 0.0, 0.0))
    rec.send(np.zeros(4), (0.0, 0.9, 0.0), frame='odom')
    ros.spin_for(0.1)
    np.testing.assert_array_equal(node.reference.value, [0.2, 0.0, 0.0])
    assert all(np.all(np.isfinite(d)) for d in rec.drive + rec.steer)


def test_a_robot_without_a_steerable_base_fails_clearly(ros):
    # Geometry and limits come from the robot YAML: only a steerable robot can be chosen.
    with pytest.raises(ConfigError, match="robot 'mecanum' has a mecanum base; swmr_controller drives steerable bases"):
        SwmrControllerNode(context=ros.context, parameter_overrides=overrides(robot='mecanum'))


# ---------------------------------------------------------------- the exchange, one per period


class DelayedReference(Node):
    """Answers each /joint_states stamped S with a /base/reference stamped S, ``value(k)`` for
    cycle k = S/DT, published ``delay`` steady seconds later (so the controller always has
    the joint state first and must wait for the reference). Records the feasible twists."""

    def __init__(self, context, value, delay=0.003):
        super().__init__('delayed_reference', context=context)
        self.value = value
        self.sent, self.feasible = {}, {}
        self._stamp = None
        self.pub = self.create_publisher(TwistStamped, '/base/reference', 10)
        self.create_subscription(JointState, '/joint_states', self._on_joints, 10)
        self.create_subscription(
            TwistStamped,
            '/base/feasible_twist',
            lambda m: self.feasible.setdefault(round(stamp_s(m) / DT), []).append(m),
            10,
        )
        self.timer = self.create_timer(
            delay, self._publish, clock=Clock(clock_type=ClockType.STEADY_TIME), autostart=False
        )

    def _on_joints(self, msg):
        self._stamp = msg.header.stamp
        self.timer.reset()

    def _publish(self):
        self.timer.cancel()
        k = round((self._stamp.sec + self._stamp.nanosec * 1e-9) / DT)
        out = TwistStamped()
        out.header.stamp = self._stamp
        out.header.frame_id = 'base_link'
        out.twist.linear.x, out.twist.linear.y, out.twist.angular.z = self.value(k)
        self.sent[k] = self.value(k)
        self.pub.publish(out)


@pytest.mark.parametrize('use_sim_time', [False, True])
def test_each_feasible_twist_answers_the_reference_of_its_own_cycle(ros, use_sim_time):
    # The reference switches between zero and 0.5 m/s every cycle (on when k % 3 == 1). From
    # rest the twist controller answers 0.5 with K_p·0.5 = 1 m/s² ≤ the limit, i.e. 0.025 m/s
    # after one period, and zero with an exact stop: the feasible twist stamped k is non-zero
    # if and only if the reference stamped k was. A controller one period late answers k with
    # the reference of k − 1 and fails.
    def value(k):
        return (0.5, 0.0, 0.0) if k % 3 == 1 else (0.0, 0.0, 0.0)

    sim_time = overrides(use_sim_time=use_sim_time)
    ros.add(
        SimNode(
            context=ros.context,
            parameter_overrides=sim_time + overrides(timing='lockstep', lockstep_groups='steer,drive'),
        )
    )
    ros.add(
        SwmrControllerNode(
            context=ros.context, parameter_overrides=sim_time + overrides(reference_wait=0.5, max_state_wait=0.0)
        )
    )
    ref = ros.add(DelayedReference(ros.context, value))
    assert ros.spin_until(lambda: len(ref.feasible) >= 60, timeout=60)
    cycles = sorted(ref.feasible)
    assert cycles == list(range(len(cycles)))  # one answer per cycle, in order
    for k in cycles:
        (answer,) = ref.feasible[k]
        assert k in ref.sent  # stamped as a reference it answers
        speed = np.linalg.norm(twist_of(answer))
        if value(k)[0]:
            assert speed == pytest.approx(0.025, abs=1e-9), k
        else:
            assert speed < 1e-9, k


def test_a_joint_state_waits_for_the_reference_of_its_stamp(ros):
    ros.add(
        SwmrControllerNode(
            context=ros.context,
            parameter_overrides=overrides(
                reference_wait=0.5, reference_timeout=2.0, joint_state_timeout=5.0, max_state_wait=0.0
            ),
        )
    )
    rec = ros.add(Recorder(ros.context))
    ros.spin_for(0.2)

    # The reference first: the joint state of its stamp runs the cycle at once.
    rec.reference((0.5, 0.0, 0.0), stamp=1.0)
    ros.spin_for(0.05)
    rec.joint_state(np.zeros(4), stamp=1.0)
    assert ros.spin_until(lambda: len(rec.feasible) == 1, timeout=0.3)
    assert stamp_s(rec.feasible[0]) == 1.0
    assert twist_of(rec.feasible[0])[0] == pytest.approx(0.025)

    # The joint state first: no cycle until the reference of its stamp comes, then at once,
    # with that reference (zero: the base stops; the previous one would accelerate it).
    rec.joint_state(np.zeros(4), stamp=1.025)
    ros.spin_for(0.1)
    assert len(rec.feasible) == 1 and len(rec.drive) == 1
    t0 = time.monotonic()
    rec.reference((0.0, 0.0, 0.0), stamp=1.025)
    assert ros.spin_until(lambda: len(rec.feasible) == 2, timeout=0.3)
    assert time.monotonic() - t0 < 0.3
    assert stamp_s(rec.feasible[1]) == 1.025
    assert np.linalg.norm(twist_of(rec.feasible[1])) < 1e-9

    # A reference published by hand (stamp 0) never matches: it is used after the wait.
    rec.reference((0.5, 0.0, 0.0))
    ros.spin_for(0.05)
    t0 = time.monotonic()
    rec.joint_state(np.zeros(4), stamp=1.05)
    assert ros.spin_until(lambda: len(rec.feasible) == 3, timeout=2.0)
    assert 0.45 <= time.monotonic() - t0
    assert stamp_s(rec.feasible[2]) == 1.05
    assert twist_of(rec.feasible[2])[0] == pytest.approx(0.025)

    # Two joint states without references: one cycle each, the first when the second comes.
    rec.joint_state(np.zeros(4), stamp=2.0)
    ros.spin_for(0.05)
    rec.joint_state(np.zeros(4), stamp=2.025)
    ros.spin_for(0.1)
    assert [stamp_s(m) for m in rec.feasible[3:]] == [2.0]
    assert ros.spin_until(lambda: len(rec.feasible) == 5, timeout=2.0)
    assert stamp_s(rec.feasible[4]) == 2.025
    assert len(rec.drive) == len(rec.steer) == 5


def test_a_joint_state_queued_while_the_node_was_held_up_runs_no_cycle(ros):
    """States that arrive one period apart, stamped one period apart, each run a cycle; one that
    arrives 0.4 s later than its stamp says (it waited in the transport while the node was held
    up) runs none, whatever its stamp's clock; the next one on time runs again."""
    ros.add(
        SwmrControllerNode(
            context=ros.context,
            parameter_overrides=overrides(reference_wait=0.0, joint_state_timeout=5.0, max_state_wait=0.1),
        )
    )
    rec = ros.add(Recorder(ros.context))
    ros.spin_for(0.2)
    origin = 1000.0 - time.time()  # the sender's clock: any offset from this one's
    answered = []

    def send(stamp):
        n = len(rec.feasible)
        rec.reference((0.2, 0.0, 0.0))
        rec.joint_state(np.zeros(4), stamp=stamp)
        answered.append(ros.spin_until(lambda: len(rec.feasible) > n, timeout=0.3))

    for _ in range(8):
        send(time.time() + origin)
        ros.spin_for(0.025)
    stamp = time.time() + origin
    ros.spin_for(0.4)
    send(stamp)  # stamped 0.4 s before it arrives
    send(time.time() + origin)
    assert answered == [True] * 8 + [False, True]


def test_joint_states_are_read_by_name(ros):
    # A zero reference holds the steer angles at the measured ones, so the controller's
    # state shows which positions it read as steer angles.
    node = ros.add(
        SwmrControllerNode(
            context=ros.context, parameter_overrides=overrides(reference_wait=0.0, joint_state_timeout=5.0)
        )
    )
    rec = ros.add(Recorder(ros.context))
    ros.spin_for(0.2)
    stop = (0.0, 0.0, 0.0)

    def cycle(**js):
        # a cycle answers within 0.5 s, even on a loaded machine; a rejected state never does
        n = len(rec.feasible)
        rec.reference(stop)
        rec.joint_state(None, **js)
        ros.spin_until(lambda: len(rec.feasible) > n, timeout=0.5)
        return len(rec.feasible) - n

    assert cycle(positions=[0.1, 0.2, 0.3, 0.4]) == 1
    np.testing.assert_array_equal(node.controller.beta, [0.1, 0.2, 0.3, 0.4])
    # Same length, another order.
    assert cycle(names=STEER[::-1], positions=[0.4, 0.3, 0.2, 0.1]) == 1
    np.testing.assert_array_equal(node.controller.beta, [0.1, 0.2, 0.3, 0.4])
    assert cycle(names=['a', 'b'] + STEER[::-1], positions=[9.0, 9.0, 0.8, 0.7, 0.6, 0.5]) == 1
    np.testing.assert_array_equal(node.controller.beta, [0.5, 0.6, 0.7, 0.8])
    # Four unrelated joints, or three steer joints: never read as steer angles.
    assert cycle(names=['a', 'b', 'c', 'd'], positions=[9.0] * 4) == 0
    assert cycle(names=STEER[:3] + ['arm_joint_1'], positions=[9.0] * 4) == 0
    # Positions and names of different lengths.
    assert cycle(positions=[9.0, 9.0, 9.0]) == 0
    assert cycle(names=STEER + ['x'], positions=[9.0] * 4) == 0
    np.testing.assert_array_equal(node.controller.beta, [0.5, 0.6, 0.7, 0.8])


def test_the_loop_closes_on_the_measured_steer_angles(ros):
    # The steer joints do not follow (stuck at 0.3 rad) while the reference asks for straight
    # motion: every cycle starts again from 0.3, so the steer rate reaches β̇_max and stays
    # there. A controller integrating its own commands would believe the wheels straight
    # and stop steering.
    ros.add(SwmrControllerNode(context=ros.context))
    rec = ros.add(Recorder(ros.context))
    ros.spin_for(0.2)
    for _ in range(60):  # each joint state answered before the next (none dropped, none stale)
        answered = len(rec.steer)
        rec.send(np.full(4, 0.3), (0.4, 0.0, 0.0))
        assert ros.spin_until(lambda n=answered: len(rec.steer) > n, timeout=5.0)
    np.testing.assert_allclose(rec.steer[-1], -1.0, atol=1e-9)


def test_closing_the_loop_changes_nothing_in_the_kinematic_simulator(ros):
    # The kinematic simulator integrates the steer command exactly: the measured angles equal
    # the commanded ones, and the commands equal those of the core run open loop.
    def ref(t):
        return (0.4 * np.cos(0.6 * t), 0.3 * np.sin(0.4 * t), 0.4 * np.sin(0.7 * t))

    pub = run(ros, ref, 6.0, controller_params=dict(reference_wait=0.5))
    node = next(n for n in ros.nodes if isinstance(n, SwmrControllerNode))
    offline = SwmrController(node.controller.geometry, node.controller.params)
    steer = np.array(pub.steer[:200])
    expected = np.array([offline.step(r).beta_dot_ref for r in pub.sent[:200]])
    assert np.abs(expected).max() > 0.5  # the wheels really steer
    np.testing.assert_allclose(steer, expected, rtol=0, atol=1e-9)


@pytest.mark.parametrize('ref', [(1e308, 0.0, 0.0), (0.0, 1e200, 0.0)], ids=['vx-1e308', 'vy-1e200'])
def test_huge_finite_references_drive_the_base_at_its_limit(ros, ref):
    pub = run(ros, lambda t: ref, 4.0)
    direction = np.sign(ref)
    assert all(np.all(np.isfinite(v)) for v in pub.feasible.values())
    assert all(np.all(np.isfinite(v)) for v in pub.steer)
    for msg in pub.truth[-20:]:
        twist = np.array([msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.angular.z])
        assert twist @ direction > 0.9  # limit 1 m/s, along the reference
        assert np.linalg.norm(twist - (twist @ direction) * direction) < 1e-3
