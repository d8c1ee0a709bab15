"""The robot's frames as TF sees them: one transform per URDF joint, and the base's (ROS-free).

:class:`JointTransforms` gives what robot_state_publisher broadcasts for a URDF: each joint's
transform from its parent link to its child link, ``origin · motion(q)``. Fixed joints give
constant transforms (``/tf_static``); revolute and continuous joints rotate about their axis,
prismatic ones slide along it (``/tf``, from joint positions by name). A mimic joint follows
its leader (``multiplier · q + offset``). Floating and planar joints are left out, as
robot_state_publisher does: the base's pose is odometry's.

:func:`planar_transform` and :func:`world_to_odom` give the base's frames: odom → base_link
from the odometry pose, and world → odom as the correction that puts base_link at its true
pose (the drift of dead reckoning), as a localisation node's map → odom does.

Quaternions are (x, y, z, w), as ``geometry_msgs/Transform`` takes them.
"""

from __future__ import annotations

import math
from collections.abc import Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wmm_control.errors import ConfigError, NonFiniteError
from wmm_control.geometry import (
    matrix_from_rpy,
    quaternion_from_axis_angle,
    quaternion_from_matrix,
    quaternion_from_yaw,
    quaternion_multiply,
    se2_compose,
    se2_inverse,
)
from wmm_control.urdf import UrdfJoint, UrdfTree

__all__ = [
    'FrameTransform',
    'JointTransforms',
    'planar_transform',
    'world_to_odom',
    'quaternion_from_matrix',
    'compose',
]


@dataclass(frozen=True)
class FrameTransform:
    """The pose of frame ``child`` in frame ``parent``: translation [m] and unit quaternion (x, y, z, w)."""

    parent: str
    child: str
    translation: np.ndarray
    quaternion: np.ndarray

    def matrix(self) -> np.ndarray:
        """The 4×4 homogeneous matrix of the transform."""
        x, y, z, w = self.quaternion
        out = np.eye(4)
        out[:3, :3] = [
            [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
            [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
            [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
        ]
        out[:3, 3] = self.translation
        return out


def compose(first: FrameTransform, second: FrameTransform) -> FrameTransform:
    """``first`` then ``second`` (``second.parent`` must be ``first.child``): parent of the first
    to child of the second."""
    if second.parent != first.child:
        raise ValueError(f'cannot compose {first.parent}→{first.child} with {second.parent}→{second.child}')
    rot = first.matrix()[:3, :3]
    quat = quaternion_multiply(first.quaternion, second.quaternion)
    return FrameTransform(
        first.parent, second.child, first.translation + rot @ second.translation, quat / np.linalg.norm(quat)
    )


def planar_transform(parent: str, child: str, pose) -> FrameTransform:
    """The transform of a planar pose (x, y, θ) [m, m, rad] of ``child`` in ``parent``."""
    x, y, th = (float(v) for v in pose)
    if not all(math.isfinite(v) for v in (x, y, th)):
        raise NonFiniteError(f'planar pose {parent}→{child} is not finite: {(x, y, th)}')
    return FrameTransform(parent, child, np.array([x, y, 0.0]), quaternion_from_yaw(th))


def world_to_odom(world: str, odom: str, true_pose, odom_pose) -> FrameTransform:
    """world → odom such that world → odom → base equals the base's true pose.

    Args:
        true_pose: the base's pose (x, y, θ) in ``world`` (ground truth, or a localisation's).
        odom_pose: its pose (x, y, θ) in ``odom`` (dead reckoning).
    """
    return planar_transform(world, odom, se2_compose(true_pose, se2_inverse(odom_pose)))


def _origin(joint: UrdfJoint) -> tuple[np.ndarray, np.ndarray]:
    """(rotation (3, 3), quaternion (x, y, z, w)) of a joint's ``<origin rpy>``."""
    rot = matrix_from_rpy(joint.rpy)
    return rot, quaternion_from_matrix(rot)


class JointTransforms:
    """Per-joint transforms of a URDF, as robot_state_publisher publishes them.

    Args:
        urdf: the URDF file.

    Raises:
        ConfigError: the URDF cannot be read, a moving joint has a zero axis, or a mimic joint
            follows a joint that does not move.
    """

    def __init__(self, urdf: str | Path) -> None:
        tree = UrdfTree(urdf)
        self.root_link: str | None = tree.root_link
        fixed, moving = [], {}
        for joint in tree.joints.values():
            rot, quat = _origin(joint)
            if joint.type == 'fixed':
                fixed.append(FrameTransform(joint.parent, joint.child, joint.xyz.copy(), quat))
            elif joint.type in ('revolute', 'continuous', 'prismatic'):
                norm = float(np.linalg.norm(joint.axis))
                if not norm > 0.0:
                    raise ConfigError(f'{tree.path.name}: joint {joint.name!r} has a zero axis')
                moving[joint.name] = (joint, rot, quat, joint.axis / norm)
        for name, (joint, *_rest) in moving.items():
            if joint.mimic is not None and joint.mimic not in moving:
                raise ConfigError(
                    f'{tree.path.name}: joint {name!r} mimics {joint.mimic!r}, which is not a moving joint of the URDF'
                )
        #: The fixed joints' transforms (constant: ``/tf_static``).
        self.fixed: tuple[FrameTransform, ...] = tuple(fixed)
        self._moving = moving
        #: Names of the joints that move (revolute, continuous, prismatic), mimic joints included.
        self.moving_joints: tuple[str, ...] = tuple(moving)

    def moving(self, positions: Mapping[str, float]) -> list[FrameTransform]:
        """The transform of every moving joint whose position is known, in URDF order.

        Args:
            positions: joint positions [rad or m] by name; names that are not joints of the
                URDF are ignored; a mimic joint takes its leader's when it has none of its own.

        Raises:
            NonFiniteError: a position used is NaN or infinite (nothing is returned).
        """
        out = []
        for name, (joint, rot, quat, axis) in self._moving.items():
            if name in positions:
                q = float(positions[name])
            elif joint.mimic is not None and joint.mimic in positions:
                q = joint.mimic_multiplier * float(positions[joint.mimic]) + joint.mimic_offset
            else:
                continue
            if not math.isfinite(q):
                raise NonFiniteError(f'joint {name!r} position {q} is not finite')
            if joint.type == 'prismatic':
                out.append(FrameTransform(joint.parent, joint.child, joint.xyz + rot @ (axis * q), quat))
            else:
                out.append(
                    FrameTransform(
                        joint.parent,
                        joint.child,
                        joint.xyz.copy(),
                        quaternion_multiply(quat, quaternion_from_axis_angle(axis, q)),
                    )
                )
        return out

    def link_poses(self, positions: Mapping[str, float]) -> dict[str, FrameTransform]:
        """The pose of every link reachable from the root link through fixed joints and joints
        of known position, in the root link's frame (the root itself: the identity)."""
        if self.root_link is None:
            raise ConfigError('the URDF has no single root link')
        by_parent: dict[str, list[FrameTransform]] = {}
        for tf in (*self.fixed, *self.moving(positions)):
            by_parent.setdefault(tf.parent, []).append(tf)
        root = self.root_link
        poses = {root: FrameTransform(root, root, np.zeros(3), np.array([0.0, 0.0, 0.0, 1.0]))}
        stack = [root]
        while stack:
            link = stack.pop()
            for tf in by_parent.get(link, ()):
                poses[tf.child] = compose(poses[link], tf)
                stack.append(tf.child)
        return poses
