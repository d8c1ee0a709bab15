"""What ``wmm_sim`` (:mod:`sim_bridge.node`) publishes: the simulated state of each period as
ROS messages, and its ``/diagnostics``.

``/ee_pose``, ``/odom`` and ``/ground_truth/odom`` are built only when a subscriber is matched
(one that comes later is matched within a period or two and gets every message from then on);
the clock and the joint states always go out. ``sim/lockstep_timeout`` (latched) tells the
other nodes how the simulator steps (:mod:`wmm_control.nodes.sim_timing`). The odometry covariances are the slip model's
(:class:`~sim_bridge.slip.OdometryCovariance`), planar: z, roll and pitch carry
:data:`~sim_bridge.slip.VARIANCE_FLOOR`.
"""

import numpy as np
from builtin_interfaces.msg import Time
from diagnostic_msgs.msg import DiagnosticArray
from geometry_msgs.msg import PoseStamped
from nav_msgs.msg import Odometry
from rclpy.node import Node
from rosgraph_msgs.msg import Clock as ClockMsg
from sensor_msgs.msg import JointState
from std_msgs.msg import Float64

from sim_bridge.slip import VARIANCE_FLOOR, OdometryCovariance
from sim_bridge.supervision import Status
from sim_bridge.world import SimWorld
from wmm_control.nodes.conversions import odometry, planar_covariance, pose_stamped
from wmm_control.nodes.diagnostics import diagnostic_array, node_status
from wmm_control.nodes.qos import CLOCK_QOS, DIAGNOSTICS_QOS, LATCHED_QOS, STATE_PUB_QOS
from wmm_control.nodes.robot_frames import RobotFrames
from wmm_control.nodes.sim_timing import LOCKSTEP_TOPIC

__all__ = ['SimOutputs']


class SimOutputs:
    """The publishers of the simulated state, ``clock`` and ``/diagnostics``, on ``node``.

    Frames: ``odom_frame`` and ``base_frame`` name the odometry's (both carry the node's
    ``frame_prefix``); ground truth is in ``world``; ``frames`` publishes ``/tf``.
    """

    def __init__(self, node: Node, frames: RobotFrames, odom_frame: str, base_frame: str):
        self.node = node
        self.frames = frames
        self.odom_frame = odom_frame
        self.base_frame = base_frame
        self.pub_joints = node.create_publisher(JointState, 'joint_states', STATE_PUB_QOS)
        self.pub_ee = node.create_publisher(PoseStamped, 'ee_pose', STATE_PUB_QOS)
        self.pub_odom = node.create_publisher(Odometry, 'odom', STATE_PUB_QOS)
        self.pub_truth = node.create_publisher(Odometry, 'ground_truth/odom', STATE_PUB_QOS)
        # Relative: each simulator in its namespace; nodes on its sim time remap /clock to it.
        self.pub_clock = node.create_publisher(ClockMsg, 'clock', CLOCK_QOS)
        self.pub_diag = node.create_publisher(DiagnosticArray, '/diagnostics', DIAGNOSTICS_QOS)
        self.pub_timing = node.create_publisher(Float64, LOCKSTEP_TOPIC, LATCHED_QOS)

    def publish_timing(self, lockstep_timeout: float) -> None:
        """Tell the nodes how the simulator steps (:mod:`wmm_control.nodes.sim_timing`): 0 in
        realtime, else its ``lockstep_timeout`` [s]."""
        self.pub_timing.publish(Float64(data=float(lockstep_timeout)))

    def publish_state(self, stamp: Time, world: SimWorld, covariance: OdometryCovariance, clock: bool) -> JointState:
        """Publish ``clock`` (when ``clock`` is set), the end-effector pose, the odometry, the
        ground truth and ``/tf`` of ``world``'s state, all stamped ``stamp``.

        Returns:
            The joint states, for the caller to publish last with :meth:`publish_joints`: in
            lockstep the controllers answer them, possibly before the call returns.
        """
        if clock:
            self.pub_clock.publish(ClockMsg(clock=stamp))
        # the driven joints, then those held (head, fingers): robot_state_publisher places every link
        names, pos, vel = world.joint_state()
        held_names, held_pos, held_vel = world.held_joint_state()
        joints = JointState(
            name=[*names, *held_names],
            position=[*pos.tolist(), *held_pos.tolist()],
            velocity=[*vel.tolist(), *held_vel.tolist()],
        )
        joints.header.stamp = stamp
        if self.pub_ee.get_subscription_count() > 0:
            self.pub_ee.publish(pose_stamped(stamp, 'world', *world.ee_pose()))
        odom_pose, true_pose = world.odom_pose(), world.base_pose()
        if self.pub_odom.get_subscription_count() > 0:
            covariances = (
                planar_covariance(covariance.pose, VARIANCE_FLOOR),
                planar_covariance(np.diag(covariance.twist), VARIANCE_FLOOR),
            )
            twist = world.odom_twist()
            self.pub_odom.publish(odometry(stamp, self.odom_frame, self.base_frame, odom_pose, twist, covariances))
        if self.pub_truth.get_subscription_count() > 0:
            self.pub_truth.publish(odometry(stamp, 'world', self.base_frame, true_pose, world.base_twist()))
        if self.frames.publishing_tf:
            self.frames.publish(stamp, dict(zip(names, joints.position)), odom_pose, true_pose)
        return joints

    def publish_joints(self, joints: JointState) -> None:
        """Publish the joint states :meth:`publish_state` returned."""
        self.pub_joints.publish(joints)

    def publish_diagnostics(self, stamp: Time, robot_name: str, statuses: list[Status]) -> None:
        """Publish the simulator's statuses (:func:`sim_bridge.supervision.statuses`) on ``/diagnostics``."""
        found = [node_status(self.node, s.part, robot_name, s.level, s.message, s.values) for s in statuses]
        self.pub_diag.publish(diagnostic_array(stamp, found))
