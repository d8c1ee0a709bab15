"""What the viewer makes of its inputs (ROS-free): which base pose it draws, where the base
heads, and the panel that says how fresh the inputs are.

The base is drawn at the simulator's ground truth while it is fresher than a timeout (judged
at receipt, on the viewer's steady clock), else at the odometry: a real robot has no ground
truth, and a simulator that stops publishing it should not freeze the view. The resolver's base
twist is drawn for a second after it came. Positions are metres, quaternions (w, x, y, z).
"""

from __future__ import annotations

import math

import numpy as np

from wmm_control.checks import Freshness
from wmm_control.geometry import twist_to_world, yaw_from_quaternion
from wmm_control.viewer.scene import xyzw_from_wxyz

__all__ = ['BASE_SOURCES', 'BasePose', 'BaseCourse', 'inputs_markdown']

#: The base pose's sources, preferred first.
BASE_SOURCES = ('ground_truth', 'odom')

_SOURCE_TEXT = {
    'ground_truth': 'the simulator\'s ground truth (/ground_truth/odom)',
    'odom': 'odometry (/odom)',
    'none': 'none yet (drawn at the origin)',
}


class BasePose:
    """The latest base pose of each source, and the one to draw.

    Args:
        timeout: how long [s] after its receipt the ground truth is preferred to odometry.
    """

    def __init__(self, timeout: float) -> None:
        self.fresh = {k: Freshness(timeout) for k in BASE_SOURCES}
        self._pose: dict[str, tuple[np.ndarray, np.ndarray] | None] = {k: None for k in BASE_SOURCES}

    def set_timeout(self, timeout: float) -> None:
        """Prefer the ground truth for ``timeout`` [s] after its receipt from now on."""
        for fresh in self.fresh.values():
            fresh.timeout = float(timeout)

    def take(self, source: str, position: np.ndarray, wxyz: np.ndarray, now: float) -> None:
        """A pose of ``source`` ('ground_truth' or 'odom') received at ``now`` [s]."""
        self._pose[source] = (position, wxyz)
        self.fresh[source].mark(now)

    def source(self, now: float) -> str:
        """Where the pose drawn at ``now`` [s] comes from: 'ground_truth' while it is fresh, else
        'odom' once there is one, else a stale ground truth, else 'none'."""
        if self._pose['ground_truth'] is not None and self.fresh['ground_truth'].fresh(now):
            return 'ground_truth'
        if self._pose['odom'] is not None:
            return 'odom'
        return 'ground_truth' if self._pose['ground_truth'] is not None else 'none'

    def pose(self, now: float) -> tuple[np.ndarray, np.ndarray]:
        """The pose drawn at ``now`` [s]: (position, wxyz); the origin before any pose came."""
        pose = self._pose.get(self.source(now))
        return pose if pose is not None else (np.zeros(3), np.array([1.0, 0.0, 0.0, 0.0]))


class BaseCourse:
    """The base twist the resolver asks for, and the world velocity it drives the base at.

    Args:
        hold: how long [s] after its receipt a twist is drawn.
    """

    def __init__(self, hold: float = 1.0) -> None:
        self._twist: np.ndarray | None = None
        self._fresh = Freshness(hold)

    def take(self, twist: np.ndarray, now: float) -> None:
        """A planar twist (vx, vy, ω) [m/s, m/s, rad/s] in the base frame received at ``now`` [s];
        a non-finite one is ignored."""
        if np.all(np.isfinite(twist)):
            self._twist = np.asarray(twist, dtype=float)
            self._fresh.mark(now)

    def velocity(self, base_wxyz: np.ndarray, now: float) -> np.ndarray | None:
        """The world velocity (vx, vy) [m/s] of the base turned by ``base_wxyz``; None when no
        twist is fresh at ``now`` [s] or it does not translate."""
        twist = self._twist
        if twist is None or not self._fresh.fresh(now) or not np.any(twist[:2]):
            return None
        yaw = yaw_from_quaternion(xyzw_from_wxyz(base_wxyz))
        return twist_to_world(yaw, (twist[0], twist[1], 0.0))[:2]


def inputs_markdown(joint_age: float, source: str, rejected: int, goals_sent: int) -> str:
    """The inputs panel: the joint states' age [s] (infinite: never), the base pose's source
    (:meth:`BasePose.source`), and the joint states rejected and goals sent so far."""
    age = 'never' if joint_age == math.inf else f'{joint_age:.2f} s ago'
    return '\n'.join(
        [
            f'- joint states: {age}',
            f'- base pose from {_SOURCE_TEXT[source]}',
            f'- joint states rejected: {rejected}',
            f'- goals sent: {goals_sent}',
        ]
    )
