"""The obstacles a node keeps: those of its ``obstacles`` file, and those published live on
``/obstacles`` (``visualization_msgs/MarkerArray``, the message rviz already draws). Every node
that takes ``/obstacles`` (``wmm_sim``, ``redundancy_resolver``, ``goal_planner``,
``wmm_viewer``) takes it here, with the same parameters (:func:`obstacle_params`).

A marker is one obstacle, named ``<ns>/<id>``, in the node's world frame:

* ``CUBE``: a box, ``scale`` its edge lengths (x, y, z) [m];
* ``SPHERE``: a sphere of diameter ``scale.x`` (= y = z; unequal, the largest is taken);
* ``CYLINDER``: a cylinder along its z axis, diameter ``scale.x`` (= y; unequal, the largest),
  length ``scale.z``;
* ``pose``: its centre and orientation.

``action`` ADD (or MODIFY) adds or replaces the obstacle of that ``ns``/``id``, DELETE removes
it, DELETEALL removes every live one (the file's stay). ``lifetime`` is not honoured: an
obstacle stays until deleted.

Bad input (:meth:`ObstacleSet.take`; each a throttled warning, the obstacles as they were):

* an empty message is ignored: nothing to add or remove;
* a message of more than ``max_obstacles`` markers is refused whole, none of them applied;
* a marker of another frame or type, an unknown action, a ``scale`` entry that is not finite
  and > 0, a size or centre beyond :data:`~wmm_control.kinematics.obstacles.MAX_EXTENT`, or
  a quaternion that is not finite or is zero, is rejected (the message's other markers still
  apply). A quaternion of another norm is normalised, with a warning when it is off 1 by
  more than 1e-3 (as a goal's is): an obstacle dropped for it would leave the robot free to
  drive into it.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from visualization_msgs.msg import Marker

from wmm_control.errors import ConfigError
from wmm_control.kinematics.obstacles import Obstacle, load_obstacles
from wmm_control.geometry import matrix_from_quaternion
from wmm_control.nodes.conversions import pose_values
from wmm_control.nodes.parameters import Param
from wmm_control.resolvers.targets import checked_quaternion

__all__ = ['ObstacleSet', 'Applied', 'obstacle_from_marker', 'obstacle_params', 'describe']

#: How often [s] each kind of warning about ``/obstacles`` is logged at most.
WARN_INTERVAL = 1.0
#: The most rejected markers of one message named in its warning.
NAMED = 3


def obstacle_params() -> tuple[Param, Param]:
    """The ``obstacles`` and ``max_obstacles`` parameters of every node that takes
    ``/obstacles`` (their defaults in each node's YAML, the same in all)."""
    return (
        Param(
            'obstacles',
            'Obstacle file: a name in config/obstacles or a YAML path ("" for none); /obstacles '
            '(visualization_msgs/MarkerArray) adds and removes obstacles live.',
            read_only=True,
        ),
        Param(
            'max_obstacles',
            'An /obstacles message of more markers than this is refused whole (none applied); the obstacles stay as '
            'they were.',
            lo=1,
            hi=100000,
        ),
    )


def obstacle_from_marker(marker, frame: str) -> tuple[Obstacle, str]:
    """The obstacle of an ADD ``marker`` in the world frame ``frame``, and '' or the warning
    that its quaternion was normalised.

    Raises:
        ConfigError: another frame or type, a bad scale, size or pose (module docstring); the
            size and the centre are checked by :class:`~wmm_control.kinematics.obstacles.Obstacle`.
    """
    name = f'{marker.ns}/{marker.id}'
    if marker.header.frame_id != frame:
        raise ConfigError(f'marker {name}: frame {marker.header.frame_id!r}, expected {frame!r}')
    if marker.type not in (Marker.CUBE, Marker.SPHERE, Marker.CYLINDER):
        raise ConfigError(f'marker {name}: type {marker.type} is not an obstacle (CUBE, SPHERE or CYLINDER)')
    s, pose = marker.scale, pose_values(marker.pose)
    # every entry checked before the largest is taken: max() passes over a NaN or a negative one
    scale = (s.x, s.y, s.z)
    if not all(math.isfinite(v) and v > 0.0 for v in scale):
        raise ConfigError(f'marker {name}: scale {list(scale)} must be finite and > 0 [m]')
    size: tuple[float, ...]
    if marker.type == Marker.CUBE:
        shape, size = 'box', scale
    elif marker.type == Marker.SPHERE:
        shape, size = 'sphere', (0.5 * max(scale),)
    else:
        shape, size = 'cylinder', (0.5 * max(s.x, s.y), s.z)
    quat, events = checked_quaternion(pose[3:], f'marker {name}:') if np.all(np.isfinite(pose[3:])) else (None, [])
    if quat is None:
        raise ConfigError(f'marker {name}: the orientation must be a finite, non-zero quaternion')
    obstacle = Obstacle(name, shape, tuple(float(v) for v in size), pose[:3], matrix_from_quaternion(quat))
    return obstacle, events[0].message if events else ''


@dataclass(frozen=True)
class Applied:
    """What a ``MarkerArray`` did to an :class:`ObstacleSet`: whether the obstacles changed,
    why markers were rejected, and which quaternions were normalised."""

    changed: bool
    rejected: tuple[str, ...] = ()
    normalised: tuple[str, ...] = ()


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

    def apply(self, msg) -> Applied:
        """Apply each marker of a ``MarkerArray`` (module docstring), a bad one rejected."""
        before, rejected, normalised = dict(self.live), [], []
        for marker in msg.markers:
            name = f'{marker.ns}/{marker.id}'
            if marker.action == Marker.DELETEALL:
                self.live.clear()
            elif marker.action == Marker.DELETE:
                self.live.pop(name, None)
            elif marker.action == Marker.ADD:  # (MODIFY is the same value)
                try:
                    self.live[name], note = obstacle_from_marker(marker, self.frame)
                except ConfigError as exc:
                    rejected.append(str(exc))
                    continue
                if note:
                    normalised.append(note)
            else:
                rejected.append(f'marker {name}: unknown action {marker.action}')
        changed = before.keys() != self.live.keys() or any(not _same(before[k], self.live[k]) for k in before)
        return Applied(changed, tuple(rejected), tuple(normalised))

    def take(self, msg, logger, max_markers: int) -> bool:
        """Take a ``MarkerArray`` from ``/obstacles``: True when the obstacles changed.

        An empty message, or one of more than ``max_markers`` markers (the ``max_obstacles``
        parameter), changes nothing; else :meth:`apply`. Each refusal, the rejected markers
        (the first :data:`NAMED` by name) and the normalised quaternions are warnings on
        ``logger``, each kind at most once per :data:`WARN_INTERVAL`; the new obstacles are
        logged.
        """
        # one call site per kind: rclpy throttles by call site
        if not msg.markers:
            logger.warn(
                'ignored an empty /obstacles message: nothing to add or remove', throttle_duration_sec=WARN_INTERVAL
            )
            return False
        if len(msg.markers) > max_markers:
            logger.warn(
                f'rejected /obstacles: {len(msg.markers)} markers, more than max_obstacles {max_markers}; '
                'the obstacles stay as they were',
                throttle_duration_sec=WARN_INTERVAL,
            )
            return False
        applied = self.apply(msg)
        if applied.rejected:
            more = len(applied.rejected) - NAMED
            logger.warn(
                'rejected /obstacles '
                + '; '.join(applied.rejected[:NAMED])
                + (f' (and {more} more markers)' if more > 0 else ''),
                throttle_duration_sec=WARN_INTERVAL,
            )
        if applied.normalised:
            logger.warn(f'/obstacles {applied.normalised[0]}', throttle_duration_sec=WARN_INTERVAL)
        if applied.changed:
            logger.info(f'now {describe(self.obstacles)}')
        return applied.changed


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
