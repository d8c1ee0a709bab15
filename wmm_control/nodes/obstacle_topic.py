"""The obstacles a node keeps: those of its ``obstacles`` file, and those published live on
``/obstacles`` (``visualization_msgs/MarkerArray``, the message rviz already draws).

A marker is one obstacle, named ``<ns>/<id>``, in the node's world frame:

* ``CUBE``: a box, ``scale`` its edge lengths (x, y, z) [m];
* ``SPHERE``: a sphere of diameter ``scale.x`` (= y = z; unequal, the largest is taken);
* ``CYLINDER``: a cylinder along its z axis, diameter ``scale.x`` (= y; unequal, the largest),
  length ``scale.z``;
* ``pose``: its centre and orientation (the quaternion is normalised).

``action`` ADD (or MODIFY) adds or replaces the obstacle of that ``ns``/``id``, DELETE removes
it, DELETEALL removes every live one (the file's stay). ``lifetime`` is not honoured: an
obstacle stays until deleted. A marker of another type or frame, or with a non-finite or
non-positive size, is rejected with a logged reason; the array's other markers still apply.
"""

from __future__ import annotations

import numpy as np
from visualization_msgs.msg import Marker

from wmm_control.errors import ConfigError
from wmm_control.kinematics.obstacles import Obstacle, load_obstacles
from wmm_control.geometry import matrix_from_quaternion, unit_quaternion
from wmm_control.nodes.conversions import pose_values

__all__ = ['ObstacleSet', 'obstacle_from_marker', 'describe', 'OBSTACLE_PARAM_HELP']

#: The ``obstacles`` parameter's description (the resolver's and the simulator's).
OBSTACLE_PARAM_HELP = (
    'Obstacle file: a name in config/obstacles or a YAML path ("" for none); /obstacles '
    '(visualization_msgs/MarkerArray) adds and removes obstacles live.'
)


def obstacle_from_marker(marker, frame: str) -> Obstacle:
    """The obstacle of an ADD ``marker`` in the world frame ``frame``.

    Raises:
        ConfigError: another frame or type, or a non-finite or bad size or pose.
    """
    name = f'{marker.ns}/{marker.id}'
    if marker.header.frame_id != frame:
        raise ConfigError(f'marker {name}: frame {marker.header.frame_id!r}, expected {frame!r}')
    s, pose = marker.scale, pose_values(marker.pose)
    size: tuple[float, ...]
    if marker.type == Marker.CUBE:
        shape, size = 'box', (s.x, s.y, s.z)
    elif marker.type == Marker.SPHERE:
        shape, size = 'sphere', (0.5 * max(s.x, s.y, s.z),)
    elif marker.type == Marker.CYLINDER:
        shape, size = 'cylinder', (0.5 * max(s.x, s.y), s.z)
    else:
        raise ConfigError(f'marker {name}: type {marker.type} is not an obstacle (CUBE, SPHERE or CYLINDER)')
    quat = unit_quaternion(pose[3:])[0] if np.all(np.isfinite(pose[3:])) else None
    if quat is None:
        raise ConfigError(f'marker {name}: the orientation must be a finite, non-zero quaternion')
    return Obstacle(name, shape, tuple(float(v) for v in size), pose[:3], matrix_from_quaternion(quat))


class ObstacleSet:
    """The file's obstacles and the live ones, in the world frame ``frame``.

    Args:
        file: the ``obstacles`` parameter (name or path; '' for none).
        frame: the world frame the markers must be in.

    Raises:
        ConfigError: the file is missing or invalid.
    """

    def __init__(self, file: str, frame: str):
        self.frame = frame
        self.fixed = load_obstacles(file)
        self.live: dict[str, Obstacle] = {}

    @property
    def obstacles(self) -> tuple[Obstacle, ...]:
        """Every obstacle: the file's, then the live ones."""
        return self.fixed + tuple(self.live.values())

    def apply(self, msg) -> tuple[bool, list[str]]:
        """Take a ``MarkerArray``: ``(whether the obstacles changed, why markers were rejected)``."""
        before, errors = dict(self.live), []
        for marker in msg.markers:
            name = f'{marker.ns}/{marker.id}'
            if marker.action == Marker.DELETEALL:
                self.live.clear()
            elif marker.action == Marker.DELETE:
                self.live.pop(name, None)
            elif marker.action == Marker.ADD:  # (MODIFY is the same value)
                try:
                    self.live[name] = obstacle_from_marker(marker, self.frame)
                except ConfigError as exc:
                    errors.append(str(exc))
            else:
                errors.append(f'marker {name}: unknown action {marker.action}')
        changed = before.keys() != self.live.keys() or any(not _same(before[k], self.live[k]) for k in before)
        return changed, errors

    def take(self, msg, logger) -> bool:
        """:meth:`apply` ``msg``, logging each rejected marker and the new obstacles to
        ``logger``; True when they changed."""
        changed, errors = self.apply(msg)
        for error in errors:
            logger.warn(f'rejected /obstacles {error}', throttle_duration_sec=1.0)
        if changed:
            logger.info(f'now {describe(self.obstacles)}')
        return changed


def _same(a: Obstacle, b: Obstacle) -> bool:
    return (
        a.shape == b.shape
        and a.size == b.size
        and np.array_equal(a.position, b.position)
        and np.array_equal(a.rotation, b.rotation)
    )


def describe(obstacles) -> str:
    """One line naming ``obstacles``, for the log."""
    if not obstacles:
        return 'no obstacles'
    return f'{len(obstacles)} obstacles: ' + ', '.join(f'{o.name} ({o.shape})' for o in obstacles)
