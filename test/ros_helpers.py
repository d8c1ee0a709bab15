"""In-process ROS test helpers: a private context per test, spinning until a condition holds,
and a scripted controller that answers each joint state with commands. The fault matrix
(:mod:`fault_matrix`) runs each of its cells on a :class:`RosHarness` too."""

import time
from contextlib import contextmanager

import numpy as np
import rclpy
from nav_msgs.msg import Odometry
from geometry_msgs.msg import PoseStamped
from diagnostic_msgs.msg import DiagnosticArray
from rclpy.executors import SingleThreadedExecutor
from rclpy.node import Node
from rclpy.parameter import Parameter
from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64MultiArray

from wmm_control.experiments.ros_run import private_domain_id
from wmm_control.geometry import yaw_from_quaternion
from wmm_control.nodes.conversions import float_array


#: What a probe subscribes to ``/rosout`` with: every message a node logged, also those logged
#: before the subscription.
ROSOUT_QOS = QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL, reliability=ReliabilityPolicy.RELIABLE)


@contextmanager
def held_up(obj, name, seconds, every=1):
    """Within the block, ``obj.name(...)`` sleeps ``seconds`` before it runs (every ``every``-th
    call, from the first): a node held up in the middle of its cycle (stopped, or starved on a
    busy machine)."""
    original = getattr(obj, name)
    calls = [0]

    def slow(*args, **kwargs):
        if calls[0] % every == 0:
            time.sleep(seconds)
        calls[0] += 1
        return original(*args, **kwargs)

    setattr(obj, name, slow)
    try:
        yield
    finally:
        delattr(obj, name)  # the class's method again


def overrides(**params):
    return [Parameter(k, value=v) for k, v in params.items()]


class RosHarness:
    """A private rclpy Context and executor; nodes added to it are destroyed at close().

    ``args``: ROS arguments of the context, e.g. ``['--ros-args', '--disable-stdout-logs']``."""

    def __init__(self, args=None):
        self.context = rclpy.Context()
        # A domain of this test process alone: no crosstalk with other ROS processes on the machine.
        rclpy.init(context=self.context, domain_id=private_domain_id(), args=args)
        self.executor = SingleThreadedExecutor(context=self.context)
        self.nodes = []

    def add(self, node):
        self.nodes.append(node)
        self.executor.add_node(node)
        return node

    def probe(self, name, **kwargs):
        """A plain node of this context (publishers, subscriptions, clients of a test), added."""
        return self.add(Node(name, context=self.context, **kwargs))

    def spin_until(self, predicate, timeout=20.0, poll=0.005):
        """Spin until ``predicate()`` is true; False if the wall-clock timeout passes first.
        ``poll``: the longest a single wait for work lasts [s]."""
        end = time.monotonic() + timeout
        while time.monotonic() < end:
            if predicate():
                return True
            self.executor.spin_once(timeout_sec=poll)
        return predicate()

    def spin_for(self, seconds):
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            self.executor.spin_once(timeout_sec=0.005)

    def close(self):
        for node in self.nodes:
            self.executor.remove_node(node)
            node.destroy_node()
        self.executor.shutdown()
        rclpy.try_shutdown(context=self.context)


class ScriptedController(Node):
    """Answers every /joint_states message with one command per group and records the topics.

    ``script(t, joint_state_msg) -> {group: values}``; groups not returned get nothing.
    """

    def __init__(self, context, groups, script, name='scripted_controller'):
        super().__init__(name, context=context)
        self.script = script
        self.pubs = {g: self.create_publisher(Float64MultiArray, f'/{g}_controller/commands', 10) for g in groups}
        self.joint_states, self.ee_poses, self.odom, self.truth, self.diagnostics = [], [], [], [], []
        self.create_subscription(JointState, '/joint_states', self._on_joints, 10)
        self.create_subscription(PoseStamped, '/ee_pose', self.ee_poses.append, 10)
        self.create_subscription(Odometry, '/odom', self.odom.append, 10)
        self.create_subscription(Odometry, '/ground_truth/odom', self.truth.append, 10)
        self.create_subscription(DiagnosticArray, '/diagnostics', self.diagnostics.append, 10)

    def _on_joints(self, msg):
        self.joint_states.append(msg)
        t = msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9
        for group, values in (self.script(t, msg) or {}).items():
            self.pubs[group].publish(values if isinstance(values, Float64MultiArray) else float_array(values))

    def positions(self, index=-1):
        msg = self.joint_states[index]
        return dict(zip(msg.name, msg.position))

    def velocities(self, index=-1):
        msg = self.joint_states[index]
        return dict(zip(msg.name, msg.velocity))


def stamp_s(msg):
    return msg.header.stamp.sec + msg.header.stamp.nanosec * 1e-9


def pose2d(odom_msg):
    p = odom_msg.pose.pose
    q = p.orientation
    return np.array([p.position.x, p.position.y, yaw_from_quaternion((q.x, q.y, q.z, q.w))])
