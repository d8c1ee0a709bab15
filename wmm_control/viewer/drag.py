"""When a dragged goal handle publishes (ROS-free).

A drag sends pose updates many times a second. The goal goes out once when the handle is
released, and while it is dragged at most once per ``period`` (the first ``period`` after the
drag began, then every ``period``): the resolver does not restart its goal progress at every
pixel, and a long drag still moves the robot. A client that reports no release publishes once
``period`` after its first update, then every ``period`` while updates come.
"""

from __future__ import annotations

import threading

import numpy as np

from wmm_control.viewer.scene import finite_pose

__all__ = ['GoalDrag']


class GoalDrag:
    """Pose updates of a dragged handle in (any thread), goals to publish out (:meth:`due`).

    Args:
        period: the shortest time [s] between two goals while a drag goes on.
    """

    def __init__(self, period: float) -> None:
        self.period = float(period)
        self._lock = threading.Lock()
        self._pending: tuple[np.ndarray, np.ndarray] | None = None
        self._since = 0.0
        self._released = False
        self.dragging = False

    def start(self) -> None:
        """The handle was grabbed."""
        with self._lock:
            self.dragging = True

    def update(self, position, wxyz, now: float) -> bool:
        """The handle is at ``position``, ``wxyz`` at time ``now`` [s]; False (ignored) when not a pose."""
        pose = finite_pose(position, wxyz)
        if pose is None:
            return False
        with self._lock:
            if self._pending is None:
                self._since = now
            self._pending = pose
        return True

    def end(self, position, wxyz, now: float) -> None:
        """The handle was released at ``position``, ``wxyz``."""
        self.update(position, wxyz, now)
        with self._lock:
            self.dragging = False
            self._released = True

    def event(self, phase: str, position, wxyz, now: float) -> None:
        """One event of the handle at time ``now`` [s]: ``phase`` 'start' (grabbed; the pose is
        not taken), 'end' (released at the pose), else an update to the pose."""
        if phase == 'start':
            self.start()
        elif phase == 'end':
            self.end(position, wxyz, now)
        else:
            self.update(position, wxyz, now)

    def due(self, now: float) -> tuple[np.ndarray, np.ndarray] | None:
        """The goal (position, unit wxyz) to publish now, or None."""
        with self._lock:
            if self._pending is None:
                self._released = False
                return None
            if not (self._released or now - self._since >= self.period):
                return None
            pose, self._pending, self._released = self._pending, None, False
            return pose
