"""``redundancy_resolver``'s ``~/markers`` (``visualization_msgs/MarkerArray``) for rviz.

Four markers in the world frame, namespaces:

* ``goal``: an arrow along the goal's x axis (``/goal_pose``), deleted while there is none;
* ``reference``: an arrow along the ``/ee_reference`` point's x axis while one is tracked;
* ``ee_trail``: a line through the end effector's past positions (as the resolver measures
  them: ``/ee_pose`` or forward kinematics of ``/odom`` and ``/joint_states``);
* ``base_footprint``: the rectangle that holds the base's body boxes
  (:meth:`~wmm_control.kinematics.workspace.Workspace.footprint`) at the base's pose (``/odom``),
  on the floor.

Nothing non-finite goes out: the inputs are the resolver's validated ones.
"""

from __future__ import annotations


import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from visualization_msgs.msg import Marker, MarkerArray

from wmm_control.kinematics import KinematicModel
from wmm_control.geometry import quaternion_from_matrix, se2_transform_points
from wmm_control.kinematics.workspace import Workspace
from wmm_control.nodes.conversions import set_pose
from wmm_control.robot_config import RobotConfig
from wmm_control.viewer.scene import Trail

__all__ = ['MarkerSet', 'ResolverMarkers', 'MARKER_NAMESPACES']

MARKER_NAMESPACES = ('goal', 'reference', 'ee_trail', 'base_footprint')

_COLOURS = {
    'goal': (1.0, 0.0, 1.0),
    'reference': (0.55, 0.2, 0.9),
    'ee_trail': (0.1, 0.4, 1.0),
    'base_footprint': (0.1, 0.7, 0.2),
}


def _marker(stamp: Time, frame: str, namespace: str, kind: int) -> Marker:
    marker = Marker()
    marker.header.stamp = stamp
    marker.header.frame_id = frame
    marker.ns = namespace
    marker.id = 0
    marker.type = kind
    marker.action = Marker.ADD
    marker.pose.orientation.w = 1.0
    marker.color.r, marker.color.g, marker.color.b = _COLOURS[namespace]
    marker.color.a = 1.0
    return marker


def _points(xyz: np.ndarray) -> list[Point]:
    return [Point(x=float(x), y=float(y), z=float(z)) for x, y, z in xyz]


class MarkerSet:
    """Builds the resolver's MarkerArray.

    Args:
        frame: the world frame of every marker.
        footprint: the base's footprint corners in the base frame (4, 2) [m].
        floor_z: the floor's height [m] (the footprint is drawn there).
    """

    def __init__(self, frame: str, footprint: np.ndarray, floor_z: float) -> None:
        self.frame = frame
        self.footprint = np.asarray(footprint, dtype=float)
        self.floor_z = float(floor_z)

    def _arrow(self, stamp: Time, namespace: str, pose) -> Marker:
        marker = _marker(stamp, self.frame, namespace, Marker.ARROW)
        if pose is None:
            marker.action = Marker.DELETE
            return marker
        position, rotation = pose
        set_pose(marker.pose, position, quaternion_from_matrix(rotation))
        marker.scale.x, marker.scale.y, marker.scale.z = 0.15, 0.015, 0.015
        return marker

    def build(self, stamp: Time, goal, reference, trail: np.ndarray, base_pose) -> MarkerArray:
        """The MarkerArray of this instant.

        Args:
            goal, reference: ``(position (3,), rotation (3, 3))`` in the world, or None.
            trail: the end effector's past positions (n, 3) [m], oldest first.
            base_pose: the base's (x, y, θ) [m, m, rad], or None before odometry comes.
        """
        markers = [self._arrow(stamp, 'goal', goal), self._arrow(stamp, 'reference', reference)]
        line = _marker(stamp, self.frame, 'ee_trail', Marker.LINE_STRIP)
        line.scale.x = 0.005
        line.points = _points(trail) if len(trail) > 1 else []
        if len(line.points) < 2:
            line.action = Marker.DELETE
        markers.append(line)
        outline = _marker(stamp, self.frame, 'base_footprint', Marker.LINE_STRIP)
        outline.scale.x = 0.01
        if base_pose is None:
            outline.action = Marker.DELETE
        else:
            corners = se2_transform_points(base_pose, self.footprint)
            closed = np.vstack((corners, corners[:1]))
            outline.points = _points(np.column_stack((closed, np.full(len(closed), self.floor_z))))
        markers.append(outline)
        return MarkerArray(markers=markers)


class ResolverMarkers:
    """The markers of the resolver's state: its target and the measured end effector's trail.

    The trail follows the end effector as the resolver last measured it: the measured pose
    with ground-truth feedback, else forward kinematics of the base pose and arm joints, on a
    configuration of its own (its own ``pin.Data`` on the robot's one pinocchio model, which
    the resolver's shares: the markers' timer leaves the resolver's configuration as its cycle
    left it).

    Args:
        robot: the robot (the resolver's :class:`~wmm_control.robot_config.RobotConfig`, a
            name or a robot YAML path).
        frame: the world frame.
        workspace: the robot's :class:`~wmm_control.kinematics.workspace.Workspace` (footprint, floor).
    """

    def __init__(self, robot: str | RobotConfig, frame: str, workspace: Workspace) -> None:
        self.markers = MarkerSet(frame, workspace.footprint(), workspace.floor_z)
        self._model = KinematicModel(robot)
        self.trail = Trail(max_points=2000, min_step=0.005)

    def build(self, stamp: Time, last_state, target, tracking: bool) -> MarkerArray:
        """The MarkerArray of this instant.

        Args:
            last_state: the :class:`~wmm_control.resolvers.RobotState` of the resolver's last
                cycle, or None before one.
            target: the :class:`~wmm_control.resolvers.PoseTarget` pursued, or None.
            tracking: the target is a trajectory point (drawn as the reference, not the goal).
        """
        base = None
        if last_state is not None:
            base = last_state.base_pose
            self.trail.add(last_state.ee_placement(self._model, update=True)[0])
        pose = None if target is None else (target.position, target.rotation)
        return self.markers.build(
            stamp, None if tracking else pose, pose if tracking else None, self.trail.points, base
        )
