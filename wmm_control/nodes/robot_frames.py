"""The robot for rviz: ``robot_description`` and its TF frames, published by ``wmm_sim``.

``robot_description`` (``std_msgs/String``, reliable, transient local: a late subscriber gets
it) carries the URDF text. TF, as robot_state_publisher and a localisation would publish it:
the fixed joints once on ``/tf_static``; every step on ``/tf`` world → odom (the drift of
dead reckoning: world → odom → base_link is the true base pose), odom → base_link (the
odometry) and each moving joint (:class:`~wmm_control.kinematics.frames.JointTransforms`).
Every frame but the world's carries ``frame_prefix`` (``r1/base_link``), so that two robots
share one TF tree.

``tf2_msgs`` has no PyPI wheel: where it cannot be imported, TF is not published and one log
line says why; ``robot_description`` is published anyway.
"""

from __future__ import annotations

from collections.abc import Iterable, Mapping

from builtin_interfaces.msg import Time
from geometry_msgs.msg import TransformStamped
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from std_msgs.msg import String

from wmm_control.kinematics.frames import FrameTransform, JointTransforms, planar_transform, world_to_odom
from wmm_control.nodes.conversions import set_pose
from wmm_control.nodes.qos import LATCHED_QOS
from wmm_control.robot_config import RobotConfig

try:
    from tf2_msgs.msg import TFMessage

    TF_UNAVAILABLE = ''
except ImportError as _exc:  # pip-only install: tf2_msgs has no PyPI wheel
    TFMessage = None
    TF_UNAVAILABLE = (
        f'cannot import tf2_msgs ({_exc}); it has no PyPI wheel (a ROS 2 Jazzy install has it: ros-jazzy-tf2-msgs)'
    )

__all__ = ['RobotFrames', 'DESCRIPTION_QOS', 'TF_UNAVAILABLE', 'transform_stamped', 'valid_frame_prefix']

#: ``robot_description`` and ``/tf_static``: a late subscriber gets the last one.
DESCRIPTION_QOS = LATCHED_QOS
#: ``/tf``: tf2's dynamic broadcaster's (reliable, keep last 100, volatile).
TF_QOS = QoSProfile(
    history=HistoryPolicy.KEEP_LAST,
    depth=100,
    reliability=ReliabilityPolicy.RELIABLE,
    durability=DurabilityPolicy.VOLATILE,
)


def valid_frame_prefix(prefix: str) -> str:
    """'' when ``prefix`` may start TF frame names (empty, or like ``r1/``), else why not."""
    if prefix and (prefix.startswith('/') or any(c.isspace() for c in prefix)):
        return f'frame_prefix {prefix!r}: no leading "/" and no spaces (tf2 frame ids are like "r1/base_link")'
    return ''


def transform_stamped(stamp: Time, tf: FrameTransform, parent: str, child: str) -> TransformStamped:
    """A ``geometry_msgs/TransformStamped`` of ``tf`` with the frame ids ``parent`` and ``child``."""
    msg = TransformStamped()
    msg.header.stamp = stamp
    msg.header.frame_id = parent
    msg.child_frame_id = child
    set_pose(msg.transform, tf.translation, tf.quaternion)
    return msg


class RobotFrames:
    """Publishes one robot's ``robot_description`` and its TF frames from ``node``.

    Args:
        node: the publishing node (the simulator).
        robot: the robot (its URDF, base link).
        frame_prefix: prefix of every frame but ``world_frame``.
        world_frame: the world's frame id.
        odom_frame: odometry's frame id (before the prefix).
        publish_tf: False publishes ``robot_description`` alone.
    """

    def __init__(
        self,
        node: Node,
        robot: RobotConfig,
        frame_prefix: str = '',
        world_frame: str = 'world',
        odom_frame: str = 'odom',
        publish_tf: bool = True,
    ) -> None:
        self.joints = JointTransforms(robot.urdf_path)
        self.prefix = frame_prefix
        self.world_frame = world_frame
        self.odom_frame = odom_frame
        self.base_link = robot.base_link
        self._pub_description = node.create_publisher(String, 'robot_description', DESCRIPTION_QOS)
        self._pub_description.publish(String(data=robot.urdf_path.read_text()))
        self._pub_tf = self._pub_static = None
        if not publish_tf:
            node.get_logger().info('TF not published: publish_tf is false')
        elif TFMessage is None:
            node.get_logger().info(f'TF not published: {TF_UNAVAILABLE}')
        else:
            self._pub_static = node.create_publisher(TFMessage, '/tf_static', DESCRIPTION_QOS)
            self._pub_tf = node.create_publisher(TFMessage, '/tf', TF_QOS)
            self._pub_static.publish(TFMessage(transforms=self.static_transforms(node.get_clock().now().to_msg())))

    @property
    def publishing_tf(self) -> bool:
        """True when TF goes out (tf2_msgs imported, ``publish_tf`` set)."""
        return self._pub_tf is not None

    def _stamped(self, stamp: Time, transforms: Iterable[FrameTransform]) -> list[TransformStamped]:
        p = self.prefix
        return [
            transform_stamped(stamp, tf, tf.parent if tf.parent == self.world_frame else p + tf.parent, p + tf.child)
            for tf in transforms
        ]

    def static_transforms(self, stamp: Time) -> list[TransformStamped]:
        """The fixed joints' transforms (``/tf_static``)."""
        return self._stamped(stamp, self.joints.fixed)

    def dynamic_transforms(
        self, stamp: Time, positions: Mapping[str, float], odom_pose, true_pose
    ) -> list[TransformStamped]:
        """world → odom, odom → base_link and every moving joint's transform (``/tf``).

        Args:
            positions: joint positions by name.
            odom_pose: the base's (x, y, θ) in odom (dead reckoning).
            true_pose: the base's (x, y, θ) in the world.
        """
        base = [
            world_to_odom(self.world_frame, self.odom_frame, true_pose, odom_pose),
            planar_transform(self.odom_frame, self.base_link, odom_pose),
        ]
        return self._stamped(stamp, (*base, *self.joints.moving(positions)))

    def publish(self, stamp: Time, positions: Mapping[str, float], odom_pose, true_pose) -> None:
        """Publish ``/tf`` for this step (nothing when TF is not published)."""
        if self._pub_tf is not None:
            self._pub_tf.publish(TFMessage(transforms=self.dynamic_transforms(stamp, positions, odom_pose, true_pose)))
