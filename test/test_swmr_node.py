"""swmr_controller node with the simulator (lockstep, kinematic base, slip off), in process."""

import numpy as np
import pytest
from geometry_msgs.msg import TwistStamped
from rclpy.node import Node
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from ros_helpers import RosHarness, ScriptedController, overrides, pose2d, stamp_s
from sim_bridge.node import SimNode
from wmm_control.errors import ConfigError
from wmm_control.nodes.swmr_controller import SwmrControllerNode

DT = 0.025


@pytest.fixture
def ros():
    harness = RosHarness()
    yield harness
    harness.close()


class ReferencePublisher(ScriptedController):
    """Answers each joint state with a /base/reference from ``ref(t)`` (None: publish nothing)
    and an arm command of zeros; records the feasible twists."""

    def __init__(self, context, ref):
        super().__init__(context, ('arm',), lambda t, js: {'arm': np.zeros(7)}, name='reference_publisher')
        self.ref = ref
        self.pub_ref = self.create_publisher(TwistStamped, '/base/reference', 10)
        self.feasible = {}
        self.create_subscription(TwistStamped, '/base/feasible_twist', self._on_feasible, 10)

    def _on_joints(self, msg):
        super()._on_joints(msg)
        value = self.ref(stamp_s(msg))
        if value is None:
            return
        out = TwistStamped()
        out.header.stamp = msg.header.stamp
        out.header.frame_id = 'base_link'
        out.twist.linear.x, out.twist.linear.y, out.twist.angular.z = (float(v) for v in value)
        self.pub_ref.publish(out)

    def _on_feasible(self, msg):
        self.feasible[round(stamp_s(msg) / DT)] = np.array(
            [msg.twist.linear.x, msg.twist.linear.y, msg.twist.angular.z])


def run(ros, ref, seconds, **sim_params):
    ros.add(SimNode(context=ros.context, parameter_overrides=overrides(
        timing='lockstep', lockstep_groups='steer,drive', **sim_params)))
    ros.add(SwmrControllerNode(context=ros.context))
    pub = ros.add(ReferencePublisher(ros.context, ref))
    n = int(round(seconds / DT)) + 1
    assert ros.spin_until(lambda: len(pub.truth) >= n, timeout=60)
    return pub


def se2_twist(p0, p1, dt):
    """Constant base-frame twist that moves pose p0 to p1 in dt (SE(2) log)."""
    c, s = np.cos(p0[2]), np.sin(p0[2])
    d = np.array([c * (p1[0] - p0[0]) + s * (p1[1] - p0[1]), -s * (p1[0] - p0[0]) + c * (p1[1] - p0[1])])
    a = (p1[2] - p0[2] + np.pi) % (2 * np.pi) - np.pi
    if abs(a) < 1e-12:
        v = d
    else:
        m = np.array([[np.sin(a), -(1 - np.cos(a))], [1 - np.cos(a), np.sin(a)]]) / a
        v = np.linalg.solve(m, d)
    return np.array([v[0], v[1], a]) / dt


@pytest.mark.parametrize('ref', [
    (0.4, 0.0, 0.0),        # translation along x
    (0.0, 0.3, 0.0),        # along y: every wheel turns by π/2
    (0.3, -0.3, 0.0),       # diagonal
    (0.0, 0.0, 0.5),        # rotation about the base centre
    (0.4, 0.0, 0.3),        # arc turning left
    (-0.2, 0.3, -0.4),      # arc backwards and right
], ids=['x', 'y', 'diagonal', 'rotation', 'arc-left', 'arc-right-backwards'])
def test_reference_twist_is_tracked_within_one_percent(ros, ref):
    pub = run(ros, lambda t: ref, 8.0)
    ref = np.array(ref)
    for msg in pub.truth[-40:]:             # the last second
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
    # The reference stops after 3 s; reference_timeout 0.2 s (wall clock of the controller:
    # lockstep runs faster than real time, so give it real seconds to notice).
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
    np.testing.assert_allclose(steer_now, steer_then, atol=0.05)   # held, not straightened
    assert np.ptp(steer_now) > 0.05                                # still set for the arc


class Recorder(Node):
    def __init__(self, context):
        super().__init__('recorder', context=context)
        self.steer, self.drive = [], []
        self.create_subscription(Float64MultiArray, '/steer_controller/commands',
                                 lambda m: self.steer.append(list(m.data)), 10)
        self.create_subscription(Float64MultiArray, '/drive_controller/commands',
                                 lambda m: self.drive.append(list(m.data)), 10)
        self.pub_js = self.create_publisher(JointState, '/joint_states', 10)
        self.pub_ref = self.create_publisher(TwistStamped, '/base/reference', 10)

    def send(self, beta, ref, frame='base_link'):
        js = JointState()
        js.name = [f'steer_{m}_joint' for m in ('fl', 'fr', 'rl', 'rr')]
        js.position = [float(b) for b in beta]
        js.velocity = [0.0] * 4
        r = TwistStamped()
        r.header.frame_id = frame
        r.twist.linear.x, r.twist.linear.y, r.twist.angular.z = (float(v) for v in ref)
        self.pub_ref.publish(r)
        self.pub_js.publish(js)


def test_joint_state_timeout_commands_zero_rates(ros):
    ros.add(SwmrControllerNode(context=ros.context, parameter_overrides=overrides(joint_state_timeout=0.1)))
    rec = ros.add(Recorder(ros.context))
    ros.spin_for(0.3)
    for _ in range(40):
        rec.send(np.zeros(4), (0.5, 0.0, 0.0))
        ros.spin_for(0.01)
    assert ros.spin_until(lambda: len(rec.drive) >= 20)
    assert max(abs(v) for v in rec.drive[-1]) > 0.1
    n = len(rec.drive)
    ros.spin_for(0.5)                      # joint states stopped
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
    np.testing.assert_array_equal(node.reference, [0.2, 0.0, 0.0])
    assert all(np.all(np.isfinite(d)) for d in rec.drive + rec.steer)


def test_inconsistent_geometry_parameters_fail_clearly(ros):
    with pytest.raises(ConfigError, match='same length'):
        SwmrControllerNode(context=ros.context, parameter_overrides=overrides(hip_x=[0.24, -0.24]))
