"""Mecanum base controller (robot B): the ROS-free core, the node, and the node with the simulator."""

import math

import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from hypothesis import given, settings
from hypothesis import strategies as st
from rclpy.clock import Clock
from rclpy.clock_type import ClockType
from rclpy.node import Node
from rclpy.time import Time as RosTime
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ros_helpers import ScriptedController, overrides, stamp_s
from sim_bridge.node import SimNode
from wmm_control.base import WheelController, WheelParams
from wmm_control.errors import ConfigError, NonFiniteError
from wmm_control.nodes.conversions import twist_stamped
from wmm_control.nodes.mecanum_controller import MecanumControllerNode
from wmm_control.robot_config import load_robot

DT = 0.025
ROBOT = load_robot('mecanum')
WHEELS = list(ROBOT.base.wheel_joints)
VMAX = np.array([0.25, 0.25, 1.0])  # Xing Table 1
AMAX = np.array([0.025, 0.025, 1.5])
WHEEL_MAX = 13.0


def controller():
    return WheelController.from_robot_config(ROBOT, DT)


def test_limits_and_geometry_come_from_the_robot_yaml():
    c = controller()
    assert c.params == WheelParams(DT, (0.25, 0.25, 1.0), (0.025, 0.025, 1.5), 13.0)
    k = c.kinematics
    assert k.wheel_radius == 0.076
    np.testing.assert_allclose(k.positions, [[0.25, 0.22], [0.25, -0.22], [-0.25, 0.22], [-0.25, -0.22]], atol=1e-12)
    with pytest.raises(ConfigError, match='has a steerable base, not a Mecanum or differential one'):
        WheelController.from_robot_config(load_robot('steerable'), DT)


# ---------------------------------------------------------------- eq 16


# R = 0.076 m, k = d1 + d2 = 0.47 m. Inverse of eq 16: ω_fl = (vx − vy − kω)/R,
# ω_fr = (vx + vy + kω)/R, ω_rl = (vx + vy − kω)/R, ω_rr = (vx − vy + kω)/R.
@pytest.mark.parametrize(
    'twist, wheels',
    [
        ((0.19, 0.0, 0.0), (2.5, 2.5, 2.5, 2.5)),  # forward: 0.19/0.076
        ((0.0, 0.076, 0.0), (-1.0, 1.0, 1.0, -1.0)),  # left
        ((0.0, 0.0, 0.4), (-0.188 / 0.076, 0.188 / 0.076, -0.188 / 0.076, 0.188 / 0.076)),  # k·ω = 0.188
        ((0.1, 0.05, 0.2), (-0.044 / 0.076, 0.244 / 0.076, 0.056 / 0.076, 0.144 / 0.076)),  # k·ω = 0.094
    ],
    ids=['forward', 'left', 'turn', 'mixed'],
)
def test_hand_computed_wheel_rates(twist, wheels):
    c = controller()
    c.reset(twist)  # within the limits, so it is the commanded twist
    out = c.step(twist)
    np.testing.assert_allclose(out.wheel_rates, wheels, rtol=0, atol=1e-12)
    np.testing.assert_allclose(out.twist, twist, rtol=0, atol=1e-12)
    assert out.accel_scale == 1.0 and out.velocity_scale == 1.0


@given(st.tuples(*(st.floats(-2.0, 2.0),) * 3))
def test_forward_of_inverse_is_the_identity(twist):
    k = controller().kinematics
    np.testing.assert_allclose(k.twist_from_wheels(k.wheel_rates(twist)), twist, rtol=0, atol=1e-12)


# ---------------------------------------------------------------- limits

finite = st.floats(allow_nan=False, allow_infinity=False)
references = st.one_of(
    st.tuples(*(st.floats(-0.6, 0.6),) * 2, st.floats(-3.0, 3.0)),  # around the limits
    st.tuples(finite, finite, finite),  # up to ±1.8e308
)


@settings(max_examples=150, deadline=None)
@given(st.lists(references, min_size=1, max_size=60))
def test_random_references_never_break_a_limit_and_keep_their_direction(refs):
    c = controller()
    previous = np.zeros(3)
    for ref in refs:
        ref = np.array(ref)
        out = c.step(ref)
        assert np.all(np.abs(out.wheel_rates) <= WHEEL_MAX * (1 + 1e-12))
        assert np.all(np.abs(out.twist) <= VMAX * (1 + 1e-12))
        change = out.twist - previous
        assert np.all(np.abs(change) <= AMAX * DT * (1 + 2e-9))  # round-off
        # The bounded reference is the requested one scaled (direction kept) ...
        assert 0.0 <= out.velocity_scale <= 1.0
        np.testing.assert_allclose(out.reference, out.velocity_scale * ref, rtol=1e-12, atol=1e-300)
        if out.velocity_scale < 1.0:
            # ... and not more than needed: one limit is exactly active.
            ratios = np.append(
                np.abs(out.reference) / VMAX, np.max(np.abs(c.kinematics.wheel_rates(out.reference))) / WHEEL_MAX
            )
            assert np.max(ratios) == pytest.approx(1.0, rel=1e-9)
        # The change goes straight towards the bounded reference, as far as the limits allow.
        wanted = out.reference - previous
        np.testing.assert_allclose(change, out.accel_scale * wanted, rtol=1e-9, atol=1e-15)
        if out.accel_scale < 1.0:
            assert np.max(np.abs(change) / (AMAX * DT)) == pytest.approx(1.0, rel=1e-9)
        else:
            np.testing.assert_array_equal(c.twist, out.reference)
        previous = out.twist


def test_huge_reference_drives_at_the_limit_in_its_direction():
    c = controller()
    for _ in range(600):  # 15 s: 0.25 m/s at 0.025 m/s² takes 10 s
        out = c.step([1e308, -1e308, 0.0])
    np.testing.assert_allclose(out.twist, [0.25, -0.25, 0.0], atol=1e-12)
    # Robot B's wheel limit admits the whole Table 1 box; with a lower one it binds first.
    slow = WheelController(c.kinematics, WheelParams(DT, VMAX, AMAX, wheel_rate_limit=5.0))
    out = slow.step([1e300, 1e300, 2e300])
    # On the direction (1, 1, 2)·s the largest wheel rate is (s + s + 0.47·2s)/0.076 = 5 at
    # s = 0.38/2.94 = 0.129 m/s, below the 0.25 m/s velocity limit.
    np.testing.assert_allclose(out.reference, np.array([1.0, 1.0, 2.0]) * 0.38 / 2.94, rtol=1e-12)
    assert np.max(np.abs(slow.kinematics.wheel_rates(out.reference))) == pytest.approx(5.0, rel=1e-12)


@pytest.mark.parametrize('bad', [(math.nan, 0.0, 0.0), (0.0, math.inf, 0.0)])
def test_non_finite_reference_is_an_error_and_changes_nothing(bad):
    c = controller()
    c.step([0.1, 0.0, 0.0])
    before = c.twist
    with pytest.raises(NonFiniteError):
        c.step(bad)
    np.testing.assert_array_equal(c.twist, before)


# ---------------------------------------------------------------- braking


@settings(max_examples=100, deadline=None)
@given(st.tuples(st.floats(-0.25, 0.25), st.floats(-0.25, 0.25), st.floats(-1.0, 1.0)))
def test_stop_brakes_to_rest_within_v_over_a_plus_one_period(v):
    c = controller()
    c.reset(v)
    v = c.twist
    bound = float(np.max(np.abs(v) / AMAX)) + DT
    t, previous = 0.0, v
    while np.any(c.twist != 0.0):
        out = c.stop()
        t += DT
        assert out.status == 'braking'
        assert np.all(np.abs(out.twist - previous) <= AMAX * DT * (1 + 2e-9))
        assert np.all(np.abs(out.twist) <= np.abs(previous) + 1e-15)  # never speeds up
        previous = out.twist
        assert t <= bound + 1e-9, (t, bound)
    np.testing.assert_array_equal(c.stop().wheel_rates, np.zeros(4))  # at rest, exactly


def test_braking_is_at_the_acceleration_limit_not_faster():
    c = controller()
    c.reset([0.2, 0.0, 0.3])  # 0.2/0.025 = 8 s, 0.3/1.5 = 0.2 s: x sets the pace
    n = 0
    while np.any(c.twist != 0.0):
        c.stop()
        n += 1
    assert n == 320  # 8 s / 25 ms


# ---------------------------------------------------------------- the node, by hand


def twist_of(msg):
    return np.array([msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z])


class Recorder(Node):
    """Publishes joint states and references by hand; records the controller's outputs."""

    def __init__(self, context):
        super().__init__('recorder', context=context)
        self.wheels, self.feasible = [], []
        self.create_subscription(
            Float64MultiArray, '/wheel_controller/commands', lambda m: self.wheels.append(list(m.data)), 10
        )
        self.create_subscription(TwistStamped, '/base/feasible_twist', self.feasible.append, 10)
        self.pub_js = self.create_publisher(JointState, '/joint_states', 10)
        self.pub_ref = self.create_publisher(TwistStamped, '/base/reference', 10)

    def joint_state(self, stamp=0.0, names=WHEELS, positions=None, velocities=None):
        js = JointState()
        js.header.stamp = RosTime(nanoseconds=round(stamp * 1e9)).to_msg()
        js.name = list(names)
        js.position = [0.0] * len(names) if positions is None else [float(v) for v in positions]
        js.velocity = [] if velocities is None else [float(v) for v in velocities]
        self.pub_js.publish(js)

    def reference(self, ref, stamp=0.0, frame='base_link'):
        self.pub_ref.publish(twist_stamped(RosTime(nanoseconds=round(stamp * 1e9)).to_msg(), frame, ref))

    def cycle(self, ros, ref=None, **js):
        """A reference (if any) and a joint state of the same stamp (0); the count of cycles run."""
        n = len(self.feasible)
        if ref is not None:
            self.reference(ref)
        self.joint_state(**js)
        ros.spin_for(0.03)
        return len(self.feasible) - n


def start(ros, **params):
    node = ros.add(MecanumControllerNode(context=ros.context, parameter_overrides=overrides(**params)))
    rec = ros.add(Recorder(ros.context))
    ros.spin_for(0.2)
    return node, rec


def test_a_stale_reference_brakes_the_base_to_rest_within_v_over_a_plus_one_period(ros):
    node, rec = start(ros, reference_wait=0.0, reference_timeout=0.1, joint_state_timeout=5.0)
    ref = np.array([0.01, -0.005, 0.1])
    for _ in range(30):  # 0.01/0.025 = 0.4 s = 16 periods to reach it
        assert rec.cycle(ros, ref) == 1
    np.testing.assert_allclose(twist_of(rec.feasible[-1]), ref, atol=1e-12)
    ros.spin_for(0.2)  # the reference goes stale (node clock)
    braking = 0
    while np.any(twist_of(rec.feasible[-1]) != 0.0):
        assert rec.cycle(ros) == 1
        braking += 1
        assert braking * DT <= 0.4 + DT + 1e-9
    assert braking == 16  # at the acceleration limit, not faster
    assert rec.wheels[-1] == [0.0] * 4
    assert node.counters['stale_cycles'] == braking


@pytest.mark.parametrize('use_sim_time', [False, True])
def test_joint_state_timeout_commands_zero_wheel_rates(ros, use_sim_time):
    # Under use_sim_time with no /clock the ROS clock stands still: the steady-clock watchdog
    # must still see the joint states stop.
    node, rec = start(ros, joint_state_timeout=0.1, reference_wait=0.0, use_sim_time=use_sim_time)
    for _ in range(20):
        rec.cycle(ros, (0.25, 0.0, 0.0))
    assert max(abs(v) for v in rec.wheels[-1]) > 0.1
    n = len(rec.wheels)
    ros.spin_for(0.4)  # joint states stopped
    assert len(rec.wheels) > n + 3
    assert rec.wheels[-1] == [0.0] * 4
    assert node.watchdog.need_resync


def test_after_a_pause_it_restarts_from_the_measured_wheel_rates(ros):
    node, rec = start(ros, joint_state_timeout=0.1, reference_wait=0.0)
    rec.cycle(ros, (0.0, 0.0, 0.0))
    ros.spin_for(0.3)  # watchdog: resync on the next joint state
    moving = np.full(4, 0.1 / 0.076)  # the wheels still turn at 0.1 m/s forward
    assert rec.cycle(ros, (0.1, 0.0, 0.0), velocities=moving) == 1
    np.testing.assert_allclose(twist_of(rec.feasible[-1]), [0.1, 0.0, 0.0], atol=1e-12)


def test_bad_references_are_rejected(ros):
    node, rec = start(ros, reference_wait=0.0)
    rec.cycle(ros, (0.2, 0.0, 0.0))
    for bad, frame in (((math.nan, 0.0, 0.0), 'base_link'), ((0.0, math.inf, 0.0), ''), ((0.0, 0.1, 0.0), 'odom')):
        rec.reference(bad, frame=frame)
        assert rec.cycle(ros) == 1  # the cycle runs, on the last good reference
    np.testing.assert_array_equal(node.reference.value, [0.2, 0.0, 0.0])
    assert node.reference.rejected == 3
    assert all(np.all(np.isfinite(w)) for w in rec.wheels)
    assert all(np.all(np.isfinite(twist_of(f))) for f in rec.feasible)


def test_huge_finite_reference_gives_finite_commands_at_the_limit(ros):
    node, rec = start(ros, reference_wait=0.0)
    for _ in range(5):
        rec.cycle(ros, (1e308, 0.0, -1e308))
    twist = twist_of(rec.feasible[-1])
    assert np.all(np.isfinite(rec.wheels[-1]))
    assert twist[0] == pytest.approx(5 * AMAX[0] * DT) and twist[0] == pytest.approx(-twist[2])


def test_joint_states_are_read_by_name_and_garbage_runs_no_cycle(ros):
    node, rec = start(ros, reference_wait=0.0, joint_state_timeout=5.0)
    stop = (0.0, 0.0, 0.0)
    assert rec.cycle(ros, stop) == 1
    assert rec.cycle(ros, stop, names=['arm_joint_1'] + WHEELS[::-1], positions=[9.0, 1, 2, 3, 4]) == 1
    garbage = [
        dict(names=['a', 'b', 'c', 'd']),  # no wheel joints
        dict(names=WHEELS[:3] + ['arm_joint_1']),  # three of four
        dict(positions=[0.0] * 3),  # 3 positions, 4 names
        dict(velocities=[0.0] * 5),  # 5 velocities, 4 names
        dict(positions=[0.0, math.nan, 0.0, 0.0]),  # non-finite wheel angle
        dict(velocities=[0.0, 0.0, math.inf, 0.0]),  # non-finite wheel rate
    ]
    for js in garbage:
        assert rec.cycle(ros, stop, **js) == 0, js
    assert node.counters['joint_states_rejected'] == len(garbage)
    assert node.counters['cycles'] == 2


def test_a_joint_state_waits_for_the_reference_of_its_stamp(ros):
    node, rec = start(ros, reference_wait=0.5, reference_timeout=2.0, joint_state_timeout=5.0, max_state_wait=0.0)
    # The joint state first: no cycle until the reference of its stamp comes, then at once.
    rec.joint_state(stamp=1.0)
    ros.spin_for(0.1)
    assert rec.feasible == []
    rec.reference((0.25, 0.0, 0.0), stamp=1.0)
    assert ros.spin_until(lambda: len(rec.feasible) == 1, timeout=0.3)
    assert stamp_s(rec.feasible[0]) == 1.0 and rec.feasible[0].header.frame_id == 'base_link'
    assert twist_of(rec.feasible[0])[0] == pytest.approx(AMAX[0] * DT)
    # A reference of another stamp does not release it: the wait ends it, with that reference.
    rec.joint_state(stamp=1.025)
    ros.spin_for(0.05)
    rec.reference((-0.25, 0.0, 0.0), stamp=7.0)
    ros.spin_for(0.1)
    assert len(rec.feasible) == 1
    assert ros.spin_until(lambda: len(rec.feasible) == 2, timeout=1.0)
    assert stamp_s(rec.feasible[1]) == 1.025
    assert twist_of(rec.feasible[1])[0] == pytest.approx(0.0, abs=1e-15)


# ---------------------------------------------------------------- with the simulator, lockstep


class ReferenceAnswerer(ScriptedController):
    """Answers each /joint_states stamped S with zero arm rates and, ``delay`` steady seconds
    later, a /base/reference stamped S of value ``value(k)``, k = S/DT. Records the answers."""

    def __init__(self, context, value, delay):
        super().__init__(context, ('arm',), lambda t, js: {'arm': np.zeros(7)}, name='reference_answerer')
        self.value, self.delay = value, delay
        self.sent, self.feasible, self.wheel_commands = {}, {}, []
        self._stamps = []
        self.pub_ref = self.create_publisher(TwistStamped, '/base/reference', 10)
        self.create_subscription(
            TwistStamped,
            '/base/feasible_twist',
            lambda m: self.feasible.setdefault(round(stamp_s(m) / DT), []).append(m),
            10,
        )
        self.create_subscription(
            Float64MultiArray, '/wheel_controller/commands', lambda m: self.wheel_commands.append(list(m.data)), 10
        )
        self.timer = self.create_timer(
            max(delay, 1e-3), self._publish, clock=Clock(clock_type=ClockType.STEADY_TIME), autostart=False
        )

    def _on_joints(self, msg):
        super()._on_joints(msg)
        self._stamps.append(msg.header.stamp)
        if self.delay > 0:
            self.timer.reset()
        else:
            self._publish()

    def _publish(self):
        self.timer.cancel()
        while self._stamps:
            stamp = self._stamps.pop(0)
            k = round(stamp_s_of(stamp) / DT)
            self.sent[k] = np.array(self.value(k), dtype=float)
            self.pub_ref.publish(twist_stamped(stamp, 'base_link', self.sent[k]))


def stamp_s_of(stamp):
    return stamp.sec + stamp.nanosec * 1e-9


def run_lockstep(ros, value, cycles, delay=0.0, use_sim_time=False):
    sim_time = overrides(use_sim_time=use_sim_time)
    ros.add(
        SimNode(
            context=ros.context,
            parameter_overrides=sim_time
            + overrides(robot='mecanum', timing='lockstep', lockstep_groups='arm,wheel', lockstep_timeout=10.0),
        )
    )
    # (a long lockstep timeout: on a loaded machine the simulator must not step without the commands)
    ros.add(
        MecanumControllerNode(
            context=ros.context, parameter_overrides=sim_time + overrides(reference_wait=0.5, max_state_wait=0.0)
        )
    )
    answerer = ros.add(ReferenceAnswerer(ros.context, value, delay))
    assert ros.spin_until(lambda: len(answerer.feasible) >= cycles and len(answerer.truth) > cycles, timeout=120)
    return answerer


def changing_reference(k):
    """A new reference every cycle, often beyond the limits, turning its direction each time."""
    return (0.3 * math.cos(0.9 * k), 0.3 * math.sin(1.3 * k), 1.2 * math.sin(0.7 * k + 0.5))


@pytest.mark.parametrize(
    'delay, use_sim_time',
    [(0.0, False), (0.003, False), (0.003, True)],
    ids=['reference-at-once', 'reference-late', 'reference-late-sim-time'],
)
def test_each_feasible_twist_answers_the_reference_of_its_own_cycle(ros, delay, use_sim_time):
    answerer = run_lockstep(ros, changing_reference, 80, delay, use_sim_time)
    cycles = sorted(answerer.feasible)[:80]
    assert cycles == list(range(80))  # one answer per cycle, stamped S
    offline, late = controller(), controller()
    expected = [offline.step(answerer.sent[k]).twist for k in cycles]
    one_late = [late.step(answerer.sent[k - 1] if k else np.zeros(3)).twist for k in cycles]
    got = []
    for k in cycles:
        (answer,) = answerer.feasible[k]
        assert answer.header.frame_id == 'base_link'
        got.append(twist_of(answer))
    np.testing.assert_allclose(got, expected, rtol=0, atol=1e-12)
    # The check is sharp: with the previous cycle's reference every answer is this far off.
    off = np.max(np.abs(np.array(one_late) - np.array(expected)), axis=1)
    assert off.min() > 5e-4


def test_the_base_follows_a_constant_reference_within_the_acceleration_ramp(ros):
    ref = np.array([0.05, -0.025, 0.6])  # ramp: max(0.05/0.025, 0.025/0.025, 0.6/1.5) = 2 s
    ramp = 2.0
    answerer = run_lockstep(ros, lambda k: ref, 120)
    feasible = {k: twist_of(m[0]) for k, m in answerer.feasible.items()}
    checked = 0
    for msg in answerer.truth:
        k = round(stamp_s(msg) / DT)
        if k == 0 or k > 120:
            continue
        truth = np.array([msg.twist.twist.linear.x, msg.twist.twist.linear.y, msg.twist.twist.angular.z])
        # The state at k shows the twist executed over period k − 1, the one commanded then.
        np.testing.assert_allclose(truth, feasible[k - 1], rtol=0, atol=1e-6)
        np.testing.assert_allclose(truth, ref * min(1.0, k * DT / ramp), rtol=0, atol=1e-6)
        checked += 1
    assert checked >= 115
    assert np.all(np.abs(np.array([w for w in answerer.wheel_commands])) <= WHEEL_MAX)
